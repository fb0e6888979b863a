"""What the dataset readers share: the error class, frame selection, image / video reading,
resizing of frames and of pixel coordinates, pinhole cameras and array shape checks.

Frames are uint8 (T, 3, H, W) RGB. ``size`` is always (height, width) of the output frames;
pixel coordinates follow lit-boot's convention (pixel centres at integer coordinates), so a
resize by factors (sx, sy) maps x to (x + 0.5) * sx - 0.5. Readers never write anything.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from ...core.cameras import Cameras
from ...core.scene import Scene, SceneValidationError
from ..scene_io import SceneFormatError
from ..visualize import read_png

__all__ = ["DatasetFormatError"]

# FFmpeg's own log lines ("moov atom not found" ...) would come on top of our one-line errors;
# OpenCV reads this when it first opens a video. Set it to e.g. 24 to see FFmpeg's warnings.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

Size = tuple[int, int]
#: Image files read as frames (lower-case suffixes).
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")


class DatasetFormatError(SceneFormatError):
    """A dataset file or folder is malformed or inconsistent (the message names the file)."""


def make_scene(source: Path, **fields: Any) -> Scene:
    """``Scene(**fields)``; a SceneValidationError (e.g. NaN in the annotations) becomes a
    DatasetFormatError naming ``source``."""
    try:
        return Scene(**fields)
    except SceneValidationError as err:
        raise DatasetFormatError(f"{source}: the data make an invalid scene: {err}") from None


def require_dir(path: Path, what: str) -> Path:
    """``path`` if it is a folder, else FileNotFoundError naming it and ``what`` it should be."""
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: no such folder ({what})")
    return path


def check_shape(array: np.ndarray, shape: tuple, file: Path, what: str) -> np.ndarray:
    """Check ``array``'s shape (None = any size); DatasetFormatError naming ``file`` otherwise."""
    try:
        array = np.asarray(array)
    except ValueError as err:  # ragged nested lists
        raise DatasetFormatError(f"{file}: {what}: not an array: {err}") from None
    want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
    if array.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, array.shape)):
        raise DatasetFormatError(f"{file}: {what}: expected shape {want}, got {array.shape}")
    if not np.issubdtype(array.dtype, np.number) and array.dtype != bool:
        raise DatasetFormatError(f"{file}: {what}: expected numbers, got dtype {array.dtype}")
    return array


def select_frames(
    available: Sequence[int],
    first: int | None,
    last: int | None,
    stride: int = 1,
    max_frames: int | None = None,
    where: str = "",
) -> list[int]:
    """Frame numbers first, first+stride, ... <= last (inclusive; default: the whole of the
    sorted ``available``), at most ``max_frames``. Raises ValueError for bad arguments and
    DatasetFormatError when a wanted frame is missing from ``available`` (named by ``where``)."""
    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride}")
    if max_frames is not None and max_frames < 1:
        raise ValueError(f"max_frames must be >= 1 or None, got {max_frames}")
    if not available:
        raise DatasetFormatError(f"{where}: no frames found")
    lo, hi = available[0], available[-1]
    first = lo if first is None else first
    last = hi if last is None else last
    if not (lo <= first <= hi and lo <= last <= hi) or first > last:
        raise ValueError(f"{where}: frames {first}..{last} requested, but the frames run {lo}..{hi}")
    wanted = list(range(first, last + 1, stride))[:max_frames]
    missing = sorted(set(wanted) - set(available))
    if missing:
        raise DatasetFormatError(f"{where}: frames {missing[:5]}{' ...' if len(missing) > 5 else ''} are missing")
    return wanted


def scale_factors(height: int, width: int, size: Size | None) -> tuple[float, float]:
    """(sx, sy) taking a width x height image to ``size`` = (height, width); (1, 1) for None."""
    if size is None:
        return 1.0, 1.0
    if len(size) != 2 or min(size) < 1:
        raise ValueError(f"size must be (height, width) with positive sides, got {size!r}")
    return size[1] / width, size[0] / height


