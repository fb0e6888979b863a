"""A finished bootstrap run folder read back for the report: :func:`read_run`.

What a run folder holds (see :mod:`lit_boot.bootstrap.runner`): summary.json (settings, every
stage's record), ``stages/initial/flows.npz`` (pretrained RAFT's flow), each flow and zoom
stage's ``flows.npz`` and ``decisions.npz``, and the final ``poses.npz``. The frames and the initial
poses are the scene's: the folder named in summary.json, or the scene passed in (a run made from
a video or a Scene object names no folder).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from ..core import Scene
from ..data import load_scene
from ..data.flows import read_flows
from ..pose.result import POSES_FILE, load_pose_result
from .decisions import final_decisions, load_decisions
from .ensemble import average_poses

__all__ = ["FinishedRun", "read_run", "SUMMARY_JSON", "RUN_FORMAT"]

SUMMARY_JSON = "summary.json"
RUN_FORMAT = "lit-boot-bootstrap"


@dataclass(kw_only=True)
class FinishedRun:
    """A finished run: its folder and summary.json; the stage records (``history``); the mode;
    pretrained RAFT's flow and the final flow (T-1, 2, H, W) px; the last kept flow or zoom
    stage's name and where the final flow comes from (the kept stages' maps combined by
    :func:`~lit_boot.bootstrap.decisions.final_decisions`; None without such a stage); the scene
    as the run started (frames, initial poses, GT; None when unknown) and the final pose points
    (T, K, 2) px with their (T, K) bool keep."""

    run_dir: Path
    summary: dict[str, Any]
    history: list[dict[str, Any]]
    mode: str
    initial_flows: torch.Tensor
    flows: torch.Tensor
    flow_stage: str | None
    decisions: dict[str, torch.Tensor] | None
    scene: Scene | None
    final_points: tuple[torch.Tensor, torch.Tensor] | None

    @property
    def initial_points(self) -> tuple[torch.Tensor, torch.Tensor] | None:
        return self.scene.pose_points(self.mode) if self.scene is not None else None


def read_summary(run_dir: str | os.PathLike) -> dict[str, Any]:
    """summary.json of a finished run; FileNotFoundError / ValueError name the folder otherwise."""
    path = Path(run_dir) / SUMMARY_JSON
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir}: no {SUMMARY_JSON} (not a finished lit-boot run folder)")
    summary = json.loads(path.read_text())
    if summary.get("format") != RUN_FORMAT:
        raise ValueError(f"{path}: not a {RUN_FORMAT!r} summary (format {summary.get('format')!r})")
    return summary


def _scene(summary: dict[str, Any], scene: Scene | str | os.PathLike | None, mode: str, ensembled: bool) -> Scene | None:
    """The scene as the run started: ``scene`` (a Scene or folder), else the folder summary.json
    names if it exists; with the run's pose ensemble averaged in (unless ``ensembled``: ``scene``
    holds it already). None when neither is known."""
    if scene is None:
        named = Path(str(summary.get("scene", "")))
        if not str(summary.get("scene", "")) or not named.is_dir():
            return None
        scene, ensembled = named, False
    loaded = scene if isinstance(scene, Scene) else load_scene(scene)
    return loaded if ensembled else average_poses(loaded, summary.get("config", {}).get("pose_ensemble", []), mode)


def read_run(
    run_dir: str | os.PathLike, scene: Scene | str | os.PathLike | None = None, *, ensembled: bool = False
) -> FinishedRun:
    """Read the finished run in ``run_dir``; ``scene`` (a Scene or a scene folder) gives the
    frames and initial poses when summary.json names no folder; ``ensembled``: its estimates
    already hold the run's pose ensemble (the runner's ``initial_scene``), else it is averaged in.
    A scene of another size than the run's flows raises ValueError naming both."""
    run_dir = Path(run_dir)
    summary = read_summary(run_dir)
    history = summary.get("stages", [])
    mode = summary.get("plan", {}).get("mode") or summary.get("config", {}).get("mode", "3d")  # the mode that ran
    initial = read_flows(run_dir / "stages" / "initial" / "flows.npz")
    kept = [r for r in history if r.get("kind") in ("flow", "zoom") and not r.get("rolled_back")]
    stage = kept[-1]["stage"] if kept else None
    flows, decisions = initial, None
    for record in kept:  # in run order: each stage's flow starts from the one before
        maps = run_dir / "stages" / record["stage"] / "decisions.npz"
        decisions = final_decisions(decisions, record["kind"], load_decisions(maps) if maps.is_file() else None)
    if stage is not None:
        flows = read_flows(run_dir / "stages" / stage / "flows.npz")
    loaded = _scene(summary, scene, mode, ensembled)
    final = None
    if loaded is not None:
        T, _, H, W = loaded.frames.shape
        if (T - 1, H, W) != (initial.shape[0], *initial.shape[-2:]):
            raise ValueError(f"{run_dir}: the scene {loaded.name!r} has {T} frames of {W}x{H}, but the run's flows are "
                             f"{initial.shape[0]} pairs of {initial.shape[-1]}x{initial.shape[-2]}")  # fmt: skip
        poses = load_pose_result(run_dir).apply_to(loaded) if (run_dir / POSES_FILE).is_file() else loaded
        final = poses.pose_points(mode)
    return FinishedRun(run_dir=run_dir, summary=summary, history=history, mode=mode, initial_flows=initial,
                       flows=flows, flow_stage=stage, decisions=decisions, scene=loaded,
                       final_points=final)  # fmt: skip
