"""Readers of precomputed pose estimates into :class:`~.pose_file.PoseEstimates`.

- METRO (:func:`read_metro`): ``pred_3d_joints_from_smpl`` (J, 3) **metres** (14 = LSP-14, or
  17 = H36M-17 mapped to LSP-14), ``pred_camera`` (s, tx, ty) weak perspective on the crop,
  ``proc_param`` (HMR: ``scale``, ``start_pt`` (2,), ``img_size`` = crop side, default 224).
  One .npz/.pkl per frame in a folder (natural name order), or one .npz/.pkl with the arrays
  stacked over T (proc_param: a dict of stacked arrays or a list of dicts). Joints become mm;
  cameras follow :func:`lit_boot.core.cameras.project_weak_perspective`. No 2D keypoints.
  These files may hold pickled objects: read only files you trust.
- DCPose (:func:`read_dcpose`): ``{"Info": [{"image_path"?, "keypoints": 17 x [x, y, score]}]}``
  in one JSON (entries grouped by image_path, images in natural order; without image_path one
  entry = one frame) or one such JSON per frame in a folder. Confidence = score clipped to [0, 1].
- COCO keypoints (:func:`read_coco_keypoints`): results (list of {"image_id", "category_id",
  "keypoints": [x, y, v] * 17, "score"}; confidence = v clipped to [0, 1]) or annotations
  ({"images", "annotations"}; confidence = 1 where v > 0, else 0; crowds skipped).
  Frames: ``image_ids`` in the order given, else images by file_name (annotations) or sorted
  image ids (results).

Several people in a frame: ``person`` = "track" (default: the largest first, then the one whose
keypoint box centre is nearest the previous choice), "largest" (largest keypoint box) or
"score" (highest detection score, else mean keypoint confidence) read one person; "all" reads
every person, linked into tracks by the file's ``track_id`` or by ``link``
(:mod:`.frame_people`; :func:`lit_boot.estimate.read_tracked_estimates` passes the person
tracker). Frames with nobody are kept as zero rows with confidence 0. 2D keypoints are COCO-17
px; frame_indices are 0..T-1.
"""

from __future__ import annotations

import json
import os
import pickle
import re
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from ...core.cameras import Cameras
from ...core.joints import map_joints
from ._common import DatasetFormatError, check_shape
from .frame_people import Link, clean_keypoints, every_person, keypoint_box, track_labels
from .pose_file import POSES_FORMAT, PoseEstimates, load_poses

__all__ = [
    "ESTIMATE_KINDS", "PERSON_RULES", "list_files", "natural_key", "pick_people",
    "read_metro", "read_dcpose", "read_coco_keypoints", "read_estimates", "detect_kind",
]  # fmt: skip

ESTIMATE_KINDS = ("poses", "metro", "dcpose", "coco")
PERSON_RULES = ("track", "largest", "score", "all")
PersonRule = Literal["track", "largest", "score", "all"]
_METRO_SUFFIXES = (".npz", ".pkl", ".pickle")
_METRO_JOINTS = ("pred_3d_joints_from_smpl", "pred_3d_joints")
_METRO_CAMERA = ("pred_camera", "pred_cam")


def list_files(folder: Path, suffixes: Sequence[str]) -> list[Path]:
    """Files of ``folder`` with one of ``suffixes`` (lower case), in natural name order
    (frame_2 before frame_10)."""
    files = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in suffixes]
    return sorted(files, key=lambda p: natural_key(p.name))


def natural_key(name: str) -> list[Any]:
    """Sort key comparing the digit runs of ``name`` as numbers."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def _person_box(p: np.ndarray) -> tuple[float, np.ndarray]:
    """(area, centre) of the box around a (K, 3) person's keypoints with confidence > 0."""
    box = keypoint_box(p)
    if box is None:
        return 0.0, np.zeros(2)
    return float(np.prod(box[2:] - box[:2])), (box[:2] + box[2:]) / 2


