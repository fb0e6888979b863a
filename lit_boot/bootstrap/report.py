"""What a bootstrap run shows: the before/after table, a metrics plot per stage
(:mod:`~lit_boot.bootstrap.metrics_plot`), an mp4 video of the before/after overlays (made by
:mod:`lit_boot.bootstrap.overlay`). The run's records are read by
:mod:`~lit_boot.bootstrap.metric_history`.

Images are uint8 tensors (3, H, W) in RGB order. Every file is written atomically (a
temporary file beside the target, then renamed).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import torch

from ..data.atomic import atomic_file
from ..metrics import base_metric_name
from .metric_history import (METRIC_LEGEND, NEUTRAL_METRICS, before_after, change_text, metric_meaning, unit,
                             verdict)  # fmt: skip
from .metrics_plot import plot_history
from .overlay import overlay_frames, video_fps

__all__ = ["before_after", "metric_meaning", "metric_rows", "metrics_table", "overlay_frames", "plot_history",
           "video_fps", "write_video", "NEUTRAL_METRICS", "METRIC_LEGEND"]


def _change(metric: str, a: float, b: float) -> str:
    """``-12.0% better``, ``+3.1% **worse**``, ``unchanged``; in the unit when ``a`` is 0."""
    text, word = change_text(metric, a, b), verdict(metric, a, b)
    return f"{text} **worse**" if word == "worse" else f"{text} better" if word == "better" else text


def metric_rows(history: Sequence[dict]) -> list[dict]:
    """One dict per metric of :func:`before_after`: ``metric``, ``unit``, ``before``, ``after``,
    ``change_pct`` (after vs before, %; None when before is 0 or a value is not finite),
    ``better`` ("lower", or "neither" for :data:`NEUTRAL_METRICS`), ``verdict`` ("better",
    "worse", "unchanged", "" for a neutral or non-finite one) and ``meaning`` (its legend line)."""
    rows = []
    for metric, (a, b) in before_after(history).items():
        finite = math.isfinite(a) and math.isfinite(b)
        rows.append({"metric": metric, "unit": unit(metric), "before": a, "after": b,
                     "change_pct": 100 * (b - a) / abs(a) if finite and a else None,
                     "better": "neither" if metric in NEUTRAL_METRICS else "lower", "verdict": verdict(metric, a, b),
                     "meaning": metric_meaning(metric)})  # fmt: skip
    return rows


#: The legend line of a scene with several people's metric names.
PEOPLE_LEGEND = ("- several people: `<metric>_person<id>` is track <id>'s own (the flow: on that person's "
                 "visible pixels and joints), `<metric>_all` pools every person; the flow's epe_person is every "
                 "person's pixels, the bare pose metrics are the main person's")


def metrics_table(history: Sequence[dict]) -> str:
    """Markdown: every metric's unit, value before (the initial stage) and after (its last
    stage), and change, marked ``better`` or ``**worse**`` (lower is better but for
    :data:`NEUTRAL_METRICS`); then one legend line per metric family present."""
    values = before_after(history)
    rows = ["| metric | unit | before | after | change (lower is better) |", "| --- | --- | --- | --- | --- |"]
    rows += [f"| {k} | {unit(k)} | {a:.3f} | {b:.3f} | {_change(k, a, b)} |" for k, (a, b) in values.items()]
    worse = [k for k, (a, b) in values.items() if k not in NEUTRAL_METRICS and b > a]
    rows += ["", "Before: the initial stage (pretrained RAFT, the input poses); after: each metric's last "
             f"stage. Lower is better for every metric but {', '.join(NEUTRAL_METRICS)}; "
             + (f"worse: {', '.join(worse)}." if worse else "none got worse.")]  # fmt: skip
    rows += [f"- {' / '.join(k for k in names if k in values)}: {text}"
             for names, text in METRIC_LEGEND if any(k in values for k in names)]  # fmt: skip
    if any(base_metric_name(k) != k for k in values):
        rows.append(PEOPLE_LEGEND)
    return "\n".join(rows)


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
