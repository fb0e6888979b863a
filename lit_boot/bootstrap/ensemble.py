"""Pose ensembles (the paper's Table 2): several estimators' poses averaged before the run."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import torch

from pathlib import Path

from ..core import Cameras, Scene, get_layout
from ..data.readers.pose_file import load_poses
from ..pose.result import POSES_FILE

__all__ = ["average_poses"]


def average_poses(scene: Scene, folders: Sequence[str], mode: str) -> Scene:
    """A copy of ``scene`` whose estimates are the mean of its own and those in ``folders``
    (lit-boot pose files, or folders holding one as ``poses.npz``, such as a refiner's output).

    3D mode: joints (T, J, 3) mm and camera parameters averaged (same layout, camera model
    and frame count required; the scene's crops kept); 2D mode: keypoints (T, K, 2) px.
    Without folders, ``scene`` itself.
    """
    if not folders:
        return scene
    results = [load_poses(Path(f) / POSES_FILE if Path(f).is_dir() else f) for f in folders]
    if mode == "3d":
        joints, params = [scene.joints3d.float()], [scene.cameras.params.float()]
        for folder, r in zip(folders, results):
            if r.joints3d is None or r.cameras is None:
                raise ValueError(f"pose_ensemble {folder}: holds no 3D joints with cameras")
            _check(folder, get_layout(r.joints3d_layout).name, get_layout(scene.joints3d_layout).name, "layout")
            _check(folder, tuple(r.joints3d.shape), tuple(scene.joints3d.shape), "joints3d shape")
            _check(folder, r.cameras.model, scene.cameras.model, "camera model")
            joints.append(r.joints3d.float())
            params.append(r.cameras.params.float())
        c = scene.cameras
        cameras = Cameras(c.model, torch.stack(params).mean(0), c.crops, c.crop_size)
        return dataclasses.replace(scene, joints3d=torch.stack(joints).mean(0), cameras=cameras)
    keypoints = [scene.keypoints2d.float()]
    for folder, r in zip(folders, results):
        if r.keypoints2d is None:
            raise ValueError(f"pose_ensemble {folder}: holds no 2D keypoints")
        _check(folder, get_layout(r.keypoints_layout).name, get_layout(scene.keypoints_layout).name, "layout")
        _check(folder, tuple(r.keypoints2d.shape), tuple(scene.keypoints2d.shape), "keypoints2d shape")
        keypoints.append(r.keypoints2d.float())
    return dataclasses.replace(scene, keypoints2d=torch.stack(keypoints).mean(0))


def _check(folder: str, found: object, expected: object, what: str) -> None:
    if found != expected:
        raise ValueError(f"pose_ensemble {folder}: {what} {found!r}, but the scene has {expected!r}")
