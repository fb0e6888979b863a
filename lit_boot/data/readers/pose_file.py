"""lit-boot's own pose file: the :class:`~.pose_estimates.PoseEstimates` of every person.

Pose file, format ``lit-boot-pose-estimates``, version 2; ``.npz`` or ``.json`` by suffix.
Arrays (P people, the main one first; T rows = T frames; every key optional unless marked)::

    frame_indices   (T,)          int64    source-video frame of each row, strictly increasing [required]
    track_ids       (P,)          int64    each person's track id, unique [required]
    keypoints2d     (P, T, K, 2)  float32  px, pixel centres at integer coordinates, (x, y)
    keypoints_conf  (P, T, K)     float32  in [0, 1], 0 = not found      [with keypoints2d]
    joints3d        (P, T, J, 3)  float32  mm, camera axes x right, y down, z forward
    cameras_params  (P, T, C)     float32  C = 3 (s, tx, ty) weak perspective, 7 pinhole
    cameras_crops   (P, T, 3)     float32  (scale, start_x, start_y) [weak perspective only]
    person_boxes    (P, T, 5)     float32  a person detector's box (x0, y0, x1, y1 px, the outer
                                           edges) and score in [0, 1] (0 = absent)

A person absent in a frame has confidences 0 and a box score 0 there. At least one of
keypoints2d / joints3d is present; cameras need joints3d. The header (in the .npz: key
``header``, a 0-d unicode array holding JSON text; in the .json: the top-level object, whose
other keys are the arrays as nested lists) holds: ``format``, ``version``, ``keypoints_layout``
(default "coco17"), ``joints3d_layout`` (default "lsp14"), ``cameras`` (null or {"model",
"crop_size"}), ``image_size`` ([H, W] of the frames the pixels refer to, or null = unknown),
``source`` (e.g. "mediapipe-0.10.14", "metro") and ``metadata`` (any JSON). The .npz loads with
``allow_pickle=False``. Camera conventions: :mod:`lit_boot.core.cameras`.

Version 1 files (one person: the same arrays without the P axis, no ``track_ids``) still read,
as one person of track id 0.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ...core.cameras import Cameras
from ...core.people import Person
from ..atomic import atomic_write_bytes
from ._common import DatasetFormatError
from .pose_estimates import ANISOTROPY_TOLERANCE, PoseEstimates

__all__ = ["POSES_FORMAT", "POSES_FORMAT_VERSION", "PoseEstimates", "save_poses", "load_poses", "ANISOTROPY_TOLERANCE"]

POSES_FORMAT = "lit-boot-pose-estimates"
POSES_FORMAT_VERSION = 2
_PER_PERSON = ("keypoints2d", "keypoints_conf", "joints3d", "cameras_params", "cameras_crops", "person_boxes")
_ARRAYS = ("frame_indices", "track_ids", *_PER_PERSON)


def _header(est: PoseEstimates) -> dict[str, Any]:
    cams = None if est.cameras is None else {"model": est.cameras.model, "crop_size": float(est.cameras.crop_size)}
    return {
        "format": POSES_FORMAT, "version": POSES_FORMAT_VERSION, "keypoints_layout": est.keypoints_layout,
        "joints3d_layout": est.joints3d_layout, "cameras": cams,
        "image_size": None if est.image_size is None else list(est.image_size),
        "source": est.source, "metadata": est.metadata,
    }  # fmt: skip


def _person_arrays(person: Person) -> dict[str, torch.Tensor | None]:
    cams = person.cameras
    return {
        "keypoints2d": person.keypoints2d, "keypoints_conf": person.keypoints_conf, "joints3d": person.joints3d,
        "cameras_params": None if cams is None else cams.params, "cameras_crops": None if cams is None else cams.crops,
        "person_boxes": person.person_boxes,
    }  # fmt: skip


def _arrays(est: PoseEstimates) -> dict[str, np.ndarray]:
    people = [_person_arrays(person) for person in est.people()]
    out = {"frame_indices": est.frame_indices.detach().cpu().numpy().astype(np.int64),
           "track_ids": np.array([person.track_id for person in est.people()], dtype=np.int64)}  # fmt: skip
    for key in _PER_PERSON:
        if people[0][key] is not None:
            out[key] = torch.stack([arrays[key] for arrays in people]).detach().cpu().numpy().astype(np.float32)
    return out


def save_poses(estimates: PoseEstimates, path: str | os.PathLike) -> Path:
    """Write ``estimates`` atomically as a pose file (module docstring); ``.npz`` or ``.json``
    by the suffix of ``path``. Returns the path."""
    path = Path(path)
    if path.suffix.lower() not in (".npz", ".json"):
        raise ValueError(f"save_poses: {path}: expected a .npz or .json file name")
    estimates.validate()
    header, arrays = _header(estimates), _arrays(estimates)
    if path.suffix.lower() == ".json":
        data = json.dumps(header | {k: v.tolist() for k, v in arrays.items()}).encode("utf-8")
    else:
        buffer = io.BytesIO()
        np.savez(buffer, header=np.array(json.dumps(header)), **arrays)
        data = buffer.getvalue()
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_bytes(path, data)


def _read_raw(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """(header, arrays) of a pose file, unchecked."""
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(path.read_text(encoding="utf-8"))
            if not isinstance(data, dict):
                raise DatasetFormatError(f"{path}: not a {POSES_FORMAT!r} file (a JSON {type(data).__name__})")
            return data, {k: data[k] for k in _ARRAYS if k in data}
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
        if "header" not in arrays:
            raise DatasetFormatError(f"{path}: not a {POSES_FORMAT!r} file (no 'header' key; keys {sorted(arrays)})")
        header = json.loads(str(arrays.pop("header")))
        if not isinstance(header, dict):
            raise DatasetFormatError(f"{path}: not a {POSES_FORMAT!r} file (its header is a {type(header).__name__})")
        return header, arrays
    except (UnicodeDecodeError, json.JSONDecodeError, OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        if isinstance(err, DatasetFormatError):
            raise
        raise DatasetFormatError(f"{path}: unreadable pose file: {err}") from None


def load_poses(path: str | os.PathLike) -> PoseEstimates:
    """Read a pose file written by :func:`save_poses`. FileNotFoundError when missing;
    DatasetFormatError naming the file for a wrong format or version, missing keys or bad shapes."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such pose file")
    header, arrays = _read_raw(path)
    fmt, version = header.get("format"), header.get("version")
    if fmt != POSES_FORMAT:
        raise DatasetFormatError(f"{path}: not a {POSES_FORMAT!r} file (format {fmt!r})")
    if not isinstance(version, int) or not 1 <= version <= POSES_FORMAT_VERSION:
        raise DatasetFormatError(f"{path}: unsupported version {version!r} (reads 1..{POSES_FORMAT_VERSION})")
    for key in ("frame_indices",) + (("track_ids",) if version >= 2 else ()):
        if key not in arrays:
            raise DatasetFormatError(f"{path}: missing key {key!r}")
    try:
        t = {k: torch.from_numpy(np.asarray(v, dtype=np.int64 if k in ("frame_indices", "track_ids") else np.float32))
             for k, v in arrays.items()}  # fmt: skip
        people = _people(header, t, version)
        return PoseEstimates(
            keypoints_layout=header.get("keypoints_layout", "coco17"),
            joints3d_layout=header.get("joints3d_layout", "lsp14"), frame_indices=t["frame_indices"],
            image_size=header.get("image_size"), source=header.get("source", "unknown"),
            metadata=header.get("metadata", {}), **people[0].fields(), track_id=people[0].track_id,
            others=tuple(people[1:]),
        )  # fmt: skip
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as err:
        raise DatasetFormatError(f"{path}: malformed pose file: {type(err).__name__}: {err}") from None


