"""The refined poses: what a refiner returns, saves into its run folder, and loads back.

Files (written atomically, so each appears complete or not at all)::

    <folder>/poses.npz    joints3d (T, J, 3) mm, cameras_params (T, P), cameras_crops (T, 3)
                          [weak perspective], projected2d (T, J, 2) px  -- 3D mode
                          keypoints2d (T, K, 2) px                      -- 2D-only mode
    <folder>/poses.json   mode, scene, layout, camera model, steps, early stop, final loss
                          terms, metrics before and after, the refiner's settings
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..core import Cameras, Scene
from ..data.atomic import atomic_write_bytes

__all__ = ["PoseResult", "load_pose_result", "POSES_NPZ", "POSES_JSON"]

POSES_NPZ = "poses.npz"
POSES_JSON = "poses.json"


@dataclass
class PoseResult:
    """Refined poses of one scene.

    mode: "3d" (joints3d (T, J, 3) mm in ``layout`` with ``cameras``, and their projection
    ``projected2d`` (T, J, 2) px) or "2d" (``keypoints2d`` (T, K, 2) px in ``layout``).
    metrics_before / metrics_after: evaluation against the scene's ground truth (empty
    without it); loss: the final weighted loss terms; steps: optimiser steps run.
    """

    mode: str
    layout: str
    scene: str = "scene"
    joints3d: torch.Tensor | None = None
    cameras: Cameras | None = None
    projected2d: torch.Tensor | None = None
    keypoints2d: torch.Tensor | None = None
    steps: int = 0
    stopped_early: bool = False
    loss: dict[str, float] = field(default_factory=dict)
    metrics_before: dict[str, float] = field(default_factory=dict)
    metrics_after: dict[str, float] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    def apply_to(self, scene: Scene) -> Scene:
        """A copy of ``scene`` whose estimates are the refined ones (joints3d and cameras in 3D
        mode, keypoints2d in 2D mode; confidences and ground truth unchanged)."""
        if self.mode == "3d":
            return dataclasses.replace(scene, joints3d=self.joints3d.clone(), cameras=self.cameras)
        return dataclasses.replace(scene, keypoints2d=self.keypoints2d.clone())

    def save(self, folder: str | os.PathLike) -> Path:
        """Write poses.npz and poses.json into ``folder`` (created if needed); returns it."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        arrays: dict[str, np.ndarray] = {}
        for key in ("joints3d", "projected2d", "keypoints2d"):
            value = getattr(self, key)
            if value is not None:
                arrays[key] = value.detach().cpu().float().numpy()
        if self.cameras is not None:
            arrays["cameras_params"] = self.cameras.params.detach().cpu().float().numpy()
            if self.cameras.crops is not None:
                arrays["cameras_crops"] = self.cameras.crops.detach().cpu().float().numpy()
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        atomic_write_bytes(folder / POSES_NPZ, buffer.getvalue())
        meta = {
            "format": "lit-boot-poses",
            "version": 1,
            "mode": self.mode,
            "scene": self.scene,
            "layout": self.layout,
            "cameras": None if self.cameras is None else {"model": self.cameras.model, "crop_size": self.cameras.crop_size},
            "arrays": {key: list(a.shape) for key, a in arrays.items()},
            "steps": self.steps,
            "stopped_early": self.stopped_early,
            "seconds": round(self.seconds, 3),
            "loss": self.loss,
            "metrics_before": self.metrics_before,
            "metrics_after": self.metrics_after,
            "settings": self.settings,
        }
        atomic_write_bytes(folder / POSES_JSON, (json.dumps(meta, indent=2, default=str) + "\n").encode())
        return folder


def load_pose_result(folder: str | os.PathLike) -> PoseResult:
    """Read what :meth:`PoseResult.save` wrote; FileNotFoundError names a missing file."""
    folder = Path(folder)
    for name in (POSES_JSON, POSES_NPZ):
        if not (folder / name).is_file():
            raise FileNotFoundError(f"{folder / name}: no such file (expected refined poses written by a pose refiner)")
    meta = json.loads((folder / POSES_JSON).read_text())
    with np.load(folder / POSES_NPZ) as data:
        arrays = {key: torch.from_numpy(np.array(data[key])) for key in data.files}
    cameras = None
    if meta["cameras"] is not None:
        cam = meta["cameras"]
        cameras = Cameras(cam["model"], arrays["cameras_params"], arrays.get("cameras_crops"), cam["crop_size"])
    return PoseResult(
        mode=meta["mode"], layout=meta["layout"], scene=meta["scene"], joints3d=arrays.get("joints3d"),
        cameras=cameras, projected2d=arrays.get("projected2d"), keypoints2d=arrays.get("keypoints2d"),
        steps=meta["steps"], stopped_early=meta["stopped_early"], loss=meta["loss"],
        metrics_before=meta["metrics_before"], metrics_after=meta["metrics_after"],
        settings=meta["settings"], seconds=meta["seconds"],
    )  # fmt: skip
