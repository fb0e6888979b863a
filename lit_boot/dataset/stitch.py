"""A chunked scene made whole again: its chunks' refined poses and flows stitched into one.

Poses are cross-faded over each overlap (:func:`~lit_boot.dataset.chunks.stitch_estimates`), so
the stitched motion stays continuous across chunk borders; each flow pair is taken from the
chunk whose centre it is nearest (:func:`~lit_boot.dataset.chunks.stitch_pairs`). The scene's
folder ``<out>/scenes/<name>/`` gets ``poses.npz`` (a lit-boot pose file), ``flows.npz`` (the
final flows) and ``initial_flows.npz`` (RAFT's); its result is scored against the whole scene's
ground truth, so the dataset metrics count every frame once.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import torch

from ..data.flows import read_flows, write_flows_npz
from ..data.readers.pose_file import save_poses
from ..pose import load_pose_result
from .chunks import stitch_estimates, stitch_pairs
from .tasks import Task
from .worker import result_record

__all__ = ["stitch_parent"]


def _chunk_outputs(run_dir: Path) -> tuple[torch.Tensor, torch.Tensor, Any]:
    """A chunk run's initial flows, final flows (T-1, 2, H, W) px and refined estimates (None
    without a pose stage)."""
    initial = read_flows(run_dir / "stages" / "initial" / "flows.npz")
    npz = run_dir / "flows" / "flows.npz"  # flow_format "npz"; "flo": one file per pair
    final = read_flows(npz if npz.is_file() else run_dir / "flows")
    poses = load_pose_result(run_dir).estimates if (run_dir / "poses.npz").is_file() else None
    return initial, final, poses


def stitch_parent(parent: Task, chunks: list[tuple[Task, dict[str, Any]]], out: str | Path, mode: str) -> dict[str, Any]:
    """Stitch the done ``chunks`` ((chunk task, its result)) of ``parent`` into the parent's
    folder; return the parent's result (see :func:`lit_boot.dataset.worker.result_record`)."""
    start_time = time.perf_counter()
    whole = parent.load(estimate=False)  # its GT and its own estimates; the chunks estimated theirs
    T = whole.num_frames
    initial, final, poses = [], [], []
    for task, result in chunks:
        first = task.frames[0]
        a, b, p = _chunk_outputs(Path(result["run_dir"]))
        initial.append((first, a))
        final.append((first, b))
        if p is not None:
            poses.append((first, p))
    initial_flows, flows = stitch_pairs(initial, T - 1), stitch_pairs(final, T - 1)
    folder = Path(out) / "scenes" / parent.name
    folder.mkdir(parents=True, exist_ok=True)
    write_flows_npz(folder / "flows.npz", flows)
    write_flows_npz(folder / "initial_flows.npz", initial_flows)
    refined = whole
    if len(poses) == len(chunks):
        estimates = stitch_estimates(poses, T)
        save_poses(estimates, folder / "poses.npz")
        refined = estimates.apply_to(whole)
    seconds = sum(float(r.get("seconds") or 0.0) for _, r in chunks)
    return result_record(parent, whole, initial_flows, refined, flows, mode, folder, seconds=seconds,
                         wall=time.perf_counter() - start_time)  # fmt: skip
