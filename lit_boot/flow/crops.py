"""Image crops for FlowTTT's full fine-tune with ``crop_margin`` (the fast fine-tune crops the
cached feature maps instead: :mod:`lit_boot.flow.warm`).

Each pair trains on the sketch's bounding box plus a margin, and, with a hold weight, on a box of
the same size elsewhere in the frame whose target is the base flow, which holds the rest of the
frame in place. Boxes are (y0, y1, x0, x1) px. Also the person region around a sketch
(:func:`person_region`): the pixels that count as the person without ground truth.
"""

from __future__ import annotations

from typing import Callable

import torch
import torch.nn.functional as F
from torch import Tensor

__all__ = ["PERSON_MARGIN", "person_region", "sketch_box", "anchor_box", "crop_loss"]

#: px around the sketch that count as the person (:func:`person_region`).
PERSON_MARGIN = 16


def person_region(masks: Tensor, margin: int = PERSON_MARGIN) -> Tensor:
    """Sketch masks (B, H, W) bool dilated by a square of ``margin`` px each way: (B, H, W)
    bool, 'the person' without ground truth (the drift's complement, the self-check's person,
    the loss's unknown zone)."""
    if masks.ndim != 3 or masks.dtype != torch.bool:
        raise ValueError(f"masks: expected (B, H, W) bool, got {tuple(masks.shape)} {masks.dtype}")
    if margin < 0:
        raise ValueError(f"margin: expected >= 0 px, got {margin}")
    r = int(margin)
    # a flat square's dilation is a separable max filter (kornia's dilation is ~100x slower here)
    rows = F.max_pool2d(masks[:, None].float(), (1, 2 * r + 1), stride=1, padding=(0, r))
    return F.max_pool2d(rows, (2 * r + 1, 1), stride=1, padding=(r, 0))[:, 0] > 0


def sketch_box(mask: Tensor, margin: int) -> tuple[int, int, int, int] | None:
    """The bounding box of ``mask`` (H, W) bool plus ``margin`` px, inside the frame; None if empty."""
    ys, xs = torch.nonzero(mask, as_tuple=True)
    if ys.numel() == 0:
        return None
    H, W = mask.shape
    return (max(0, int(ys.min()) - margin), min(H, int(ys.max()) + margin + 1),
            max(0, int(xs.min()) - margin), min(W, int(xs.max()) + margin + 1))  # fmt: skip


def anchor_box(box: tuple[int, int, int, int], H: int, W: int) -> tuple[int, int, int, int]:
    """A box of the same size elsewhere in an H x W frame, overlapping ``box`` the least (of 8 draws)."""
    y0, y1, x0, x1 = box
    h, w = y1 - y0, x1 - x0
    best, best_overlap = (0, h, 0, w), None
    for _ in range(8):
        ay = int(torch.randint(0, H - h + 1, ()))
        ax = int(torch.randint(0, W - w + 1, ()))
        overlap = max(0, min(y1, ay + h) - max(y0, ay)) * max(0, min(x1, ax + w) - max(x0, ax))
        if best_overlap is None or overlap < best_overlap:
            best, best_overlap = (ay, ay + h, ax, ax + w), overlap
    return best


def crop_loss(step: Callable[[Tensor, Tensor, Tensor, Tensor], Tensor], image1: Tensor, image2: Tensor,
              target: Tensor, weight: Tensor, mask: Tensor, *, margin: int, hold_weight: float) -> Tensor:  # fmt: skip
    """Mean over the batch of ``step(image1, image2, target, weight)`` on each pair's sketch box
    (the whole frame when nothing is painted), plus ``hold_weight`` x the same on its anchor box.
    Inputs (B, C, H, W) / (B, H, W); ``step`` takes one pair's crops with a batch dim on the
    target and weight."""
    losses = []
    for b in range(image1.shape[0]):
        box = sketch_box(mask[b], margin) or (0, mask.shape[1], 0, mask.shape[2])
        boxes = [(box, 1.0)]
        if hold_weight > 0:  # outside the sketch the target is the base flow: the anchor holds it there
            boxes.append((anchor_box(box, *mask.shape[1:]), hold_weight))
        for (y0, y1, x0, x1), w in boxes:
            def crop(x: Tensor) -> Tensor:
                return x[..., y0:y1, x0:x1]

            losses.append(w * step(crop(image1[b]), crop(image2[b]), crop(target[b])[None], crop(weight[b])[None]))
    return sum(losses) / image1.shape[0]
