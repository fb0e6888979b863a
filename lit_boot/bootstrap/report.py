"""What a bootstrap run shows: the before/after table, a metrics plot per stage, an mp4 video
of the before/after overlays (made by :mod:`lit_boot.bootstrap.overlay`).

Images are uint8 tensors (3, H, W) in RGB order. Every file is written atomically (a
temporary file beside the target, then renamed).
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import torch
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..data.atomic import atomic_file, atomic_write_bytes
from .overlay import overlay_frames, video_fps

__all__ = ["before_after", "metric_meaning", "metric_rows", "metrics_table", "overlay_frames", "plot_history",
           "video_fps", "write_video"]

_NOT_METRICS = ("stage", "kind", "cycle")
_UNITS = (("_mm_per_frame2", "mm/frame²"), ("_px", "px"), ("_mm", "mm"), ("_error", "of 48"))


def _unit(metric: str) -> str:
    """Unit from the name: ``*_px`` px, ``*_mm`` mm, ``*_mm_per_frame2`` mm/frame², ``epe*`` px,
    ``*_error`` "of 48" (a census error)."""
    for suffix, unit in _UNITS:
        if metric.endswith(suffix):
            return unit
    return "px" if metric.startswith("epe") else ""


def _metric_value(value: object) -> float | None:
    """A finite float (Python or NumPy) as float; anything else (None, NaN, int, text) is None."""
    if not isinstance(value, (float, np.floating)) or not math.isfinite(value):
        return None
    return float(value)


#: Metrics that are not better when lower: a diagnostic, shown without "better" / "worse".
NEUTRAL_METRICS = ("drift_px",)

#: One legend line per metric family (lit_boot.metrics.suite's and lit_boot.bootstrap.evaluate's), in order.
METRIC_LEGEND = (
    (("epe", "epe_person", "epe_background", "epe_joints"),
     "flow end-point error vs the GT flow over valid, non-occluded pixels: all, on / off the GT "
     "person mask, at the GT joints"),
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
    (("drift_px",),
     "how far the flow outside the person moved from RAFT's (needs no GT; 0 before by definition; "
     "a diagnostic, neither better nor worse)"),
)  # fmt: skip


def before_after(history: Sequence[dict]) -> dict[str, tuple[float, float]]:
    """Each metric's value (float) at its first record and at its last, rolled-back stages left
    out, in order of first appearance; drift_px starts at 0.0 (the initial flow is RAFT's)."""
    first: dict[str, float] = {}
    last: dict[str, float] = {}
    for record in history:
        if record.get("rolled_back"):
            continue
        for k, v in record.items():
            if isinstance(v, float) and k not in _NOT_METRICS:
                first.setdefault(k, v)
                last[k] = v
    if "drift_px" in first:
        first["drift_px"] = 0.0
    return {k: (first[k], last[k]) for k in first}


def _change(metric: str, a: float, b: float) -> str:
    """``-12.0% better``, ``+3.1% **worse**``, ``unchanged``; in the unit when ``a`` is 0."""
    if not (math.isfinite(a) and math.isfinite(b)):
        return ""
    if b == a:
        return "unchanged"
    change = f"{100 * (b - a) / abs(a):+.1f}%" if a else f"{b - a:+.3f} {_unit(metric)}".rstrip()
    if metric in NEUTRAL_METRICS:
        return change
    return f"{change} better" if b < a else f"{change} **worse**"


def metric_meaning(metric: str) -> str:
    """The :data:`METRIC_LEGEND` line of ``metric``'s family ("" if unknown)."""
    return next((text for names, text in METRIC_LEGEND if metric in names), "")


def metric_rows(history: Sequence[dict]) -> list[dict]:
    """One dict per metric of :func:`before_after`: ``metric``, ``unit``, ``before``, ``after``,
    ``change_pct`` (after vs before, %; None when before is 0 or a value is not finite),
    ``better`` ("lower", or "neither" for :data:`NEUTRAL_METRICS`), ``verdict`` ("better",
    "worse", "unchanged", "" for a neutral or non-finite one) and ``meaning`` (its legend line)."""
    rows = []
    for metric, (a, b) in before_after(history).items():
        finite = math.isfinite(a) and math.isfinite(b)
        neutral = metric in NEUTRAL_METRICS
        verdict = "" if neutral or not finite else "unchanged" if a == b else "better" if b < a else "worse"
        rows.append({"metric": metric, "unit": _unit(metric), "before": a, "after": b,
                     "change_pct": 100 * (b - a) / abs(a) if finite and a else None,
                     "better": "neither" if neutral else "lower", "verdict": verdict,
                     "meaning": metric_meaning(metric)})  # fmt: skip
    return rows


def metrics_table(history: Sequence[dict]) -> str:
    """Markdown: every metric's unit, value before (the initial stage) and after (its last
    stage), and change, marked ``better`` or ``**worse**`` (lower is better but for
    :data:`NEUTRAL_METRICS`); then one legend line per metric family present."""
    values = before_after(history)
    rows = ["| metric | unit | before | after | change (lower is better) |", "| --- | --- | --- | --- | --- |"]
    rows += [f"| {k} | {_unit(k)} | {a:.3f} | {b:.3f} | {_change(k, a, b)} |" for k, (a, b) in values.items()]
    worse = [k for k, (a, b) in values.items() if k not in NEUTRAL_METRICS and b > a]
    rows += ["", "Before: the initial stage (pretrained RAFT, the input poses); after: each metric's last "
             f"stage. Lower is better for every metric but {', '.join(NEUTRAL_METRICS)}; "
             + (f"worse: {', '.join(worse)}." if worse else "none got worse.")]  # fmt: skip
    rows += [f"- {' / '.join(k for k in names if k in values)}: {text}"
             for names, text in METRIC_LEGEND if any(k in values for k in names)]  # fmt: skip
    return "\n".join(rows)


def plot_history(history: Sequence[dict], path: str | os.PathLike) -> Path:
    """Plot the metrics of a bootstrap run per stage into a PNG at ``path``; returns the path.

    ``history``: records in run order, each a dict with "stage" (the x tick label; the first is
    usually "initial", the inputs' metrics), optionally "kind" and "cycle", and metrics: every
    other key with a float value (e.g. "epe", "mpjpe_mm", "agreement_px"; ints are not metrics).
    A metric that is missing, None or not finite in a record is left out for that record. One
    subplot per metric (up to 3 per row), in order of first appearance, markers and lines, the
    y unit from the name's suffix. Rendered with Matplotlib's Agg canvas (pyplot is untouched).
    Raises ValueError for an empty history, a record without "stage", or no metric at all.
    """
    path = Path(path)
    if not history:
        raise ValueError(f"plot_history({path}): empty history, nothing to plot")
    stages: list[str] = []
    for i, record in enumerate(history):
        if not isinstance(record, dict) or "stage" not in record:
            raise ValueError(f"plot_history({path}): history[{i}] is not a dict with a 'stage' key: {record!r}")
        stages.append(str(record["stage"]))
    series: dict[str, tuple[list[int], list[float]]] = {}
    for i, record in enumerate(history):
        for key, value in record.items():
            if key not in _NOT_METRICS and (v := _metric_value(value)) is not None:
                xs, ys = series.setdefault(key, ([], []))
                xs.append(i)
                ys.append(v)
    if not series:
        raise ValueError(f"plot_history({path}): no metrics in the history (no numeric values besides {_NOT_METRICS})")
    cols = min(3, len(series))
    rows = math.ceil(len(series) / cols)
    width = max(3.6, 0.55 * len(stages) + 1.5)
    fig = Figure(figsize=(width * cols, 2.9 * rows), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    for n, (name, (xs, ys)) in enumerate(series.items()):
        ax = fig.add_subplot(rows, cols, n + 1)
        ax.plot(xs, ys, marker="o", linestyle="-")
        ax.set_title(name)
        ax.set_ylabel(_unit(name))
        tilt = len(stages) > 3
        ax.set_xticks(range(len(stages)), stages, rotation=30 if tilt else 0, ha="right" if tilt else "center")
        ax.set_xlim(-0.5, len(stages) - 0.5)
        ax.grid(True, alpha=0.3)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return atomic_write_bytes(path, buffer.getvalue())


def write_video(frames_uint8: torch.Tensor, path: str | os.PathLike, fps: float) -> Path:
    """Write uint8 (N, 3, H, W) RGB frames as an mp4 video at ``path``, atomically; returns the path.

    Codec "mp4v", else "avc1". Odd H or W is padded by one pixel (edge replicated) at the
    bottom / right, since codecs need even sizes: the video is (H + H % 2) x (W + W % 2).
    The video goes to a hidden temporary file in the same folder, then ``os.replace``s ``path``.
    Raises ValueError for bad frames or fps, RuntimeError naming the path and codecs if OpenCV
    can open no writer, FileNotFoundError if the folder is missing.
    """
    path = Path(path)
    frames = frames_uint8
    if not isinstance(frames, torch.Tensor) or frames.dtype != torch.uint8 or frames.ndim != 4 \
            or frames.shape[1] != 3 or frames.shape[0] < 1:  # fmt: skip
        got = f"{frames.dtype} {tuple(frames.shape)}" if isinstance(frames, torch.Tensor) else type(frames).__name__
        raise ValueError(f"write_video({path}): expected frames_uint8 as uint8 (N, 3, H, W) with N >= 1, got {got}")
    if not fps > 0:
        raise ValueError(f"write_video({path}): fps must be positive, got {fps}")
    if not path.parent.is_dir():
        raise FileNotFoundError(f"write_video({path}): folder {path.parent} does not exist")
    frames = frames.detach().cpu()
    if frames.shape[2] % 2:
        frames = torch.cat([frames, frames[:, :, -1:]], dim=2)
    if frames.shape[3] % 2:
        frames = torch.cat([frames, frames[:, :, :, -1:]], dim=3)
    H, W = frames.shape[2:]
    codecs = ("mp4v", "avc1")
    with atomic_file(path) as tmp:  # the temporary name keeps the extension: OpenCV picks the container from it
        for codec in codecs:
            writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*codec), float(fps), (int(W), int(H)))
            if writer.isOpened():
                break
            writer.release()
            tmp.unlink(missing_ok=True)
        else:
            raise RuntimeError(
                f"write_video({path}): OpenCV could not open a video writer with codec {' or '.join(codecs)}"
            )
        try:
            for frame in frames:
                writer.write(cv2.cvtColor(np.ascontiguousarray(frame.permute(1, 2, 0).numpy()), cv2.COLOR_RGB2BGR))
        finally:
            writer.release()
        if not tmp.is_file() or tmp.stat().st_size == 0:
            raise RuntimeError(f"write_video({path}): OpenCV wrote no data with codec {codec!r}")
    return path
