"""Resolution where the person is: RAFT on a zoomed crop around the person (issue 24, part 1).

RAFT matches features on a grid of 1/8 of the image: a limb a few cells wide is smeared with the
background around it. Run on a crop around the person, upsampled by a scale ``s``, the same
network resolves the limb with ``s`` times the cells, and its flow, scaled back, is a
*candidate* for the person and the context around it. It is no more than a candidate: where the
motion is large, RAFT at ``s`` times the size sees ``s`` times the displacement and fails
(BENCHMARKS.md, "Resolution where the person is"). So:

- the scale is chosen per pair from the motion (:func:`zoom_scale`): the zoomed motion (``s`` x
  the 95th percentile of RAFT's own flow magnitude on the person's box) must stay within
  ``reach_px``; at most ``max_scale`` (or, for a small person's crop, more: :func:`scale_cap`),
  and no zoom below ``min_scale``;
- what is kept is decided from the frames, per pixel, by the orchestrator
  (:mod:`lit_boot.bootstrap.zoom`, whose ``ZoomConfig`` holds the settings), with
  :func:`refines` as one of its tests: the zoomed flow may move RAFT's flow by less than
  ``max_change_px`` (two cells of RAFT's grid by default): a refinement, not another match.

Conventions: person boxes are (x0, y0, x1, y1, score) px with pixel centres at integer
coordinates (:mod:`lit_boot.estimate.detector`; score 0 = nobody); crops and regions are
(y0, y1, x0, x1) px, half-open, inside the frame. Flows are (2, H, W) px, forward t -> t+1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor
from torchvision.models.optical_flow import RAFT

from .raft import predict_flow

__all__ = ["boxes_from_points", "pair_boxes", "zoom_crop", "zoom_scale", "zoom_updates", "zoomed_flow",
           "box_motion", "shifted_crop", "scale_cap", "ZOOM_STARTS",
           "paste_region", "refines", "ZoomedPair", "zoom_pair"]

Region = tuple[int, int, int, int]
#: How RAFT starts on the zoomed crops: see :func:`zoom_pair`.
ZOOM_STARTS = ("zero", "shift", "warm")


def boxes_from_points(points: Tensor, keep: Tensor) -> Tensor:
    """Per-frame boxes around a pose's image points: points (T, K, 2) px, keep (T, K) bool ->
    (T, 5) (x0, y0, x1, y1, score): the points' bounding box with score 1 where at least two
    points count, zeros (nobody) elsewhere. The box is tight: :func:`zoom_crop` adds the context."""
    boxes = torch.zeros(points.shape[0], 5)
    for t in range(points.shape[0]):
        p = points[t][keep[t]].float()
        if p.shape[0] >= 2:
            boxes[t] = torch.cat([p.min(0).values, p.max(0).values, torch.ones(1)])
    return boxes


def pair_boxes(boxes: Tensor) -> list[Tensor | None]:
    """Per pair (t, t+1) of T frames: the box (4,) holding the person's boxes (T, 5) of both
    frames (of the one that has somebody), or None when neither has."""
    out = []
    for t in range(boxes.shape[0] - 1):
        found = [boxes[i, :4] for i in (t, t + 1) if boxes[i, 4] > 0]
        if not found:
            out.append(None)
            continue
        stack = torch.stack(found)
        out.append(torch.cat([stack[:, :2].min(0).values, stack[:, 2:].max(0).values]))
    return out


def zoom_crop(box: Tensor, size: tuple[int, int], *, context: float, min_context_px: int) -> Region:
    """The crop (y0, y1, x0, x1) px around ``box`` (4,) x0, y0, x1, y1: the box plus a margin of
    ``context`` x its larger side (at least ``min_context_px``), inside the frame of ``size`` (H, W)."""
    height, width = size
    x0, y0, x1, y1 = (float(v) for v in box)
    margin = max(min_context_px, context * max(x1 - x0, y1 - y0))
    return (max(0, math.floor(y0 - margin)), min(height, math.ceil(y1 + margin) + 1),
            max(0, math.floor(x0 - margin)), min(width, math.ceil(x1 + margin) + 1))  # fmt: skip


def _box_slices(box: Tensor, size: tuple[int, int]) -> tuple[slice, slice]:
    """The rows and columns of a box (4,) x0, y0, x1, y1 px inside a frame of ``size`` (H, W)."""
    height, width = size
    x0, y0, x1, y1 = box.tolist()
    return (slice(max(0, round(y0)), min(height, round(y1) + 1)),
            slice(max(0, round(x0)), min(width, round(x1) + 1)))  # fmt: skip


def box_motion(base: Tensor, box: Tensor) -> Tensor:
    """The person's typical motion: the per-axis median of ``base`` (2, H, W) px on the box (4,)
    x0, y0, x1, y1 px, (2,) px (dx, dy); zeros for an empty box."""
    ys, xs = _box_slices(box, tuple(base.shape[-2:]))
    values = base[:, ys, xs].detach().reshape(2, -1).float()
    return values.median(dim=1).values if values.shape[1] else torch.zeros(2)


def zoom_scale(base: Tensor, box: Tensor, *, max_scale: float, min_scale: float, reach_px: float,
               relative_to: Tensor | None = None) -> tuple[float, float]:  # fmt: skip
    """The scale to zoom a pair at, and the motion it was chosen from: (s, the 95th percentile of
    the magnitude (px) of ``base`` (2, H, W), RAFT's own flow, on the box (4,); less
    ``relative_to`` (2,) px where given: the motion left once frame2's crop follows the person).
    s = min(max_scale, reach_px / motion); 1.0 (no zoom) when that is below ``min_scale``."""
    ys, xs = _box_slices(box, tuple(base.shape[-2:]))
    flow = base[:, ys, xs].detach().float()  # a statistic: no graph (the flow may come from a tuned RAFT)
    if relative_to is not None:
        flow = flow - relative_to.float()[:, None, None]
    magnitude = flow.norm(dim=0).flatten()
    motion = float(magnitude.quantile(0.95)) if magnitude.numel() else 0.0
    scale = min(max_scale, reach_px / motion) if motion > 0 else max_scale
    return (scale if scale >= min_scale else 1.0), motion


def zoom_updates(scale: float, motion: float, *, min_updates: int, max_updates: int) -> int:
    """RAFT iterations for a crop zoomed ``scale`` times whose motion is ``motion`` px: one more
    than ``min_updates`` per cell of RAFT's grid (8 px) the zoomed motion spans, at most
    ``max_updates`` (a small motion converges in a few iterations, a large one needs more)."""
    return min(max_updates, min_updates + math.ceil(scale * motion / 8))


def _resize(image: Tensor, size: tuple[int, int]) -> Tensor:
    """(C, h, w) -> (C, *size), bilinear (the values' dtype kept; uint8 rounded)."""
    out = F.interpolate(image[None].float(), size=size, mode="bilinear", align_corners=False)[0]
    return out.clamp(0, 255).round().to(torch.uint8) if image.dtype == torch.uint8 else out


@torch.no_grad()
def zoomed_flow(model: RAFT, frame1: Tensor, frame2: Tensor, crop: Region, scale: float, updates: int,
                shift: tuple[int, int] = (0, 0), start: Tensor | None = None) -> Tensor:  # fmt: skip
    """RAFT's flow (2, h, w) px at the crop's own size for the crop (y0, y1, x0, x1) of frame1
    and the same-size crop of frame2 moved by ``shift`` (dx, dy) px (inside the frame: see
    :func:`shifted_crop`), frames (3, H, W) uint8, computed on the crops upsampled by ``scale``
    (bilinear) and scaled back (bilinear, flow / scale), the shift added back; ``updates``
    iterations from zero, or from ``start`` (2, h, w) px (a flow of the crop, e.g. RAFT's own:
    a warm start, so that RAFT's reach applies to what it corrects, not to the whole motion), on
    the model's device."""
    y0, y1, x0, x1 = crop
    dx, dy = shift
    a, b = frame1[:, y0:y1, x0:x1], frame2[:, y0 + dy : y1 + dy, x0 + dx : x1 + dx]
    h, w = a.shape[-2:]
    size = (max(1, round(h * scale)), max(1, round(w * scale)))
    factor = torch.tensor([size[1] / w, size[0] / h])[:, None, None]
    was_training = model.training
    model.eval()
    try:
        if start is None:
            flow = predict_flow(model, _resize(a, size)[None], _resize(b, size)[None], updates)[0].float().cpu()
        else:
            moved = (start.float() - torch.tensor([dx, dy], dtype=torch.float32)[:, None, None]) * factor
            flow = predict_flow(model, _resize(a, size)[None], _resize(b, size)[None], updates,
                                start=_resize(moved, size)[None])[0].float().cpu()
    finally:
        model.train(was_training)
    return _resize(flow, (h, w)) / factor + torch.tensor([dx, dy], dtype=torch.float32)[:, None, None]


def shifted_crop(crop: Region, shift: Tensor, size: tuple[int, int]) -> tuple[int, int]:
    """The whole-pixel shift (dx, dy) of frame2's crop that follows ``shift`` (2,) px (the
    person's typical motion) as far as the crop (y0, y1, x0, x1) stays inside a frame of ``size``
    (H, W)."""
    y0, y1, x0, x1 = crop
    height, width = size
    dx = min(max(round(float(shift[0])), -x0), width - x1)
    dy = min(max(round(float(shift[1])), -y0), height - y1)
    return dx, dy


def paste_region(crop: Region, size: tuple[int, int], border: int) -> Region:
    """Where a crop's zoomed flow is used: the crop less ``border`` px along its inner edges
    (those not on the frame's border of ``size`` (H, W)); may be empty (y0 >= y1 or x0 >= x1)."""
    height, width = size
    y0, y1, x0, x1 = crop
    return (y0 + (border if y0 > 0 else 0), y1 - (border if y1 < height else 0),
            x0 + (border if x0 > 0 else 0), x1 - (border if x1 < width else 0))  # fmt: skip


def refines(base: Tensor, zoomed: Tensor, max_change_px: float) -> Tensor:
    """Where ``zoomed`` (..., 2, H, W) px moves ``base`` by less than ``max_change_px``: (..., H, W) bool."""
    return (zoomed - base).norm(dim=-3) < max_change_px


@dataclass
class ZoomedPair:
    """One pair's zoom: the candidate flow (2, H, W) px (``base`` with the zoomed flow pasted
    into ``region``; ``base`` itself when not zoomed), the scale (1.0: not zoomed), the motion
    it was chosen from (px), the crop and the pasted region (y0, y1, x0, x1) px or None, the
    zoomed pixels as a fraction of the frame's (the zoom's cost relative to RAFT's) and the RAFT
    iterations run on them (0: not zoomed), and the whole-pixel shift (dx, dy) of frame2's crop.
    """

    candidate: Tensor
    scale: float
    motion_px: float
    crop: Region | None
    region: Region | None
    cost: float
    updates: int = 0
    shift: tuple[int, int] = (0, 0)

    def record(self) -> dict:
        """JSON-ready: scale, motion, crop, region, cost, updates, shift (dx, dy) px."""
        return {"scale": round(self.scale, 4), "motion_px": round(self.motion_px, 3), "crop": self.crop,
                "region": self.region, "cost": round(self.cost, 4), "updates": self.updates,
                "shift": list(self.shift)}  # fmt: skip


def scale_cap(crop: Region, size: tuple[int, int], *, max_scale: float, small_scale: float | None = None,
              max_cost: float = 1.0, max_pixels: int | None = None) -> float:  # fmt: skip
    """The largest scale for a crop (y0, y1, x0, x1) of a frame of ``size`` (H, W): ``max_scale``,
    or more for a small person, up to ``small_scale`` (None: no more), as far as the zoomed crop
    stays within ``max_cost`` frames of pixels (a small person is zoomed more at the same cost as a
    large one); and whatever the person's size, no more than keeps the zoomed crop within
    ``max_pixels`` (None: no limit; RAFT's correlation memory grows with their square)."""
    y0, y1, x0, x1 = crop
    area = max(1, (y1 - y0) * (x1 - x0))
    cap = max_scale
    if small_scale is not None:
        cap = max(max_scale, min(small_scale, math.sqrt(max_cost * size[0] * size[1] / area)))
    return cap if max_pixels is None else min(cap, math.sqrt(max_pixels / area))


def zoom_pair(model: RAFT, frame1: Tensor, frame2: Tensor, base: Tensor, box: Tensor | None, *, max_scale: float,
              min_scale: float, reach_px: float, context: float, min_context_px: int, border_px: int,
              min_updates: int, max_updates: int, start: str = "zero", small_scale: float | None = None,
              max_cost: float = 1.0, max_pixels: int | None = None) -> ZoomedPair:  # fmt: skip
    """The zoom of one pair: frames (3, H, W) uint8, ``base`` (2, H, W) px RAFT's own flow, the
    pair's person box (4,) or None (nobody: not zoomed); the scale from :func:`zoom_scale`, at most
    :func:`scale_cap` (``small_scale`` None: ``max_scale``; ``max_pixels`` None: no limit), the
    crop from :func:`zoom_crop`,
    pasted into :func:`paste_region` (``border_px``), the RAFT
    iterations on the zoomed crop from :func:`zoom_updates`. ``start``: ``zero`` (RAFT from zero
    on the same crop of both frames), ``shift`` (frame2's crop follows the person's typical
    motion, :func:`box_motion`, and the scale is chosen from the motion left) or ``warm``
    (``shift``, and RAFT starts from ``base``). See :class:`ZoomedPair`."""
    if start not in ZOOM_STARTS:
        raise ValueError(f"start: expected one of {ZOOM_STARTS}, got {start!r}")
    size = tuple(base.shape[-2:])
    if box is None:
        return ZoomedPair(base, 1.0, 0.0, None, None, 0.0)
    crop = zoom_crop(box, size, context=context, min_context_px=min_context_px)
    shift = (0, 0) if start == "zero" else shifted_crop(crop, box_motion(base, box), size)
    relative_to = None if start == "zero" else torch.tensor(shift, dtype=torch.float32)
    max_scale = scale_cap(crop, size, max_scale=max_scale, small_scale=small_scale, max_cost=max_cost,
                          max_pixels=max_pixels)  # fmt: skip
    scale, motion = zoom_scale(base, box, max_scale=max_scale, min_scale=min_scale, reach_px=reach_px,
                               relative_to=relative_to)  # fmt: skip
    region = paste_region(crop, size, border_px)
    ry0, ry1, rx0, rx1 = region
    if scale == 1.0 or ry0 >= ry1 or rx0 >= rx1:
        return ZoomedPair(base, 1.0, motion, None, None, 0.0)
    updates = zoom_updates(scale, motion, min_updates=min_updates, max_updates=max_updates)
    y0, y1, x0, x1 = crop
    warm = base[:, y0:y1, x0:x1] if start == "warm" else None
    flow = zoomed_flow(model, frame1, frame2, crop, scale, updates, shift, warm)
    candidate = base.clone()
    candidate[:, ry0:ry1, rx0:rx1] = flow[:, ry0 - y0 : ry1 - y0, rx0 - x0 : rx1 - x0].to(candidate)
    cost = (y1 - y0) * (x1 - x0) * scale**2 / (size[0] * size[1])
    return ZoomedPair(candidate, scale, motion, crop, region, cost, updates, shift)
