"""Human3.6M as the paper evaluates it: one action of one subject seen by one camera, GT from
VideoPose3D's preprocessed files.

Files (paths overridable): ``root``/data_3d_h36m.npz (``positions_3d``: {subject: {action:
(N, 32, 3) world metres}}; VideoPose3D keeps joints :data:`H36M_KEEP_JOINTS`, in h36m17
order), ``root``/data_2d_h36m_gt.npz (``positions_2d``: {subject: {action: [4 cameras of
(N, 17, 2) px]}}, cameras in :data:`H36M_CAMERA_IDS` order), and the frames: a video
``root``/<subject>/Videos/<action>.<camera>.mp4 (50 fps, 1000x1002 for camera 60457274) or a
folder of images (sorted by name, one per annotated frame). Frame i of the video is row i of
the annotations; a video longer than the annotations is accepted (H3.6M videos often run a
few frames past the mocap), a shorter one is an error.

Cameras (:class:`H36MCamera`, VideoPose3D's convention): ``orientation`` is the quaternion
(w, x, y, z) of the camera-to-world rotation R, ``translation`` the camera centre C in world
mm; world -> camera is X_cam = R^T (X_world - C), in mm, x right, y down, z forward. The
published values of camera 60457274 for S9 and S11 (VideoPose3D's h36m_dataset.py) are
built in (:data:`H36M_CAMERAS`); the paper's authors used their own camera file, which
differs from this public one, so their numbers need not match exactly. Lens distortion is
ignored: GroundTruth.joints2d are VideoPose3D's 2D positions (made with distortion), while
GroundTruth.cameras is the undistorted pinhole; ``metadata["pinhole_error_px"]`` gives their
mean gap.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ...core.joints import map_joints
from ...core.scene import GroundTruth, Scene
from ._common import IMAGE_SUFFIXES, DatasetFormatError, Size, check_shape, make_scene, pinhole_cameras, read_images
from ._common import read_video_frames, scale_factors, scale_points, select_frames

__all__ = [
    "H36M_CAMERAS",
    "H36M_CAMERA_IDS",
    "H36M_EVAL_CAMERA",
    "H36M_EVAL_STRIDE",
    "H36M_EVAL_SUBJECTS",
    "H36M_FPS",
    "H36M_KEEP_JOINTS",
    "H36MCamera",
    "list_h36m_actions",
    "read_h36m",
]

H36M_EVAL_SUBJECTS = ("S9", "S11")
H36M_EVAL_CAMERA = "60457274"
H36M_EVAL_STRIDE = 5
H36M_FPS = 50.0
#: VideoPose3D's camera order: index of a camera in positions_2d[subject][action].
H36M_CAMERA_IDS = ("54138969", "55011271", "58860488", "60457274")
#: The 17 of the 32 mocap joints that VideoPose3D keeps, giving the h36m17 order.
H36M_KEEP_JOINTS = (0, 1, 2, 3, 6, 7, 8, 12, 13, 14, 15, 17, 18, 19, 25, 26, 27)


@dataclass(frozen=True)
class H36MCamera:
    """One calibrated camera: orientation (w, x, y, z) camera -> world, translation = camera
    centre in world mm, focal_length (fx, fy) px, center (cx, cy) px."""

    orientation: tuple[float, float, float, float]
    translation: tuple[float, float, float]
    focal_length: tuple[float, float]
    center: tuple[float, float]

    def rotation(self) -> np.ndarray:
        """(3, 3) world -> camera rotation R^T (float64)."""
        w, x, y, z = np.asarray(self.orientation, dtype=np.float64) / np.linalg.norm(self.orientation)
        r = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ])  # fmt: skip
        return r.T

    def world_to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) in metres -> camera frame (..., 3) in mm."""
        return (points * 1000.0 - np.asarray(self.translation)) @ self.rotation().T

    def intrinsics(self) -> np.ndarray:
        """(3, 3) K."""
        (fx, fy), (cx, cy) = self.focal_length, self.center
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


