"""The refiners' objective: every weighted SmoothL1 term reduced in one pass.

Each term is ``lambda * (1/N) * sum(w * SmoothL1(r))`` over its residual r (N, ...) with
constant per-element weights w (confidences; 1 by default). Rather than reducing every term
on its own (a dozen small kernels each, forward and backward), the residuals are flattened,
concatenated and reduced by one SmoothL1 and one dot product with a weight vector built once:
``lambda / N * w`` per element. On a CPU, where a step is dominated by per-kernel overhead,
this makes a step markedly cheaper. Binary masks that change during optimisation (e.g. joints
outside the image) are applied to the residual itself (SmoothL1(0) = 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["Term", "Objective"]


@dataclass
class Term:
    """One weighted term: residual shape (N, ...) (N frames or pairs), lambda, and optional
    constant weights (N, J) that weigh the rows of an (N, J, D) residual."""

    name: str
    shape: tuple[int, ...]
    weight: float
    element_weight: torch.Tensor | None = None


class Objective(nn.Module):
    """Sum of weighted SmoothL1 (beta 1) terms; ``forward(residuals)`` in the order of ``terms``.

    Terms with lambda 0 or no elements are dropped at construction (:attr:`names` lists the
    kept ones, in order; give their residuals only).
    """

    def __init__(self, terms: list[Term]):
        super().__init__()
        kept = [t for t in terms if t.weight != 0 and all(n > 0 for n in t.shape)]
        self.names = [t.name for t in kept]
        self.shapes = [t.shape for t in kept]
        self.sizes = [int(torch.Size(t.shape).numel()) for t in kept]
        parts = []
        for t in kept:
            w = torch.full(t.shape, t.weight / t.shape[0])
            if t.element_weight is not None:
                w = w * t.element_weight.detach().float().reshape(t.element_weight.shape + (1,) * (len(t.shape) - 2))
            parts.append(w.reshape(-1))
        weights = torch.cat(parts) if parts else torch.zeros(0)
        self.register_buffer("weights", weights, persistent=False)
        self.register_buffer("zeros", torch.zeros_like(weights), persistent=False)

    def __len__(self) -> int:
        return len(self.names)

    def _check(self, residuals: list[torch.Tensor]) -> None:
        if len(residuals) != len(self.names):
            raise ValueError(f"Objective: expected {len(self.names)} residuals ({self.names}), got {len(residuals)}")
        for name, shape, r in zip(self.names, self.shapes, residuals):
            if tuple(r.shape) != shape:
                raise ValueError(f"Objective: residual {name!r} has shape {tuple(r.shape)}, expected {shape}")

    def forward(self, residuals: list[torch.Tensor]) -> torch.Tensor:
        """The total loss, a scalar (0 without terms)."""
        if not self.names:
            return self.weights.sum()
        flat = torch.cat([r.reshape(-1) for r in residuals])
        if flat.shape != self.weights.shape:
            self._check(residuals)
        return torch.dot(F.smooth_l1_loss(flat, self.zeros, reduction="none", beta=1.0), self.weights)

    @torch.no_grad()
    def split(self, residuals: list[torch.Tensor]) -> dict[str, torch.Tensor]:
        """Each term's weighted value (no gradient), by name."""
        self._check(residuals)
        flat = torch.cat([r.detach().reshape(-1) for r in residuals]) if residuals else self.weights
        per_element = F.smooth_l1_loss(flat, self.zeros, reduction="none", beta=1.0) * self.weights
        return {name: part.sum() for name, part in zip(self.names, per_element.split(self.sizes))}
