"""PoseRefiner: per-video optimisation of 3D joints and cameras against the flow (paper 3.2).

Variables: joints X (T, J, 3) in metres (METRO's unit: Adam's lr is a distance per step in
metres, as for the authors) and per-frame camera variables C (T, 3) (see
:class:`CameraModel`), both initialised from the scene's estimates. Loss (each term SmoothL1,
beta 1, summed over elements, averaged over frames, times its lambda)::

    L = opt * L_opt(P(X, C); F)          projected motion vs the flow, px
      + joints3d * |X - X0|              deviation from the initial joints, m (frames with a pose)
      + keypoints2d * c |P(X, C) - x|    agreement with the detector, px
      + pos * |X_t - X_t-1|              joint smoothness, m
      + cam * |C_t - C_t-1|              camera smoothness
      + bone * |len_t - len_t-1|         bone-length constancy (the layout's length_bones), m
      + proj_smooth * |P_t - P_t-1|      2D smoothness (the authors' code, lambda 0), px

Every person of a scene is refined at once, each with its own cameras: joints (T, P, J, 3),
camera variables (T, P, 3) (:mod:`lit_boot.pose.people`). The deviation term holds a person's
joints to the estimates only in the frames where the pose was estimated
(:meth:`~lit_boot.core.Person.posed`): elsewhere the estimator's joints are a neighbour frame's,
filled in, and the flow, the smoothness and the bone lengths place them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import nn

from ..core import Person, Scene, get_layout
from ..metrics import PoseMetrics
from .base import RefinerBase
from .camera import CameraModel
from .keypoints import keypoints_for_layout
from .losses import bone_lengths, bone_matrix, inside_image, temporal_residual
from .objective import Objective, Term
from .people import TruthIndex, people_metrics, refined_people, side_by_side, unrefined_people
from .result import PoseResult

__all__ = ["PoseLossWeights", "PoseRefiner", "inside_image"]


@dataclass
class PoseLossWeights:
    """The lambdas of the 3D refiner (defaults: the paper's, for METRO). 0 switches a term off."""

    opt: float = 0.01
    joints3d: float = 400.0
    keypoints2d: float = 0.01
    pos: float = 300.0
    cam: float = 0.1
    bone: float = 1.0e4
    proj_smooth: float = 0.0



class PoseRefiner(RefinerBase):
    """Refine a video's 3D joints and cameras so that their projected motion follows the flow.

    Args:
        lr: Adam learning rate on joints (metres) and camera variables (the paper: 1e-3).
        loss_weights: the lambdas (:class:`PoseLossWeights`; the paper's by default).
        keypoint_joints: joints that get the 2D term (names in the joints' layout; default the
            authors' 10: shoulders, elbows, wrists, knees, ankles).
        confidence: binary (1 where confidence > threshold: the authors), real (the confidence
            itself), or none (every keypoint weighs 1).
        confidence_threshold: detections at or below it weigh 0 (default 0: undetected).
        flow_inside_only: the flow term only for joints whose frame t-1 projection lies in
            the image (the authors sample the border flow there).
        pixel_scale: 2D residuals (flow, detections, 2D smoothness) are multiplied by this
            before SmoothL1, i.e. measured in pixels of an image this many times larger. 1 (the
            paper): pixels of this image. The paper's 2D lambdas were tuned on Human3.6M frames
            (1000x1000, a person some 400-500 px tall), so the 2D terms pull correspondingly
            less on a smaller person. Raise it when the person is much smaller than ~450 px
            tall, to about 450 / (their height in px): e.g. 6 for a 75 px person (on the
            synthetic suite that made L_2D and L_opt with exact flow help a little more; with
            RAFT's flow no better: see BENCHMARKS.md). Leave it at 1 otherwise.
        eval_every_n_steps: evaluate against ground truth every this many steps (see :class:`RefinerBase`).
        save: write the refined poses into ``output_dir`` at the end of fitting.
        output_dir: where to save (default: the trainer's log_dir).
        num_threads: torch CPU threads during fitting (restored afterwards); None leaves them.
        people: "all" refines every person of the scene at once (each with its own cameras),
            "main" the main person alone.
    """

    mode = "3d"

    def __init__(
        self,
        lr: float = 1e-3,
        loss_weights: PoseLossWeights | None = None,
        keypoint_joints: Sequence[str] | None = None,
        confidence: str = "binary",
        confidence_threshold: float = 0.0,
        flow_inside_only: bool = True,
        pixel_scale: float = 1.0,
        eval_every_n_steps: int = 100,
        save: bool = True,
        output_dir: str | None = None,
        num_threads: int | None = 1,
        people: str = "all",
    ):
        super().__init__(lr, eval_every_n_steps, save, output_dir, num_threads, people)
        if pixel_scale <= 0:
            raise ValueError(f"pixel_scale: expected a positive factor, got {pixel_scale}")
        self.save_settings(loss_weights, PoseLossWeights, confidence)
        self.layout_name = "lsp14"

    # --- building ------------------------------------------------------------------------------
    def build(self, scene: Scene, flows: torch.Tensor | None) -> None:
        if scene.joints3d is None or scene.cameras is None:
            raise ValueError(f"PoseRefiner: scene {scene.name!r} has no 3D joints with cameras (use KeypointRefiner)")
        w = self.loss_weights
        if flows is None and w.opt != 0:
            raise ValueError("PoseRefiner: no flows given; pass flows (a .flo folder, flows.npz or 'gt') or set loss_weights.opt 0")
        layout = get_layout(scene.joints3d_layout)
        self.layout_name = layout.name
        people = refined_people(scene, self.hparams.people)
        self.track_ids = [p.track_id for p in people]
        self.unrefined = unrefined_people(scene, people, ("joints3d", "cameras"))
        self.register_buffer("bones", bone_matrix(layout.length_bones, layout.num_joints), persistent=False)
        self.camera = CameraModel([p.cameras for p in people])
        joints_m = torch.stack([p.joints3d.detach().float() / 1000.0 for p in people], 1)  # (T, P, J, 3)
        self.joints = nn.Parameter(joints_m.clone())
        self.camera_vars = nn.Parameter(self.camera.initial())  # (T, P, 3)
        self.register_buffer("initial_joints", joints_m, persistent=False)
        self.register_buffer("flows", flows, persistent=False)
        keypoints = weight = None
        if scene.keypoints2d is not None and w.keypoints2d != 0:
            keypoints, weight = self._keypoints(scene, len(people), layout.name)
        self.register_buffer("keypoints", keypoints, persistent=False)
        self.register_buffer("keypoint_weight", weight, persistent=False)
        T, P, J = joints_m.shape[:3]
        posed = torch.stack([p.posed() for p in people], 1)[:, :, None].expand(T, P, J).reshape(T, P * J)
        self.objective = Objective([
            Term("opt", (T - 1, P * J, 2), w.opt),
            Term("3d", (T, P * J, 3), w.joints3d, posed),
            Term("2d", (T, P * J, 2), w.keypoints2d if keypoints is not None else 0.0, weight),
            Term("pos", (T - 1, P * J, 3), w.pos),
            Term("cam", (T - 1, P * 3), w.cam),
            Term("bone", (T - 1, P * len(layout.length_bones)), w.bone),
            Term("proj_smooth", (T - 1, P * J, 2), w.proj_smooth),
        ])  # fmt: skip
        same_layout = scene.gt is not None and scene.gt.joints_layout == layout.name
        truth = TruthIndex(scene, people, ["joints3d", "joints2d"] if same_layout else [])
        self.gt_people = {name: truth.people.get(name, []) for name in ("joints3d", "joints2d")}
        self.register_buffer("gt_joints3d", truth.values.get("joints3d"), persistent=False)
        self.register_buffer("gt_joints2d", truth.values.get("joints2d"), persistent=False)
        self.pose_metrics = PoseMetrics(root=layout.root or (0,))

    def _keypoints(self, scene: Scene, count: int, layout: str) -> tuple[torch.Tensor, torch.Tensor]:
        """The first ``count`` people's keypoints in ``layout``, side by side: (T, P*J, 2) px
        and their weights (T, P*J)."""
        h = self.hparams
        mapped = [keypoints_for_layout(scene.person(p), layout, h.keypoint_joints, h.confidence, h.confidence_threshold)
                  for p in range(count)]  # fmt: skip
        return torch.cat([m[0] for m in mapped], 1), torch.cat([m[1] for m in mapped], 1)

    # --- the loss -----------------------------------------------------------------------------
    def projected(self) -> torch.Tensor:
        """The current joints projected by the current cameras, every person's side by side,
        (T, P*J, 2) px."""
        return side_by_side(self.camera.project(self.joints, self.camera_vars))

    def residuals(self) -> list[torch.Tensor]:
        """The active terms' residuals, in ``objective.names`` order (see the module doc)."""
        X, k, names = side_by_side(self.joints), self.hparams.pixel_scale, self.objective.names
        P = self.projected()
        out: dict[str, torch.Tensor] = {}
        if "opt" in names:
            out["opt"] = self.flow_term(P, k)
        if "3d" in names:
            out["3d"] = X - side_by_side(self.initial_joints)
        if "2d" in names:
            out["2d"] = P - self.keypoints if k == 1.0 else (P - self.keypoints) * k
        if "pos" in names:
            out["pos"] = temporal_residual(X)
        if "cam" in names:
            out["cam"] = temporal_residual(self.camera_vars).flatten(1)
        if "bone" in names:
            T, people, J = self.joints.shape[:3]
            lengths = bone_lengths(self.joints.reshape(T * people, J, 3), self.bones)
            out["bone"] = temporal_residual(lengths.reshape(T, -1))
        if "proj_smooth" in names:
            out["proj_smooth"] = temporal_residual(P) * k
        return [out[name] for name in names]

    # --- evaluation and results -----------------------------------------------------------------
    def joints_mm(self) -> torch.Tensor:
        """The current joints (T, P, J, 3) in millimetres."""
        return self.joints.detach() * 1000.0

    @torch.no_grad()
    def evaluate(self) -> dict[str, float]:
        """MPJPE, PA-MPJPE (mm), acceleration error (mm/frame^2) against the GT 3D joints, and
        the projection's 2D error (px) against the GT 2D joints; {} without ground truth. The
        bare names are the main person's; with several people also pooled and per person."""
        scored: dict[int, dict] = {}
        joints = self.joints_mm()
        for g, p in enumerate(self.gt_people["joints3d"]):
            scored.setdefault(p, {}).update(self.pose_metrics.joints3d_metrics(joints[:, p], self.gt_joints3d[:, g]))
        if self.gt_people["joints2d"]:
            projected = self.camera.project(self.joints.detach(), self.camera_vars.detach())
            for g, p in enumerate(self.gt_people["joints2d"]):
                scored.setdefault(p, {}).update(
                    self.pose_metrics.points2d_metrics("proj2d_px", projected[:, p], self.gt_joints2d[:, g]))
        return people_metrics(self.track_ids, scored)

    def make_result(self) -> PoseResult:
        joints = self.joints_mm().float().cpu()
        refined = [Person(i, joints3d=joints[:, p].clone(), cameras=self.camera.to_cameras(self.camera_vars, p))
                   for p, i in enumerate(self.track_ids)]  # fmt: skip
        return self.result_with("3d", refined + self.unrefined, joints3d_layout=self.layout_name)
