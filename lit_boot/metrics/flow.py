"""Optical-flow metrics: end-point error, accuracy rates, Fl-all, and errors at query points.

Flows are ``(B, 2, H, W)`` or ``(2, H, W)`` tensors in pixels; channel 0 is x (u), channel 1
is y (v). Pixel centres lie at integer coordinates, so the flow ``(u, v)`` at pixel ``(x, y)``
maps it to ``(x + u, y + v)``. Dense averages pool all selected pixels of all images
(each pixel weighs the same; no per-image mean first), as in torchvision's reference scripts.
The ``Metric`` classes accumulate float64 sums and divide only in ``compute()``.
"""

from __future__ import annotations

from typing import Any, Literal

import torch
import torch.nn.functional as F
from torch import Tensor
from torchmetrics import Metric

__all__ = [
    "endpoint_error",
    "flow_error_sums",
    "flow_errors",
    "sample_flow_at_points",
    "epe_at_points",
    "EndPointError",
    "FlowErrorRates",
    "PointEndPointError",
]

SampleMode = Literal["bilinear", "nearest"]
_RATE_THRESHOLDS = {"1px": 1.0, "3px": 3.0, "5px": 5.0}


def _check_flow(name: str, flow: Tensor, batched: bool | None = None) -> None:
    """Raise ValueError unless ``flow`` is a floating (B,2,H,W) / (2,H,W) tensor."""
    ndims = {True: (4,), False: (3,), None: (3, 4)}[batched]
    expected = " or ".join({3: "(2, H, W)", 4: "(B, 2, H, W)"}[n] for n in ndims)
    if not isinstance(flow, Tensor) or flow.ndim not in ndims or flow.shape[-3] != 2:
        shape = tuple(flow.shape) if isinstance(flow, Tensor) else type(flow).__name__
        raise ValueError(f"`{name}` must have shape {expected}, got {shape}")
    if not flow.is_floating_point():
        raise ValueError(f"`{name}` must be a floating-point tensor, got {flow.dtype}")


def endpoint_error(pred: Tensor, gt: Tensor) -> Tensor:
    """Per-pixel end-point error ``||pred - gt||_2`` over the channel dim, in pixels.

    pred, gt: (B, 2, H, W) or (2, H, W), same shape. Returns (B, H, W) or (H, W).
    """
    _check_flow("pred", pred)
    _check_flow("gt", gt)
    if pred.shape != gt.shape:
        raise ValueError(f"`gt` must have the shape of `pred` {tuple(pred.shape)}, got {tuple(gt.shape)}")
    return _magnitude(pred - gt)


def _magnitude(flow: Tensor) -> Tensor:
    """|flow| over the channel dim (..., 2, H, W) -> (..., H, W); hypot of the two channels
    (on a CPU ~30x faster than a vector norm reduced over dim -3)."""
    return torch.hypot(flow[..., 0, :, :], flow[..., 1, :, :])


def flow_error_sums(pred: Tensor, gt: Tensor, mask: Tensor | None = None) -> dict[str, Tensor]:
    """Sums behind :func:`flow_errors`, for exact accumulation across batches and devices.

    pred, gt: (B, 2, H, W) or (2, H, W) in pixels; mask: bool (B, H, W) / (H, W) of pixels to
    count (None = all). Returns scalar tensors: "epe_sum" (sum of EPE, pred's dtype), and int64
    counts "1px" / "3px" / "5px" (EPE < 1 / 3 / 5 px), "fl_all" (EPE > 3 px and
    EPE > 0.05 * |gt|) and "count" (selected pixels). Unselected pixels may hold NaN/inf.
    """
    epe = endpoint_error(pred, gt)
    if mask is None:
        mask = torch.ones_like(epe, dtype=torch.bool)
    elif mask.shape != epe.shape or mask.dtype != torch.bool:
        raise ValueError(
            f"`mask` must be a bool tensor of shape {tuple(epe.shape)}, got {mask.dtype} "
            f"{tuple(mask.shape)} (use `mask.bool()` for 0/1 validity maps)"
        )
    gt_norm = _magnitude(gt)
    sums = {"epe_sum": torch.where(mask, epe, torch.zeros_like(epe)).sum()}
    for name, threshold in _RATE_THRESHOLDS.items():
        sums[name] = (mask & (epe < threshold)).sum()
    sums["fl_all"] = (mask & (epe > 3.0) & (epe > 0.05 * gt_norm)).sum()
    sums["count"] = mask.sum()
    return sums


