"""The scene: one video of one or more people, their pose estimates and optional ground truth.

Shapes: T frames of H x W pixels; J 3D joints in ``joints3d_layout``; K 2D keypoints in
``keypoints_layout``. Units: pixels (pixel centres at integer coordinates), millimetres in the
camera frame (x right, y down, z forward). Flows are forward flows from frame t to t+1.

Every field is checked on construction; a bad one raises :class:`SceneValidationError`
naming the field and what was expected.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import torch

from .cameras import Cameras
from .checks import SceneValidationError, check_cameras, check_estimates, check_tensor
from .joints import get_layout
from .people import Person, check_people

__all__ = ["Scene", "GroundTruth", "PersonTruth", "SceneValidationError", "check_estimates", "POSE_MODES"]

#: The method's two modes: "3d" works from 3D joints with cameras, "2d" from 2D keypoints alone.
POSE_MODES = ("3d", "2d")


@dataclass
class PersonTruth:
    """The ground truth of one of a scene's other people (``GroundTruth.others``); every tensor
    is optional, but all of a scene's others have the same ones.

    track_id: the person's track id (as in ``Scene.others``); joints3d (T, J, 3) mm camera frame
    and joints2d (T, J, 2) px in the GroundTruth's ``joints_layout``; keypoints2d (T, K, 2) px in
    the scene's ``keypoints_layout``; person_mask (T, H, W) bool: where this person is the
    visible surface (inside GroundTruth.person_mask, disjoint from the other people's).
    """

    track_id: int
    joints3d: torch.Tensor | None = None
    joints2d: torch.Tensor | None = None
    keypoints2d: torch.Tensor | None = None
    person_mask: torch.Tensor | None = None


@dataclass
class GroundTruth:
    """Ground truth of a scene; every field is optional.

    flow (T-1, 2, H, W) px, forward t -> t+1; flow_valid (T-1, H, W) bool (where the flow is
    defined); flow_occluded (T-1, H, W) bool (pixels hidden in frame t+1); joints3d (T, J, 3) mm
    camera frame and joints2d (T, J, 2) px in ``joints_layout``; cameras: the true cameras that
    project joints3d to joints2d; person_mask (T, H, W) bool (every person); keypoints2d (T, K, 2)
    px: the true positions of the scene's 2D keypoints (in the scene's ``keypoints_layout``).
    joints3d, joints2d and keypoints2d are the main person's; ``others`` holds the other
    people's (:class:`PersonTruth`, each with its own visible mask).
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
    others: tuple[PersonTruth, ...] = ()

    def flow_mask(self) -> torch.Tensor | None:
        """Where a flow is scored against ``flow`` (lit-boot's one convention, for FlowTTT's
        validation and the orchestrator's metrics alike): valid and not occluded, (T-1, H, W)
        bool; None without a GT flow. (Sintel's "all" counts the occluded pixels too.)"""
        if self.flow is None:
            return None
        mask = self.flow_valid if self.flow_valid is not None else torch.ones_like(self.flow[:, 0], dtype=torch.bool)
        return mask & ~self.flow_occluded if self.flow_occluded is not None else mask

    def unmatched_mask(self) -> torch.Tensor | None:
        """The valid pixels occluded in frame t+1 (Sintel's "unmatched"), (T-1, H, W) bool; None
        without a GT flow or without occlusions. With :meth:`flow_mask` (the matched pixels) they
        make Sintel's "all"."""
        if self.flow is None or self.flow_occluded is None:
            return None
        mask = self.flow_valid if self.flow_valid is not None else torch.ones_like(self.flow[:, 0], dtype=torch.bool)
        return mask & self.flow_occluded

    def truths(self, track_ids: Sequence[int]) -> list[PersonTruth | None]:
        """Each person's truth, in ``track_ids`` order: the first id is the main person (this
        GroundTruth's own joints and keypoints; its visible mask the person mask less the
        others'), the rest are looked up in ``others`` by track id (None: no ground truth)."""
        by_id = {person.track_id: person for person in self.others}
        mask = self.person_mask
        if mask is not None and self.others and all(o.person_mask is not None for o in self.others):
            mask = mask & ~torch.stack([o.person_mask for o in self.others]).any(0)
        main = PersonTruth(int(track_ids[0]), self.joints3d, self.joints2d, self.keypoints2d, mask)
        return [main, *(by_id.get(int(i)) for i in track_ids[1:])]

    def with_main(self, track_id: int, main_id: int) -> GroundTruth:
        """This ground truth with person ``track_id`` (one of ``others``) as the main person and
        the main one (track ``main_id``, its mask its own visible part) among the others, where it
        was; itself when ``track_id`` has no truth here or the two do not have the same fields."""
        new = next((o for o in self.others if o.track_id == track_id), None)
        old = self.truths([main_id])[0]
        fields = ("joints3d", "joints2d", "keypoints2d", "person_mask")
        if new is None or any((getattr(new, k) is None) != (getattr(old, k) is None) for k in fields):
            return self
        others = tuple(old if o.track_id == track_id else o for o in self.others)
        return dataclasses.replace(self, joints3d=new.joints3d, joints2d=new.joints2d, keypoints2d=new.keypoints2d,
                                   others=others)  # fmt: skip

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
                check_tensor(f"GroundTruth.{key}", value, shape, kind)
        if self.cameras is not None:
            check_cameras("GroundTruth.cameras", self.cameras, T)
        self._validate_others({key: checks[key] for key in ("joints3d", "joints2d", "keypoints2d", "person_mask")})

    def _validate_others(self, checks: dict[str, tuple[tuple, str]]) -> None:
        """Check ``others`` against the per-person ``checks`` ({field: (shape, kind)}): PersonTruths
        with unique track ids >= 0, the same fields present, masks disjoint and inside person_mask."""
        if not isinstance(self.others, tuple):
            raise SceneValidationError(f"GroundTruth.others: expected a tuple of PersonTruth, got "
                                       f"{type(self.others).__name__}")  # fmt: skip
        ids, union, first = [], None, None
        for i, person in enumerate(self.others):
            name = f"GroundTruth.others[{i}]"
            if not isinstance(person, PersonTruth):
                raise SceneValidationError(f"{name}: expected a lit_boot PersonTruth, got {type(person).__name__}")
            if isinstance(person.track_id, bool) or not isinstance(person.track_id, int) or person.track_id < 0:
                raise SceneValidationError(f"{name}.track_id: expected an int >= 0, got {person.track_id!r}")
            present = [key for key in checks if getattr(person, key) is not None]
            first = present if first is None else first
            if present != first:
                raise SceneValidationError(f"{name}: expected the fields of GroundTruth.others[0] {first}, "
                                           f"got {present}")  # fmt: skip
            for key in present:
                check_tensor(f"{name}.{key}", getattr(person, key), *checks[key])
            mask = person.person_mask
            if mask is not None and self.person_mask is not None and (mask & ~self.person_mask).any():
                raise SceneValidationError(f"{name}.person_mask: expected pixels inside GroundTruth.person_mask "
                                           "(every person's)")  # fmt: skip
            if mask is not None and union is not None and (mask & union).any():
                raise SceneValidationError(f"{name}.person_mask: expected no pixel of another person's mask")
            union = mask if union is None else union | mask
            ids.append(person.track_id)
        if len(set(ids)) != len(ids):
            raise SceneValidationError(f"GroundTruth.others: track ids must be unique, got {ids}")


