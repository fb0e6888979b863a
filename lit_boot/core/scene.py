"""The scene: one video of one person, its pose estimates and optional ground truth.

Shapes: T frames of H x W pixels; J 3D joints in ``joints3d_layout``; K 2D keypoints in
``keypoints_layout``. Units: pixels (pixel centres at integer coordinates), millimetres in the
camera frame (x right, y down, z forward). Flows are forward flows from frame t to t+1.

Every field is checked on construction; a bad one raises :class:`SceneValidationError`
naming the field and what was expected.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import torch

from .cameras import Cameras
from .joints import get_layout

__all__ = ["Scene", "GroundTruth", "SceneValidationError", "check_estimates", "POSE_MODES"]

#: The method's two modes: "3d" works from 3D joints with cameras, "2d" from 2D keypoints alone.
POSE_MODES = ("3d", "2d")


class SceneValidationError(ValueError):
    """A scene field has the wrong shape, dtype or values."""


def _check(name: str, value: Any, shape: tuple, kind: str) -> None:
    """Check a tensor's shape (None in ``shape`` = any size), dtype kind and finiteness."""
    if not isinstance(value, torch.Tensor):
        raise SceneValidationError(f"{name}: expected a torch.Tensor, got {type(value).__name__}")
    want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
    if value.ndim != len(shape) or any(s is not None and s != v for s, v in zip(shape, value.shape)):
        raise SceneValidationError(f"{name}: expected shape {want}, got {tuple(value.shape)}")
    if kind == "uint8" and value.dtype != torch.uint8:
        raise SceneValidationError(f"{name}: expected dtype uint8, got {value.dtype}")
    if kind == "bool" and value.dtype != torch.bool:
        raise SceneValidationError(f"{name}: expected dtype bool, got {value.dtype}")
    if kind == "float":
        if not value.is_floating_point():
            raise SceneValidationError(f"{name}: expected a floating-point dtype, got {value.dtype}")
        if not torch.isfinite(value).all():
            raise SceneValidationError(f"{name}: expected finite values, found NaN or inf")


def _check_cameras(name: str, cameras: Any, T: int) -> None:
    if not isinstance(cameras, Cameras):
        raise SceneValidationError(f"{name}: expected a lit_boot Cameras, got {type(cameras).__name__}")
    _check(f"{name}.params", cameras.params, (T, cameras.params.shape[1]), "float")
    if cameras.crops is not None:
        _check(f"{name}.crops", cameras.crops, (T, 3), "float")


def check_estimates(owner: str, est: Any, T: int) -> None:
    """Check the pose-estimate fields of ``est`` (a Scene or alike: joints3d, joints3d_layout,
    cameras, keypoints2d, keypoints_conf, keypoints_layout) for T frames; errors name
    ``owner.field``."""
    for key in ("joints3d_layout", "keypoints_layout"):
        try:
            get_layout(getattr(est, key))
        except ValueError as err:
            raise SceneValidationError(f"{owner}.{key}: {err}") from None
    if est.joints3d is not None:
        J = get_layout(est.joints3d_layout).num_joints
        _check(f"{owner}.joints3d", est.joints3d, (T, J, 3), "float")
    if est.cameras is not None:
        _check_cameras(f"{owner}.cameras", est.cameras, T)
    if (est.keypoints2d is None) != (est.keypoints_conf is None):
        raise SceneValidationError(f"{owner}.keypoints2d and {owner}.keypoints_conf: give both or neither")
    if est.keypoints2d is not None:
        K = get_layout(est.keypoints_layout).num_joints
        _check(f"{owner}.keypoints2d", est.keypoints2d, (T, K, 2), "float")
        _check(f"{owner}.keypoints_conf", est.keypoints_conf, (T, K), "float")
        if (est.keypoints_conf < 0).any() or (est.keypoints_conf > 1).any():
            raise SceneValidationError(f"{owner}.keypoints_conf: expected values in [0, 1]")
    boxes = getattr(est, "person_boxes", None)
    if boxes is not None:
        _check(f"{owner}.person_boxes", boxes, (T, 5), "float")
        if (boxes[:, 4] < 0).any() or (boxes[:, 4] > 1).any():
            raise SceneValidationError(f"{owner}.person_boxes: expected scores (column 4) in [0, 1]")
        found = boxes[:, 4] > 0
        if ((boxes[found, 2:4] < boxes[found, 0:2])).any():
            raise SceneValidationError(f"{owner}.person_boxes: expected x0 <= x1 and y0 <= y1 where a person is found")


