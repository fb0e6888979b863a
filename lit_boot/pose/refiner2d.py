"""KeypointRefiner: the 2D-only mode (paper section 3.3, the authors' Sintel script).

When the 3D estimates are unreliable, the detector's 2D keypoints x (T, K, 2) px (in the
scene's keypoint layout, e.g. COCO-17) are optimised directly: no joints, no cameras. The
projection is replaced by x itself, the 3D-only terms are dropped, and the 3D deviation
becomes a deviation from the initial keypoints::

    L = opt * L_opt(x; F) + init * c |x - x0| + smooth * |x_t - x_t-1|     (all px)

The authors: Adam lr 0.1, opt 300, init 400, smooth 0, 1500 steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from ..core import Scene
from ..metrics import PoseMetrics
from .base import RefinerBase
from .keypoints import confidence_weights
from .losses import temporal_residual
from .objective import Objective, Term
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
    ):
        super().__init__(lr, eval_every_n_steps, save, output_dir, num_threads)
        self.save_settings(loss_weights, KeypointLossWeights, confidence)
        self.layout_name = "coco17"

    def build(self, scene: Scene, flows: torch.Tensor | None) -> None:
        if scene.keypoints2d is None:
            raise ValueError(f"KeypointRefiner: scene {scene.name!r} has no 2D keypoints")
        if flows is None and self.loss_weights.opt != 0:
            raise ValueError("KeypointRefiner: no flows given; pass flows (a .flo folder, flows.npz or 'gt') or set loss_weights.opt 0")
        self.layout_name = scene.keypoints_layout
        self.keypoints_conf = scene.keypoints_conf.detach().float().cpu()
        initial = scene.keypoints2d.detach().float()
        self.keypoints = nn.Parameter(initial.clone())
        self.register_buffer("initial_keypoints", initial, persistent=False)
        weight = confidence_weights(scene.keypoints_conf, self.hparams.confidence, self.hparams.confidence_threshold)
        self.register_buffer("init_weight", weight, persistent=False)
        self.register_buffer("flows", flows, persistent=False)
        w, (T, K) = self.loss_weights, initial.shape[:2]
        self.objective = Objective([
            Term("opt", (T - 1, K, 2), w.opt),
            Term("init", (T, K, 2), w.init, weight),
            Term("smooth", (T - 1, K, 2), w.smooth),
        ])  # fmt: skip
        gt = scene.gt
        has_gt = gt is not None and gt.keypoints2d is not None
        self.register_buffer("gt_keypoints", gt.keypoints2d.float() if has_gt else None, persistent=False)
        self.pose_metrics = PoseMetrics()

    def residuals(self) -> list[torch.Tensor]:
        """The active terms' residuals, in ``objective.names`` order (see the module doc)."""
        x, names = self.keypoints, self.objective.names
        out: dict[str, torch.Tensor] = {}
        if "opt" in names:
            out["opt"] = self.flow_term(x)
        if "init" in names:
            out["init"] = x - self.initial_keypoints
        if "smooth" in names:
            out["smooth"] = temporal_residual(x)
        return [out[name] for name in names]

    @torch.no_grad()
    def evaluate(self) -> dict[str, float]:
        """Mean 2D keypoint error (px) against the GT keypoints (all keypoints, all frames)."""
        if self.gt_keypoints is None:
            return {}
        return self.pose_metrics.points2d("kp2d_px", self.keypoints.detach(), self.gt_keypoints)

    def make_result(self) -> PoseResult:
        return self.result_with("2d", keypoints2d=self.keypoints.detach().float().cpu(),
                                keypoints_conf=self.keypoints_conf, keypoints_layout=self.layout_name)  # fmt: skip