@dataclass
class Scene:
    """One video with the pose estimates of its people and optional ground truth.

    frames (T, 3, H, W) uint8 RGB; fps frames per second.
    joints3d (T, J, 3) mm in the camera frame (root-relative when the camera model is
    weak perspective), ``joints3d_layout`` names the joints; cameras: per-frame cameras.
    keypoints2d (T, K, 2) px with keypoints_conf (T, K) in [0, 1] (0 = not detected).
    person_boxes (T, 5): the person's box per frame from a person detector, (x0, y0, x1, y1) px
    (pixel centres at integer coordinates, the box's outer edges) and a score in [0, 1] (0 =
    nobody found). These fields are the main person's, whose track id is ``track_id``; the
    other people of the video, if any, are in ``others`` (:class:`~lit_boot.core.people.Person`,
    the same fields and layouts; ``people()``, ``person(p)``). A single-person scene has none.
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
    track_id: int = 0
    others: tuple[Person, ...] = ()

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
        check_tensor("Scene.frames", self.frames, (None, 3, None, None), "uint8")
        T, _, H, W = self.frames.shape
        if T < 1:
            raise SceneValidationError("Scene.frames: expected at least one frame, got T=0")
        if not (isinstance(self.fps, (int, float)) and self.fps > 0):
            raise SceneValidationError(f"Scene.fps: expected a positive number, got {self.fps!r}")
        check_estimates("Scene", self, T)
        check_people("Scene", self, self.others, T)
        if self.gt is not None:
            if not isinstance(self.gt, GroundTruth):
                raise SceneValidationError(f"Scene.gt: expected a GroundTruth, got {type(self.gt).__name__}")
            self.gt.validate(T, H, W, self.keypoints_layout)

    # --- the people ----------------------------------------------------------------------------------
    @property
    def num_people(self) -> int:
        """P: the main person and the others."""
        return 1 + len(self.others)

    def people(self) -> list[Person]:
        """Every person, the main one first."""
        return [Person.of(self), *self.others]

    def person(self, p: int) -> Scene:
        """A single-person scene of person ``p`` (0 = the main one, in :meth:`people` order):
        the same frames, that person's estimates in the main fields, and the ground truth with
        that person's truth as the main one (:meth:`GroundTruth.with_main`)."""
        if isinstance(p, bool) or not isinstance(p, int) or not 0 <= p < self.num_people:
            raise IndexError(f"scene {self.name!r}: person {p!r} of {self.num_people} "
                             f"(expected 0..{self.num_people - 1})")  # fmt: skip
        if p == 0 and not self.others:
            return self
        person = self.people()[p]
        alone = self.with_people([person])
        if p == 0 or self.gt is None:
            return alone
        return dataclasses.replace(alone, gt=self.gt.with_main(person.track_id, self.track_id))

    def with_people(self, people: Sequence[Person]) -> Scene:
        """A copy with ``people`` (at least one): the first is the main person, the rest the others."""
        if not people:
            raise ValueError(f"scene {self.name!r}: with_people needs at least one person")
        main, *rest = people
        return dataclasses.replace(self, **main.fields(), track_id=main.track_id, others=tuple(rest))

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
        points that count. "3d": the 3D joints projected by the cameras (every joint of the frames
        where the pose was estimated, :meth:`~lit_boot.core.Person.posed`: elsewhere an
        estimator's joints are a neighbour frame's, filled in); "2d": the keypoints (those with
        confidence above ``threshold`` count)."""
        self.require_pose(mode)
        if mode == "3d":
            points = self.cameras.project(self.joints3d.float())
            return points, Person.of(self).posed()[:, None].expand(points.shape[:2]).clone()
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
        if self.others:
            seen = ", ".join(f"{p.track_id}: {int(p.found().sum())}" for p in self.people())
            lines.append(f"  people: {self.num_people} (track id: frames found, {seen})")
        if self.gt is not None:
            have = [k for k in ("flow", "flow_occluded", "joints3d", "joints2d", "keypoints2d", "person_mask", "cameras")
                    if getattr(self.gt, k) is not None]  # fmt: skip
            others = f"; every person's ({1 + len(self.gt.others)} people)" if self.gt.others else ""
            lines.append(f"  ground truth: {', '.join(have) if have else 'none'}{others}")
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
