"""Human3.6M reader (lit_boot.data.readers.h36m) on tiny VideoPose3D-style npz files with a
frame folder or a short mp4."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from lit_boot.core.joints import H36M_J17_TO_J14
from lit_boot.data.readers import (
    H36M_CAMERA_IDS,
    H36M_CAMERAS,
    H36M_EVAL_CAMERA,
    H36M_EVAL_STRIDE,
    H36M_EVAL_SUBJECTS,
    H36M_KEEP_JOINTS,
    DatasetFormatError,
    H36MCamera,
    list_h36m_actions,
    read_h36m,
)
from lit_boot.data.visualize import write_png

N, H, W = 12, 16, 24
CAM = H36M_CAMERAS["S9", "60457274"]
# World -> camera rotation of S9 / 60457274 as published elsewhere (a matrix, not the quaternion).
S9_ROTATION = [[0.9154607080837831, -0.39734606500700814, 0.06362229623477154],
               [-0.049406284684695274, -0.2678916756611978, -0.9621814117644814],
               [0.3993628813352506, 0.877695935238897, -0.26487569589663096]]  # fmt: skip


def _project(points: np.ndarray) -> np.ndarray:
    (fx, fy), (cx, cy) = CAM.focal_length, CAM.center
    return np.stack([fx * points[..., 0] / points[..., 2] + cx, fy * points[..., 1] / points[..., 2] + cy], -1)


def _write_dataset(root: Path, n3: int = N, n2: int = N, joints: int = 32) -> dict:
    """npz files for S9 'Walking 1' whose camera-frame joints are known, and a frame folder."""
    rng = np.random.default_rng(1)
    camera = rng.uniform(-400, 400, size=(n3, joints, 3)) + [0.0, 0.0, 4000.0]  # mm, in front
    rotation_c2w = CAM.rotation().T
    world = (camera @ rotation_c2w.T + np.asarray(CAM.translation)) / 1000.0  # metres
    pixels = _project(camera[:n2][:, list(H36M_KEEP_JOINTS)] if joints == 32 else camera[:n2, :17])
    views = [rng.normal(size=pixels.shape), rng.normal(size=pixels.shape), rng.normal(size=pixels.shape), pixels]
    np.savez(root / "data_3d_h36m.npz", positions_3d={"S9": {"Walking 1": world, "Eating": world[:2]}})
    np.savez(root / "data_2d_h36m_gt.npz", positions_2d={"S9": {"Walking 1": views}}, metadata={})
    folder = root / "S9" / "Videos" / "Walking 1.60457274"
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(N):
        write_png(folder / f"{i:06d}.png", torch.full((3, H, W), 20 * i, dtype=torch.uint8))
    return {"camera": camera, "pixels": pixels}


@pytest.fixture()
def h36m(tmp_path: Path) -> tuple[Path, dict]:
    return tmp_path, _write_dataset(tmp_path)


def test_presets_and_published_camera() -> None:
    assert H36M_EVAL_SUBJECTS == ("S9", "S11") and H36M_EVAL_CAMERA == "60457274" and H36M_EVAL_STRIDE == 5
    assert H36M_CAMERA_IDS.index(H36M_EVAL_CAMERA) == 3 and len(H36M_KEEP_JOINTS) == 17
    np.testing.assert_allclose(CAM.rotation(), S9_ROTATION, atol=1e-6)
    for cam in H36M_CAMERAS.values():
        r = cam.rotation()
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-6)
        assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-6)
        # the camera centre maps to the camera frame's origin; a point 1 m along +z is in front
        np.testing.assert_allclose(cam.world_to_camera(np.asarray(cam.translation) / 1000.0), 0.0, atol=1e-6)
        ahead = np.asarray(cam.translation) / 1000.0 + r[2]  # the optical axis in world, 1 m
        np.testing.assert_allclose(cam.world_to_camera(ahead), [0.0, 0.0, 1000.0], atol=1e-6)


def test_paper_preset_reads_every_fifth_frame(h36m: tuple[Path, dict]) -> None:
    root, truth = h36m
    scene = read_h36m(root, "S9", "Walking 1", joints_layout="h36m17")
    assert scene.metadata["frames"] == [0, 5, 10] and scene.fps == 10.0
    assert scene.name == "h36m_S9_Walking_1_60457274" and (scene.height, scene.width) == (H, W)
    assert [int(f[0, 0, 0]) for f in scene.frames] == [0, 100, 200]
    gt = scene.gt
    assert gt.joints_layout == "h36m17"
    keep = list(H36M_KEEP_JOINTS)
    torch.testing.assert_close(gt.joints3d.double(), torch.from_numpy(truth["camera"][[0, 5, 10]][:, keep]),
                               rtol=0, atol=1e-2)  # fmt: skip
    torch.testing.assert_close(gt.joints2d.double(), torch.from_numpy(truth["pixels"][[0, 5, 10]]), rtol=0, atol=1e-3)
    # the known 3D points project with the built-in pinhole to the stored 2D points
    torch.testing.assert_close(gt.cameras.project(gt.joints3d), gt.joints2d, rtol=0, atol=1e-2)
    assert scene.metadata["pinhole_error_px"] < 1e-2


def test_lsp14_default_range_and_resize(h36m: tuple[Path, dict]) -> None:
    root, _ = h36m
    full = read_h36m(root, "S9", "Walking 1", stride=1, joints_layout="h36m17")
    lsp = read_h36m(root, "S9", "Walking 1", stride=1)
    assert lsp.gt.joints_layout == "lsp14" and full.num_frames == N and full.fps == 50.0
    torch.testing.assert_close(lsp.gt.joints3d, full.gt.joints3d[:, list(H36M_J17_TO_J14)])
    part = read_h36m(root, "S9", "Walking 1", first=3, last=9, stride=2, max_frames=3)
    assert part.metadata["frames"] == [3, 5, 7] and [int(f[0, 0, 0]) for f in part.frames] == [60, 100, 140]
    small = read_h36m(root, "S9", "Walking 1", size=(8, 12))
    native = read_h36m(root, "S9", "Walking 1")
    assert small.frames.shape == (3, 3, 8, 12)
    torch.testing.assert_close(small.gt.joints2d, (native.gt.joints2d + 0.5) * 0.5 - 0.5)
    torch.testing.assert_close(small.gt.cameras.project(small.gt.joints3d), small.gt.joints2d, rtol=0, atol=1e-2)
    assert list_h36m_actions(root, "S9") == ["Eating", "Walking 1"]


def test_mp4_video_and_explicit_paths(h36m: tuple[Path, dict], tmp_path: Path) -> None:
    root, _ = h36m
    video = tmp_path / "clip.mp4"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 50.0, (48, 32))
    if not writer.isOpened():
        pytest.skip("OpenCV cannot write mp4 here")
    for i in range(N):
        writer.write(np.full((32, 48, 3), 20 * i, dtype=np.uint8))
    writer.release()
    custom = H36MCamera(CAM.orientation, CAM.translation, CAM.focal_length, CAM.center)
    files = {"positions_3d": root / "data_3d_h36m.npz", "positions_2d": root / "data_2d_h36m_gt.npz"}
    scene = read_h36m(tmp_path / "elsewhere", "S9", "Walking 1", video=video, camera_params=custom, **files)
    assert scene.frames.shape == (3, 3, 32, 48)
    assert [round(float(f.float().mean()) / 20) for f in scene.frames] == [0, 5, 10]
    with pytest.raises(DatasetFormatError, match=r"clip.mp4: the video ends after 12 frames, but frame 15"):
        read_h36m(_longer(tmp_path), "S9", "Walking 1", video=video, first=5, last=15, stride=10)


def _longer(tmp_path: Path) -> Path:
    """A root whose npz files annotate 16 frames (more than the 12-frame video)."""
    other = tmp_path / "longer"
    other.mkdir()
    _write_dataset(other, n3=16, n2=16)
    return other


def test_missing_and_unknown(h36m: tuple[Path, dict], tmp_path: Path) -> None:
    root, _ = h36m
    with pytest.raises(ValueError, match=r"no subject 'S11'; it has \['S9'\]"):
        read_h36m(root, "S11", "Walking 1")
    with pytest.raises(ValueError, match=r"no action 'Walking' for S9; it has \['Eating', 'Walking 1'\]"):
        read_h36m(root, "S9", "Walking")
    with pytest.raises(ValueError, match="pass camera_params"):
        read_h36m(root, "S1", "Walking 1")
    with pytest.raises(ValueError, match="camera"):
        read_h36m(root, "S9", "Walking 1", camera="123")
    with pytest.raises(FileNotFoundError, match=r"data_3d_h36m.npz"):
        read_h36m(tmp_path / "empty", "S9", "Walking 1")
    with pytest.raises(FileNotFoundError, match=r"neither .*Eating.60457274.mp4"):
        read_h36m(root, "S9", "Eating", positions_2d=_two_frame_2d(root, tmp_path))


def _two_frame_2d(root: Path, tmp_path: Path) -> Path:
    path = tmp_path / "eating_2d.npz"
    pixels = np.zeros((2, 17, 2))
    np.savez(path, positions_2d={"S9": {"Eating": [pixels] * 4}})
    return path


def test_malformed_files_name_the_file(tmp_path: Path) -> None:
    _write_dataset(tmp_path, joints=31)
    where = r"positions_3d\['S9'\]\['Walking 1'\]"
    message = rf"data_3d_h36m.npz: {where}: expected shape \(\*, 32, 3\), got \(12, 31, 3"
    with pytest.raises(DatasetFormatError, match=message):
        read_h36m(tmp_path, "S9", "Walking 1")
    _write_dataset(tmp_path, n2=11)
    where = r"positions_2d\['S9'\]\['Walking 1'\]\[3\]"
    message = rf"data_2d_h36m_gt.npz: {where} has 11 frames, but .*data_3d_h36m.npz has 12"
    with pytest.raises(DatasetFormatError, match=message):
        read_h36m(tmp_path, "S9", "Walking 1")
    np.savez(tmp_path / "data_2d_h36m_gt.npz", wrong_key=np.zeros(3))
    with pytest.raises(DatasetFormatError, match=r"data_2d_h36m_gt.npz: no 'positions_2d' array"):
        read_h36m(tmp_path, "S9", "Walking 1")
    (tmp_path / "data_2d_h36m_gt.npz").write_bytes(b"garbage")
    with pytest.raises(DatasetFormatError, match=r"data_2d_h36m_gt.npz: unreadable .npz"):
        read_h36m(tmp_path, "S9", "Walking 1")


def test_frame_folder_too_short_or_unreadable(h36m: tuple[Path, dict]) -> None:
    root, _ = h36m
    folder = root / "S9" / "Videos" / "Walking 1.60457274"
    (folder / "000005.png").write_bytes(b"not a png")
    with pytest.raises(DatasetFormatError, match=r"000005.png: unreadable image"):
        read_h36m(root, "S9", "Walking 1")
    for i in range(6, N):
        (folder / f"{i:06d}.png").unlink()
    with pytest.raises(DatasetFormatError, match=r"Walking 1.60457274: holds 6 images, but frame 10 is needed"):
        read_h36m(root, "S9", "Walking 1")
    (root / "bad.mp4").write_bytes(b"not a video")
    with pytest.raises(DatasetFormatError, match=r"bad.mp4: unreadable video"):
        read_h36m(root, "S9", "Walking 1", video=root / "bad.mp4")
