"""The pose-refinement loss terms' residuals (paper section 3.2) as pure functions.

Every term is the authors' reduction of a residual: SmoothL1 (beta 1) summed over every
element of a frame (joints and coordinates), then averaged over frames (or over the T-1
consecutive pairs for the terms between frames), times its lambda; terms between frames are 0
with a single frame. The reduction of all of a refiner's terms is one pass of
:class:`lit_boot.pose.objective.Objective`; the functions here give the residuals.

Units are the caller's: the 3D refiner passes joints in metres and projections in pixels,
which is what the paper's lambdas were tuned for (METRO's unit, image pixels).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from ..core import inside_image as core_inside_image
from ..metrics import sample_flow_at_points

__all__ = [
    "inside_image",
    "flow_residual",
    "temporal_residual",
    "bone_matrix",
    "bone_lengths",
]


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


def inside_image(points: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """(..., J) float: 1 where the point (..., J, 2) px lies within the image, else 0 (core's test)."""
    return core_inside_image(points, height, width).float()
