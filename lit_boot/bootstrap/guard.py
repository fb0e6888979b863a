"""The drift guard: after each stage, did the stage make its image evidence worse?

A flow stage (and the zoom stage) is judged by its flow's ``photo_error`` (the mean census error of frame t against
frame t+1 warped by the flow), a pose stage by its poses' ``track_error`` (the mean census
distance along the joint tracks); see :mod:`lit_boot.bootstrap.evaluate`. Each is compared
with the last kept stage that has the same figure. Neither needs ground truth. (The flow-pose
agreement is recorded too, but it cannot tell better from worse: a flow can follow a wrong pose.)
"""

from __future__ import annotations

from typing import Any

from .config import BootstrapConfig

__all__ = ["drift_guard", "guard_text"]


def drift_guard(config: BootstrapConfig, record: dict[str, Any], history: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The guard's event for a finished stage's ``record``, None when the evidence did not get
    worse by more than ``config.drift_tolerance``, a fraction:
    ``{"guard": "drift", "evidence": key, "before": x, "after": y, "action": record | stop | rollback}``
    (``config.drift_guard``: with record the run goes on, the event is kept in summary.json and
    the report)."""
    key = "photo_error" if record["kind"] in ("flow", "zoom") else "track_error"
    before = next((r[key] for r in reversed(history) if key in r and not r.get("rolled_back")), float("nan"))
    after = record[key]
    if not after > before * (1.0 + config.drift_tolerance):
        return None
    return {"guard": "drift", "evidence": key, "before": before, "after": after, "action": config.drift_guard}


def guard_text(guard: dict[str, Any]) -> str:
    """The drift guard's event in words."""
    what = "the flow's census error" if guard["evidence"] == "photo_error" else "the joint tracks' census error"
    return f"{what} rose {guard['before']:.3f} -> {guard['after']:.3f}"
