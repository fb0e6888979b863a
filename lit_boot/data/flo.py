"""Middlebury ``.flo`` optical-flow files (the format of MPI Sintel and FlyingChairs).

Layout, all little-endian: float32 magic 202021.25 (the bytes ``PIEH``), int32 width,
int32 height, then height x width pairs (u, v) of float32, row-major. u is the horizontal
(x, right) and v the vertical (y, down) displacement in pixels. Unknown flow is often stored
as values around 1e9; it is read back as is. NaN or infinite values are not part of the format:
:func:`read_flo` refuses them unless asked (``allow_nonfinite=True``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from .atomic import atomic_write_bytes

__all__ = ["FLO_MAGIC", "FloFormatError", "read_flo", "write_flo"]

FLO_MAGIC = 202021.25
_HEADER_BYTES = 12
_MAX_SIDE = 100_000  # larger sides mean a corrupted header


class FloFormatError(ValueError):
    """A ``.flo`` file is foreign, truncated, oversized or holds NaN / inf (the message names it)."""


def read_flo(path: str | os.PathLike, *, allow_nonfinite: bool = False) -> torch.Tensor:
    """Read a ``.flo`` file into a (2, H, W) float32 tensor: channel 0 = u (x), 1 = v (y), px.

    Raises FileNotFoundError for a missing file and :class:`FloFormatError` (a ValueError),
    naming the file, for a foreign file (wrong magic), an impossible size, a truncated /
    oversized payload or, unless ``allow_nonfinite``, NaN or infinite values.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such .flo file")
    data = path.read_bytes()
    if len(data) < _HEADER_BYTES:
        raise FloFormatError(
            f"{path}: not a Middlebury .flo file: {len(data)} bytes, shorter than the {_HEADER_BYTES}-byte header"
        )
    magic = float(np.frombuffer(data, dtype="<f4", count=1)[0])
    if magic != FLO_MAGIC:
        raise FloFormatError(
            f"{path}: not a Middlebury .flo file: magic {magic!r} (bytes {data[:4]!r}), expected {FLO_MAGIC}"
        )
    width, height = (int(v) for v in np.frombuffer(data, dtype="<i4", count=2, offset=4))
    if not (0 < width <= _MAX_SIDE and 0 < height <= _MAX_SIDE):
        raise FloFormatError(f"{path}: corrupted .flo header: width {width}, height {height} (expected 1..{_MAX_SIDE})")
    expected = _HEADER_BYTES + 8 * width * height
    if len(data) != expected:
        what = "truncated" if len(data) < expected else "has trailing bytes"
        raise FloFormatError(
            f"{path}: .flo file {what}: expected {expected} bytes for {width}x{height} flow, found {len(data)}"
        )
    uv = np.frombuffer(data, dtype="<f4", offset=_HEADER_BYTES).reshape(height, width, 2)
    bad = int(np.count_nonzero(~np.isfinite(uv).all(-1)))
    if bad and not allow_nonfinite:
        raise FloFormatError(
            f"{path}: .flo file holds NaN or infinite flow at {bad} of {width * height} pixels "
            "(corrupted; expected finite displacements in px)"
        )
    return torch.from_numpy(np.array(uv.transpose(2, 0, 1), dtype=np.float32, order="C"))  # a writable copy


def write_flo(path: str | os.PathLike, flow: torch.Tensor | np.ndarray) -> Path:
    """Write a (2, H, W) flow (channel 0 = u, 1 = v, px) as a ``.flo`` file, atomically.

    Values are stored as float32 (float64 input is rounded). Returns the path.
    """
    path = Path(path)
    if isinstance(flow, torch.Tensor):
        flow = flow.detach().cpu().numpy()
    flow = np.asarray(flow)
    if flow.ndim != 3 or flow.shape[0] != 2 or flow.shape[1] < 1 or flow.shape[2] < 1:
        raise ValueError(f"write_flo({path}): expected flow of shape (2, H, W), got {tuple(flow.shape)}")
    if not np.issubdtype(flow.dtype, np.floating):
        raise ValueError(f"write_flo({path}): expected a floating-point flow, got dtype {flow.dtype}")
    _, height, width = flow.shape
    if height > _MAX_SIDE or width > _MAX_SIDE:
        raise ValueError(f"write_flo({path}): flow of {width}x{height} px exceeds {_MAX_SIDE} px per side")
    header = np.array([FLO_MAGIC], dtype="<f4").tobytes() + np.array([width, height], dtype="<i4").tobytes()
    payload = np.ascontiguousarray(flow.transpose(1, 2, 0), dtype="<f4").tobytes()
    return atomic_write_bytes(path, header + payload)