_F60457274 = (1145.5113525390625, 1144.77392578125)
_C60457274 = (514.9682006835938, 501.88201904296875)
#: Published calibration (VideoPose3D) of camera 60457274 for the evaluation subjects.
H36M_CAMERAS: dict[tuple[str, str], H36MCamera] = {
    ("S9", "60457274"): H36MCamera(
        (0.5879399180412292, -0.7823407053947449, 0.1427614390850067, -0.14794869720935822),
        (-1696.04345703125, -3827.099853515625, 1591.4127197265625), _F60457274, _C60457274,
    ),
    ("S11", "60457274"): H36MCamera(
        (0.5894251465797424, -0.7818877100944519, 0.13991211354732513, -0.14715361595153809),
        (-1590.738037109375, -3854.1689453125, 1578.017578125), _F60457274, _C60457274,
    ),
}  # fmt: skip


@functools.lru_cache(maxsize=4)
def _load_npz_dict(path: str, key: str, stamp: tuple[int, ...]) -> dict[str, Any]:
    """``np.load(path)[key].item()``, cached while the file is unchanged (``stamp``)."""
    try:
        with np.load(path, allow_pickle=True) as npz:
            files = list(npz.files)
            value = npz[key].item() if key in files else None
    except Exception as err:  # np.load / unpickling raise many kinds of errors
        raise DatasetFormatError(f"{path}: unreadable .npz: {type(err).__name__}: {err}") from None
    if value is None:
        raise DatasetFormatError(f"{path}: no {key!r} array (has {files}); expected VideoPose3D's file")
    if not isinstance(value, dict):
        raise DatasetFormatError(f"{path}: {key} should hold a dict {{subject: {{action: array}}}}")
    return value