@dataclass
class GroundTruth:
    """Ground truth of a scene; every field is optional.

    flow (T-1, 2, H, W) px, forward t -> t+1; flow_valid (T-1, H, W) bool (where the flow is
    defined); flow_occluded (T-1, H, W) bool (pixels hidden in frame t+1); joints3d (T, J, 3) mm
    camera frame and joints2d (T, J, 2) px in ``joints_layout``; cameras: the true cameras that
    project joints3d to joints2d; person_mask (T, H, W) bool; keypoints2d (T, K, 2) px: the
    true positions of the scene's 2D keypoints (in the scene's ``keypoints_layout``).
    """

    flow: torch.Tensor | None = None
    flow_valid: torch.Tensor | None = None
    flow_occluded: torch.Tensor | None = None
    joints3d: torch.Tensor | None = None
    joints2d: torch.Tensor | None = None
    joints_layout: str = "lsp14"
    cameras: Cameras | None = None
    person_mask: torch.Tensor | None = None
    keypoints2d: torch.Tensor | None = None

    def flow_mask(self) -> torch.Tensor | None:
        """Where a flow is scored against ``flow`` (lit-boot's one convention, for FlowTTT's
        validation and the orchestrator's metrics alike): valid and not occluded, (T-1, H, W)
        bool; None without a GT flow. (Sintel's "all" counts the occluded pixels too.)"""
        if self.flow is None:
            return None
        mask = self.flow_valid if self.flow_valid is not None else torch.ones_like(self.flow[:, 0], dtype=torch.bool)
        return mask & ~self.flow_occluded if self.flow_occluded is not None else mask

    def validate(self, T: int, H: int, W: int, keypoints_layout: str = "coco17") -> None:
        """Check every present field against the scene's T, H, W and keypoint layout."""
        try:
            J = get_layout(self.joints_layout).num_joints
        except ValueError as err:
            raise SceneValidationError(f"GroundTruth.joints_layout: {err}") from None
        K = get_layout(keypoints_layout).num_joints
        checks = {
            "flow": ((T - 1, 2, H, W), "float"),
            "flow_valid": ((T - 1, H, W), "bool"),
            "flow_occluded": ((T - 1, H, W), "bool"),
            "joints3d": ((T, J, 3), "float"),
            "joints2d": ((T, J, 2), "float"),
            "person_mask": ((T, H, W), "bool"),
            "keypoints2d": ((T, K, 2), "float"),
        }
        for key, (shape, kind) in checks.items():
            value = getattr(self, key)
            if value is not None:
                _check(f"GroundTruth.{key}", value, shape, kind)
        if self.cameras is not None:
            _check_cameras("GroundTruth.cameras", self.cameras, T)


