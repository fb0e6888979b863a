"""Flow files, one format for everything lit-boot writes and reads back.

A set of forward flows, one per pair t -> t+1, (P, 2, H, W) px, is stored either as a folder of
Middlebury files ``flow_000000.flo``, ``flow_000001.flo``, ... (with optional colour images
``flow_<t>.png``; other files are ignored) or as one ``.npz`` file with key ``flow``
(P, 2, H, W) float32 and optionally ``index`` (P,), the pair of each flow. Every file is
written atomically. :func:`read_flows` checks what it reads against an expected count and size
and names the file and what was expected when they do not fit.
"""

from __future__ import annotations

import io
import os
import re
import zipfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from .atomic import atomic_write_bytes
from .flo import read_flo, write_flo
from .visualize import flow_image, write_png

__all__ = ["FlowSourceError", "check_flows", "read_flows", "write_flows", "write_flows_npz"]

_FLO_NAME = re.compile(r"^flow_(\d+)\.flo$")


class FlowSourceError(ValueError):
    """The flows do not fit the scene (count, size) or cannot be read."""


def write_flows(folder: str | os.PathLike, flows: torch.Tensor, indices: Sequence[int] | None = None,
                flo: bool = True, png: bool = True) -> Path:  # fmt: skip
    """Per pair t of ``indices`` (default 0..P-1) write ``flow_<t>.flo`` and/or the colour image
    ``flow_<t>.png`` of flows (P, 2, H, W) px into ``folder``, atomically; returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    indices = list(range(len(flows))) if indices is None else list(indices)
    for i, flow in zip(indices, flows.detach().float().cpu()):
        if flo:
            write_flo(folder / f"flow_{i:06d}.flo", flow)
        if png:
            write_png(folder / f"flow_{i:06d}.png", flow_image(flow))
    return folder


def write_flows_npz(path: str | os.PathLike, flows: torch.Tensor, indices: Sequence[int] | None = None) -> Path:
    """One npz (keys ``flow`` (P, 2, H, W) float32, ``index`` (P,)), written atomically."""
    indices = list(range(len(flows))) if indices is None else list(indices)
    buffer = io.BytesIO()
    np.savez(buffer, flow=flows.detach().float().cpu().numpy(), index=np.array(indices))
    return atomic_write_bytes(Path(path), buffer.getvalue())


def check_flows(flows: torch.Tensor, what: str, pairs: int | None, height: int | None, width: int | None) -> torch.Tensor:
    """``flows`` as float if they are (pairs, 2, height, width) and finite (None: any count or
    size), else :class:`FlowSourceError` naming ``what``."""
    want = tuple("P" if n is None else n for n in (pairs, 2, height, width))
    if flows.ndim != 4 or flows.shape[1] != 2:
        raise FlowSourceError(f"{what}: expected flows of shape {want}, got {tuple(flows.shape)}")
    if pairs is not None and flows.shape[0] != pairs:
        raise FlowSourceError(
            f"{what}: expected {pairs} flows (one per pair of the scene's {pairs + 1} frames), got {flows.shape[0]}"
        )
    if height is not None and tuple(flows.shape[2:]) != (height, width):
        raise FlowSourceError(
            f"{what}: flows are {flows.shape[3]}x{flows.shape[2]} px, expected {width}x{height} (the scene's frames)"
        )
    flows = flows.float()
    if not torch.isfinite(flows).all():
        raise FlowSourceError(f"{what}: flows contain NaN or inf")
    return flows


def _count(found: dict[int, Path], pairs: int | None) -> int:
    """The expected number of flows: ``pairs``, else as many as the highest pair found says."""
    return pairs if pairs is not None else max(found) + 1


def _read_folder(folder: Path, pairs: int | None, height: int | None, width: int | None) -> torch.Tensor:
    found = {int(m.group(1)): folder / name for name in os.listdir(folder) if (m := _FLO_NAME.match(name))}
    if not found:
        raise FlowSourceError(f"{folder}: expected flow_000000.flo, flow_000001.flo, ... (one per frame pair), found none")
    pairs = _count(found, pairs)
    wanted = set(range(pairs))
    if set(found) != wanted:
        missing, extra = sorted(wanted - set(found)), sorted(set(found) - wanted)
        detail = []
        if missing:
            detail.append(f"missing flow_{missing[0]:06d}.flo" + (f" and {len(missing) - 1} more" if len(missing) > 1 else ""))
        if extra:
            detail.append(f"unexpected flow_{extra[0]:06d}.flo" + (f" and {len(extra) - 1} more" if len(extra) > 1 else ""))
        raise FlowSourceError(
            f"{folder}: expected {pairs} flows flow_000000.flo .. flow_{max(pairs - 1, 0):06d}.flo "
            f"(one per pair of the scene's {pairs + 1} frames), found {len(found)}: {', '.join(detail)}"
        )
    flows = [read_flo(found[t]) for t in range(pairs)]
    height, width = (height, width) if height is not None else tuple(flows[0].shape[1:])
    for t, flow in enumerate(flows):
        if tuple(flow.shape[1:]) != (height, width):
            raise FlowSourceError(
                f"{found[t]}: flow is {flow.shape[2]}x{flow.shape[1]} px, expected {width}x{height} (the scene's frames)"
            )
    return torch.stack(flows)


def _read_npz(path: Path, pairs: int | None, height: int | None, width: int | None) -> torch.Tensor:
    try:
        with np.load(path) as data:
            arrays = {key: np.asarray(data[key]) for key in data.files if key in ("flow", "index")}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise FlowSourceError(f"{path}: not a readable .npz file ({type(err).__name__}: {err})") from None
    if "flow" not in arrays:
        raise FlowSourceError(f"{path}: expected an array 'flow' (P, 2, H, W), found none")
    flow = torch.from_numpy(arrays["flow"].astype(np.float32))
    if not torch.isfinite(flow).all():
        bad = int((~torch.isfinite(flow)).any(dim=-3).sum()) if flow.ndim >= 3 else int((~torch.isfinite(flow)).sum())
        raise FlowSourceError(f"{path}: 'flow' holds NaN or infinite values at {bad} pixels (expected finite px)")
    index = arrays.get("index")
    if index is not None:
        count = pairs if pairs is not None else flow.shape[0]
        if index.shape != (flow.shape[0],):
            raise FlowSourceError(f"{path}: 'index' has shape {index.shape}, expected ({flow.shape[0]},)")
        if sorted(index.tolist()) != list(range(count)):
            raise FlowSourceError(
                f"{path}: 'index' must list the pairs 0..{count - 1} once each (the scene has {count + 1} frames), "
                f"got {len(index)} entries from {index.min() if len(index) else '-'} to {index.max() if len(index) else '-'}"
            )
        flow = flow[torch.from_numpy(np.argsort(index, kind="stable"))]
    return check_flows(flow, str(path), pairs, height, width)


def read_flows(
    path: str | os.PathLike, pairs: int | None = None, height: int | None = None, width: int | None = None
) -> torch.Tensor:
    """The flows (P, 2, H, W) px float32 in ``path``: a folder of ``flow_<t>.flo`` files or a
    ``.npz`` file (see the module doc), checked to be ``pairs`` flows of ``height`` x ``width``
    px when given. Raises FileNotFoundError for a missing path and :class:`FlowSourceError`
    (a ValueError), naming the file, for anything unreadable or unfit."""
    path = Path(path)
    if path.is_dir():
        return _read_folder(path, pairs, height, width)
    if path.is_file():
        if path.suffix != ".npz":
            raise FlowSourceError(f"{path}: expected a folder of flow_*.flo files or a .npz file")
        return _read_npz(path, pairs, height, width)
    raise FileNotFoundError(f"{path}: no such flow folder or .npz file (expected flow_*.flo files or flows.npz)")
