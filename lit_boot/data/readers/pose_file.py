"""Precomputed pose estimates of one person (:class:`PoseEstimates`) and lit-boot's own pose file.

Pose file, format ``lit-boot-pose-estimates``, version 1; ``.npz`` or ``.json`` by suffix.
Arrays (T rows = T frames; every key optional unless marked)::

    frame_indices   (T,)       int64    source-video frame of each row, strictly increasing [required]
    keypoints2d     (T, K, 2)  float32  px, pixel centres at integer coordinates, (x, y)
    keypoints_conf  (T, K)     float32  in [0, 1], 0 = not found      [with keypoints2d]
    joints3d        (T, J, 3)  float32  mm, camera axes x right, y down, z forward
    cameras_params  (T, P)     float32  P = 3 (s, tx, ty) weak perspective, 7 pinhole
    cameras_crops   (T, 3)     float32  (scale, start_x, start_y) [weak perspective only]
    person_boxes    (T, 5)     float32  a person detector's box (x0, y0, x1, y1 px, the outer
                                        edges) and score in [0, 1] (0 = nobody found)

At least one of keypoints2d / joints3d is present; cameras need joints3d. The header (in the
.npz: key ``header``, a 0-d unicode array holding JSON text; in the .json: the top-level
object, whose other keys are the arrays as nested lists) holds: ``format``, ``version``,
``keypoints_layout`` (default "coco17"), ``joints3d_layout`` (default "lsp14"), ``cameras``
(null or {"model", "crop_size"}), ``image_size`` ([H, W] of the frames the pixels refer to,
or null = unknown), ``source`` (e.g. "mediapipe-0.10.14", "metro") and ``metadata`` (any
JSON). The .npz loads with ``allow_pickle=False``. Camera conventions: :mod:`lit_boot.core.cameras`.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ...core.cameras import Cameras
from ...core.joints import get_layout
from ...core.scene import Scene, SceneValidationError, check_estimates
from ..atomic import atomic_write_bytes
from ._common import DatasetFormatError, scale_factors, scale_points

__all__ = ["POSES_FORMAT", "POSES_FORMAT_VERSION", "PoseEstimates", "save_poses", "load_poses"]

POSES_FORMAT = "lit-boot-pose-estimates"
POSES_FORMAT_VERSION = 1
_ARRAYS = ("frame_indices", "keypoints2d", "keypoints_conf", "joints3d", "cameras_params", "cameras_crops",
           "person_boxes")
#: Largest relative difference of the x and y resize factors weak-perspective cameras tolerate.
ANISOTROPY_TOLERANCE = 0.01


@dataclass
class PoseEstimates:
    """Per-frame pose estimates of one person in T frames (no pixels).

    keypoints2d (T, K, 2) px + keypoints_conf (T, K) in [0, 1] (0 = not found) in
    ``keypoints_layout``; joints3d (T, J, 3) mm in ``joints3d_layout`` with ``cameras``;
    either part may be absent, not both. frame_indices (T,) int64: the source-video frame of
    each row (default 0..T-1); image_size (H, W) of the frames the pixels refer to (None =
    unknown: taken to be the scene's); source: who made them; metadata: JSON-serialisable;
    person_boxes (T, 5): a person detector's box and score per frame (see
    :class:`~lit_boot.core.Scene`), or None. Checked on construction (:meth:`validate`).
    """

    keypoints2d: torch.Tensor | None = None
    keypoints_conf: torch.Tensor | None = None
    keypoints_layout: str = "coco17"
    joints3d: torch.Tensor | None = None
    joints3d_layout: str = "lsp14"
    cameras: Cameras | None = None
    frame_indices: torch.Tensor | None = None
    image_size: tuple[int, int] | None = None
    source: str = "unknown"
    metadata: dict[str, Any] = field(default_factory=dict)
    person_boxes: torch.Tensor | None = None

    def __post_init__(self) -> None:
        if self.frame_indices is None and self.num_frames is not None:
            self.frame_indices = torch.arange(self.num_frames, dtype=torch.int64)
        if self.image_size is not None:
            self.image_size = tuple(int(v) for v in self.image_size)
        self.validate()

    @property
    def num_frames(self) -> int | None:
        """T (None while neither keypoints2d nor joints3d is set)."""
        present = self.keypoints2d if self.keypoints2d is not None else self.joints3d
        return None if present is None else int(present.shape[0])

    def validate(self) -> None:
        """Check every field; SceneValidationError names the field and what was expected."""
        T = self.num_frames
        if T is None:
            raise SceneValidationError("PoseEstimates: give keypoints2d (with keypoints_conf) or joints3d, or both")
        if self.cameras is not None and self.joints3d is None:
            raise SceneValidationError("PoseEstimates.cameras: cameras need joints3d")
        check_estimates("PoseEstimates", self, T)
        fi = self.frame_indices
        if not isinstance(fi, torch.Tensor) or fi.dtype != torch.int64 or tuple(fi.shape) != (T,):
            got = f"{fi.dtype} {tuple(fi.shape)}" if isinstance(fi, torch.Tensor) else type(fi).__name__
            raise SceneValidationError(f"PoseEstimates.frame_indices: expected int64 of shape ({T},), got {got}")
        if (fi < 0).any() or (fi[1:] <= fi[:-1]).any():
            raise SceneValidationError("PoseEstimates.frame_indices: expected non-negative, strictly increasing")
        if self.image_size is not None and (len(self.image_size) != 2 or min(self.image_size) < 1):
            raise SceneValidationError(f"PoseEstimates.image_size: expected (H, W) > 0 or None, got {self.image_size}")
        if not isinstance(self.source, str):
            raise SceneValidationError(f"PoseEstimates.source: expected a str, got {type(self.source).__name__}")
        try:
            json.dumps(self.metadata, allow_nan=False)
        except (TypeError, ValueError) as err:
            raise SceneValidationError(f"PoseEstimates.metadata: must be JSON-serialisable: {err}") from None

    def found(self) -> torch.Tensor:
        """(T,) bool: rows with any keypoint of confidence > 0 (all True without keypoints)."""
        if self.keypoints_conf is None:
            return torch.ones(self.num_frames, dtype=torch.bool)
        return (self.keypoints_conf > 0).any(-1)

    def take(self, rows: torch.Tensor | list[int]) -> PoseEstimates:
        """The estimates of rows ``rows`` (0-based row numbers, increasing)."""
        rows = torch.as_tensor(rows, dtype=torch.int64)
        pick = lambda x: None if x is None else x[rows].clone()  # noqa: E731
        cams = self.cameras
        if cams is not None:
            cams = Cameras(cams.model, pick(cams.params), pick(cams.crops), cams.crop_size)
        return dataclasses.replace(
            self, keypoints2d=pick(self.keypoints2d), keypoints_conf=pick(self.keypoints_conf),
            joints3d=pick(self.joints3d), cameras=cams, frame_indices=self.frame_indices[rows].clone(),
            person_boxes=pick(self.person_boxes),
        )  # fmt: skip

    def rescaled(self, image_size: tuple[int, int]) -> PoseEstimates:
        """The estimates for the frames resized to ``image_size`` (H, W): pixels, pinhole
        intrinsics and weak-perspective crops move with the image (pixel centres at integer
        coordinates). Weak-perspective cameras need x and y factors within 1 %."""
        if self.image_size is None or tuple(self.image_size) == tuple(image_size):
            return dataclasses.replace(self, image_size=tuple(image_size))
        sx, sy = scale_factors(*self.image_size, image_size)
        keypoints = None if self.keypoints2d is None else scale_points(self.keypoints2d, sx, sy)
        boxes = self.person_boxes
        if boxes is not None:
            corners = scale_points(boxes[:, :4].reshape(-1, 2, 2), sx, sy).reshape(-1, 4)
            boxes = torch.cat([corners, boxes[:, 4:]], dim=1)
        return dataclasses.replace(
            self, keypoints2d=keypoints, cameras=_rescale_cameras(self.cameras, sx, sy), image_size=tuple(image_size),
            person_boxes=boxes,
        )  # fmt: skip

    def apply_to(self, scene: Scene) -> Scene:
        """A copy of ``scene`` with these estimates (the fields present here replace the scene's).

        Rows are matched to the scene's frames by ``scene.metadata["frame_indices"]`` when the
        scene has them and all are among ``frame_indices``; otherwise row by row when T agrees
        and ``frame_indices`` is the default 0..T-1. Pixels are rescaled when ``image_size``
        (if None: ``scene.metadata["native_size"]``, which :func:`~.video.read_video` records,
        else the scene's size) differs from the scene's. ``metadata["pose_estimates"]`` lists the
        estimates applied so far (source, fields, frame_indices, metadata). Raises
        SceneValidationError on a mismatch, or for a found keypoint (confidence > 0) more than
        one image size outside the frame (x outside [-W, 2W], y outside [-H, 2H]).
        """
        est = self.take(self._rows_for(scene))
        if est.image_size is None and scene.metadata.get("native_size"):
            est = dataclasses.replace(est, image_size=tuple(scene.metadata["native_size"]))
        est = est.rescaled((scene.height, scene.width))
        _check_in_image(est, scene.height, scene.width)
        fields: dict[str, Any] = {}
        if est.keypoints2d is not None:
            fields |= {"keypoints2d": est.keypoints2d, "keypoints_conf": est.keypoints_conf,
                       "keypoints_layout": est.keypoints_layout}  # fmt: skip
        if est.joints3d is not None:
            fields |= {"joints3d": est.joints3d, "joints3d_layout": est.joints3d_layout, "cameras": est.cameras}
        if est.person_boxes is not None:
            fields["person_boxes"] = est.person_boxes
        info = {"source": self.source, "fields": sorted(fields), "frame_indices": est.frame_indices.tolist(),
                "metadata": self.metadata}  # fmt: skip
        history = [*scene.metadata.get("pose_estimates", []), info]
        return dataclasses.replace(scene, **fields, metadata={**scene.metadata, "pose_estimates": history})

    def _rows_for(self, scene: Scene) -> list[int]:
        T, mine = scene.num_frames, self.frame_indices.tolist()
        wanted = scene.metadata.get("frame_indices")
        if wanted is not None and set(wanted) <= set(mine):
            where = {f: r for r, f in enumerate(mine)}
            return [where[f] for f in wanted]
        if T == len(mine) and mine == list(range(T)):
            return mine
        raise SceneValidationError(
            f"PoseEstimates ({self.source}): {len(mine)} rows for video frames {_span(mine)} do not cover the "
            f"scene {scene.name!r}'s {T} frames" + (f" (video frames {_span(wanted)})" if wanted is not None else "")
        )


def _check_in_image(est: PoseEstimates, height: int, width: int) -> None:
    """SceneValidationError for found keypoints more than one image size outside the frame."""
    if est.keypoints2d is None:
        return
    x, y = est.keypoints2d[..., 0], est.keypoints2d[..., 1]
    far = (est.keypoints_conf > 0) & ((x < -width) | (x > 2 * width) | (y < -height) | (y > 2 * height))
    if not far.any():
        return
    t, k = (int(i) for i in far.nonzero()[0])
    name = get_layout(est.keypoints_layout).names[k]
    raise SceneValidationError(
        f"PoseEstimates ({est.source}).keypoints2d: {int(far.sum())} found keypoints in {int(far.any(1).sum())} "
        f"frames lie more than one image size outside the {width}x{height} px frames, first {name} of video frame "
        f"{int(est.frame_indices[t])} at ({float(x[t, k]):.0f}, {float(y[t, k]):.0f}) px (expected x in "
        f"[{-width}, {2 * width}], y in [{-height}, {2 * height}]; wrong image_size or units?)"
    )


def _span(values: list[int]) -> str:
    return f"{values[0]}..{values[-1]}" if values else "none"


def _rescale_cameras(cameras: Cameras | None, sx: float, sy: float) -> Cameras | None:
    if cameras is None:
        return None
    p = cameras.params.clone()
    if cameras.model == "pinhole":
        p[:, 0:2] *= torch.tensor([sx, sy], dtype=p.dtype)
        p[:, 2:4] = scale_points(p[:, 2:4], sx, sy)
        return Cameras("pinhole", p)
    if abs(sx / sy - 1.0) > ANISOTROPY_TOLERANCE:
        raise SceneValidationError(
            f"PoseEstimates.cameras: cannot rescale weak-perspective cameras by x {sx:.4f} / y {sy:.4f} "
            "(the aspect ratio changes)"
        )
    # u' = (u + 0.5) s - 0.5 with u = (u_crop + start - c/2) / scale  =>  scale' = scale / s,
    # start' = start + (s - 1) / 2 * scale'.
    crops = cameras.crops.clone()
    crops[:, 0] = crops[:, 0] / (sx * sy) ** 0.5
    crops[:, 1:3] = crops[:, 1:3] + (torch.tensor([sx, sy], dtype=crops.dtype) - 1.0) / 2.0 * crops[:, 0:1]
    return Cameras("weak_perspective", p, crops, cameras.crop_size)


def _header(est: PoseEstimates) -> dict[str, Any]:
    cams = None if est.cameras is None else {"model": est.cameras.model, "crop_size": float(est.cameras.crop_size)}
    return {
        "format": POSES_FORMAT, "version": POSES_FORMAT_VERSION, "keypoints_layout": est.keypoints_layout,
        "joints3d_layout": est.joints3d_layout, "cameras": cams,
        "image_size": None if est.image_size is None else list(est.image_size),
        "source": est.source, "metadata": est.metadata,
    }  # fmt: skip


def _arrays(est: PoseEstimates) -> dict[str, np.ndarray]:
    cams = est.cameras
    values = {
        "frame_indices": est.frame_indices, "keypoints2d": est.keypoints2d, "keypoints_conf": est.keypoints_conf,
        "joints3d": est.joints3d, "cameras_params": None if cams is None else cams.params,
        "cameras_crops": None if cams is None else cams.crops, "person_boxes": est.person_boxes,
    }  # fmt: skip
    out = {}
    for key, value in values.items():
        if value is not None:
            dtype = np.int64 if key == "frame_indices" else np.float32
            out[key] = value.detach().cpu().numpy().astype(dtype)
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
    if "frame_indices" not in arrays:
        raise DatasetFormatError(f"{path}: missing key 'frame_indices'")
    try:
        t = {k: torch.from_numpy(np.asarray(v, dtype=np.int64 if k == "frame_indices" else np.float32))
             for k, v in arrays.items()}  # fmt: skip
        cams = header.get("cameras")
        cameras = None
        if cams is not None:
            cameras = Cameras(cams["model"], t["cameras_params"], t.get("cameras_crops"), cams.get("crop_size", 224.0))
        return PoseEstimates(
            keypoints2d=t.get("keypoints2d"), keypoints_conf=t.get("keypoints_conf"),
            keypoints_layout=header.get("keypoints_layout", "coco17"), joints3d=t.get("joints3d"),
            joints3d_layout=header.get("joints3d_layout", "lsp14"), cameras=cameras, frame_indices=t["frame_indices"],
            image_size=header.get("image_size"), source=header.get("source", "unknown"),
            metadata=header.get("metadata", {}), person_boxes=t.get("person_boxes"),
        )  # fmt: skip
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise DatasetFormatError(f"{path}: malformed pose file: {type(err).__name__}: {err}") from None