def _npz(path: Path, key: str) -> dict[str, Any]:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file (VideoPose3D's {key} .npz)")
    stat = path.stat()
    return _load_npz_dict(str(path), key, (stat.st_mtime_ns, stat.st_size, stat.st_ino))


def _entry(data: dict[str, Any], path: Path, subject: str, action: str) -> Any:
    if subject not in data:
        raise ValueError(f"{path}: no subject {subject!r}; it has {sorted(data)}")
    if action not in data[subject]:
        raise ValueError(f"{path}: no action {action!r} for {subject}; it has {sorted(data[subject])}")
    return data[subject][action]


def list_h36m_actions(
    root: str | os.PathLike, subject: str, *, positions_3d: str | os.PathLike | None = None
) -> list[str]:
    """Sorted action names of ``subject`` in data_3d_h36m.npz."""
    path = Path(positions_3d) if positions_3d is not None else Path(root) / "data_3d_h36m.npz"
    data = _npz(path, "positions_3d")
    if subject not in data:
        raise ValueError(f"{path}: no subject {subject!r}; it has {sorted(data)}")
    return sorted(data[subject])


def _frame_source(root: Path, subject: str, action: str, camera: str, video: str | os.PathLike | None) -> Path:
    if video is not None:
        return Path(video)
    default = root / subject / "Videos" / f"{action}.{camera}.mp4"
    if default.exists():
        return default
    folder = default.with_suffix("")
    if folder.is_dir():
        return folder
    raise FileNotFoundError(
        f"no frames for {subject} {action!r} camera {camera}: neither {default} nor {folder} exists"
    )


def _read_frames(source: Path, indices: list[int], size: Size | None) -> tuple[torch.Tensor, tuple[int, int]]:
    """Frames ``indices`` from a video file or a folder of images (sorted by name)."""
    if not source.is_dir():
        return read_video_frames(source, indices, size)
    files = sorted(p for p in source.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if len(files) <= indices[-1]:
        raise DatasetFormatError(f"{source}: holds {len(files)} images, but frame {indices[-1]} is needed")
    return read_images([files[i] for i in indices], size)


def read_h36m(
    root: str | os.PathLike,
    subject: str,
    action: str,
    *,
    camera: str = H36M_EVAL_CAMERA,
    camera_params: H36MCamera | None = None,
    video: str | os.PathLike | None = None,
    positions_3d: str | os.PathLike | None = None,
    positions_2d: str | os.PathLike | None = None,
    first: int | None = None,
    last: int | None = None,
    stride: int = H36M_EVAL_STRIDE,
    max_frames: int | None = None,
    size: Size | None = None,
    joints_layout: str = "lsp14",
) -> Scene:
    """Read one action of one subject from one camera as a :class:`Scene` (50 / stride fps).

    Frames ``first``, ``first + stride``, ... ``last`` (0-based, inclusive; default all), at
    most ``max_frames``; the paper's preset is stride 5 (:data:`H36M_EVAL_STRIDE`), subjects
    :data:`H36M_EVAL_SUBJECTS`, camera :data:`H36M_EVAL_CAMERA`. ``camera_params`` defaults to
    the built-in :data:`H36M_CAMERAS`; ``video`` (file or image folder), ``positions_3d`` and
    ``positions_2d`` override the default paths under ``root``. GroundTruth: joints3d (T, J, 3)
    mm camera frame and joints2d (T, J, 2) px in ``joints_layout`` ("lsp14", the paper's 14
    joints, default; or "h36m17"), cameras pinhole. ``size`` = (height, width) resizes
    frames, joints2d and cameras.

    Raises FileNotFoundError (missing file), ValueError (bad arguments, unknown subject /
    action / camera), :class:`DatasetFormatError` naming the file (unreadable npz or video,
    wrong shapes, 2D / 3D frame counts differing, too few video frames).
    """
    root = Path(root)
    if camera not in H36M_CAMERA_IDS:
        raise ValueError(f"camera: expected one of {H36M_CAMERA_IDS}, got {camera!r}")
    if camera_params is None:
        if (subject, camera) not in H36M_CAMERAS:
            raise ValueError(
                f"no built-in calibration for {subject} camera {camera} (built in: {sorted(H36M_CAMERAS)}); "
                "pass camera_params"
            )
        camera_params = H36M_CAMERAS[subject, camera]
    path3 = Path(positions_3d) if positions_3d is not None else root / "data_3d_h36m.npz"
    path2 = Path(positions_2d) if positions_2d is not None else root / "data_2d_h36m_gt.npz"
    world = check_shape(_entry(_npz(path3, "positions_3d"), path3, subject, action), (None, 32, 3), path3,
                        f"positions_3d[{subject!r}][{action!r}]")  # fmt: skip
    views = _entry(_npz(path2, "positions_2d"), path2, subject, action)
    if len(views) != len(H36M_CAMERA_IDS):
        raise DatasetFormatError(f"{path2}: {subject} {action!r} has {len(views)} cameras, expected {H36M_CAMERA_IDS}")
    where = f"positions_2d[{subject!r}][{action!r}][{H36M_CAMERA_IDS.index(camera)}]"
    pixels = check_shape(views[H36M_CAMERA_IDS.index(camera)], (None, 17, 2), path2, where)
    if len(pixels) != len(world):
        raise DatasetFormatError(f"{path2}: {where} has {len(pixels)} frames, but {path3} has {len(world)}")
    indices = select_frames(range(len(world)), first, last, stride, max_frames, where=f"{path3} {subject} {action!r}")
    source = _frame_source(root, subject, action, camera, video)
    frames, native = _read_frames(source, indices, size)
    sx, sy = scale_factors(*native, size)

    cam = torch.from_numpy(camera_params.world_to_camera(world[indices][:, H36M_KEEP_JOINTS])).float()
    cameras = pinhole_cameras(camera_params.intrinsics(), len(indices))
    stored = torch.from_numpy(np.asarray(pixels[indices], dtype=np.float32))
    gap = float((cameras.project(cam) - stored).norm(dim=-1).mean())
    joints3d, _, _ = map_joints(cam, "h36m17", joints_layout)
    joints2d, _, _ = map_joints(scale_points(stored, sx, sy), "h36m17", joints_layout)
    cameras = pinhole_cameras(camera_params.intrinsics(), len(indices), sx, sy)
    gt = GroundTruth(joints3d=joints3d, joints2d=joints2d, joints_layout=joints_layout, cameras=cameras)
    metadata = {"dataset": "human3.6m", "subject": subject, "action": action, "camera": camera,
                "frames": indices, "pinhole_error_px": gap}  # fmt: skip
    name = f"h36m_{subject}_{action.replace(' ', '_')}_{camera}"
    return make_scene(path3, frames=frames, fps=H36M_FPS / stride, name=name, gt=gt, metadata=metadata)
