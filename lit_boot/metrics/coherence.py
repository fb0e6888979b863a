"""How usable a flow is beyond its end-point error, without ground truth: does a change of the flow
come in coherent regions, is the flow rough, does it step where a crop ended?

Someone who warps frames or edits video with a flow sees what EPE averages away: a flow kept from
one candidate on scattered single pixels (speckle) and a step along the edge of the crop that a
candidate came from (a seam). Conventions: flows (B, 2, H, W) px; masks (B, H, W) bool; boxes
(y0, y1, x0, x1) px, end-exclusive.

- :func:`changed_pixels`: where two flows differ by more than a tolerance.
- :func:`speckle`: the share of changed pixels that disagree with most of their 8 neighbours on
  whether they changed.
- :func:`roughness`: the flow's mean gradient magnitude (the Jacobian's Frobenius norm, px/px)
  over a region.
- :func:`border_step`: the flow's mean step across the border of a box (the pairs of pixels on
  either side of it).
"""

from __future__ import annotations

import kornia
import torch
import torch.nn.functional as F
from torch import Tensor

__all__ = ["CHANGE_PX", "changed_pixels", "speckle", "roughness", "border_step"]

#: A flow changed where it moved by more than this, px.
CHANGE_PX = 0.05


def changed_pixels(flow: Tensor, reference: Tensor, tolerance: float = CHANGE_PX) -> Tensor:
    """(B, H, W) bool: where ``flow`` and ``reference`` (B, 2, H, W) px differ by more than
    ``tolerance`` px (end-point distance)."""
    return torch.hypot(*(flow - reference).unbind(1)) > tolerance


def _neighbours(mask: Tensor) -> tuple[Tensor, Tensor]:
    """Per pixel of (B, H, W) bool ``mask``: how many of its 8 neighbours inside the image are
    set, and how many neighbours it has inside the image (8, 5 on an edge, 3 at a corner)."""
    kernel = torch.ones(1, 1, 3, 3, device=mask.device)
    kernel[0, 0, 1, 1] = 0
    count = lambda m: F.conv2d(F.pad(m.float()[:, None], (1, 1, 1, 1)), kernel)[:, 0]  # noqa: E731 zeros outside
    return count(mask), count(torch.ones_like(mask))


def speckle(changed: Tensor) -> float:
    """The share of the changed pixels (``changed`` (B, H, W) bool) that disagree with most of
    their 8 neighbours on whether they changed: fewer than half of their neighbours inside the
    image changed too. 0.0 when nothing changed. A change in coherent regions scores near 0 (only
    thin tips); one on scattered single pixels near 1."""
    if not changed.any():
        return 0.0
    same, neighbours = _neighbours(changed)
    return float((changed & (2 * same < neighbours)).sum() / changed.sum())


def roughness(flow: Tensor, region: Tensor | None = None) -> float:
    """The mean gradient magnitude of ``flow`` (B, 2, H, W) px over ``region`` (B, H, W) bool
    (None: every pixel): per pixel the Frobenius norm of the flow's Jacobian by central
    differences (replicate border), px of flow per px; NaN for an empty region."""
    grad = kornia.filters.spatial_gradient(flow.float(), mode="diff", order=1, normalized=False)  # (B, 2, 2, H, W)
    magnitude = grad.square().sum((1, 2)).sqrt() / 2  # kornia's unnormalised kernel is [-1, 0, 1]
    if region is None:
        return float(magnitude.mean())
    return float(magnitude[region].mean()) if region.any() else float("nan")


def border_step(flow: Tensor, box: tuple[int, int, int, int]) -> float:
    """The mean step of ``flow`` (2, H, W) px across the border of ``box`` (y0, y1, x0, x1) px:
    the end-point distance between each pixel just inside the box and its neighbour just outside,
    over the sides that lie inside the frame; NaN when no side does."""
    _, height, width = flow.shape
    y0, y1, x0, x1 = box
    steps = []
    if y0 > 0:
        steps.append(flow[:, y0, x0:x1] - flow[:, y0 - 1, x0:x1])
    if y1 < height:
        steps.append(flow[:, y1 - 1, x0:x1] - flow[:, y1, x0:x1])
    if x0 > 0:
        steps.append(flow[:, y0:y1, x0] - flow[:, y0:y1, x0 - 1])
    if x1 < width:
        steps.append(flow[:, y0:y1, x1 - 1] - flow[:, y0:y1, x1])
    if not steps:
        return float("nan")
    step = torch.cat(steps, 1)
    return float(torch.hypot(step[0], step[1]).mean())
