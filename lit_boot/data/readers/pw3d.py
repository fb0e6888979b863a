"""3DPW (3D Poses in the Wild): one person (or every person) of one sequence with its ground-truth joints.

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
from ...core.people import Person
from ...core.scene import GroundTruth, PersonTruth, Scene
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


def _people_arrays(data: dict[str, Any], people: list[int], path: Path) -> dict[str, Any]:
    """The arrays used here, shape-checked: cam_poses (T, 4, 4), K (3, 3), and per person (lists
    in ``people`` order) joints (T, 24, 3) m, valid (T,) bool, poses2d (T, 18, 3)."""
    count = len(data["jointPositions"])
    for key in ("poses2d", "campose_valid"):
        if len(data[key]) != count:
            raise DatasetFormatError(f"{path}: {key} lists {len(data[key])} people, jointPositions {count}")
    poses = check_shape(data["cam_poses"], (None, 4, 4), path, "cam_poses")
    T = poses.shape[0]
    each = lambda key, p, shape: check_shape(data[key][p], shape, path, f"{key}[{p}]")  # noqa: E731
    return {
        "cam_poses": poses,
        "K": check_shape(data["cam_intrinsics"], (3, 3), path, "cam_intrinsics"),
        "joints": [each("jointPositions", p, (T, 72)).reshape(T, 24, 3) for p in people],
        "valid": [each("campose_valid", p, (T,)).astype(bool) for p in people],
        "poses2d": [each("poses2d", p, (T, 3, 18)).transpose(0, 2, 1) for p in people],
    }


def _which_people(data: dict[str, Any], person: int | str, path: Path) -> list[int]:
    """The people ``person`` asks for: [person], or every person ("all")."""
    count = len(data["jointPositions"])
    if person == "all":
        return list(range(count))
    if isinstance(person, bool) or not isinstance(person, int):
        raise ValueError(f"person: expected a person index or 'all', got {person!r}")
    if not 0 <= person < count:
        raise ValueError(f"{path}: person {person} out of range, the sequence has {count} people")
    return [person]


def read_3dpw(
    root: str | os.PathLike,
    sequence: str,
    *,
    person: int | str = 0,
    split: str | None = None,
    first: int | None = None,
    last: int | None = None,
    stride: int = 1,
    max_frames: int | None = None,
    size: Size | None = None,
    invalid: InvalidFrames = "drop",
    joints_layout: str = "lsp14",
) -> Scene:
    """Read one person of a 3DPW sequence (``person="all"``: every person) as a :class:`Scene`
    (30 / stride fps).

    Frames ``first``, ``first + stride``, ... ``last`` (inclusive, 0-based image numbers;
    default all), at most ``max_frames``. ``split`` None searches train, validation, test.
    Frames whose ``campose_valid`` is 0 (GT not aligned to the image; with every person: 0 for
    anyone): ``invalid="drop"`` removes them (the standard evaluation; gaps show in
    ``metadata["frames"]``), ``"keep"`` keeps them with their unreliable GT
    (``metadata["campose_valid"]`` marks them), ``"error"`` raises. ``size`` = (height, width)
    resizes frames, keypoints and cameras. ``joints_layout``: "lsp14" (default) or "smpl" (the 24
    SMPL joints). With every person, person 0 is the main one and the others (track id = their
    index in the sequence) are in ``Scene.others`` with their truth in ``GroundTruth.others``.

    Raises FileNotFoundError (missing folder, pickle or image), ValueError (bad arguments),
    :class:`DatasetFormatError` naming the file (missing keys, wrong shapes, image count
    differing from the annotated frame count, unreadable image).
    """
    if invalid not in ("drop", "keep", "error"):
        raise ValueError(f"invalid: expected 'drop', 'keep' or 'error', got {invalid!r}")
    root = require_dir(Path(root), "3DPW root")
    path = _find(root, sequence, split)
    data = load_3dpw_pickle(path)
    people = _which_people(data, person, path)
    arrays = _people_arrays(data, people, path)
    T = arrays["cam_poses"].shape[0]
    folder = require_dir(root / "imageFiles" / sequence, f"the images of 3DPW sequence {sequence}")
    count = len(list(folder.glob("image_*.jpg")))
    if count != T:
        raise DatasetFormatError(f"{folder}: holds {count} image_*.jpg files, but {path} annotates {T} frames")
    valid = np.logical_and.reduce(arrays["valid"])
    which = f"campose_valid[{person}]" if person != "all" else "campose_valid of some person"
    frames_idx = select_frames(range(T), first, last, stride, max_frames, where=str(path))
    bad = [t for t in frames_idx if not valid[t]]
    if bad and invalid == "error":
        raise DatasetFormatError(f"{path}: {which} is 0 at frames {bad[:5]}{' ...' * (len(bad) > 5)}")
    if invalid == "drop":
        frames_idx = [t for t in frames_idx if valid[t]]
        if not frames_idx:
            raise DatasetFormatError(f"{path}: no frame with campose_valid = 1 for every person read in the "
                                     "selected range")
    idx = np.asarray(frames_idx)
    frames, native = read_images([folder / f"image_{t:05d}.jpg" for t in frames_idx], size)
    sx, sy = scale_factors(*native, size)
    cameras = pinhole_cameras(arrays["K"], len(idx), sx, sy)
    poses = arrays["cam_poses"][idx]
    truths, estimates = [], []
    for p, world, poses2d in zip(people, arrays["joints"], arrays["poses2d"]):
        camera = np.einsum("tij,tkj->tki", poses[:, :3, :3], world[idx]) + poses[:, None, :3, 3]
        joints3d, _, _ = map_joints(torch.from_numpy(camera * 1000.0).float(), "smpl", joints_layout)
        detected = torch.from_numpy(poses2d[idx][:, OPENPOSE18_TO_COCO17]).float()
        truths.append(PersonTruth(p, joints3d=joints3d, joints2d=cameras.project(joints3d)))
        estimates.append(Person(p, keypoints2d=scale_points(detected[..., :2], sx, sy),
                                keypoints_conf=detected[..., 2].clamp(0.0, 1.0)))  # fmt: skip
    main = truths[0]
    gt = GroundTruth(joints3d=main.joints3d, joints2d=main.joints2d, joints_layout=joints_layout, cameras=cameras,
                     others=tuple(truths[1:]))  # fmt: skip
    metadata = {
        "dataset": "3dpw", "sequence": sequence, "split": path.parent.name, "person": person,
        "frames": frames_idx, "campose_valid": [bool(valid[t]) for t in frames_idx],
    }  # fmt: skip
    name = f"3dpw_{sequence}_p{person}" if person != "all" else f"3dpw_{sequence}"
    return make_scene(
        path, frames=frames, fps=PW3D_FPS / stride, name=name, **estimates[0].fields(), track_id=people[0],
        others=tuple(estimates[1:]), keypoints_layout="coco17", gt=gt, metadata=metadata,
    )  # fmt: skip