def flow_errors(pred: Tensor, gt: Tensor, mask: Tensor | None = None) -> dict[str, Tensor]:
    """Dense flow errors over the pixels where ``mask`` is True (None = all pixels).

    pred, gt: (B, 2, H, W) or (2, H, W) in pixels; mask: bool (B, H, W) or (H, W).
    Returns scalar tensors (pred's dtype):

    - "epe": mean end-point error in pixels;
    - "1px", "3px", "5px": accuracy rates, the fraction of pixels with EPE < 1 / 3 / 5 px
      (higher is better, as in RAFT's evaluation);
    - "fl_all": KITTI outlier rate, the fraction of pixels with EPE > 3 px and
      EPE > 0.05 * |gt| (lower is better).

    Averaging: all selected pixels of all images count equally (not per-image first).
    An empty selection gives NaN.
    """
    sums = flow_error_sums(pred, gt, mask)
    count = sums.pop("count").to(sums["epe_sum"].dtype)
    epe = sums.pop("epe_sum") / count
    return {"epe": epe, **{name: value.to(count.dtype) / count for name, value in sums.items()}}


def sample_flow_at_points(flow: Tensor, points: Tensor, mode: SampleMode = "bilinear") -> Tensor:
    """Flow vectors at sub-pixel points, in pixels.

    flow: (B, 2, H, W) (or (2, H, W)); points: (B, K, 2) (or (K, 2)) pixel coordinates (x, y)
    with pixel centres at integers. Returns (B, K, 2) (or (K, 2)) as (u, v), in flow's dtype.

    - "bilinear": ``grid_sample`` with ``align_corners=True`` and border padding (points
      outside the image get the nearest edge value); differentiable w.r.t. ``flow`` and
      ``points``.
    - "nearest": ``torch.round`` (ties to even) then clamp into the image; no gradient to
      ``points``; non-finite coordinates are clamped (mask such points out downstream).
    """
    unbatched = flow.ndim == 3
    _check_flow("flow", flow, batched=None)
    batch_mismatch = not unbatched and points.shape[0] != flow.shape[0]
    if points.ndim != flow.ndim - 1 or points.shape[-1] != 2 or batch_mismatch:
        expected = "(K, 2)" if unbatched else f"({flow.shape[0]}, K, 2)"
        raise ValueError(f"`points` must have shape {expected} to match `flow`, got {tuple(points.shape)}")
    if mode not in ("bilinear", "nearest"):
        raise ValueError(f"`mode` must be 'bilinear' or 'nearest', got {mode!r}")
    if unbatched:
        return sample_flow_at_points(flow[None], points[None], mode)[0]

    height, width = flow.shape[-2:]
    if mode == "bilinear":
        pts = points.to(flow.dtype)
        scale = pts.new_tensor([max(width - 1, 1), max(height - 1, 1)])
        grid = (2.0 * pts / scale - 1.0)[:, :, None, :]  # (B, K, 1, 2)
        out = F.grid_sample(flow, grid, mode="bilinear", padding_mode="border", align_corners=True)
        return out[..., 0].transpose(1, 2)  # (B, 2, K) -> (B, K, 2)

    pts = points.detach()
    if pts.is_floating_point():
        pts = torch.nan_to_num(pts).round()
    x = pts[..., 0].clamp(0, width - 1).long()
    y = pts[..., 1].clamp(0, height - 1).long()
    index = (y * width + x)[:, None, :].expand(-1, 2, -1)  # (B, 2, K)
    return flow.flatten(2).gather(2, index).transpose(1, 2)


def epe_at_points(
    flow: Tensor,
    points: Tensor,
    gt_displacement: Tensor,
    visible: Tensor | None = None,
    mode: SampleMode = "bilinear",
) -> Tensor:
    """Per-point end-point error between the flow sampled at ``points`` and ``gt_displacement``.

    flow: (B, 2, H, W); points, gt_displacement: (B, K, 2) in pixels (x, y); visible: bool (B, K).
    Returns (B, K) errors in pixels. Points with ``visible`` False get error 0 (no NaN, and no
    gradient), so ``err.sum() / visible.sum()`` is the mean over visible points.
    """
    sampled = sample_flow_at_points(flow, points, mode)
    if gt_displacement.shape != sampled.shape:
        raise ValueError(
            f"`gt_displacement` must have shape {tuple(sampled.shape)} (like `points`), "
            f"got {tuple(gt_displacement.shape)}"
        )
    err = torch.linalg.vector_norm(sampled - gt_displacement, dim=-1)
    if visible is None:
        return err
    if visible.shape != err.shape or visible.dtype != torch.bool:
        raise ValueError(
            f"`visible` must be a bool tensor of shape {tuple(err.shape)}, got {visible.dtype} {tuple(visible.shape)}"
        )
    return torch.where(visible, err, torch.zeros_like(err))