def pick_people(people: list[list[np.ndarray]], rule: PersonRule, scores: list[list[float]] | None = None):
    """One person per frame: people[t] = (K, 3) [x, y, confidence] arrays. Returns
    keypoints (T, K, 2), confidence (T, K) float32 tensors and the chosen index per frame (-1: nobody)."""
    if rule not in PERSON_RULES or rule == "all":
        raise ValueError(f"person: expected one of {PERSON_RULES[:-1]}, got {rule!r}")
    K = next((len(p) for frame in people for p in frame), 17)
    out, chosen, last = np.zeros((len(people), K, 3), np.float32), [], None
    for t, frame in enumerate(people):
        boxes = [_person_box(p) for p in frame]
        if not frame:
            chosen.append(-1)
            continue
        if rule == "score":
            key = [scores[t][i] if scores else float(p[:, 2].mean()) for i, p in enumerate(frame)]
        elif rule == "track" and last is not None:
            key = [-float(np.linalg.norm(c - last)) if a > 0 else -np.inf for a, c in boxes]
        else:
            key = [a for a, _ in boxes]
        i = int(np.argmax(key))
        chosen.append(i)
        out[t] = frame[i]
        if boxes[i][0] > 0:
            last = boxes[i][1]
    keypoints, conf = clean_keypoints(out)
    return keypoints, conf, chosen


