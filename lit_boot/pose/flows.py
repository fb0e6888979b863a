"""Reading the forward flows the pose refiner follows, with errors that say what was expected.

Sources: a folder of Middlebury files ``flow_000000.flo`` ... (one per pair t -> t+1, as
:class:`lit_boot.flow.FlowWriter` writes them; other files are ignored), one ``.npz`` file with
key ``flow`` (P, 2, H, W) and optionally ``index`` (P,) (the pair of each flow), ``"gt"`` for the
scene's ground-truth flow (an oracle; refused when some pair has no valid GT pixel at all), or a
tensor (or NumPy array) of flows.
"""

from __future__ import annotations

import os
import re
import zipfile
from pathlib import Path

import numpy as np
import torch

from ..core import Scene
from ..data import read_flo

__all__ = ["FlowSourceError", "load_flows"]

_FLO_NAME = re.compile(r"^flow_(\d+)\.flo$")


class FlowSourceError(ValueError):
    """The flows do not fit the scene (count, size) or cannot be read."""


def _check_shape(flows: torch.Tensor, what: str, pairs: int, height: int, width: int) -> torch.Tensor:
    want = (pairs, 2, height, width)
    if flows.ndim != 4 or flows.shape[1] != 2:
        raise FlowSourceError(f"{what}: expected flows of shape {want}, got {tuple(flows.shape)}")
    if flows.shape[0] != pairs:
        raise FlowSourceError(
            f"{what}: expected {pairs} flows (one per pair of the scene's {pairs + 1} frames), got {flows.shape[0]}"
        )
    if tuple(flows.shape[2:]) != (height, width):
        raise FlowSourceError(
            f"{what}: flows are {flows.shape[3]}x{flows.shape[2]} px, expected {width}x{height} (the scene's frames)"
        )
    flows = flows.float()
    if not torch.isfinite(flows).all():
        raise FlowSourceError(f"{what}: flows contain NaN or inf")
    return flows


def _read_folder(folder: Path, pairs: int, height: int, width: int) -> torch.Tensor:
    found = {int(m.group(1)): folder / name for name in os.listdir(folder) if (m := _FLO_NAME.match(name))}
    wanted = set(range(pairs))
    if set(found) != wanted:
        missing = sorted(wanted - set(found))
        extra = sorted(set(found) - wanted)
        detail = []
        if missing:
            detail.append(f"missing flow_{missing[0]:06d}.flo" + (f" and {len(missing) - 1} more" if len(missing) > 1 else ""))
        if extra:
            detail.append(f"unexpected flow_{extra[0]:06d}.flo" + (f" and {len(extra) - 1} more" if len(extra) > 1 else ""))
        raise FlowSourceError(
            f"{folder}: expected {pairs} flows flow_000000.flo .. flow_{pairs - 1:06d}.flo "
            f"(one per pair of the scene's {pairs + 1} frames), found {len(found)}: {', '.join(detail)}"
        )
    flows = torch.empty(pairs, 2, height, width)
    for t in range(pairs):
        flow = read_flo(found[t])
        if tuple(flow.shape[1:]) != (height, width):
            raise FlowSourceError(
                f"{found[t]}: flow is {flow.shape[2]}x{flow.shape[1]} px, expected {width}x{height} (the scene's frames)"
            )
        flows[t] = flow
    return flows


def _read_npz(path: Path, pairs: int, height: int, width: int) -> torch.Tensor:
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
        if index.shape != (flow.shape[0],):
            raise FlowSourceError(f"{path}: 'index' has shape {index.shape}, expected ({flow.shape[0]},)")
        if sorted(index.tolist()) != list(range(pairs)):
            raise FlowSourceError(
                f"{path}: 'index' must list the pairs 0..{pairs - 1} once each (the scene has {pairs + 1} frames), "
                f"got {len(index)} entries from {index.min() if len(index) else '-'} to {index.max() if len(index) else '-'}"
            )
        flow = flow[torch.from_numpy(np.argsort(index, kind="stable"))]
    return _check_shape(flow, str(path), pairs, height, width)


def _check_gt_pairs_valid(scene: Scene) -> None:
    """A pair whose GT flow is valid nowhere (e.g. a partial Sintel copy without its .flo) holds
    zeros, which the refiner would take for "no motion": refuse it."""
    valid = scene.gt.flow_valid
    if valid is None:
        return
    empty = [t for t in range(valid.shape[0]) if not bool(valid[t].any())]
    if empty:
        shown = ", ".join(f"{t}->{t + 1}" for t in empty[:5]) + (f" and {len(empty) - 5} more" if len(empty) > 5 else "")
        raise FlowSourceError(
            f"flows 'gt': scene {scene.name!r} has no ground-truth flow for pair(s) {shown} (flow_valid is False "
            f"everywhere there); give flows from the flow stage (a folder or .npz) or a frame range with GT"
        )


def load_flows(source: str | os.PathLike | torch.Tensor | np.ndarray, scene: Scene) -> torch.Tensor:
    """The forward flows (T-1, 2, H, W) px for ``scene`` from ``source`` (see the module doc;
    an array is taken like a tensor).

    Raises FileNotFoundError for a missing path, TypeError for another kind of source, and
    :class:`FlowSourceError` (a ValueError), naming the path, when the count or size does not
    match the scene.
    """
    T, H, W = scene.num_frames, scene.height, scene.width
    pairs = T - 1
    if isinstance(source, np.ndarray):
        source = torch.from_numpy(source)
    if isinstance(source, torch.Tensor):
        return _check_shape(source.detach().cpu(), "flows", pairs, H, W)
    if not isinstance(source, (str, os.PathLike)):
        raise TypeError(
            f"flows: expected a folder of flow_*.flo files, a .npz file, 'gt' or a ({pairs}, 2, {H}, {W}) "
            f"tensor, got {type(source).__name__}"
        )
    if str(source) == "gt":
        if scene.gt is None or scene.gt.flow is None:
            raise FlowSourceError(f"flows 'gt': scene {scene.name!r} has no ground-truth flow")
        _check_gt_pairs_valid(scene)
        return scene.gt.flow.float()
    path = Path(source)
    if path.is_dir():
        return _read_folder(path, pairs, H, W)
    if path.is_file():
        if path.suffix != ".npz":
            raise FlowSourceError(f"{path}: expected a folder of flow_*.flo files or a .npz file")
        return _read_npz(path, pairs, H, W)
    raise FileNotFoundError(f"{path}: no such flow folder or .npz file (expected flow_*.flo files or flows.npz)")