@dataclass
class Scene:
    """One video of one person with pose estimates and optional ground truth.

    frames (T, 3, H, W) uint8 RGB; fps frames per second.
    joints3d (T, J, 3) mm in the camera frame (root-relative when the camera model is
    weak perspective), ``joints3d_layout`` names the joints; cameras: per-frame cameras.
    keypoints2d (T, K, 2) px with keypoints_conf (T, K) in [0, 1] (0 = not detected).
    person_boxes (T, 5): the person's box per frame from a person detector, (x0, y0, x1, y1) px
    (pixel centres at integer coordinates, the box's outer edges) and a score in [0, 1] (0 =
    nobody found).
    """

    frames: torch.Tensor
    fps: float = 30.0
    name: str = "scene"
    joints3d: torch.Tensor | None = None
    joints3d_layout: str = "lsp14"
    cameras: Cameras | None = None
    keypoints2d: torch.Tensor | None = None
    keypoints_conf: torch.Tensor | None = None
    keypoints_layout: str = "coco17"
    gt: GroundTruth | None = None
    metadata: dict[str, Any] = field(default_factory=dict)
    person_boxes: torch.Tensor | None = None

    def __post_init__(self) -> None:
        self.validate()

    @property
    def num_frames(self) -> int:
        return self.frames.shape[0]

    @property
    def height(self) -> int:
        return self.frames.shape[2]

    @property
    def width(self) -> int:
        return self.frames.shape[3]

    def validate(self) -> None:
        """Check all fields; raises :class:`SceneValidationError`."""
        _check("Scene.frames", self.frames, (None, 3, None, None), "uint8")
        T, _, H, W = self.frames.shape
        if T < 1:
            raise SceneValidationError("Scene.frames: expected at least one frame, got T=0")
        if not (isinstance(self.fps, (int, float)) and self.fps > 0):
            raise SceneValidationError(f"Scene.fps: expected a positive number, got {self.fps!r}")
        check_estimates("Scene", self, T)
        if self.gt is not None:
            if not isinstance(self.gt, GroundTruth):
                raise SceneValidationError(f"Scene.gt: expected a GroundTruth, got {type(self.gt).__name__}")
            self.gt.validate(T, H, W, self.keypoints_layout)

    # --- the pose in the method's two modes (the one place the 3D/2D switch is made) --------------
    def require_pose(self, mode: str) -> None:
        """Raise ValueError (naming the scene) unless it has the pose ``mode`` works from: "3d",
        3D joints with cameras; "2d", 2D keypoints with a confidence above 0 somewhere, or a
        person box. Keypoints of confidence 0 everywhere and no person box (the estimators found
        nobody) are named as such."""
        if mode not in POSE_MODES:
            raise ValueError(f"mode: expected one of {POSE_MODES}, got {mode!r}")
        nobody = self.keypoints_conf is not None and not bool((self.keypoints_conf > 0).any())
        nobody &= self.person_boxes is None or not bool((self.person_boxes[:, 4] > 0).any())
        if nobody and (mode == "2d" or self.joints3d is None):
            raise ValueError(f"scene {self.name!r}: no person in any frame (every keypoint has confidence 0: the "
                             "pose estimator found nobody), so there is nothing to bootstrap")  # fmt: skip
        if mode == "3d" and (self.joints3d is None or self.cameras is None):
            no_pose = self.keypoints_conf is not None and not bool((self.keypoints_conf > 0).any())
            why = (" and the pose estimator found no pose in any frame (only the person detector's boxes; in "
                   "mode '2d' the zoom stage still works on them)" if no_pose else " (use mode '2d')")
            raise ValueError(f"scene {self.name!r}: 3D mode needs 3D joints with cameras{why}")
        if mode == "2d" and self.keypoints2d is None:
            raise ValueError(f"scene {self.name!r}: 2D mode needs 2D keypoints")

    def pose_points(self, mode: str, threshold: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
        """The pose as image points in ``mode``: (T, K, 2) px float and a (T, K) bool of the
        points that count. "3d": the 3D joints projected by the cameras (every joint counts);
        "2d": the keypoints (those with confidence above ``threshold`` count)."""
        self.require_pose(mode)
        if mode == "3d":
            points = self.cameras.project(self.joints3d.float())
            return points, torch.ones(points.shape[:2], dtype=torch.bool)
        conf = self.keypoints_conf
        keep = conf > threshold if conf is not None else torch.ones(self.keypoints2d.shape[:2], dtype=torch.bool)
        return self.keypoints2d.float(), keep

    def pose_layout(self, mode: str) -> str:
        """The joint layout of the pose ``mode`` works from (3D joints' or keypoints')."""
        if mode not in POSE_MODES:
            raise ValueError(f"mode: expected one of {POSE_MODES}, got {mode!r}")
        return self.joints3d_layout if mode == "3d" else self.keypoints_layout

    def summary(self) -> str:
        """A few human-readable lines describing the scene."""
        T, H, W = self.num_frames, self.height, self.width
        lines = [f"scene {self.name!r}: {T} frames, {W}x{H} px, {self.fps:g} fps"]
        if self.joints3d is not None:
            cam = f", cameras: {self.cameras.model}" if self.cameras is not None else ""
            lines.append(f"  3D joints: {self.joints3d_layout} ({self.joints3d.shape[1]} joints){cam}")
        if self.keypoints2d is not None:
            mean_conf = self.keypoints_conf.float().mean().item()
            found = int((self.keypoints_conf > 0).flatten(1).any(1).sum())
            lines.append(f"  2D keypoints: {self.keypoints_layout}, mean confidence {mean_conf:.2f}"
                         f" (a person in {found} of {T} frames)")
        if self.person_boxes is not None:
            lines.append(f"  person boxes: in {int((self.person_boxes[:, 4] > 0).sum())} of {T} frames")
        if self.gt is not None:
            have = [k for k in ("flow", "flow_occluded", "joints3d", "joints2d", "keypoints2d", "person_mask", "cameras")
                    if getattr(self.gt, k) is not None]  # fmt: skip
            lines.append(f"  ground truth: {', '.join(have) if have else 'none'}")
            if self.gt.flow is not None:
                valid, mag = self.gt.flow_valid, self.gt.flow.norm(dim=1)
                pairs = ""
                if valid is not None:
                    mag = mag[valid]
                    pairs = f" (valid pixels; GT on {int(valid.flatten(1).any(1).sum())} of {len(valid)} pairs)"
                if mag.numel():
                    stats = f"mean {mag.mean().item():.2f} px, max {mag.max().item():.2f} px"
                    lines.append(f"  GT flow magnitude: {stats}{pairs}")
                else:
                    lines.append("  GT flow: valid nowhere")
        return "\n".join(lines)
