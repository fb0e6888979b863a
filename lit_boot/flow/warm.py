"""The fast fine-tune: frozen encoders, cached features, a warm start, and crops (issue 15).

With RAFT's encoders frozen (``train_parts="update_block"``), a frame's feature maps and a
pair's context never change during a fine-tune, so they are computed once per scene
(:class:`FeatureCache`), with the untuned network's flow of every pair (``predict_updates``
iterations from zero, kept at 1/8 resolution and upsampled). A warm-started step then runs a
few update iterations from that flow, on a box of cells around the person
(:func:`crop_box`): the correlation pyramid of the box is built from the cached maps, which is
cheap, and nothing else of the frame is computed. A warm prediction runs the same iterations on
the same box and pastes the result into the untuned flow (:func:`paste`, FlowTTT's default):
outside the box the output *is* the untuned flow, so the fine-tune cannot move the flow where
the target taught nothing. (Or, ``paste_crop=False``, on the whole frame from the untuned flow.)

:class:`WarmStart` is FlowTTT's side of it: it owns the cache, each pair's box and the untuned
weights, and gives a training step's loss and a prediction.

Coordinates: boxes are (y0, y1, x0, x1) in cells of the padded 1/8-resolution grid; pixel
regions are (y0, y1, x0, x1) in px of the unpadded frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch
from torch import Tensor
from torchvision.models.optical_flow import RAFT

from .raft import context_state, encode_frames, pad_to_multiple, run_updates, to_unit_range, unpad

__all__ = ["FeatureCache", "WarmStart", "MIN_CELLS", "TUNED_PARTS", "crop_box", "box_region", "paste"]

#: The smallest side of a box, in cells: torchvision's correlation pyramid needs 16 (128 px).
MIN_CELLS = 16
#: The parts of RAFT a warm start tunes (the encoders stay frozen: their outputs are cached).
TUNED_PARTS = ("update_block.", "mask_predictor.")


@dataclass
class FeatureCache:
    """RAFT's frozen-encoder outputs for every frame of a scene, and the untuned flow of every pair.

    Attributes:
        frames: (T, 3, H, W) the frames it was built from (to tell whether it fits a scene).
        fmaps: (T, C, h, w) feature maps, h = padded H / 8.
        hidden, context: (T-1, C', h, w) the context encoder's initial state of each pair's first frame.
        flow8: (T-1, 2, h, w) the untuned flow at 1/8 resolution, 1/8 px.
        base: (T-1, 2, H, W) px the untuned flow at full resolution (what :func:`predict_flow` gives).
        pad: (left, right, top, bottom) px of the padding.
    """

    frames: Tensor
    fmaps: Tensor
    hidden: Tensor
    context: Tensor
    flow8: Tensor
    base: Tensor
    pad: tuple[int, int, int, int]

    @classmethod
    def build(cls, model: RAFT, frames: Tensor, updates: int) -> FeatureCache:
        """Encode ``frames`` (T, 3, H, W; uint8 0..255 or float 0..1) once each and run
        ``updates`` iterations from zero per pair, on the model's device in eval mode (normal
        tensors even when called under inference mode, e.g. from a Lightning predict: training
        uses them later)."""
        with torch.inference_mode(False), torch.no_grad():
            return cls._build(model, frames, updates)

    @classmethod
    def _build(cls, model: RAFT, frames: Tensor, updates: int) -> FeatureCache:
        device = next(model.parameters()).device
        was_training = model.training
        model.eval()
        try:
            fmaps, hidden, context, pad = [], [], [], (0, 0, 0, 0)
            for t in range(frames.shape[0]):
                image, pad = pad_to_multiple(to_unit_range(frames[t].to(device), "frames"))
                fmaps.append(encode_frames(model, image))
                if t < frames.shape[0] - 1:
                    h, c = context_state(model, image)
                    hidden.append(h)
                    context.append(c)
            fmaps = torch.cat(fmaps)
            flow8, base = [], []
            for i in range(frames.shape[0] - 1):
                flows, low = run_updates(model, fmaps[i : i + 1], fmaps[i + 1 : i + 2], hidden[i], context[i], None,
                                         updates, grad_updates=1)  # fmt: skip
                flow8.append(low)
                base.append(unpad(flows[-1], pad).float().cpu())
        finally:
            model.train(was_training)
        return cls(frames, fmaps, torch.cat(hidden), torch.cat(context), torch.cat(flow8), torch.cat(base), pad)

    def fits(self, frames: Tensor) -> bool:
        """Whether the cache was built from these frames."""
        if frames is self.frames:
            return True
        return frames.shape == self.frames.shape and bool(torch.equal(frames.cpu(), self.frames.cpu()))

    @property
    def cells(self) -> tuple[int, int]:
        """(h, w): the padded 1/8-resolution grid."""
        return self.fmaps.shape[-2], self.fmaps.shape[-1]

    @property
    def whole(self) -> tuple[int, int, int, int]:
        """The box of the whole grid."""
        return 0, self.fmaps.shape[-2], 0, self.fmaps.shape[-1]

    def flows(self, model: RAFT, pair: int, box: tuple[int, int, int, int], updates: int,
              grad_updates: int | None = None) -> list[Tensor]:  # fmt: skip
        """The flows (1, 2, 8 (y1 - y0), 8 (x1 - x0)) px of the last ``grad_updates`` (None:
        every) of ``updates`` iterations on ``box`` of pair ``pair``, from the untuned flow;
        gradients (when enabled) reach the update block (and mask predictor)."""
        y0, y1, x0, x1 = box
        device = next(model.parameters()).device

        def crop(t: Tensor) -> Tensor:
            return t[..., y0:y1, x0:x1].to(device).contiguous()

        i = slice(pair, pair + 1)
        return run_updates(model, crop(self.fmaps[i]), crop(self.fmaps[pair + 1 : pair + 2]), crop(self.hidden[i]),
                           crop(self.context[i]), crop(self.flow8[i]), updates, grad_updates)[0]  # fmt: skip


def crop_box(mask: Tensor, margin: int | None, pad: tuple[int, int, int, int], cells: tuple[int, int],
             flow: Tensor | None = None) -> tuple[int, int, int, int] | None:  # fmt: skip
    """The box of cells (y0, y1, x0, x1) holding ``mask`` (H, W) bool's bounding box, and where
    ``flow`` (2, H, W) px (the target) moves its pixels, plus ``margin`` px, grown to
    :data:`MIN_CELLS` a side where the grid allows; the whole grid when ``margin`` is None; None
    when the mask is empty and a margin is given (nothing to crop to)."""
    h, w = cells
    if margin is None:
        return 0, h, 0, w
    ys, xs = torch.nonzero(mask, as_tuple=True)
    if ys.numel() == 0:
        return None
    if flow is not None:  # the correlation must reach where the pixels go
        u, v = flow[0, ys, xs], flow[1, ys, xs]
        ys, xs = torch.cat([ys, (ys + v).round().long()]), torch.cat([xs, (xs + u).round().long()])
    left, _, top, _ = pad

    def span(lo: int, hi: int, size: int) -> tuple[int, int]:
        a, b = max(0, (lo - margin) // 8), min(size, -(-(hi + margin + 1) // 8))
        need = min(MIN_CELLS, size)
        if b - a < need:  # grow both ways, kept inside the grid
            a = max(0, min(a - (need - (b - a)) // 2, size - need))
            b = a + need
        return a, b

    y0, y1 = span(int(ys.min()) + top, int(ys.max()) + top, h)
    x0, x1 = span(int(xs.min()) + left, int(xs.max()) + left, w)
    return y0, y1, x0, x1


def box_region(box: tuple[int, int, int, int], pad: tuple[int, int, int, int], size: tuple[int, int]) -> tuple[tuple[int, int, int, int], tuple[int, int, int, int]]:
    """Where a box's upsampled flow lies: (frame region, the same region within the box's flow),
    each (y0, y1, x0, x1) px; ``size`` is the unpadded (H, W)."""
    y0, y1, x0, x1 = (8 * v for v in box)
    left, _, top, _ = pad
    H, W = size
    fy0, fy1 = max(0, y0 - top), min(H, y1 - top)
    fx0, fx1 = max(0, x0 - left), min(W, x1 - left)
    return (fy0, fy1, fx0, fx1), (fy0 + top - y0, fy1 + top - y0, fx0 + left - x0, fx1 + left - x0)


def paste(base: Tensor, flow: Tensor, box: tuple[int, int, int, int], pad: tuple[int, int, int, int]) -> Tensor:
    """``base`` (2, H, W) with the box's flow (1, 2, 8 bh, 8 bw) pasted where it lies (a copy)."""
    (fy0, fy1, fx0, fx1), (by0, by1, bx0, bx1) = box_region(box, pad, base.shape[-2:])
    out = base.clone()
    out[:, fy0:fy1, fx0:fx1] = flow[0, :, by0:by1, bx0:bx1].to(out)
    return out


