"""What a bootstrap run gives back: :class:`BootstrapResult`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from ..core import Scene
from ..pose import PoseResult

__all__ = ["BootstrapResult"]


@dataclass(kw_only=True)
class BootstrapResult:
    """What a run gives: the refined scene (its estimates replaced by the refined poses), the
    initial and final flows (T-1, 2, H, W) px, the final PoseResult (None without a pose
    stage), one metrics record per stage (see :mod:`lit_boot.bootstrap.evaluate`), the run
    folder, seconds per stage, the scene as the run started (initial estimates), and where the
    final flow comes from: the last flow stage's target, the tuned and zoomed flows' shares
    (:func:`~lit_boot.bootstrap.decisions.final_decisions`; None without a flow or zoom stage)."""

    run_dir: Path
    scene: Scene
    initial_scene: Scene
    initial_flows: torch.Tensor
    flows: torch.Tensor
    poses: PoseResult | None
    history: list[dict[str, Any]] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    decisions: dict[str, torch.Tensor] | None = None

    def before_after(self) -> dict[str, tuple[float, float]]:
        """Each metric's value at the start and at its last stage (see report.before_after)."""
        from .report import before_after

        return before_after(self.history)

    def table(self) -> str:
        """A before/after table (markdown) of every metric with units, changes marked better /
        worse, and a legend (see report.metrics_table)."""
        from .report import metrics_table

        return metrics_table(self.history)
