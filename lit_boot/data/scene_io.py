"""A :class:`~lit_boot.core.scene.Scene` saved as a folder, losslessly.

Folder layout (format ``lit-boot-scene``, version 2; version 1, without people, still reads)::

    <path>/frames/000000.png ...   RGB frames, lossless 8-bit PNG (one per frame)
    <path>/arrays.npz              uncompressed np.savez; one key per present tensor field
    <path>/scene.json              everything else (see :func:`save_scene`)

npz keys: joints3d, cameras_params, cameras_crops, keypoints2d, keypoints_conf, person_boxes, and the
ground truth's gt_flow, gt_flow_valid, gt_flow_occluded, gt_joints3d, gt_joints2d, gt_keypoints2d,
gt_cameras_params, gt_cameras_crops, gt_person_mask; the other people's fields (``Scene.others``)
as others_joints3d, others_keypoints2d, ... and their ground truth (``GroundTruth.others``) as
gt_others_joints3d, gt_others_joints2d, gt_others_keypoints2d, gt_others_person_mask, each with a
person axis first (P - 1, T, ...). Dtypes are kept exactly.
"""

from __future__ import annotations

import errno
import json
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..core.cameras import Cameras
from ..core.people import Person
from ..core.scene import GroundTruth, PersonTruth, Scene, SceneValidationError
from .atomic import atomic_directory, atomic_write_bytes
from .memory import check_memory, format_bytes
from .visualize import read_png, write_png

__all__ = ["SCENE_FORMAT", "SCENE_FORMAT_VERSION", "SceneFormatError", "load_scene", "save_scene"]

SCENE_FORMAT = "lit-boot-scene"
SCENE_FORMAT_VERSION = 2
_PERSON_TENSORS = ("joints3d", "keypoints2d", "keypoints_conf", "person_boxes")
_GT_TENSORS = ("flow", "flow_valid", "flow_occluded", "joints3d", "joints2d", "person_mask", "keypoints2d")
_GT_PERSON_TENSORS = ("joints3d", "joints2d", "keypoints2d", "person_mask")


class SceneFormatError(ValueError):
    """A scene folder is malformed, inconsistent or of an unsupported format version."""


def _is_saved_scene(folder: Path) -> bool:
    return (folder / "scene.json").is_file()


def _frame_name(t: int) -> str:
    return f"{t:06d}.png"


def _camera_arrays(prefix: str, cameras: Cameras | None) -> dict[str, torch.Tensor | None]:
    if cameras is None:
        return {}
    return {f"{prefix}_params": cameras.params, f"{prefix}_crops": cameras.crops}


def _camera_json(cameras: Cameras | None) -> dict[str, Any] | None:
    return None if cameras is None else {"model": cameras.model, "crop_size": cameras.crop_size}


def _arrays(scene: Scene) -> dict[str, torch.Tensor]:
    """The scene's present tensor fields under their npz keys."""
    out = {"joints3d": scene.joints3d, "keypoints2d": scene.keypoints2d, "keypoints_conf": scene.keypoints_conf,
           "person_boxes": scene.person_boxes}
    out |= _camera_arrays("cameras", scene.cameras)
    if scene.others:
        others = [{key: getattr(p, key) for key in _PERSON_TENSORS} | _camera_arrays("cameras", p.cameras)
                  for p in scene.others]  # fmt: skip
        out |= {f"others_{key}": torch.stack([o[key] for o in others]) for key, value in others[0].items()
                if value is not None}  # fmt: skip
    if scene.gt is not None:
        out |= {f"gt_{key}": getattr(scene.gt, key) for key in _GT_TENSORS}
        out |= _camera_arrays("gt_cameras", scene.gt.cameras)
        others = scene.gt.others
        if others:
            out |= {f"gt_others_{key}": torch.stack([getattr(p, key) for p in others]) for key in _GT_PERSON_TENSORS
                    if getattr(others[0], key) is not None}  # fmt: skip
    return {key: value for key, value in out.items() if value is not None}


