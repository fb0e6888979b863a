"""The refined poses: what a refiner returns, saves into its run folder, and loads back.

One container for poses, one file format: the refined poses are a
:class:`~lit_boot.data.readers.PoseEstimates` (3D mode: joints3d (T, J, 3) mm with cameras;
2D mode: keypoints2d (T, K, 2) px with the scene's confidences), saved as a lit-boot pose file,
so they read back with :func:`~lit_boot.data.readers.load_poses` and go into another run as
its poses. The optimisation report sits beside them. Files (each written atomically)::

    <folder>/poses.npz           the refined poses (format lit-boot-pose-estimates)
    <folder>/pose_report.json    mode, scene, steps, early stop, final loss terms, metrics
                                 before and after (lit_boot.metrics.suite's names), settings
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from ..core import Cameras, Scene
from ..data.atomic import atomic_write_bytes
from ..data.readers.pose_file import PoseEstimates, load_poses, save_poses

__all__ = ["PoseResult", "load_pose_result", "POSES_FILE", "REPORT_FILE"]

POSES_FILE = "poses.npz"
REPORT_FILE = "pose_report.json"
REPORT_FORMAT = "lit-boot-pose-report"


@dataclass
class PoseResult:
    """Refined poses of one scene (``estimates``) and how they were found.

    mode: "3d" or "2d"; metrics_before / metrics_after: evaluation against the scene's ground
    truth (empty without it); loss: the final weighted loss terms; steps: optimiser steps run;
    seconds: the fit's wall time; settings: the refiner's hyperparameters.
    """

    mode: str
    estimates: PoseEstimates
    scene: str = "scene"
    steps: int = 0
    stopped_early: bool = False
    loss: dict[str, float] = field(default_factory=dict)
    metrics_before: dict[str, float] = field(default_factory=dict)
    metrics_after: dict[str, float] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def joints3d(self) -> torch.Tensor | None:
        """(T, J, 3) mm in 3D mode, else None."""
        return self.estimates.joints3d

    @property
    def cameras(self) -> Cameras | None:
        return self.estimates.cameras

    @property
    def keypoints2d(self) -> torch.Tensor | None:
        """(T, K, 2) px in 2D mode, else None."""
        return self.estimates.keypoints2d

    @property
    def layout(self) -> str:
        """The joint layout of the refined poses."""
        return self.estimates.joints3d_layout if self.mode == "3d" else self.estimates.keypoints_layout

    @property
    def projected2d(self) -> torch.Tensor | None:
        """3D mode: the joints projected by the cameras, (T, J, 2) px; else None."""
        return None if self.joints3d is None else self.cameras.project(self.joints3d.float())

    def apply_to(self, scene: Scene) -> Scene:
        """A copy of ``scene`` whose estimates are the refined ones (joints3d and cameras in 3D
        mode, keypoints2d in 2D mode; see :meth:`PoseEstimates.apply_to`)."""
        return self.estimates.apply_to(scene)

    def report(self) -> dict[str, Any]:
        """The optimisation report, as pose_report.json holds it."""
        return {"format": REPORT_FORMAT, "version": 1, "mode": self.mode, "scene": self.scene, "steps": self.steps,
                "stopped_early": self.stopped_early, "seconds": round(self.seconds, 3), "loss": self.loss,
                "metrics_before": self.metrics_before, "metrics_after": self.metrics_after,
                "settings": self.settings}  # fmt: skip

    def save(self, folder: str | os.PathLike) -> Path:
        """Write poses.npz and pose_report.json into ``folder`` (created if needed); returns it."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        save_poses(self.estimates, folder / POSES_FILE)
        text = json.dumps(self.report(), indent=2, default=str) + "\n"
        atomic_write_bytes(folder / REPORT_FILE, text.encode())
        return folder


def load_pose_result(folder: str | os.PathLike) -> PoseResult:
    """Read what :meth:`PoseResult.save` wrote; FileNotFoundError names a missing file."""
    folder = Path(folder)
    for name in (REPORT_FILE, POSES_FILE):
        if not (folder / name).is_file():
            raise FileNotFoundError(f"{folder / name}: no such file (expected refined poses written by a pose refiner)")
    report = json.loads((folder / REPORT_FILE).read_text())
    if report.get("format") != REPORT_FORMAT:
        raise ValueError(f"{folder / REPORT_FILE}: not a {REPORT_FORMAT!r} file (format {report.get('format')!r})")
    keys = ("mode", "scene", "steps", "stopped_early", "loss", "metrics_before", "metrics_after", "settings", "seconds")
    return PoseResult(estimates=load_poses(folder / POSES_FILE), **{k: report[k] for k in keys})
