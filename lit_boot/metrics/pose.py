"""3D pose metrics: MPJPE with root / scale / Procrustes alignment, and acceleration error.

Joints are ``(..., J, 3)`` tensors in millimetres (any leading dims = frames). The default
layout is LSP-14, whose root (pelvis) is the mean of the hips at indices ``(2, 3)``.
Means pool all valid joints of all frames (each joint of each frame weighs the same).
The ``Metric`` classes accumulate float64 sums and divide only in ``compute()``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import torch
from torch import Tensor
from torchmetrics import Metric

from ..core import LSP14
from .flow import _sum_state

__all__ = [
    "LSP14_ROOT",
    "align_root",
    "procrustes_transform",
    "procrustes_align",
    "scale_align",
    "mpjpe",
    "pa_mpjpe",
    "n_mpjpe",
    "acceleration_error",
    "MeanPerJointPositionError",
    "MPJPE",
    "AccelerationError",
]

Alignment = Literal["root", "procrustes", "scale", "none"]
Root = int | Sequence[int]
LSP14_ROOT: tuple[int, ...] = LSP14.root  # the pelvis: the mean of the hips
_ALIGNMENTS = ("root", "procrustes", "scale", "none")


def _check_joints(name: str, joints: Tensor, ndims: tuple[int, ...] | None = None) -> None:
    """Raise ValueError unless ``joints`` is a floating (..., J, 3) tensor."""
    ok_ndim = joints.ndim >= 2 if ndims is None else joints.ndim in ndims
    if not ok_ndim or joints.shape[-1] != 3:
        expected = "(..., J, 3)" if ndims is None else " or ".join(
            {3: "(T, J, 3)", 4: "(B, T, J, 3)"}[n] for n in ndims
        )
        raise ValueError(f"`{name}` must have shape {expected}, got {tuple(joints.shape)}")
    if not joints.is_floating_point():
        raise ValueError(f"`{name}` must be a floating-point tensor, got {joints.dtype}")


def _check_pair(pred: Tensor, gt: Tensor, ndims: tuple[int, ...] | None = None) -> None:
    _check_joints("pred", pred, ndims)
    _check_joints("gt", gt, ndims)
    if pred.shape != gt.shape:
        raise ValueError(f"`gt` must have the shape of `pred` {tuple(pred.shape)}, got {tuple(gt.shape)}")


def _check_mask(mask: Tensor | None, shape: torch.Size) -> None:
    if mask is not None and (mask.shape != shape or mask.dtype != torch.bool):
        raise ValueError(f"`mask` must be a bool tensor of shape {tuple(shape)}, got {mask.dtype} {tuple(mask.shape)}")


def _weights(pred: Tensor, mask: Tensor | None) -> Tensor:
    """Per-joint weights (..., J, 1): the mask as 0/1, or ones."""
    if mask is None:
        return torch.ones_like(pred[..., :1])
    return mask[..., None].to(pred.dtype)


def align_root(joints: Tensor, root: Root = LSP14_ROOT) -> Tensor:
    """Subtract the root per frame: (..., J, 3) -> (..., J, 3), same unit.

    ``root`` is a joint index or a tuple of indices whose mean is the root (LSP-14 pelvis:
    the mean of the hips, ``(2, 3)``).
    """
    _check_joints("joints", joints)
    index = [root] if isinstance(root, int) else list(root)
    num_joints = joints.shape[-2]
    if not index or not all(-num_joints <= i < num_joints for i in index):
        raise ValueError(f"`root` must hold joint indices in [0, {num_joints}), got {root!r}")
    return joints - joints[..., index, :].mean(dim=-2, keepdim=True)


def procrustes_transform(pred: Tensor, gt: Tensor, mask: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
    """Similarity ``(s, R, t)`` that best maps ``pred`` onto ``gt`` per frame (least squares).

    pred, gt: (..., J, 3); mask: bool (..., J), joints used for the fit (None = all).
    Returns scale (...,), rotation (..., 3, 3) and translation (..., 3) such that
    ``s * R @ p_j + t`` approximates ``g_j``. The SVD is sign-corrected so that ``R`` is a
    proper rotation (det +1): a mirrored prediction is never "fixed" by a reflection.
    """
    _check_pair(pred, gt)
    _check_mask(mask, pred.shape[:-1])
    dtype = torch.promote_types(pred.dtype, gt.dtype)
    pred, gt = pred.to(dtype), gt.to(dtype)
    w = _weights(pred, mask)
    n = w.sum(dim=-2, keepdim=True).clamp_min(1.0)
    mu_pred = (w * pred).sum(dim=-2, keepdim=True) / n
    mu_gt = (w * gt).sum(dim=-2, keepdim=True) / n
    pred0, gt0 = pred - mu_pred, gt - mu_gt
    cov = (w * gt0).transpose(-1, -2) @ pred0  # sum_j w_j g_j p_j^T, (..., 3, 3)
    u, sigma, vh = torch.linalg.svd(cov)
    det_sign = torch.where(torch.linalg.det(u @ vh) < 0, -1.0, 1.0).to(dtype)
    signs = torch.cat([torch.ones_like(sigma[..., :2]), det_sign[..., None]], dim=-1)
    rotation = (u * signs[..., None, :]) @ vh
    var = (w * pred0.square()).sum(dim=(-2, -1))
    scale = (sigma * signs).sum(dim=-1) / var.clamp_min(torch.finfo(dtype).tiny)
    rotated_mu = (mu_pred @ rotation.transpose(-1, -2))[..., 0, :]
    translation = mu_gt[..., 0, :] - scale[..., None] * rotated_mu
    return scale, rotation, translation


def procrustes_align(pred: Tensor, gt: Tensor, mask: Tensor | None = None) -> Tensor:
    """``pred`` (..., J, 3) mapped onto ``gt`` by the best similarity (scale, rotation,
    translation) per frame; see :func:`procrustes_transform`. Same unit as the inputs."""
    scale, rotation, translation = procrustes_transform(pred, gt, mask)
    pred = pred.to(rotation.dtype)
    return scale[..., None, None] * pred @ rotation.transpose(-1, -2) + translation[..., None, :]


def scale_align(pred: Tensor, gt: Tensor, mask: Tensor | None = None) -> Tensor:
    """``s * pred`` with ``s = <pred, gt> / <pred, pred>`` per frame (the N-MPJPE scale).

    pred, gt: (..., J, 3), expected root-centred already (the scale is about the origin);
    mask: bool (..., J), joints used for the fit (None = all).
    """
    _check_pair(pred, gt)
    _check_mask(mask, pred.shape[:-1])
    w = _weights(pred, mask)
    num = (w * pred * gt).sum(dim=(-2, -1), keepdim=True)
    den = (w * pred.square()).sum(dim=(-2, -1), keepdim=True)
    return num / den.clamp_min(torch.finfo(den.dtype).tiny) * pred


def mpjpe(
    pred: Tensor,
    gt: Tensor,
    mask: Tensor | None = None,
    alignment: Alignment = "root",
    root: Root = LSP14_ROOT,
) -> Tensor:
    """Per-joint position errors (..., J) in the input unit (mm) after aligning ``pred``.

    pred, gt: (..., J, 3). ``alignment``:

    - "root": both root-centred (MPJPE, protocol 1);
    - "scale": both root-centred, then pred scaled by :func:`scale_align` (N-MPJPE);
    - "procrustes": pred mapped by :func:`procrustes_align` (PA-MPJPE, protocol 2);
    - "none": raw positions.

    ``mask`` (bool, (..., J)) restricts the scale / Procrustes fit to valid joints; errors are
    still returned for every joint (select with the mask before averaging).
    """
    _check_pair(pred, gt)
    _check_mask(mask, pred.shape[:-1])
    if alignment == "none":
        aligned, target = pred, gt
    elif alignment in ("root", "scale"):
        aligned, target = align_root(pred, root), align_root(gt, root)
        if alignment == "scale":
            aligned = scale_align(aligned, target, mask)
    elif alignment == "procrustes":
        aligned, target = procrustes_align(pred, gt, mask), gt
    else:
        raise ValueError(f"`alignment` must be one of {_ALIGNMENTS}, got {alignment!r}")
    return torch.linalg.vector_norm(aligned - target, dim=-1)


def _masked_sum_count(errors: Tensor, mask: Tensor | None) -> tuple[Tensor, Tensor]:
    """Sum of ``errors`` where ``mask`` is True, and the number of such entries (as a tensor)."""
    if mask is None:
        return errors.sum(), torch.tensor(errors.numel(), device=errors.device)
    return torch.where(mask, errors, torch.zeros_like(errors)).sum(), mask.sum()


def _masked_mean(errors: Tensor, mask: Tensor | None) -> Tensor:
    total, count = _masked_sum_count(errors, mask)
    return total / count.to(total.dtype)


def pa_mpjpe(pred: Tensor, gt: Tensor, mask: Tensor | None = None) -> Tensor:
    """PA-MPJPE (mm): mean Procrustes-aligned error over valid joints of all frames.

    pred, gt: (..., J, 3); mask: bool (..., J). Scalar; NaN if no joint is valid.
    """
    return _masked_mean(mpjpe(pred, gt, mask, alignment="procrustes"), mask)


def n_mpjpe(pred: Tensor, gt: Tensor, mask: Tensor | None = None, root: Root = LSP14_ROOT) -> Tensor:
    """N-MPJPE (mm): mean root-centred, scale-aligned error over valid joints of all frames.

    pred, gt: (..., J, 3); mask: bool (..., J). Scalar; NaN if no joint is valid.
    """
    return _masked_mean(mpjpe(pred, gt, mask, alignment="scale", root=root), mask)


def acceleration_error(pred: Tensor, gt: Tensor, root: Root | None = LSP14_ROOT) -> Tensor:
    """Per-joint acceleration error in mm/frame^2 (VIBE / TCMR convention, never scaled by fps).

    pred, gt: (T, J, 3) or (B, T, J, 3) in mm. Both are root-centred first unless ``root`` is
    None. The acceleration at frame t is ``x[t-1] - 2 x[t] + x[t+1]``; returns the L2 norm of
    the pred-minus-gt difference, (T-2, J) or (B, T-2, J) (empty if T < 3).
    """
    _check_pair(pred, gt, ndims=(3, 4))
    if root is not None:
        pred, gt = align_root(pred, root), align_root(gt, root)

    def second_difference(x: Tensor) -> Tensor:
        return x[..., :-2, :, :] - 2.0 * x[..., 1:-1, :, :] + x[..., 2:, :, :]

    return torch.linalg.vector_norm(second_difference(pred) - second_difference(gt), dim=-1)


class MeanPerJointPositionError(Metric):
    """Mean per-joint position error (mm) over all valid joints of all frames of all updates.

    ``update(pred, gt, mask=None)`` with pred, gt (..., J, 3) in mm and bool mask (..., J).
    ``alignment`` and ``root`` are as in :func:`mpjpe` ("root" = MPJPE, "procrustes" =
    PA-MPJPE, "scale" = N-MPJPE). Each joint of each frame weighs the same. ``compute()``
    gives a float64 scalar; NaN if no joint was seen.
    """

    is_differentiable = True
    higher_is_better = False
    full_state_update = False

    def __init__(self, alignment: Alignment = "root", root: Root = LSP14_ROOT, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if alignment not in _ALIGNMENTS:
            raise ValueError(f"`alignment` must be one of {_ALIGNMENTS}, got {alignment!r}")
        self.alignment = alignment
        self.root_joints = root
        _sum_state(self, "error_sum")
        _sum_state(self, "count")

    def update(self, pred: Tensor, gt: Tensor, mask: Tensor | None = None) -> None:
        """Accumulate the error sum and valid-joint count of one batch."""
        errors = mpjpe(pred, gt, mask, alignment=self.alignment, root=self.root_joints)
        total, count = _masked_sum_count(errors, mask)
        self.error_sum += total.to(torch.float64)
        self.count += count.to(torch.float64)

    def compute(self) -> Tensor:
        """Mean error (mm)."""
        return self.error_sum / self.count


MPJPE = MeanPerJointPositionError


class AccelerationError(Metric):
    """Mean acceleration error in mm/frame^2 (not scaled by fps) over joints and frames.

    ``update(pred, gt)`` with sequences (T, J, 3) or (B, T, J, 3) in mm; see
    :func:`acceleration_error`. Each (frame, joint) of the T-2 inner frames of every update
    weighs the same, so longer sequences weigh more. NaN if nothing was seen.
    """

    is_differentiable = True
    higher_is_better = False
    full_state_update = False

    def __init__(self, root: Root | None = LSP14_ROOT, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.root_joints = root
        _sum_state(self, "error_sum")
        _sum_state(self, "count")

    def update(self, pred: Tensor, gt: Tensor) -> None:
        """Accumulate the error sum and (frame, joint) count of one sequence batch."""
        errors = acceleration_error(pred, gt, self.root_joints)
        total, count = _masked_sum_count(errors, None)
        self.error_sum += total.to(torch.float64)
        self.count += count.to(torch.float64)

    def compute(self) -> Tensor:
        """Mean acceleration error (mm/frame^2)."""
        return self.error_sum / self.count
