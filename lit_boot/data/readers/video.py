"""Any video as a :class:`~lit_boot.core.scene.Scene`: an mp4 (anything OpenCV reads) or a folder
of image frames, optionally with precomputed pose estimates.

Frames are uint8 (T, 3, H, W) RGB. The scene's metadata: ``source`` (the path),
``frame_indices`` (the 0-based source frame of each scene frame), ``native_size`` ([H, W]
before resizing), ``stride``, ``source_fps`` and, for folders, ``files`` (the frames' names).
"""

from __future__ import annotations

import os
from pathlib import Path

from ...core.scene import Scene, SceneValidationError
from ..memory import check_memory
from ._common import IMAGE_SUFFIXES, DatasetFormatError, Size, decode_video, make_scene, probe_video, read_image
from ._common import read_images
from .estimates import list_files, read_estimates
from .pose_file import PoseEstimates

__all__ = ["IMAGE_SUFFIXES", "DEFAULT_FOLDER_FPS", "output_size", "read_video", "video_frame_count"]

#: Frame rate assumed for a folder of frames when ``fps`` is not given.
DEFAULT_FOLDER_FPS = 30.0
Resize = int | float | tuple[int, int]


def output_size(native: Size, resize: Resize | None) -> Size | None:
    """(H, W) after ``resize``: None = native; an int = the height (width keeps the aspect ratio,
    rounded); a float = a scale factor for both sides (rounded); (H, W) = exactly that."""
    H, W = native
    if resize is None:
        return None
    if isinstance(resize, bool):
        raise ValueError(f"resize: expected a height, a scale or (H, W), got {resize!r}")
    if isinstance(resize, int):
        size = (resize, round(W * resize / H))
    elif isinstance(resize, float):
        size = (round(H * resize), round(W * resize))
    elif isinstance(resize, (tuple, list)) and len(resize) == 2:
        size = (int(resize[0]), int(resize[1]))
    else:
        raise ValueError(f"resize: expected a height (int), a scale (float) or (H, W), got {resize!r}")
    if min(size) < 1:
        raise ValueError(f"resize {resize!r}: gives an empty {size[1]}x{size[0]} image from {W}x{H}")
    return size


def _check_memory(path: Path, total: int, native: Size, stride: int, first: int, max_frames: int | None,
                  resize) -> None:
    """Refuse, before decoding, a selection of frames that would not fit in memory."""
    T = len(range(first, total, stride)[:max_frames])
    H, W = output_size(native, resize) or native
    check_memory(path, T, H, W, advice="read fewer or smaller frames:")


def _read_folder(folder: Path, stride: int, first: int, max_frames: int | None, resize: Resize | None):
    files = list_files(folder, IMAGE_SUFFIXES)
    if not files:
        raise DatasetFormatError(f"{folder}: no image frames ({', '.join(IMAGE_SUFFIXES)}) in this folder")
    indices = list(range(first, len(files), stride))[:max_frames]
    if not indices:
        raise ValueError(f"{folder}: first={first} but the folder has {len(files)} frames")
    native = tuple(read_image(files[0]).shape[1:])
    _check_memory(folder, len(files), native, stride, first, max_frames, resize)
    frames, _ = read_images([files[t] for t in indices], output_size(native, resize))
    extra = {"files": [files[t].name for t in indices]}
    return frames, indices, native, len(files), None, extra


def _read_file(path: Path, stride: int, first: int, max_frames: int | None, resize: Resize | None, count_all: bool):
    def keep(index: int, kept: int) -> bool | None:
        if max_frames is not None and kept >= max_frames:
            return False if count_all else None  # go on only to count the frames
        return index >= first and (index - first) % stride == 0  # earlier frames: grabbed, not decoded

    probed = probe_video(path)
    if probed is not None:
        _check_memory(path, *probed, stride, first, max_frames, resize)
    video = decode_video(path, keep, lambda native: output_size(native, resize))
    if not video.indices:
        if first and video.seen:
            raise ValueError(f"{path}: first={first} but the video has {video.seen} frames")
        raise DatasetFormatError(f"{path}: no frame could be read (empty or undecodable video)")
    total = video.seen if count_all else None
    return video.frames, video.indices, video.native, total, video.fps, {}


