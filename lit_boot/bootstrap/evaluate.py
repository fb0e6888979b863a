"""What the orchestrator measures after every stage.

- Against ground truth, when the scene has it: the flow and pose metrics of
  :mod:`lit_boot.metrics.suite` (``epe``, ``epe_person``, ... ``mpjpe_mm``, ``kp2d_px``), the same
  names and conventions as FlowTTT's and the refiners' validation.
- Flow-pose agreement, which needs no ground truth: the L_opt residual of the current poses
  under the current flow, i.e. the mean distance (px) between the flow sampled bilinearly at
  each pose joint in frame t and that joint's displacement to frame t+1, over confident joints
  inside the image.
- Drift: the mean distance (px) between a stage's flow and the initial flow outside the
  person (the sketch dilated), which needs no ground truth either.
- Image evidence, no ground truth (what the drift guard compares): ``photo_error``, the mean
  soft census error (7x7, 0..48) of frame t against frame t+1 warped by the flow, over the pixels
  whose target lies in the image; ``track_error``, the mean soft census distance between each
  confident pose joint's neighbourhood in frame t and its neighbourhood at the joint's position
  in frame t+1 (:func:`~lit_boot.flow.evidence.track_error`). Lower is better for both.

EPE-like means pool every selected pixel (or joint) of every pair, not per pair first.
"""

from __future__ import annotations

import numpy as np
import torch

from ..core import inside_image
from ..flow.evidence import photometric_error, track_error
from ..metrics import epe_at_points, flow_errors

__all__ = ["agreement", "drift", "person_height", "photo_error", "pose_track_error"]


@torch.no_grad()
def agreement(flows: torch.Tensor, points: torch.Tensor, keep: torch.Tensor) -> float:
    """Mean |flow(p_t) - (p_t+1 - p_t)| px over pairs and kept joints inside the image.

    flows: (T-1, 2, H, W) px; points: (T, K, 2) px; keep: (T, K) bool (a joint counts in a pair
    when kept in both frames). NaN when no joint counts.
    """
    H, W = flows.shape[-2:]
    p0, p1 = points[:-1].float(), points[1:].float()
    visible = keep[:-1] & keep[1:] & inside_image(p0, H, W)
    err = epe_at_points(flows.float(), p0, p1 - p0, visible, mode="bilinear")
    n = visible.sum()
    return float(err.sum() / n) if n else float("nan")


@torch.no_grad()
def drift(flows: torch.Tensor, initial: torch.Tensor, person: torch.Tensor) -> float:
    """Mean |flows - initial| px over the pixels outside ``person`` (T-1, H, W) bool."""
    return float(flow_errors(flows.float(), initial.float(), ~person)["epe"])


@torch.no_grad()
def photo_error(frames: torch.Tensor, flows: torch.Tensor) -> float:
    """Mean census error (0..48) of ``flows`` (T-1, 2, H, W) px on ``frames`` (T, 3, H, W)
    uint8, pooled over the pixels of every pair whose target is in the image; NaN if none."""
    total, count = 0.0, 0
    for t in range(flows.shape[0]):  # one pair at a time: census maps are 49 channels deep
        error, valid = photometric_error(frames[t : t + 1], frames[t + 1 : t + 2], flows[t : t + 1].float())
        total, count = total + float(error[valid].sum()), count + int(valid.sum())
    return total / count if count else float("nan")


@torch.no_grad()
def pose_track_error(frames: torch.Tensor, points: torch.Tensor, keep: torch.Tensor) -> float:
    """Mean census distance (0..48) along the pose's joint tracks: ``points`` (T, K, 2) px,
    ``keep`` (T, K) bool (a joint counts in a pair when kept in both frames and inside both
    images); NaN when no joint counts."""
    total, count = 0.0, 0
    for t in range(frames.shape[0] - 1):
        error, valid = track_error(frames[t : t + 1], frames[t + 1 : t + 2], points[t : t + 1].float(),
                                   points[t + 1 : t + 2].float())  # fmt: skip
        valid = valid[0] & keep[t] & keep[t + 1]
        total, count = total + float(error[0][valid].sum()), count + int(valid.sum())
    return total / count if count else float("nan")


def person_height(points: torch.Tensor, keep: torch.Tensor) -> float:
    """Median over frames of the vertical extent (px) of the kept pose points (``points`` (T, K, 2)
    px, ``keep`` (T, K) bool); 0 if no frame keeps two."""
    heights = []
    for p, k in zip(points, keep):
        if k.sum() >= 2:
            y = p[k, 1]
            heights.append(float(y.max() - y.min()))
    return float(np.median(heights)) if heights else 0.0
