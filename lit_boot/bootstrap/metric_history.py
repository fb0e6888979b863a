"""A run's metric records, read the one way every view (table, plot, report) reads them.

A history is the run's records in order, each a dict with "stage", optionally "kind", "cycle",
"rolled_back", "info", and metrics: every other key with a finite float value (names and
conventions: :mod:`lit_boot.metrics.suite`, :mod:`lit_boot.bootstrap.evaluate`). Lower is better
for every metric but :data:`NEUTRAL_METRICS`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..metrics import base_metric_name

__all__ = ["NOT_METRICS", "NEUTRAL_METRICS", "METRIC_LEGEND", "unit", "metric_value", "metric_meaning",
           "before_after", "stage_series", "change_text", "verdict"]

NOT_METRICS = ("stage", "kind", "cycle")
_UNITS = (("_mm_per_frame2", "mm/frame²"), ("_px_per_frame2", "px/frame²"), ("_px", "px"), ("_mm", "mm"),
          ("_error", "of 48"))

#: Metrics that are not better when lower: a diagnostic, shown without "better" / "worse".
NEUTRAL_METRICS = ("drift_px",)

#: One legend line per metric family (lit_boot.metrics.suite's and lit_boot.bootstrap.evaluate's), in order.
METRIC_LEGEND = (
    (("epe", "epe_person", "epe_background", "epe_joints"),
     "flow end-point error vs the GT flow over valid pixels that stay visible in frame t+1 (Sintel's "
     "matched): all of them, on / off the GT person mask, at the GT joints"),
    (("epe_unmatched", "epe_all_pixels"),
     "flow end-point error vs the GT flow over the valid pixels occluded in frame t+1 (Sintel's "
     "unmatched: the frames cannot judge them), and over every valid pixel (Sintel's all)"),
    (("mpjpe_mm", "pa_mpjpe_mm"), "3D joint error vs GT, root-aligned / after Procrustes alignment"),
    (("accel_mm_per_frame2",), "acceleration error vs GT (jitter)"),
    (("proj2d_px",), "the 3D joints projected by the cameras vs the GT 2D joints"),
    (("kp2d_px",), "2D keypoint error vs GT"),
    (("agreement_px",),
     "flow-pose agreement: the L_opt residual of the current poses under the current flow "
     "(self-consistency, not accuracy; needs no GT)"),
    (("photo_error",),
     "image evidence: census error of frame t against frame t+1 warped by the flow (0..48; needs no GT)"),
    (("track_error",),
     "image evidence: census error along the joint tracks from frame t to t+1 (0..48; needs no GT)"),
    (("reprojection_px",),
     "the 3D joints projected by the cameras vs the detector's 2D keypoints (needs no GT)"),
    (("bone_variation",),
     "bone-length constancy: each bone's standard deviation over the frames over its mean length (needs no GT)"),
    (("jitter_mm_per_frame2", "jitter_px_per_frame2"),
     "jitter: the joints' acceleration from frame to frame (needs no GT)"),
    (("drift_px",),
     "how far the flow outside the person moved from RAFT's (needs no GT; 0 before by definition; "
     "a diagnostic, neither better nor worse)"),
)  # fmt: skip


def unit(metric: str) -> str:
    """Unit from the name: ``*_px`` px, ``*_mm`` mm, ``*_mm_per_frame2`` mm/frame², ``epe*`` px,
    ``*_error`` "of 48" (a census error); a pooled or per-person name as its metric's."""
    metric = base_metric_name(metric)
    for suffix, name in _UNITS:
        if metric.endswith(suffix):
            return name
    return "px" if metric.startswith("epe") else ""


def metric_value(value: object) -> float | None:
    """A finite float (Python or NumPy) as float; anything else (None, NaN, int, text) is None."""
    if not isinstance(value, (float, np.floating)) or not math.isfinite(value):
        return None
    return float(value)


def metric_meaning(metric: str) -> str:
    """The :data:`METRIC_LEGEND` line of ``metric``'s family ("" if unknown)."""
    metric = base_metric_name(metric)
    return next((text for names, text in METRIC_LEGEND if metric in names), "")


def before_after(history: Sequence[dict]) -> dict[str, tuple[float, float]]:
    """Each metric's value (float) at its first record and at its last, rolled-back stages left
    out, in order of first appearance; drift_px starts at 0.0 (the initial flow is RAFT's)."""
    first: dict[str, float] = {}
    last: dict[str, float] = {}
    for record in history:
        if record.get("rolled_back"):
            continue
        for k, v in record.items():
            if isinstance(v, float) and k not in NOT_METRICS:
                first.setdefault(k, v)
                last[k] = v
    if "drift_px" in first:
        first["drift_px"] = 0.0
    return {k: (first[k], last[k]) for k in first}


def stage_series(history: Sequence[dict]) -> dict[str, list[float]]:
    """Each metric's value at every record (NaN where the record has none, or not a finite
    float), in order of first appearance: a plot draws no line across a NaN."""
    series: dict[str, list[float]] = {}
    for i, record in enumerate(history):
        for key, value in record.items():
            if key not in NOT_METRICS and (v := metric_value(value)) is not None:
                series.setdefault(key, [math.nan] * len(history))[i] = v
    return series


def change_text(metric: str, before: float, after: float) -> str:
    """The change from ``before`` to ``after``: ``-12.0%``; in the unit when ``before`` is 0
    (``+0.008 px``); ``unchanged``; "" when either is not finite."""
    if not (math.isfinite(before) and math.isfinite(after)):
        return ""
    if after == before:
        return "unchanged"
    if before:
        return f"{100 * (after - before) / abs(before):+.1f}%"
    step = after - before
    return f"{step:+.3f} {unit(metric)}".rstrip() if abs(step) >= 1e-3 else f"{step:+.2g} {unit(metric)}".rstrip()


def verdict(metric: str, before: float, after: float) -> str:
    """"better" (lower), "worse", "unchanged", or "" for a neutral metric or a non-finite value."""
    if metric in NEUTRAL_METRICS or not (math.isfinite(before) and math.isfinite(after)):
        return ""
    return "unchanged" if after == before else "better" if after < before else "worse"