def _people(header: dict[str, Any], t: dict[str, torch.Tensor], version: int) -> list[Person]:
    """Each person's fields from the arrays ``t`` of a version-``version`` file."""
    if version == 1:  # one person, no person axis
        t = {k: (v if k == "frame_indices" else v[None]) for k, v in t.items()}
        t["track_ids"] = torch.zeros(1, dtype=torch.int64)
    ids = t["track_ids"]
    if ids.ndim != 1 or ids.numel() < 1:
        raise ValueError(f"track_ids: expected shape (P,) with P >= 1, got {tuple(ids.shape)}")
    for key in _PER_PERSON:
        if key in t and t[key].shape[0] != ids.numel():
            raise ValueError(f"{key}: expected {ids.numel()} people (track_ids) on its first axis, "
                             f"got {t[key].shape[0]}")  # fmt: skip
    cams = header.get("cameras")
    people = []
    for p, track_id in enumerate(ids.tolist()):
        get = lambda key: t[key][p] if key in t else None  # noqa: E731
        cameras = None
        if cams is not None:
            crop_size = cams.get("crop_size", 224.0)
            cameras = Cameras(cams["model"], t["cameras_params"][p], get("cameras_crops"), crop_size)
        people.append(Person(track_id=int(track_id), joints3d=get("joints3d"), cameras=cameras,
                             keypoints2d=get("keypoints2d"), keypoints_conf=get("keypoints_conf"),
                             person_boxes=get("person_boxes")))  # fmt: skip
    return people