def _sum_state(metric: Metric, name: str) -> None:
    metric.add_state(name, default=torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum")


class EndPointError(Metric):
    """Mean end-point error in pixels over all selected pixels of all updates.

    ``update(pred, gt, mask=None)`` with flows (B, 2, H, W) / (2, H, W) and bool mask
    (B, H, W) / (H, W). Every selected pixel weighs the same. ``compute()`` gives a float64
    scalar; NaN if no pixel was seen.
    """

    is_differentiable = True
    higher_is_better = False
    full_state_update = False

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        _sum_state(self, "epe_sum")
        _sum_state(self, "count")

    def update(self, pred: Tensor, gt: Tensor, mask: Tensor | None = None) -> None:
        """Accumulate the EPE sum and pixel count of one batch."""
        sums = flow_error_sums(pred, gt, mask)
        self.epe_sum += sums["epe_sum"].to(torch.float64)
        self.count += sums["count"].to(torch.float64)

    def compute(self) -> Tensor:
        """Mean EPE (pixels)."""
        return self.epe_sum / self.count


class FlowErrorRates(Metric):
    """Accuracy rates and KITTI Fl-all over all selected pixels of all updates.

    ``update(pred, gt, mask=None)`` as :class:`EndPointError`. ``compute()`` gives a dict of
    float64 scalars: "1px" / "3px" / "5px" (fraction with EPE < 1 / 3 / 5 px, higher is
    better) and "fl_all" (fraction with EPE > 3 px and > 5 % of |gt|, lower is better).
    Every selected pixel weighs the same; NaN if no pixel was seen.
    """

    is_differentiable = False
    higher_is_better = None
    full_state_update = False

    _names = (*_RATE_THRESHOLDS, "fl_all")

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        for name in self._names:
            _sum_state(self, f"n_{name}")
        _sum_state(self, "count")

    def update(self, pred: Tensor, gt: Tensor, mask: Tensor | None = None) -> None:
        """Accumulate the per-threshold counts and the pixel count of one batch."""
        sums = flow_error_sums(pred, gt, mask)
        for name in self._names:
            state = getattr(self, f"n_{name}")
            setattr(self, f"n_{name}", state + sums[name].to(torch.float64))
        self.count += sums["count"].to(torch.float64)

    def compute(self) -> dict[str, Tensor]:
        """Rates in [0, 1] keyed "1px", "3px", "5px", "fl_all"."""
        return {name: getattr(self, f"n_{name}") / self.count for name in self._names}


class PointEndPointError(Metric):
    """Mean end-point error (pixels) of flow sampled at query points, over visible points.

    ``update(flow, points, gt_displacement, visible=None)`` with flow (B, 2, H, W), points and
    gt_displacement (B, K, 2) in pixels (x, y), visible bool (B, K) (None = all). ``mode`` is
    "bilinear" or "nearest" (see :func:`sample_flow_at_points`). Every visible point of every
    update weighs the same; ``compute()`` is NaN if no visible point was seen.
    """

    is_differentiable = True
    higher_is_better = False
    full_state_update = False

    def __init__(self, mode: SampleMode = "bilinear", **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if mode not in ("bilinear", "nearest"):
            raise ValueError(f"`mode` must be 'bilinear' or 'nearest', got {mode!r}")
        self.mode = mode
        _sum_state(self, "epe_sum")
        _sum_state(self, "count")

    def update(self, flow: Tensor, points: Tensor, gt_displacement: Tensor, visible: Tensor | None = None) -> None:
        """Accumulate the error sum and the visible-point count of one batch."""
        err = epe_at_points(flow, points, gt_displacement, visible, self.mode)
        self.epe_sum += err.sum().to(torch.float64)
        self.count += float(err.numel()) if visible is None else visible.sum().to(torch.float64)

    def compute(self) -> Tensor:
        """Mean point EPE (pixels)."""
        return self.epe_sum / self.count