def _numbers(value: Any, file: Path, what: str) -> np.ndarray:
    """``value`` as a float64 array; DatasetFormatError naming ``file`` when it is not numbers."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise DatasetFormatError(f"{file}: {what}: expected an array of numbers: {err}") from None


def _person(value: Any, file: Path, what: str, K: int = 17) -> np.ndarray:
    """A (K, 3) [x, y, confidence] array from (K, 3) or flat (3K,) numbers."""
    array = _numbers(value, file, what)
    return check_shape(array.reshape(K, 3) if array.shape == (3 * K,) else array, (K, 3), file, what)


def _load_json(path: Path) -> Any:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DatasetFormatError(f"{path}: not valid JSON: {err}") from None


def _estimates_2d(people, person, scores, source, image_size, metadata, *, path: Path, track_ids=None,
                  link: Link | None = None) -> PoseEstimates:  # fmt: skip
    """The PoseEstimates of ``people`` (per frame, (K, 3) arrays) under the ``person`` rule; "all"
    links them by ``track_ids`` (the file's, per detection) or else by ``link``."""
    if person == "all":
        labels, by = (track_labels(track_ids) if track_ids is not None else None), "track_id"
        if labels is None:
            if link is None:
                raise DatasetFormatError(
                    f"{path}: person 'all': not every detection has a track_id; read it with "
                    "lit_boot.estimate.read_tracked_estimates (links each frame's people with the person tracker) "
                    "or `lit-boot import ... --poses FILE --people all`"
                )
            labels, by = link(people, scores), "tracker"
        return every_person(people, labels, source=source, image_size=image_size,
                            metadata={**metadata, "linked_by": by})  # fmt: skip
    keypoints, conf, chosen = pick_people(people, person, scores)
    meta = {**metadata, "person_rule": person, "chosen_person": chosen}
    return PoseEstimates(keypoints2d=keypoints, keypoints_conf=conf, keypoints_layout="coco17",
                         image_size=image_size, source=source, metadata=meta)  # fmt: skip


# --- DCPose --------------------------------------------------------------------------------------
def _dcpose_entries(data: Any, file: Path) -> list[dict[str, Any]]:
    if not isinstance(data, dict) or not isinstance(data.get("Info"), list):
        raise DatasetFormatError(f"{file}: not a DCPose result (expected {{'Info': [...]}})")
    for i, entry in enumerate(data["Info"]):
        if not isinstance(entry, dict) or "keypoints" not in entry:
            raise DatasetFormatError(f"{file}: Info[{i}] lacks 'keypoints'")
    return data["Info"]


def read_dcpose(
    path: str | os.PathLike, *, person: PersonRule = "track", image_size: tuple[int, int] | None = None,
    link: Link | None = None,
) -> PoseEstimates:
    """DCPose keypoints (a JSON file or a folder of per-frame JSON files; module docstring);
    ``link``: with ``person="all"`` and no track ids in the file (:mod:`.frame_people`)."""
    path = Path(path)
    if path.is_dir():
        files = list_files(path, (".json",))
        if not files:
            raise DatasetFormatError(f"{path}: no .json files (expected one DCPose result per frame)")
        frames = [[(f, i, e) for i, e in enumerate(_dcpose_entries(_load_json(f), f))] for f in files]
        names = [f.name for f in files]
    else:
        entries = [(path, i, e) for i, e in enumerate(_dcpose_entries(_load_json(path), path))]
        if all("image_path" in e for _, _, e in entries):
            names = sorted({str(e["image_path"]) for _, _, e in entries}, key=natural_key)
            where = {n: t for t, n in enumerate(names)}
            frames = [[] for _ in names]
            for entry in entries:
                frames[where[str(entry[2]["image_path"])]].append(entry)
        else:
            names, frames = None, [[entry] for entry in entries]
    people = [[_person(e["keypoints"], f, f"Info[{i}].keypoints") for f, i, e in frame] for frame in frames]
    track_ids = [[e.get("track_id") for _, _, e in frame] for frame in frames]
    return _estimates_2d(people, person, None, "dcpose", image_size, {"frames": names}, path=path,
                         track_ids=track_ids, link=link)  # fmt: skip


# --- COCO keypoints ------------------------------------------------------------------------------
def read_coco_keypoints(
    path: str | os.PathLike,
    *,
    image_ids: Sequence[int | str] | None = None,
    person: PersonRule = "track",
    image_size: tuple[int, int] | None = None,
    category_id: int = 1,
    link: Link | None = None,
) -> PoseEstimates:
    """COCO keypoint JSON, results or annotations format (module docstring). ``image_ids``: the
    frames' image ids in video order (images without a detection become zero rows); ``link``:
    with ``person="all"`` and no track ids in the file (:mod:`.frame_people`)."""
    path = Path(path)
    data = _load_json(path)
    if isinstance(data, dict) and {"images", "annotations"} <= set(data):
        images, dets, annotations = data["images"], data["annotations"], True
    elif isinstance(data, list) and all(isinstance(d, dict) and {"image_id", "keypoints"} <= set(d) for d in data):
        images, dets, annotations = None, data, False
    else:
        raise DatasetFormatError(f"{path}: not COCO keypoints (expected a results list of {{'image_id', "
                                 "'keypoints', ...}} or {'images': [...], 'annotations': [...]})")  # fmt: skip
    if image_ids is None:
        if annotations:
            try:
                by_name = {str(im["file_name"]): im["id"] for im in images}
            except (TypeError, KeyError) as err:
                raise DatasetFormatError(f"{path}: images entries need 'id' and 'file_name' ({err!r})") from None
            image_ids = [by_name[n] for n in sorted(by_name, key=natural_key)]
        else:
            image_ids = sorted({d["image_id"] for d in dets}, key=lambda i: (isinstance(i, str), i))
    if image_size is None and annotations:
        sizes = {(im.get("height"), im.get("width")) for im in images if im["id"] in set(image_ids)}
        if len(sizes) == 1 and None not in next(iter(sizes)):
            image_size = tuple(int(v) for v in next(iter(sizes)))
    where = {i: t for t, i in enumerate(image_ids)}
    people = [[] for _ in image_ids]
    scores = [[] for _ in image_ids]
    track_ids = [[] for _ in image_ids]
    for n, d in enumerate(dets):
        if d.get("image_id") not in where or d.get("category_id", category_id) != category_id or d.get("iscrowd"):
            continue
        p = _person(d["keypoints"], path, f"{'annotations' if annotations else 'results'}[{n}].keypoints")
        if annotations:
            p[:, 2] = p[:, 2] > 0
        people[where[d["image_id"]]].append(p)
        scores[where[d["image_id"]]].append(float(d.get("score", p[:, 2].mean())))
        track_ids[where[d["image_id"]]].append(d.get("track_id"))
    meta = {"format": "annotations" if annotations else "results", "image_ids": list(image_ids)}
    return _estimates_2d(people, person, scores, "coco", image_size, meta, path=path, track_ids=track_ids, link=link)


# --- METRO ---------------------------------------------------------------------------------------
def _load_metro_file(file: Path) -> dict[str, Any]:
    try:
        if file.suffix.lower() == ".npz":
            with np.load(file, allow_pickle=True) as npz:
                data = {k: npz[k] for k in npz.files}
        else:
            with open(file, "rb") as f:
                data = pickle.load(f, encoding="latin1")
    except (OSError, ValueError, EOFError, pickle.UnpicklingError) as err:
        raise DatasetFormatError(f"{file}: unreadable METRO output: {err}") from None
    if not isinstance(data, dict):
        raise DatasetFormatError(f"{file}: expected a dict of METRO outputs, got {type(data).__name__}")
    return {k: v.item() if isinstance(v, np.ndarray) and v.dtype == object and v.ndim == 0 else v
            for k, v in data.items()}  # fmt: skip


def _first_key(data: dict[str, Any], keys: Sequence[str], file: Path) -> np.ndarray:
    for key in keys:
        if key in data:
            return _numbers(data[key], file, key)
    raise DatasetFormatError(f"{file}: missing METRO key (one of {list(keys)}); keys found: {sorted(data)}")


def _metro_arrays(data: dict[str, Any], file: Path, per_frame: bool) -> dict[str, np.ndarray]:
    """joints (T, J, 3) m, camera (T, 3), crops (T, 3), crop_size (T,) from one file."""
    joints, camera = _first_key(data, _METRO_JOINTS, file), _first_key(data, _METRO_CAMERA, file)
    proc = data.get("proc_param", {k: data[k] for k in ("scale", "start_pt", "img_size") if k in data})
    if isinstance(proc, (list, tuple, np.ndarray)):  # per-frame dicts
        dicts = [p for p in proc if isinstance(p, dict)]
        proc = {k: [p[k] for p in dicts] for k in ("scale", "start_pt", "img_size") if dicts and k in dicts[0]}
    if not isinstance(proc, dict) or "scale" not in proc or "start_pt" not in proc:
        raise DatasetFormatError(f"{file}: missing proc_param with 'scale' and 'start_pt'")
    if per_frame:
        joints, camera = joints.reshape(1, *joints.shape[-2:]), camera.reshape(1, -1)
    T = joints.shape[0]
    check_shape(joints, (T, None, 3), file, "pred_3d_joints_from_smpl")
    try:
        scale = np.broadcast_to(np.asarray(proc["scale"], np.float64).reshape(-1), (T,))
        start = np.asarray(proc["start_pt"], np.float64).reshape(-1, 2)
        crop = np.broadcast_to(np.asarray(proc.get("img_size", 224.0), np.float64).reshape(-1), (T,))
    except (ValueError, TypeError) as err:
        raise DatasetFormatError(f"{file}: proc_param does not fit {T} frames: {err}") from None
    return {"joints": joints, "camera": check_shape(camera, (T, 3), file, "pred_camera"),
            "crops": np.column_stack([scale, check_shape(start, (T, 2), file, "proc_param start_pt")]),
            "crop_size": crop}  # fmt: skip


def read_metro(path: str | os.PathLike, *, image_size: tuple[int, int] | None = None) -> PoseEstimates:
    """METRO 3D joints (LSP-14, mm) and weak-perspective cameras: a folder with one file per
    frame or one stacked file (module docstring). ``image_size`` (H, W) of the video, if known."""
    path = Path(path)
    if path.is_dir():
        files = list_files(path, _METRO_SUFFIXES)
        if not files:
            raise DatasetFormatError(f"{path}: no {'/'.join(_METRO_SUFFIXES)} files (expected METRO outputs per frame)")
        parts = [_metro_arrays(_load_metro_file(f), f, per_frame=True) for f in files]
        arrays = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        if len({p["joints"].shape for p in parts}) > 1:
            raise DatasetFormatError(f"{path}: the files hold different joint counts")
    elif not path.is_file():
        raise FileNotFoundError(f"{path}: no such file or folder (METRO outputs)")
    else:
        files = [path]
        arrays = _metro_arrays(_load_metro_file(path), path, per_frame=False)
    if len(set(arrays["crop_size"].tolist())) != 1:
        raise DatasetFormatError(f"{path}: proc_param img_size (the crop side) varies between frames")
    J = arrays["joints"].shape[1]
    if J not in (14, 17):
        raise DatasetFormatError(f"{path}: expected 14 (LSP) or 17 (H36M) METRO joints, got {J}")
    if np.nanmax(np.abs(arrays["joints"])) > 20.0:
        raise DatasetFormatError(f"{path}: joints up to {np.nanmax(np.abs(arrays['joints'])):.0f}: METRO "
                                 "writes metres; these look like millimetres")  # fmt: skip
    joints = torch.from_numpy(arrays["joints"] * 1000.0).float()
    if J == 17:
        joints = map_joints(joints, "h36m17", "lsp14")[0]
    cameras = Cameras("weak_perspective", torch.from_numpy(arrays["camera"]).float(),
                      torch.from_numpy(arrays["crops"]).float(), float(arrays["crop_size"][0]))  # fmt: skip
    meta = {"files": [f.name for f in files], "joints_in_file": "lsp14" if J == 14 else "h36m17"}
    return PoseEstimates(joints3d=joints, joints3d_layout="lsp14", cameras=cameras, image_size=image_size,
                         source="metro", metadata=meta)  # fmt: skip


# --- dispatcher ----------------------------------------------------------------------------------
def detect_kind(path: str | os.PathLike) -> str:
    """The kind of pose estimates at ``path`` (one of :data:`ESTIMATE_KINDS`) from its suffix and
    content, "?" if none; may raise OSError / ValueError for an unreadable file."""
    path = Path(path)
    if path.is_dir():
        files = list_files(path, (".json",) + _METRO_SUFFIXES)
        return "dcpose" if files and files[0].suffix.lower() == ".json" else "metro" if files else "?"
    suffix = path.suffix.lower()
    if suffix in (".pkl", ".pickle"):
        return "metro"
    if suffix == ".npz":
        with np.load(path, allow_pickle=False) as npz:
            keys = set(npz.files)
        return "poses" if "header" in keys else "metro" if keys & set(_METRO_JOINTS) else "?"
    if suffix == ".json":
        data = _load_json(path)
        if isinstance(data, dict):
            return ("poses" if data.get("format") == POSES_FORMAT else "dcpose" if "Info" in data
                    else "coco" if {"images", "annotations"} <= set(data) else "?")  # fmt: skip
        is_results = isinstance(data, list) and data and isinstance(data[0], dict) and "image_id" in data[0]
        return "coco" if is_results else "?"
    return "?"


def read_estimates(path: str | os.PathLike, *, kind: str | None = None, **options: Any) -> PoseEstimates:
    """Read pose estimates of any supported kind: "poses" (lit-boot pose file, :func:`load_poses`),
    "metro", "dcpose" or "coco"; ``kind`` None picks it from the suffix and content. ``options``
    go to that kind's reader (e.g. ``person``, ``image_size``, ``image_ids``)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such pose file or folder")
    readers = {"poses": load_poses, "metro": read_metro, "dcpose": read_dcpose, "coco": read_coco_keypoints}
    if kind is None:
        try:
            kind = detect_kind(path)
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
            raise DatasetFormatError(f"{path}: unreadable pose file: {err}") from None
        if kind == "?":
            raise DatasetFormatError(
                f"{path}: unrecognised pose estimates; accepted: lit-boot pose file (.npz/.json, format "
                f"{POSES_FORMAT!r}), METRO (.npz/.pkl or a folder of them), DCPose JSON ({{'Info': [...]}} or a "
                "folder of them), COCO keypoint JSON (results list or {'images', 'annotations'})"
            )
    if kind not in readers:
        raise ValueError(f"kind: expected one of {ESTIMATE_KINDS} or None, got {kind!r}")
    try:
        return readers[kind](path, **options)
    except TypeError as err:
        if "unexpected keyword" in str(err):
            raise TypeError(f"read_estimates: kind {kind!r} does not take these options: {err}") from None
        raise
