"""3DPW (3D Poses in the Wild): one person of one sequence with its ground-truth joints.

Layout under ``root``::

    sequenceFiles/{train,validation,test}/<sequence>.pkl   annotations (Python 2 pickles)
    imageFiles/<sequence>/image_00000.jpg ...               frames, 30 fps; image t <-> row t

Pickle keys used: ``jointPositions`` (per person (T, 72): the 24 SMPL joints, world metres),
``cam_poses`` (T, 4, 4) world -> camera, ``cam_intrinsics`` (3, 3), ``campose_valid`` (per
person (T,)), ``poses2d`` (per person (T, 3, 18): OpenPose-18 x, y, confidence rows).

Ground truth: joints3d (T, J, 3) mm in the camera frame (x right, y down, z forward) in
``joints_layout`` (default lsp14 through :data:`~lit_boot.core.joints.SMPL24_TO_LSP14`: the
head top is SMPL's head joint; SMPL's kinematic joints are not the mesh-regressed H36M
joints of the official 3DPW protocol, which needs the SMPL model, so MPJPE values are not
comparable with published numbers); joints2d = their pinhole projection with the
intrinsics (GroundTruth.cameras). The scene's keypoints2d are the pickle's OpenPose
detections mapped to COCO-17 (confidence clipped to [0, 1]; 0 where not detected).
"""

from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from ...core.joints import map_joints
from ...core.scene import GroundTruth, Scene
from ._common import DatasetFormatError, Size, check_shape, make_scene, pinhole_cameras, read_images, require_dir
from ._common import scale_factors, scale_points, select_frames

__all__ = ["OPENPOSE18_TO_COCO17", "PW3D_FPS", "PW3D_SPLITS", "list_3dpw_sequences", "load_3dpw_pickle", "read_3dpw"]

PW3D_SPLITS = ("train", "validation", "test")
PW3D_FPS = 30.0
#: OpenPose-18 index of each COCO-17 joint. OpenPose-18: nose, neck, r shoulder, r elbow,
#: r wrist, l shoulder, l elbow, l wrist, r hip, r knee, r ankle, l hip, l knee, l ankle,
#: r eye, l eye, r ear, l ear (the neck has no COCO counterpart).
OPENPOSE18_TO_COCO17 = (0, 15, 14, 17, 16, 5, 2, 6, 3, 7, 4, 11, 8, 12, 9, 13, 10)
_REQUIRED = ("jointPositions", "cam_poses", "cam_intrinsics", "campose_valid", "poses2d")
InvalidFrames = Literal["drop", "keep", "error"]


def list_3dpw_sequences(root: str | os.PathLike, split: str | None = None) -> list[str]:
    """Sorted sequence names of one split (or of all splits) under ``root``/sequenceFiles."""
    base = require_dir(Path(root) / "sequenceFiles", "a 3DPW root holds sequenceFiles/<split>/<sequence>.pkl")
    splits = PW3D_SPLITS if split is None else (_check_split(split),)
    return sorted(p.stem for s in splits if (base / s).is_dir() for p in (base / s).glob("*.pkl"))


def _check_split(split: str) -> str:
    if split not in PW3D_SPLITS:
        raise ValueError(f"split: expected one of {PW3D_SPLITS} or None, got {split!r}")
    return split


def _find(root: Path, sequence: str, split: str | None) -> Path:
    base = require_dir(root / "sequenceFiles", "a 3DPW root holds sequenceFiles/<split>/<sequence>.pkl")
    splits = PW3D_SPLITS if split is None else (_check_split(split),)
    candidates = [base / s / f"{sequence}.pkl" for s in splits]
    for path in candidates:
        if path.is_file():
            return path
    raise FileNotFoundError(f"3DPW sequence {sequence!r} not found; looked for {[str(p) for p in candidates]}")


