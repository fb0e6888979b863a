"""The pose-refinement loss terms (paper section 3.2) as pure functions.

Every term is the authors' reduction: SmoothL1 (beta 1) of a residual, summed over every
element of a frame (joints and coordinates), then averaged over frames (or over the T-1
consecutive pairs for the terms between frames). The weight (lambda) is applied by the caller.
Terms between frames are 0 when there is a single frame (never NaN). The ``*_residual``
functions give the residuals alone, for :class:`lit_boot.pose.objective.Objective`, which
reduces all terms of a refiner in one pass.

Units are the caller's: the 3D refiner passes joints in metres and projections in pixels,
which is what the paper's lambdas were tuned for (METRO's unit, image pixels).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F

from ..core import inside_image as core_inside_image
from ..metrics import sample_flow_at_points

__all__ = [
    "inside_image",
    "smooth_l1_per_frame",
    "flow_residual",
    "temporal_residual",
    "flow_consistency_loss",
    "deviation_loss",
    "keypoint_loss",
    "temporal_loss",
    "bone_matrix",
    "bone_lengths",
    "bone_length_loss",
]


def smooth_l1_per_frame(residual: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """SmoothL1 (beta 1) of ``residual`` (N, ...) summed over all but the first dim, then the
    mean over N: a scalar. ``weight`` (N, J) weighs the rows of a (N, J, D) residual. N = 0
    gives 0."""
    n = residual.shape[0]
    if n == 0:
        return residual.sum() * 0.0
    zero = torch.zeros_like(residual)
    if weight is None:
        return F.smooth_l1_loss(residual, zero, reduction="sum", beta=1.0) / n
    per_element = F.smooth_l1_loss(residual, zero, reduction="none", beta=1.0)
    return (per_element * weight[..., None]).sum() / n


def flow_residual(points: torch.Tensor, flows: torch.Tensor, scale: float = 1.0) -> torch.Tensor:
    """(T-1, J, 2): the flow F(t-1 -> t), a constant, sampled bilinearly at ``points[t-1]``,
    minus the displacement ``points[t] - points[t-1]``; times ``scale``.

    points (T, J, 2) px (projected joints or 2D keypoints); flows (T-1, 2, H, W) px, forward.
    The gradient reaches both frames' points, including through the sampling position.
    """
    if points.shape[0] < 2:
        return points[:0]
    sampled = sample_flow_at_points(flows.detach(), points[:-1], mode="bilinear")  # (T-1, J, 2)
    residual = sampled - (points[1:] - points[:-1])
    return residual if scale == 1.0 else residual * scale


def temporal_residual(values: torch.Tensor) -> torch.Tensor:
    """(T-1, ...): change of ``values`` (T, ...) between consecutive frames."""
    return values[1:] - values[:-1]


def flow_consistency_loss(
    points: torch.Tensor, flows: torch.Tensor, valid: torch.Tensor | None = None, scale: float = 1.0
) -> torch.Tensor:
    """L_opt without its lambda: :func:`flow_residual` through SmoothL1; valid (T-1, J) optional
    weights of each pair's joints (e.g. 0 outside the image); scale multiplies the residual
    (1: pixels of this image)."""
    return smooth_l1_per_frame(flow_residual(points, flows, scale), valid)


def deviation_loss(values: torch.Tensor, initial: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """L_3D (or the 2D-only mode's L_init) without its lambda: ``values`` (T, J, D) against
    their ``initial`` estimate; ``weight`` (T, J) optional."""
    return smooth_l1_per_frame(values - initial.detach(), weight)


def keypoint_loss(projected: torch.Tensor, keypoints: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """L_2D without its lambda: projections (T, J, 2) px against detections (T, J, 2) px,
    weighted per joint by ``weight`` (T, J) (confidence, 0 where undetected or unused)."""
    return smooth_l1_per_frame(projected - keypoints.detach(), weight)


def temporal_loss(values: torch.Tensor) -> torch.Tensor:
    """Change between consecutive frames of ``values`` (T, ...): joints (L_pos), cameras
    (L_cam), projections (the authors' 2D smoothness term)."""
    return smooth_l1_per_frame(temporal_residual(values))


def bone_matrix(bones: Sequence[tuple[int, int]], num_joints: int) -> torch.Tensor:
    """(B, J) matrix with +1 at a bone's first joint and -1 at its second: ``M @ joints``
    gives the bone vectors (a matrix product is cheaper to differentiate than indexing)."""
    m = torch.zeros(len(bones), num_joints)
    for b, (i, j) in enumerate(bones):
        m[b, i] += 1.0
        m[b, j] -= 1.0
    return m


def bone_lengths(joints: torch.Tensor, bones: Sequence[tuple[int, int]] | torch.Tensor) -> torch.Tensor:
    """Lengths (T, B) of ``bones`` of ``joints`` (T, J, 3), in the joints' unit. ``bones``:
    index pairs, or their :func:`bone_matrix` (B, J)."""
    m = bones if isinstance(bones, torch.Tensor) else bone_matrix(bones, joints.shape[-2]).to(joints)
    T, J, D = joints.shape
    # One (B, J) x (J, T*D) product rather than T small ones.
    vectors = (m @ joints.transpose(0, 1).reshape(J, T * D)).reshape(-1, T, D)
    return vectors.norm(dim=-1).transpose(0, 1)


def bone_length_loss(joints: torch.Tensor, bones: Sequence[tuple[int, int]] | torch.Tensor) -> torch.Tensor:
    """L_bone without its lambda: change of every bone's length between consecutive frames.
    ``bones`` as in :func:`bone_lengths`."""
    if len(bones) == 0:
        return joints.sum() * 0.0
    return temporal_loss(bone_lengths(joints, bones))

def inside_image(points: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """(..., J) float: 1 where the point (..., J, 2) px lies within the image, else 0 (core's test)."""
    return core_inside_image(points, height, width).float()