def resize_array(image: np.ndarray, size: Size | None, nearest: bool = False) -> np.ndarray:
    """Resize an (H, W[, C]) array to ``size`` = (height, width): area averaging when
    shrinking, bilinear when enlarging, or centre-aligned nearest neighbour (masks, flow)."""
    if size is None or tuple(image.shape[:2]) == tuple(size):
        return image
    shrink = size[0] * size[1] < image.shape[0] * image.shape[1]
    mode = cv2.INTER_NEAREST_EXACT if nearest else (cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    return cv2.resize(np.ascontiguousarray(image), (size[1], size[0]), interpolation=mode)


def scale_points(points: torch.Tensor, sx: float, sy: float) -> torch.Tensor:
    """Pixel coordinates (..., 2) after resizing the image by (sx, sy)."""
    if sx == sy == 1.0:
        return points
    scale = torch.tensor([sx, sy], dtype=points.dtype)
    return (points + 0.5) * scale - 0.5


def pinhole_cameras(intrinsics: np.ndarray, num_frames: int, sx: float = 1.0, sy: float = 1.0) -> Cameras:
    """Static pinhole Cameras (T, 7) = (fx, fy, cx, cy, 0, 0, 0) from a (3, 3) K, rescaled by
    (sx, sy) like the image (skew is ignored)."""
    fx, fy, cx, cy = intrinsics[0, 0], intrinsics[1, 1], intrinsics[0, 2], intrinsics[1, 2]
    row = [fx * sx, fy * sy, (cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5, 0.0, 0.0, 0.0]
    return Cameras("pinhole", torch.tensor(row, dtype=torch.float32).repeat(num_frames, 1))


def hwc_to_tensor(image: np.ndarray) -> torch.Tensor:
    """(H, W, 3) uint8 array -> (3, H, W) tensor."""
    return torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1).contiguous()


def read_image(path: Path) -> torch.Tensor:
    """One image (PNG, JPEG, ...) as uint8 (3, H, W) RGB. FileNotFoundError when missing,
    DatasetFormatError naming the file when undecodable."""
    try:
        return read_png(path)
    except FileNotFoundError:
        raise
    except ValueError as err:
        raise DatasetFormatError(str(err)) from None


def resize_frames(frames: torch.Tensor, size: Size | None) -> torch.Tensor:
    """Resize uint8 (T, 3, H, W) frames to ``size`` = (height, width) (as :func:`resize_array`)."""
    if size is None or tuple(frames.shape[-2:]) == tuple(size):
        return frames
    return torch.stack([hwc_to_tensor(resize_array(f.permute(1, 2, 0).numpy(), size)) for f in frames])


def read_images(paths: Sequence[Path], size: Size | None = None) -> tuple[torch.Tensor, tuple[int, int]]:
    """Images of one size as uint8 (T, 3, H, W) RGB resized to ``size``, and their native
    (height, width); DatasetFormatError names an odd-sized image."""
    frames, native = [], None
    for path in paths:
        frame = read_image(path)
        if native is None:
            native = tuple(frame.shape[1:])
        elif tuple(frame.shape[1:]) != native:
            raise DatasetFormatError(
                f"{path}: image of {frame.shape[2]}x{frame.shape[1]} px, "
                f"but {paths[0].name} is {native[1]}x{native[0]} px"
            )
        frames.append(resize_frames(frame[None], size)[0])
    return torch.stack(frames), native


@dataclass
class DecodedVideo:
    """Frames decoded from a video file: frames uint8 (T, 3, H, W) RGB (T may be 0), indices
    (the 0-based source frame of each), native (H, W) before resizing (None if nothing was
    decoded), seen (frames grabbed before stopping) and fps (the file's; None if unknown)."""

    frames: torch.Tensor
    indices: list[int]
    native: Size | None
    seen: int
    fps: float | None


def decode_video(
    path: Path, keep: Callable[[int, int], bool | None], size: Size | Callable[[Size], Size | None] | None = None
) -> DecodedVideo:
    """Decode ``path`` with OpenCV. ``keep(index, kept)`` says for each source frame whether
    to decode it (True), skip it (False; grabbed, not decoded) or stop reading (None); ``kept``
    counts the frames decoded so far. ``size``: output (H, W), or a function of the native
    (H, W) giving it. DatasetFormatError when the file is unreadable or a frame undecodable."""
    capture = cv2.VideoCapture(os.fspath(path))
    try:
        if not capture.isOpened():
            raise DatasetFormatError(f"{path}: unreadable video (OpenCV could not open it)")
        fps = capture.get(cv2.CAP_PROP_FPS)
        frames, indices, native, index = [], [], None, 0
        while (wanted := keep(index, len(frames))) is not None and capture.grab():
            if wanted:
                ok, image = capture.retrieve()
                if not ok or image is None:
                    raise DatasetFormatError(f"{path}: frame {index} failed to decode")
                if native is None:
                    native = tuple(image.shape[:2])
                    size = size(native) if callable(size) else size
                frames.append(hwc_to_tensor(resize_array(cv2.cvtColor(image, cv2.COLOR_BGR2RGB), size)))
                indices.append(index)
            index += 1
    finally:
        capture.release()
    stacked = torch.stack(frames) if frames else torch.empty(0, 3, 0, 0, dtype=torch.uint8)
    return DecodedVideo(stacked, indices, native, index, fps if fps and fps > 0 else None)


def probe_video(path: Path) -> tuple[int, Size] | None:
    """(frame count, native (H, W)) from a video file's header; None when OpenCV cannot open
    it or does not know them (the count of some streams is unknown until decoded)."""
    capture = cv2.VideoCapture(os.fspath(path))
    try:
        if not capture.isOpened():
            return None
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        size = (int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)), int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)))
    finally:
        capture.release()
    return (count, size) if count > 0 and min(size) > 0 else None


def read_video_frames(
    path: Path, indices: Sequence[int], size: Size | None = None
) -> tuple[torch.Tensor, tuple[int, int]]:
    """Frames ``indices`` (0-based, increasing) of a video file as uint8 (T, 3, H, W) RGB
    resized to ``size``, and the native (height, width). DatasetFormatError when the file is
    unreadable or ends before the last wanted frame."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"{path}: no such video file")
    wanted, last = set(indices), max(indices)
    video = decode_video(path, lambda index, kept: None if index > last else index in wanted, size)
    if video.seen <= last:
        raise DatasetFormatError(
            f"{path}: the video ends after {video.seen} frames, but frame {last} is needed "
            f"(fewer video frames than annotated frames)"
        )
    return video.frames, video.native