Box = tuple[int, int, int, int]


class WarmStart:
    """FlowTTT's fast fine-tune on one scene at a time: the :class:`FeatureCache` (built with the
    untuned weights), each pair's crop box (:func:`crop_box`) and the untuned weights of
    :data:`TUNED_PARTS`.

    Args:
        raft: the network, held (not copied): its tuned parts are what training changes.
        loss: a step's loss, (flows list of (1, 2, h, w) px, target (1, 2, h, w) px, weight
            (1, h, w)) -> scalar (FlowTTT's :class:`~lit_boot.flow.losses.SketchLoss`).
        train_updates: iterations from the untuned flow per training step and tuned prediction.
        grad_updates: backpropagate through the last this many (None: all).
        predict_updates: iterations from zero of the untuned flow (the cache's base flow).
        crop_margin: px around the sketch of a pair's box (None: the whole grid).
        paste_crop: predict on the box only and paste it into the untuned flow (else the whole
            frame from the untuned flow).
    """

    def __init__(self, raft: RAFT, loss: Callable[[list[Tensor], Tensor, Tensor], Tensor], *, train_updates: int,
                 grad_updates: int | None, predict_updates: int, crop_margin: int | None,
                 paste_crop: bool):  # fmt: skip
        self.raft, self.loss_fn = raft, loss
        self.train_updates, self.grad_updates, self.predict_updates = train_updates, grad_updates, predict_updates
        self.crop_margin, self.paste_crop = crop_margin, paste_crop
        self.untuned = self.trainable_state()  # the weights the network had when the warm start was made
        self.cache: FeatureCache | None = None
        self.boxes: list[Box | None] | None = None  # the fit's boxes, per pair (None: nothing painted there)
        self.active = False  # this predict / validation run predicts from the cache (see begin)
        self.tuned = False  # ... with the tuned iterations (else: the cache's base flow)

    def trainable_state(self) -> dict[str, Tensor]:
        """A copy of the network's :data:`TUNED_PARTS` weights."""
        return {k: v.detach().clone() for k, v in self.raft.state_dict().items() if k.startswith(TUNED_PARTS)}

    def is_untuned(self) -> bool:
        """Whether the network's tuned parts hold the untuned weights."""
        state = self.raft.state_dict()
        return all(torch.equal(state[k], v.to(state[k].device)) for k, v in self.untuned.items())

    def build(self, frames: Tensor) -> FeatureCache:
        """The cache of ``frames`` (T, 3, H, W), built with the untuned weights (and the network's
        own restored after) unless the one held fits; a new cache drops the boxes."""
        if self.cache is None or not self.cache.fits(frames):
            self.boxes = None  # the boxes were the previous frames'
            tuned = self.trainable_state()
            self.raft.load_state_dict(self.untuned, strict=False)
            try:
                self.cache = FeatureCache.build(self.raft, frames, self.predict_updates)
            finally:
                self.raft.load_state_dict(tuned, strict=False)
        return self.cache

    def fit(self, frames: Tensor, masks: Tensor, targets: Tensor) -> FeatureCache:
        """Ready a fit on ``frames``: the cache, and each pair's box around its sketch mask
        ``masks`` (P, H, W) bool and where its target ``targets`` (P, 2, H, W) px moves them (with
        a margin, a pair with nothing painted has no box: its flow stays the untuned one)."""
        cache = self.build(frames)
        self.boxes = [crop_box(m, self.crop_margin, cache.pad, cache.cells, t)
                      for m, t in zip(masks.cpu(), targets.cpu())]  # fmt: skip
        return cache

    def begin(self, frames: Tensor | None) -> None:
        """Start a predict or validation run on ``frames`` (None: not known, the run predicts
        from zero instead): build the cache if it does not fit, and predict its base flow (RAFT's
        own) while the network is untuned, else the tuned iterations from it."""
        self.active = frames is not None
        if self.active:
            self.build(frames)
            self.tuned = not self.is_untuned()

    def _boxes(self, index: Tensor, grad: bool) -> list[Box | None]:
        """Each pair's box: its crop in training; in prediction too with ``paste_crop`` (after a
        fit on these frames), else the whole frame."""
        if grad or (self.paste_crop and self.boxes is not None):
            return [self.boxes[i] for i in index.tolist()]
        return [self.cache.whole] * len(index)

    def _flows(self, index: Tensor, grad: bool) -> list[list[Tensor] | None]:
        """Per pair of ``index``: the last iterations' flows on its box (None: no box)."""
        grad_updates = self.grad_updates if grad else 1
        return [None if box is None else self.cache.flows(self.raft, int(i), box, self.train_updates, grad_updates)
                for i, box in zip(index.tolist(), self._boxes(index, grad))]  # fmt: skip

    def loss(self, index: Tensor, target: Tensor, weight: Tensor) -> Tensor | None:
        """A training step's loss on pairs ``index`` (B,) against ``target`` (B, 2, H, W) px with
        ``weight`` (B, H, W): the mean over the pairs with a box of the loss on the box (None if
        none has one)."""
        losses = []
        for b, flows in enumerate(self._flows(index, grad=True)):
            if flows is not None:
                (fy0, fy1, fx0, fx1), (by0, by1, bx0, bx1) = box_region(self.boxes[int(index[b])], self.cache.pad,
                                                                        target.shape[-2:])  # fmt: skip
                region = [f[..., by0:by1, bx0:bx1] for f in flows]
                losses.append(self.loss_fn(region, target[b : b + 1, :, fy0:fy1, fx0:fx1],
                                           weight[b : b + 1, fy0:fy1, fx0:fx1]))  # fmt: skip
        return sum(losses) / len(losses) if losses else None

    def predict(self, index: Tensor) -> Tensor:
        """The flows (B, 2, H, W) px on the CPU of pairs ``index`` (B,) of the run's frames (see
        :meth:`begin`): the untuned flow, with the tuned iterations' flow pasted on each box."""
        base = self.cache.base
        if not self.tuned:
            return base[index]
        pairs = zip(index.tolist(), self._flows(index, grad=False), self._boxes(index, grad=False))
        out = [base[i] if flows is None else paste(base[i], flows[-1].float().cpu(), box, self.cache.pad)
               for i, flows, box in pairs]  # fmt: skip
        return torch.stack(out)