def _attach(scene: Scene, poses: PoseEstimates, where: str, total: int) -> Scene:
    """Check ``poses`` against the video (counts, frames, somebody found) and apply them."""
    fi = poses.frame_indices.tolist()
    default = fi == list(range(len(fi)))
    if (default and len(fi) != total) or fi[-1] >= total:
        raise DatasetFormatError(
            f"{where}: pose estimates for {len(fi)} frames (video frames {fi[0]}..{fi[-1]}), "
            f"but the video has {total} frames"
        )
    missing = sorted(set(scene.metadata["frame_indices"]) - set(fi))
    if missing:
        more = " ..." * (len(missing) > 5)
        raise DatasetFormatError(f"{where}: no pose estimates for video frames {missing[:5]}{more}")
    try:
        scene = poses.apply_to(scene)  # no image_size: in native pixels (metadata["native_size"])
    except SceneValidationError as err:
        raise DatasetFormatError(f"{where}: {err}") from None
    if scene.keypoints_conf is not None and poses.keypoints2d is not None and not (scene.keypoints_conf > 0).any():
        raise DatasetFormatError(f"{where}: nobody is ever found in the pose estimates of the selected frames")
    return scene


def video_frame_count(path: str | os.PathLike, *, stride: int = 1, max_frames: int | None = None, first: int = 0,
                      **_: object) -> int:
    """How many frames :func:`read_video` with these arguments gives, without decoding any: a
    folder's image files are counted; a video file's frames are grabbed (demuxed), not decoded,
    since container headers may not know or may misstate the count. Other read_video
    arguments are accepted and ignored. FileNotFoundError / DatasetFormatError as read_video."""
    path = Path(path)
    if path.is_dir():
        total = len(list_files(path, IMAGE_SUFFIXES))
    elif path.is_file():
        total = decode_video(path, lambda index, kept: False).seen
    else:
        raise FileNotFoundError(f"{path}: no such video file or folder of frames")
    if total == 0:
        raise DatasetFormatError(f"{path}: no frame could be read (empty folder or undecodable video)")
    return len(range(first, total, stride)[:max_frames])


def read_video(
    path: str | os.PathLike,
    *,
    stride: int = 1,
    max_frames: int | None = None,
    resize: Resize | None = None,
    poses: str | os.PathLike | PoseEstimates | None = None,
    fps: float | None = None,
    first: int = 0,
) -> Scene:
    """Read a video file (mp4, anything OpenCV reads) or a folder of frames (jpg/png/...,
    natural name order) as a Scene: source frames first, first + stride, first + 2 stride, ...
    (at most ``max_frames``; ``first`` 0-based). The frames before ``first`` are skipped, not
    decoded: a chunk of a long video costs memory and decoding for its own frames only.

    ``resize``: None, a height (int; the width keeps the aspect ratio), a scale (float) or
    (H, W). ``poses``: a pose file of any kind :func:`~.estimates.read_estimates` reads, or
    PoseEstimates, indexed by source frame (``frame_indices``; without ``image_size`` taken to
    be in the video's native pixels); the kept frames' rows are selected and their pixels and
    crops rescaled. ``fps``: the source's frame rate (default: the file's, 30 for folders); the
    scene's fps is ``fps / stride``.

    Raises FileNotFoundError (missing path), ValueError (bad arguments), DatasetFormatError
    naming the file (unreadable video, empty folder, undecodable frame, pose estimates not
    matching the video's frames, or nobody ever found in them), and, before decoding,
    :class:`~lit_boot.data.memory.NotEnoughMemoryError` when the selected frames would not fit
    in the available memory (its message suggests a stride, a frame count and a size that do).
    """
    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride}")
    if max_frames is not None and max_frames < 1:
        raise ValueError(f"max_frames must be >= 1 or None, got {max_frames}")
    if isinstance(first, bool) or not isinstance(first, int) or first < 0:
        raise ValueError(f"first must be an int >= 0, got {first!r}")
    path = Path(path)
    if path.is_dir():
        frames, indices, native, total, file_fps, extra = _read_folder(path, stride, first, max_frames, resize)
    elif path.is_file():
        count_all = poses is not None  # to check the pose file's frame count
        frames, indices, native, total, file_fps, extra = _read_file(path, stride, first, max_frames, resize,
                                                                     count_all)  # fmt: skip
    else:
        raise FileNotFoundError(f"{path}: no such video file or folder of frames")
    source_fps = float(fps or file_fps or DEFAULT_FOLDER_FPS)
    metadata = {"source": str(path), "frame_indices": indices, "native_size": list(native), "stride": stride,
                "source_fps": source_fps, **extra}  # fmt: skip
    scene = make_scene(path, frames=frames, fps=source_fps / stride, name=path.stem or path.name, metadata=metadata)
    if poses is None:
        return scene
    where = str(poses) if not isinstance(poses, PoseEstimates) else f"{path} (pose estimates from {poses.source})"
    if not isinstance(poses, PoseEstimates):
        poses = read_estimates(poses)
    return _attach(scene, poses, where, total)