def load_3dpw_pickle(path: str | os.PathLike) -> dict[str, Any]:
    """Unpickle a 3DPW sequence file (``encoding="latin1"``) and check it has the keys used
    here; DatasetFormatError naming the file otherwise. Only load files you trust (pickle)."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            data = pickle.load(f, encoding="latin1")
    except FileNotFoundError:
        raise
    except Exception as err:  # unpickling raises many kinds of errors
        raise DatasetFormatError(f"{path}: unreadable pickle: {type(err).__name__}: {err}") from None
    if not isinstance(data, dict):
        raise DatasetFormatError(f"{path}: expected a dict (a 3DPW sequence file), got {type(data).__name__}")
    missing = [key for key in _REQUIRED if key not in data]
    if missing:
        raise DatasetFormatError(f"{path}: missing keys {missing}; a 3DPW sequence file has {list(_REQUIRED)}")
    return data


def _person_arrays(data: dict[str, Any], person: int, path: Path) -> dict[str, np.ndarray]:
    """The arrays used here, shape-checked: joints (T, 24, 3) m, cam_poses (T, 4, 4), K (3, 3),
    valid (T,) bool, poses2d (T, 18, 3)."""
    people = len(data["jointPositions"])
    if not 0 <= person < people:
        raise ValueError(f"{path}: person {person} out of range, the sequence has {people} people")
    for key in ("poses2d", "campose_valid"):
        if len(data[key]) != people:
            raise DatasetFormatError(f"{path}: {key} lists {len(data[key])} people, jointPositions {people}")
    poses = check_shape(data["cam_poses"], (None, 4, 4), path, "cam_poses")
    T = poses.shape[0]
    joints = check_shape(data["jointPositions"][person], (T, 72), path, f"jointPositions[{person}]")
    return {
        "joints": joints.reshape(T, 24, 3),
        "cam_poses": poses,
        "K": check_shape(data["cam_intrinsics"], (3, 3), path, "cam_intrinsics"),
        "valid": check_shape(data["campose_valid"][person], (T,), path, f"campose_valid[{person}]").astype(bool),
        "poses2d": check_shape(data["poses2d"][person], (T, 3, 18), path, f"poses2d[{person}]").transpose(0, 2, 1),
    }


def read_3dpw(
    root: str | os.PathLike,
    sequence: str,
    *,
    person: int = 0,
    split: str | None = None,
    first: int | None = None,
    last: int | None = None,
    stride: int = 1,
    max_frames: int | None = None,
    size: Size | None = None,
    invalid: InvalidFrames = "drop",
    joints_layout: str = "lsp14",
) -> Scene:
    """Read one person of a 3DPW sequence as a :class:`Scene` (30 / stride fps).

    Frames ``first``, ``first + stride``, ... ``last`` (inclusive, 0-based image numbers;
    default all), at most ``max_frames``. ``split`` None searches train, validation, test.
    Frames whose ``campose_valid`` is 0 (GT not aligned to the image): ``invalid="drop"``
    removes them (the standard evaluation; gaps show in ``metadata["frames"]``), ``"keep"``
    keeps them with their unreliable GT (``metadata["campose_valid"]`` marks them),
    ``"error"`` raises. ``size`` = (height, width) resizes frames, keypoints and cameras.
    ``joints_layout``: "lsp14" (default) or "smpl" (the 24 SMPL joints).

    Raises FileNotFoundError (missing folder, pickle or image), ValueError (bad arguments),
    :class:`DatasetFormatError` naming the file (missing keys, wrong shapes, image count
    differing from the annotated frame count, unreadable image).
    """
    if invalid not in ("drop", "keep", "error"):
        raise ValueError(f"invalid: expected 'drop', 'keep' or 'error', got {invalid!r}")
    root = require_dir(Path(root), "3DPW root")
    path = _find(root, sequence, split)
    arrays = _person_arrays(load_3dpw_pickle(path), person, path)
    T = arrays["cam_poses"].shape[0]
    folder = require_dir(root / "imageFiles" / sequence, f"the images of 3DPW sequence {sequence}")
    count = len(list(folder.glob("image_*.jpg")))
    if count != T:
        raise DatasetFormatError(f"{folder}: holds {count} image_*.jpg files, but {path} annotates {T} frames")
    frames_idx = select_frames(range(T), first, last, stride, max_frames, where=str(path))
    bad = [t for t in frames_idx if not arrays["valid"][t]]
    if bad and invalid == "error":
        raise DatasetFormatError(f"{path}: campose_valid[{person}] is 0 at frames {bad[:5]}{' ...' * (len(bad) > 5)}")
    if invalid == "drop":
        frames_idx = [t for t in frames_idx if arrays["valid"][t]]
        if not frames_idx:
            raise DatasetFormatError(f"{path}: no frame with campose_valid[{person}] = 1 in the selected range")
    idx = np.asarray(frames_idx)
    frames, native = read_images([folder / f"image_{t:05d}.jpg" for t in frames_idx], size)
    sx, sy = scale_factors(*native, size)

    poses = arrays["cam_poses"][idx]
    world = arrays["joints"][idx]
    camera = np.einsum("tij,tkj->tki", poses[:, :3, :3], world) + poses[:, None, :3, 3]
    joints3d, _, _ = map_joints(torch.from_numpy(camera * 1000.0).float(), "smpl", joints_layout)
    cameras = pinhole_cameras(arrays["K"], len(idx), sx, sy)
    detected = torch.from_numpy(arrays["poses2d"][idx][:, OPENPOSE18_TO_COCO17]).float()
    joints2d = cameras.project(joints3d)
    gt = GroundTruth(joints3d=joints3d, joints2d=joints2d, joints_layout=joints_layout, cameras=cameras)
    metadata = {
        "dataset": "3dpw", "sequence": sequence, "split": path.parent.name, "person": person,
        "frames": frames_idx, "campose_valid": [bool(arrays["valid"][t]) for t in frames_idx],
    }  # fmt: skip
    return make_scene(
        path, frames=frames, fps=PW3D_FPS / stride, name=f"3dpw_{sequence}_p{person}",
        keypoints2d=scale_points(detected[..., :2], sx, sy), keypoints_conf=detected[..., 2].clamp(0.0, 1.0),
        keypoints_layout="coco17", gt=gt, metadata=metadata,
    )  # fmt: skip