def _to_numpy(key: str, value: torch.Tensor) -> np.ndarray:
    try:
        return value.detach().cpu().numpy()
    except TypeError:
        raise ValueError(f"save_scene: field {key} has dtype {value.dtype}, which .npz cannot store") from None


def _checked_metadata(metadata: Any) -> Any:
    try:
        text = json.dumps(metadata, allow_nan=False)
    except (TypeError, ValueError) as err:
        raise ValueError(f"save_scene: Scene.metadata must be JSON-serialisable: {err}") from None
    if json.loads(text) != metadata:
        raise ValueError(
            "save_scene: Scene.metadata would not load back identical from JSON "
            "(tuples become lists, non-string keys become strings); use lists and string keys"
        )
    return metadata


def save_scene(scene: Scene, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Save ``scene`` as a folder at ``path`` (layout in the module docstring); returns the path.

    scene.json holds: format, version, name, fps, num_frames, height, width, joints3d_layout,
    keypoints_layout, cameras ({model, crop_size} or null), gt (null or {joints_layout,
    cameras}, plus others: the track ids of GroundTruth.others when it has some), fields ({npz
    key: dtype} of the present tensors) and metadata (as is; it must load back identical from
    JSON). The folder is built beside ``path`` and renamed in at the
    end. An existing non-empty ``path`` raises FileExistsError unless ``overwrite`` is True
    and it is itself a saved scene (holds a scene.json); it is then swapped out atomically.
    Any other OSError (read-only folder, disk full) removes the partial copy and is raised
    again, of the same type, with a message naming ``path`` and the cause.
    """
    scene.validate()
    path = Path(path)
    arrays = {key: _to_numpy(key, value) for key, value in _arrays(scene).items()}
    gt = scene.gt
    meta = {
        "format": SCENE_FORMAT,
        "version": SCENE_FORMAT_VERSION,
        "name": scene.name,
        "fps": scene.fps,
        "num_frames": scene.num_frames,
        "height": scene.height,
        "width": scene.width,
        "joints3d_layout": scene.joints3d_layout,
        "keypoints_layout": scene.keypoints_layout,
        "cameras": _camera_json(scene.cameras),
        "track_id": scene.track_id,
        "others": [p.track_id for p in scene.others],
        "gt": None if gt is None else {"joints_layout": gt.joints_layout, "cameras": _camera_json(gt.cameras)}
        | ({"others": [p.track_id for p in gt.others]} if gt.others else {}),
        "fields": {key: str(value.dtype) for key, value in arrays.items()},
        "metadata": _checked_metadata(scene.metadata),
    }
    try:
        with atomic_directory(path, overwrite=overwrite, may_replace=_is_saved_scene, replaceable="a saved scene") as t:
            _write_folder(t, scene.frames, arrays, meta)
    except FileExistsError:
        raise
    except OSError as err:
        size = scene.frames.numel() + sum(a.nbytes for a in arrays.values())
        raise _write_error(path, err, size) from None
    return path


def _write_folder(tmp: Path, frames: torch.Tensor, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
    (tmp / "frames").mkdir()
    for t, frame in enumerate(frames):
        write_png(tmp / "frames" / _frame_name(t), frame)
    with open(tmp / "arrays.npz", "wb") as f:
        np.savez(f, **arrays)
        f.flush()
        os.fsync(f.fileno())
    atomic_write_bytes(tmp / "scene.json", json.dumps(meta, indent=2).encode("utf-8"))


def _write_error(path: Path, err: OSError, size: int) -> OSError:
    """The same kind of OSError, saying what failed where, that nothing was left behind, and
    (disk full) how much room the scene needs."""
    reason = err.strerror or str(err)
    if err.errno == errno.ENOSPC:
        reason = f"no space left on the device; the scene needs up to {format_bytes(size)}"
    where = f" (writing {err.filename})" if err.filename else ""
    message = f"{path}: could not save the scene: {reason}{where}; nothing was saved and the partial copy was removed"
    return type(err)(err.errno, message) if err.errno is not None else type(err)(message)


def _read_meta(path: Path) -> dict[str, Any]:
    file = path / "scene.json"
    if not file.is_file():
        raise FileNotFoundError(f"{path}: not a saved scene: {file.name} is missing")
    try:
        meta = json.loads(file.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise SceneFormatError(f"{file}: corrupted, not valid JSON: {err}") from None
    if not isinstance(meta, dict) or meta.get("format") != SCENE_FORMAT:
        found = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
        raise SceneFormatError(f"{file}: not a {SCENE_FORMAT!r} file (format {found!r})")
    version = meta.get("version")
    if not isinstance(version, int) or version < 1:
        raise SceneFormatError(f"{file}: invalid format version {version!r}")
    if version > SCENE_FORMAT_VERSION:
        raise SceneFormatError(
            f"{file}: format version {version} is newer than this lit_boot reads (up to {SCENE_FORMAT_VERSION})"
        )
    required = ("name", "fps", "num_frames", "height", "width", "joints3d_layout", "keypoints_layout",
                "cameras", "gt", "fields", "metadata")  # fmt: skip
    missing = [key for key in required if key not in meta]
    if missing:
        raise SceneFormatError(f"{file}: corrupted, missing keys {missing}")
    for key in ("num_frames", "height", "width"):
        if not isinstance(meta[key], int) or meta[key] < 1:
            raise SceneFormatError(f"{file}: {key} must be a positive integer, got {meta[key]!r}")
    fields = meta["fields"]
    if not isinstance(fields, dict) or not all(isinstance(v, str) for v in fields.values()):
        raise SceneFormatError(f"{file}: fields must map npz keys to dtype names, got {fields!r}")
    return meta


def _read_frames(path: Path, meta: dict[str, Any]) -> torch.Tensor:
    folder = path / "frames"
    T, H, W = meta["num_frames"], meta["height"], meta["width"]
    found = sorted(p.name for p in folder.glob("*.png")) if folder.is_dir() else []
    expected = [_frame_name(t) for t in range(T)]
    if len(found) != T:
        raise SceneFormatError(f"{path}: scene.json says num_frames={T} but {folder} holds {len(found)} PNG files")
    if found != expected:
        raise SceneFormatError(f"{folder}: expected frames {expected[0]} .. {expected[-1]}, found {found[:3]} ...")
    check_memory(path, T, H, W, advice="import it again with")
    frames = []
    for name in expected:
        try:
            frame = read_png(folder / name)
        except ValueError as err:
            raise SceneFormatError(str(err)) from None
        if frame.shape != (3, H, W):
            raise SceneFormatError(f"{folder / name}: expected a {W}x{H} RGB frame, got shape {tuple(frame.shape)}")
        frames.append(frame)
    return torch.stack(frames)


def _read_arrays(path: Path, fields: dict[str, str]) -> dict[str, torch.Tensor]:
    if not fields:
        return {}
    file = path / "arrays.npz"
    if not file.is_file():
        raise SceneFormatError(f"{file}: missing, but scene.json lists fields {sorted(fields)}")
    try:
        with np.load(file, allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in fields if key in npz.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise SceneFormatError(f"{file}: unreadable .npz: {err or type(err).__name__}") from None
    missing = sorted(set(fields) - set(arrays))
    if missing:
        raise SceneFormatError(f"{file}: lacks keys {missing} that scene.json marks present")
    for key, dtype in fields.items():
        if str(arrays[key].dtype) != dtype:
            raise SceneFormatError(f"{file}: key {key} has dtype {arrays[key].dtype}, scene.json says {dtype}")
    return {key: torch.from_numpy(value) for key, value in arrays.items()}


def _cameras(info: dict[str, Any] | None, arrays: dict[str, torch.Tensor], prefix: str) -> Cameras | None:
    if info is None:
        return None
    if f"{prefix}_params" not in arrays:
        raise SceneFormatError(f"scene.json describes {prefix} but fields lack {prefix}_params")
    return Cameras(info["model"], arrays[f"{prefix}_params"], arrays.get(f"{prefix}_crops"), info["crop_size"])


def _others(meta: dict[str, Any], arrays: dict[str, torch.Tensor]) -> tuple[Person, ...]:
    """The other people of a saved scene (none in version 1)."""
    ids = meta.get("others", [])
    if not isinstance(ids, list):
        raise SceneFormatError(f"scene.json: others must be a list of track ids, got {ids!r}")
    people = []
    for i, track_id in enumerate(ids):
        get = lambda key: arrays[f"others_{key}"][i] if f"others_{key}" in arrays else None  # noqa: E731
        cameras = None
        if meta["cameras"] is not None:
            cameras = Cameras(meta["cameras"]["model"], get("cameras_params"), get("cameras_crops"),
                              meta["cameras"]["crop_size"])  # fmt: skip
        people.append(Person(track_id=track_id, cameras=cameras, **{key: get(key) for key in _PERSON_TENSORS}))
    return tuple(people)


def _gt_others(info: dict[str, Any], arrays: dict[str, torch.Tensor]) -> tuple[PersonTruth, ...]:
    """The other people's ground truth of a saved scene (none before there was any)."""
    ids = info.get("others", [])
    if not isinstance(ids, list):
        raise SceneFormatError(f"scene.json: gt.others must be a list of track ids, got {ids!r}")
    get = lambda key, i: arrays[f"gt_others_{key}"][i] if f"gt_others_{key}" in arrays else None  # noqa: E731
    return tuple(PersonTruth(track_id, **{key: get(key, i) for key in _GT_PERSON_TENSORS})
                 for i, track_id in enumerate(ids))  # fmt: skip


def load_scene(path: str | os.PathLike) -> Scene:
    """Load a scene saved by :func:`save_scene`: identical tensors (bit-exact, same dtypes, on
    the CPU), layouts, cameras and metadata. Reads only; writes nothing into the folder.

    Raises FileNotFoundError (missing folder or scene.json), :class:`SceneFormatError`
    (a ValueError) naming the file for anything malformed or inconsistent, and, before reading
    the frames, :class:`~lit_boot.data.memory.NotEnoughMemoryError` when the scene would not
    fit in the available memory.
    """
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: no such scene folder")
    meta = _read_meta(path)
    frames = _read_frames(path, meta)
    arrays = _read_arrays(path, meta["fields"])
    try:
        gt = None
        if meta["gt"] is not None:
            tensors = {key: arrays.get(f"gt_{key}") for key in _GT_TENSORS}
            cameras = _cameras(meta["gt"].get("cameras"), arrays, "gt_cameras")
            gt = GroundTruth(**tensors, joints_layout=meta["gt"]["joints_layout"], cameras=cameras,
                             others=_gt_others(meta["gt"], arrays))  # fmt: skip
        return Scene(
            frames=frames, fps=meta["fps"], name=meta["name"],
            joints3d=arrays.get("joints3d"), joints3d_layout=meta["joints3d_layout"],
            cameras=_cameras(meta["cameras"], arrays, "cameras"),
            keypoints2d=arrays.get("keypoints2d"), keypoints_conf=arrays.get("keypoints_conf"),
            keypoints_layout=meta["keypoints_layout"], gt=gt, metadata=meta["metadata"],
            person_boxes=arrays.get("person_boxes"), track_id=meta.get("track_id", 0),
            others=_others(meta, arrays),
        )  # fmt: skip
    except KeyError as err:
        raise SceneFormatError(f"{path / 'scene.json'}: corrupted, missing key {err}") from None
    except (SceneValidationError, ValueError, TypeError, AttributeError, IndexError) as err:
        raise SceneFormatError(f"{path}: stored scene is inconsistent: {err}") from None
