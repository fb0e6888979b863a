"""The optimiser both per-video optimisations use (FlowTTT's fine-tune, the pose refiners)."""

from __future__ import annotations

from collections.abc import Iterable

import torch

__all__ = ["adam"]


def adam(params: Iterable[torch.nn.Parameter], lr: float) -> torch.optim.Adam:
    """Adam, the fused implementation where the device has one: one kernel for all the weights
    instead of several per tensor (on CPU, 2.3x faster for RAFT's update block)."""
    params = list(params)
    try:
        return torch.optim.Adam(params, lr=lr, fused=True)
    except (RuntimeError, ValueError):
        return torch.optim.Adam(params, lr=lr)
