"""KeypointRefiner: the 2D-only mode (paper section 3.3, the authors' Sintel script).

When the 3D estimates are unreliable, the detector's 2D keypoints x (T, K, 2) px (in the
scene's keypoint layout, e.g. COCO-17) are optimised directly: no joints, no cameras. The
projection is replaced by x itself, the 3D-only terms are dropped, and the 3D deviation
becomes a deviation from the initial keypoints::

    L = opt * L_opt(x; F) + init * c |x - x0| + smooth * |x_t - x_t-1|     (all px)

The authors: Adam lr 0.1, opt 300, init 400, smooth 0, 1500 steps. Every person of a scene is
refined at once (keypoints (T, P, K, 2): :mod:`lit_boot.pose.people`).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from ..core import Person, Scene
from ..metrics import PoseMetrics
from .base import RefinerBase
from .keypoints import confidence_weights
from .losses import temporal_residual
from .objective import Objective, Term
from .people import TruthIndex, people_metrics, refined_people, side_by_side, unrefined_people
from .result import PoseResult

__all__ = ["KeypointLossWeights", "KeypointRefiner"]


@dataclass
class KeypointLossWeights:
    """The lambdas of the 2D-only mode (defaults: the authors' Sintel script)."""

    opt: float = 300.0
    init: float = 400.0
    smooth: float = 0.0


class KeypointRefiner(RefinerBase):
    """Refine a video's 2D keypoints directly so that their motion follows the flow.

    Args:
        lr: Adam learning rate in pixels (the authors: 0.1).
        loss_weights: the lambdas (:class:`KeypointLossWeights`).
        confidence: weights of the deviation term: binary (1 where confidence > threshold, so
            undetected keypoints are free to follow the flow), real, or none (all 1).
        confidence_threshold: detections at or below it weigh 0 in the deviation term.
        flow_inside_only: the flow term only for keypoints inside the image at frame t-1.
        eval_every_n_steps: evaluate against ground truth every this many steps (see :class:`RefinerBase`).
        save: write the refined poses into ``output_dir`` at the end of fitting.
        output_dir: where to save (default: the trainer's log_dir).
        num_threads: torch CPU threads during fitting (restored afterwards); None leaves them.
        people: "all" refines every person of the scene at once, "main" the main person alone.
    """

    mode = "2d"

    def __init__(
        self,
        lr: float = 0.1,
        loss_weights: KeypointLossWeights | None = None,
        confidence: str = "binary",
        confidence_threshold: float = 0.0,
        flow_inside_only: bool = True,
        eval_every_n_steps: int = 100,
        save: bool = True,
        output_dir: str | None = None,
        num_threads: int | None = 1,
        people: str = "all",
    ):
        super().__init__(lr, eval_every_n_steps, save, output_dir, num_threads, people)
        self.save_settings(loss_weights, KeypointLossWeights, confidence)
        self.layout_name = "coco17"

    def build(self, scene: Scene, flows: torch.Tensor | None) -> None:
        if scene.keypoints2d is None:
            raise ValueError(f"KeypointRefiner: scene {scene.name!r} has no 2D keypoints")
        if flows is None and self.loss_weights.opt != 0:
            raise ValueError("KeypointRefiner: no flows given; pass flows (a .flo folder, flows.npz or 'gt') or set loss_weights.opt 0")
        self.layout_name = scene.keypoints_layout
        people = refined_people(scene, self.hparams.people)
        self.unrefined = unrefined_people(scene, people, ("keypoints2d", "keypoints_conf"))
        self.track_ids = [p.track_id for p in people]
        self.keypoints_conf = torch.stack([p.keypoints_conf.detach().float().cpu() for p in people], 1)  # (T, P, K)
        initial = torch.stack([p.keypoints2d.detach().float() for p in people], 1)  # (T, P, K, 2)
        self.keypoints = nn.Parameter(initial.clone())
        self.register_buffer("initial_keypoints", initial, persistent=False)
        conf = self.keypoints_conf.reshape(initial.shape[0], -1)
        weight = confidence_weights(conf, self.hparams.confidence, self.hparams.confidence_threshold)
        self.register_buffer("init_weight", weight, persistent=False)
        self.register_buffer("flows", flows, persistent=False)
        w, (T, PK) = self.loss_weights, weight.shape
        self.objective = Objective([
            Term("opt", (T - 1, PK, 2), w.opt),
            Term("init", (T, PK, 2), w.init, weight),
            Term("smooth", (T - 1, PK, 2), w.smooth),
        ])  # fmt: skip
        truth = TruthIndex(scene, people, ["keypoints2d"])
        self.gt_people = truth.people["keypoints2d"]
        self.register_buffer("gt_keypoints", truth.values["keypoints2d"], persistent=False)
        self.pose_metrics = PoseMetrics()

    def residuals(self) -> list[torch.Tensor]:
        """The active terms' residuals, in ``objective.names`` order (see the module doc)."""
        x, names = side_by_side(self.keypoints), self.objective.names
        out: dict[str, torch.Tensor] = {}
        if "opt" in names:
            out["opt"] = self.flow_term(x)
        if "init" in names:
            out["init"] = x - side_by_side(self.initial_keypoints)
        if "smooth" in names:
            out["smooth"] = temporal_residual(x)
        return [out[name] for name in names]

    @torch.no_grad()
    def evaluate(self) -> dict[str, float]:
        """Mean 2D keypoint error (px) against the GT keypoints (all keypoints, all frames):
        ``kp2d_px`` the main person's, with several people also pooled and per person."""
        x = self.keypoints.detach()
        scored = {p: self.pose_metrics.points2d_metrics("kp2d_px", x[:, p], self.gt_keypoints[:, g])
                  for g, p in enumerate(self.gt_people)}  # fmt: skip
        return people_metrics(self.track_ids, scored)

    def make_result(self) -> PoseResult:
        x = self.keypoints.detach().float().cpu()
        refined = [Person(track_id=i, keypoints2d=x[:, p].clone(), keypoints_conf=self.keypoints_conf[:, p].clone())
                   for p, i in enumerate(self.track_ids)]  # fmt: skip
        return self.result_with("2d", refined + self.unrefined, keypoints_layout=self.layout_name)
