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

- The poses without ground truth (:func:`pose_evidence`; per person and pooled, in the frames
  where the pose was estimated; lower is better for all): ``reprojection_px`` (3D mode), the 3D
  joints projected by the cameras against the detector's 2D keypoints (mapped to the joints'
  layout, confidence above 0), mean px; ``bone_variation``, each bone's standard deviation over
  the frames over its mean length, averaged over the layout's ``length_bones`` (3D joints in 3D
  mode; keypoints in 2D mode, where foreshortening moves them too); ``jitter_mm_per_frame2`` (3D)
  / ``jitter_px_per_frame2`` (2D), the joints' acceleration ``|x[t+1] - 2 x[t] + x[t-1]|``. On
  synthetic scenes they are reported beside MPJPE (BENCHMARKS.md), so that a reader learns how
  far each follows it.

EPE-like means pool every selected pixel (or joint) of every pair, not per pair first.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..core import Scene, get_layout, inside_image, map_joints
from ..flow.evidence import photometric_error, track_error
from ..metrics import epe_at_points, flow_errors
from ..metrics.suite import PERSON_SUFFIX

__all__ = ["agreement", "drift", "person_height", "photo_error", "pose_track_error", "POSE_EVIDENCE", "pose_evidence"]


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


#: The measures' names, per mode (``track_error`` is recorded with them by the runner).
POSE_EVIDENCE = {"3d": ("reprojection_px", "bone_variation", "jitter_mm_per_frame2"),
                 "2d": ("bone_variation", "jitter_px_per_frame2")}  # fmt: skip


def _sums(person: Scene, mode: str) -> dict[str, tuple[float, int]]:
    """One person's measures as (sum, count) pairs, for pooling over people."""
    points, keep = person.pose_points(mode)
    posed = keep.any(-1)
    out: dict[str, tuple[float, int]] = {}
    if mode == "3d":
        values, layout = person.joints3d.float(), get_layout(person.joints3d_layout)
        if person.keypoints2d is not None and person.keypoints_conf is not None:
            detected, defined, weight = map_joints(person.keypoints2d.float(), person.keypoints_layout, layout,
                                                   person.keypoints_conf.float())  # fmt: skip
            seen = defined[None] & (weight > 0) & keep
            distance = (points - detected).norm(dim=-1)
            out["reprojection_px"] = (float(distance[seen].sum()), int(seen.sum()))
    else:
        values, layout = points.float(), get_layout(person.keypoints_layout)
    values, seen_joints = layout.with_virtual(values, keep.float())  # length_bones may join virtual joints
    keep = seen_joints > 0
    bones = torch.tensor(layout.length_bones)
    lengths = (values[:, bones[:, 0]] - values[:, bones[:, 1]]).norm(dim=-1)  # (T, B)
    both = keep[:, bones[:, 0]] & keep[:, bones[:, 1]] & posed[:, None]
    variation = []
    for b in range(bones.shape[0]):
        seen = lengths[both[:, b], b]
        if seen.numel() >= 2 and float(seen.mean()) > 0:
            variation.append(float(seen.std() / seen.mean()))
    out["bone_variation"] = (sum(variation), len(variation))
    if values.shape[0] >= 3:
        joints = layout.num_joints  # the joints themselves, not the virtual ones
        accel = (values[2:, :joints] - 2 * values[1:-1, :joints] + values[:-2, :joints]).norm(dim=-1)
        seen = keep[2:, :joints] & keep[1:-1, :joints] & keep[:-2, :joints]
        out[f"jitter_{'mm' if mode == '3d' else 'px'}_per_frame2"] = (float(accel[seen].sum()), int(seen.sum()))
    return out


def pose_evidence(scene: Scene, mode: str) -> dict[str, float]:
    """The no-GT pose measures of ``scene``'s current poses in ``mode`` (module doc): pooled over
    every person with the pose of ``mode`` under the bare names, and with several people each
    one's under ``<name>_person<track id>``. A measure with nothing to count is left out."""
    people = [scene.person(p) for p in range(scene.num_people)]
    has_pose = (lambda p: p.joints3d is not None and p.cameras is not None) if mode == "3d" else \
        (lambda p: p.keypoints2d is not None)  # fmt: skip
    per = [(int(p.track_id), _sums(p, mode)) for p in people if has_pose(p)]
    out: dict[str, float] = {}
    for name in POSE_EVIDENCE[mode]:
        total = sum(s[name][0] for _, s in per if name in s)
        count = sum(s[name][1] for _, s in per if name in s)
        if count:
            out[name] = total / count
        if len(per) > 1:
            for track_id, s in per:
                if name in s and s[name][1]:
                    out[f"{name}{PERSON_SUFFIX}{track_id}"] = s[name][0] / s[name][1]
    return {k: v for k, v in out.items() if math.isfinite(v)}
