"""FlowTTT's loss: RAFT's flows pulled towards the sketched target flow (paper 3.1).

SmoothL1 per pixel (the mean of its two components), averaged with per-pixel weights
(:meth:`SketchLoss.weights`): ``sketch_weight`` on the sketch, 0 in the unknown zone of ``gap``
px beside it (limb or background: no loss), 1 elsewhere (held to the base flow). ``final``
scores the last update's flow (the authors), ``sequence`` every update's, weighted
``gamma ** (n - 1 - i)`` as RAFT's training loss.
"""

from __future__ import annotations

import torch.nn.functional as F
from torch import Tensor, nn

from .crops import person_region

__all__ = ["LOSSES", "SketchLoss"]

#: The loss kinds: the last update's flow only, or every update's (RAFT's sequence loss).
LOSSES = ("final", "sequence")


class SketchLoss(nn.Module):
    """The weighted SmoothL1 between flows and the target flow.

    Args:
        loss: final (the last flow only, as the authors) or sequence (every flow, RAFT's
            gamma-weighted loss).
        gamma: decay of the sequence loss per update from the last.
        beta: SmoothL1's beta, px: quadratic below it, linear above (1: the authors).
        sketch_weight: weight of sketch pixels relative to the held ones (1: every pixel alike).
        gap: px beside the sketch whose unpainted pixels get no loss (0: every unpainted pixel
            is held to the base flow, the authors).
    """

    def __init__(self, *, loss: str = "final", gamma: float = 0.8, beta: float = 1.0, sketch_weight: float = 1.0,
                 gap: int = 0):  # fmt: skip
        super().__init__()
        if loss not in LOSSES:
            raise ValueError(f"loss: expected one of {LOSSES}, got {loss!r}")
        if not beta >= 0:
            raise ValueError(f"beta: expected >= 0 px, got {beta}")
        if not sketch_weight >= 0:
            raise ValueError(f"sketch_weight: expected >= 0, got {sketch_weight}")
        if gap < 0:
            raise ValueError(f"gap: expected >= 0 px, got {gap}")
        self.loss, self.gamma, self.beta, self.sketch_weight, self.gap = loss, gamma, beta, sketch_weight, int(gap)

    def weights(self, mask: Tensor) -> Tensor:
        """Per-pixel weights (B, H, W) float from sketch masks (B, H, W) bool: ``sketch_weight``
        on the sketch, 0 on the unpainted pixels within ``gap`` px of it, 1 elsewhere."""
        weight = 1.0 + (self.sketch_weight - 1.0) * mask.float()
        if self.gap:
            weight = weight * (mask | ~person_region(mask, self.gap)).float()
        return weight

    def _one(self, flow: Tensor, target: Tensor, weight: Tensor) -> Tensor:
        per_pixel = F.smooth_l1_loss(flow.float(), target, beta=self.beta, reduction="none").mean(1)
        return (per_pixel * weight).sum() / weight.sum()

    def forward(self, flows: list[Tensor], target: Tensor, weight: Tensor) -> Tensor:
        """The loss (a scalar) of ``flows`` (each (B, 2, H, W) px, in update order) against
        ``target`` (B, 2, H, W) px with ``weight`` (B, H, W) (see :meth:`weights`)."""
        if not flows:
            raise ValueError("flows: expected at least one flow, got none")
        if self.loss == "final":
            return self._one(flows[-1], target, weight)
        n = len(flows)
        return sum(self.gamma ** (n - 1 - i) * self._one(f, target, weight) for i, f in enumerate(flows))

    def extra_repr(self) -> str:
        return (f"loss={self.loss!r}, gamma={self.gamma}, beta={self.beta}, sketch_weight={self.sketch_weight}, "
                f"gap={self.gap}")
