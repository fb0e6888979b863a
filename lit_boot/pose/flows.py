"""Reading the forward flows the pose refiner follows, with errors that say what was expected.

Sources: a folder of ``flow_<t>.flo`` files or a ``.npz`` file (the one flow file format,
:mod:`lit_boot.data.flows`, as :class:`lit_boot.flow.FlowWriter` and the orchestrator write
them), ``"gt"`` for the
scene's ground-truth flow (an oracle; refused when some pair has no valid GT pixel at all), or a
tensor (or NumPy array) of flows.
"""

from __future__ import annotations

import os

import numpy as np
import torch

from ..core import Scene
from ..data.flows import FlowSourceError, check_flows, read_flows

__all__ = ["FlowSourceError", "load_flows"]

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
        return check_flows(source.detach().cpu(), "flows", pairs, H, W)
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
    return read_flows(source, pairs, H, W)
