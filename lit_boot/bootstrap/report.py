"""What a bootstrap run shows: a metrics plot per stage, before/after overlays, an mp4 video.

Images are uint8 tensors (3, H, W) in RGB order; flows are (2, H, W) px, the displacement from
frame t to frame t+1; keypoints are (x, y) pixels with pixel centres at integer coordinates.
Every file is written atomically (a temporary file beside the target, then renamed).
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

from ..core.joints import JointLayout, get_layout
from ..data.atomic import atomic_file, atomic_write_bytes
from ..data.visualize import draw_skeleton, flow_image

__all__ = ["overlay_frames", "plot_history", "write_video"]

_NOT_METRICS = ("stage", "kind", "cycle")
_UNITS = (("_mm_per_frame2", "mm/frame²"), ("_px", "px"), ("_mm", "mm"))


def _unit(metric: str) -> str:
    """Unit from the name: ``*_px`` px, ``*_mm`` mm, ``*_mm_per_frame2`` mm/frame², ``epe*`` px."""
    for suffix, unit in _UNITS:
        if metric.endswith(suffix):
            return unit
    return "px" if metric.startswith("epe") else ""


def _metric_value(value: object) -> float | None:
    """A finite float (Python or NumPy) as float; anything else (None, NaN, int, text) is None."""
    if not isinstance(value, (float, np.floating)) or not math.isfinite(value):
        return None
    return float(value)


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


def _check(
    tensor: object, name: str, shape: tuple[int | None, ...], expected: str, dtype: torch.dtype | None = None
) -> None:
    """ValueError naming ``name`` unless ``tensor`` is a tensor of ``shape`` (None: any size)."""
    ok = isinstance(tensor, torch.Tensor) and tensor.ndim == len(shape)
    ok = ok and all(s is None or s == t for s, t in zip(shape, tensor.shape))
    ok = ok and (dtype is None or tensor.dtype == dtype) and (dtype is not None or tensor.is_floating_point())
    if not ok:
        got = f"{tensor.dtype} {tuple(tensor.shape)}" if isinstance(tensor, torch.Tensor) else type(tensor).__name__
        kind = "uint8" if dtype == torch.uint8 else "float"
        raise ValueError(f"overlay_frames: expected {name} as a {kind} tensor of shape {expected}, got {got}")


def _label(image: np.ndarray, text: str) -> np.ndarray:
    """A copy of an HWC uint8 image with ``text`` top left: white on a black box (an outline
    drawn thicker would not line up: OpenCV's glyph advance grows with the thickness)."""
    scale = max(0.3, min(image.shape[:2]) / 400)
    org = (3, 3 + round(22 * scale))
    image = np.array(image, order="C", copy=True)  # never draw into a caller's (or shared) buffer
    (w, h), baseline = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    cv2.rectangle(image, (0, 0), (org[0] + w + 2, org[1] + baseline), (0, 0, 0), cv2.FILLED)
    cv2.putText(image, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return image


def overlay_frames(
    frames: torch.Tensor,
    flow_before: torch.Tensor,
    flow_after: torch.Tensor,
    joints_before: torch.Tensor | None,
    joints_after: torch.Tensor | None,
    layout: str | JointLayout | None,
    max_side: int = 1280,
    flow_labels: tuple[str, str] = ("RAFT", "refined"),
) -> torch.Tensor:
    """Before/after mosaics, one per frame pair: uint8 (T-1, 3, 2h, 2w).

    frames uint8 (T, 3, H, W) RGB; flow_before / flow_after float (T-1, 2, H, W) px, pair t ->
    t+1; joints_before / joints_after (T, J, 2) px in ``layout`` (J = its number of joints),
    or None. Mosaic for pair t: [frame t | flow before] over [flow after | frame t with the
    skeleton before in red and after in green (drawn last, on top)]. Both flows of a pair are
    coloured with the same maximum magnitude (the larger of the two), so colours compare;
    zero flow is white. Each panel carries a text label. Panels are h x w = H x W, scaled down
    (INTER_AREA; joints scaled with them, so lines stay crisp) when the mosaic's longer side
    would exceed ``max_side``. Raises ValueError naming the argument for a wrong shape.
    """
    _check(frames, "frames", (None, 3, None, None), "(T, 3, H, W)", torch.uint8)
    T, _, H, W = frames.shape
    if T < 2:
        raise ValueError(f"overlay_frames: expected frames with T >= 2 frames, got {tuple(frames.shape)}")
    for name, flow in (("flow_before", flow_before), ("flow_after", flow_after)):
        _check(flow, name, (T - 1, 2, H, W), f"(T-1, 2, H, W) = ({T - 1}, 2, {H}, {W})")
    joints = {"before": joints_before, "after": joints_after}
    if any(j is not None for j in joints.values()):
        if layout is None:
            raise ValueError("overlay_frames: layout is required when joints_before or joints_after is given")
        layout = get_layout(layout)
        J = layout.num_joints
        for name, j in joints.items():
            if j is not None:
                _check(j, f"joints_{name}", (T, J, 2), f"(T, J, 2) = ({T}, {J}, 2) for layout {layout.name!r}")
    if max_side < 2:
        raise ValueError(f"overlay_frames: max_side must be >= 2, got {max_side}")
    scale = min(1.0, max_side / (2 * max(H, W)))
    h, w = max(1, int(H * scale)), max(1, int(W * scale))
    sx, sy = w / W, h / H

    def resize(image: torch.Tensor) -> np.ndarray:  # (3, H, W) -> HWC (h, w, 3)
        array = image.permute(1, 2, 0).numpy()
        return array if (h, w) == (H, W) else cv2.resize(array, (w, h), interpolation=cv2.INTER_AREA)

    frames = frames.detach().cpu()
    mosaics = []
    for t in range(T - 1):
        pair = torch.nan_to_num(torch.stack([flow_before[t], flow_after[t]]).detach().cpu().float(), 0.0, 0.0, 0.0)
        top = float(pair.norm(dim=1).max())
        before_img, after_img = flow_image(pair, max_magnitude=max(top, 1e-6))
        frame = torch.from_numpy(np.ascontiguousarray(resize(frames[t]))).permute(2, 0, 1)
        pose = frame
        for j, colour in zip(joints.values(), ("red", "lime")):
            if j is not None:
                points = j[t].detach().cpu().float()
                points = (points + 0.5) * torch.tensor([sx, sy]) - 0.5  # pixel centres stay centres
                pose = draw_skeleton(pose, points, layout, color=colour)
        panels = [
            _label(frame.permute(1, 2, 0).numpy(), f"frame {t}"),
            _label(resize(before_img), flow_labels[0]),
            _label(resize(after_img), flow_labels[1]),
            _label(pose.permute(1, 2, 0).numpy(), "pose before/after"),
        ]
        mosaic = np.concatenate([np.concatenate(panels[:2], 1), np.concatenate(panels[2:], 1)], 0)
        mosaics.append(torch.from_numpy(mosaic).permute(2, 0, 1))
    return torch.stack(mosaics).contiguous()


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
