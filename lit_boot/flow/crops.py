"""Image crops for FlowTTT's full fine-tune with ``crop_margin`` (the fast fine-tune crops the
cached feature maps instead: :mod:`lit_boot.flow.warm`).

Each pair trains on the sketch's bounding box plus a margin, and, with a hold weight, on a box of
the same size elsewhere in the frame whose target is the base flow, which holds the rest of the
frame in place. Boxes are (y0, y1, x0, x1) px.
"""

from __future__ import annotations

from typing import Callable

import torch
from torch import Tensor

__all__ = ["sketch_box", "anchor_box", "crop_loss"]


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
              target: Tensor, weight: Tensor, mask: Tensor, margin: int, hold_weight: float) -> Tensor:  # fmt: skip
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
