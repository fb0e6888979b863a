"""read_video: folders of frames and video files, with and without pose estimates."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from lit_boot.data.readers import DatasetFormatError, PoseEstimates, read_video, save_poses
from lit_boot.data.readers.video import output_size, video_frame_count


def _frames(T: int, H: int = 24, W: int = 32) -> np.ndarray:
    """T distinct BGR frames (smooth, so that the video codec keeps them recognisable)."""
    y, x = np.mgrid[0:H, 0:W]
    frames = [np.stack([(x * 8 + 40 * t) % 256, y * 10, np.full_like(x, 30 * t)], -1) for t in range(T)]
    return np.stack(frames).astype(np.uint8)


@pytest.fixture
def folder(tmp_path):
    path = tmp_path / "frames"
    path.mkdir()
    for t, image in enumerate(_frames(5)):
        cv2.imwrite(str(path / f"img_{t + 8}.png"), image)  # img_8 .. img_12: natural order
    return path


@pytest.fixture
def mp4(tmp_path):
    path = tmp_path / "clip.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (32, 24))
    for image in _frames(6):
        writer.write(image)
    writer.release()
    return path


@pytest.fixture
def decoded(monkeypatch):
    """A list that gets one item per video frame OpenCV decodes (retrieves) from now on."""
    retrieved = []
    real = cv2.VideoCapture

    class Counting:
        def __init__(self, *args):
            self.capture = real(*args)

        def retrieve(self, *args):
            retrieved.append(1)
            return self.capture.retrieve(*args)

        def __getattr__(self, name):
            return getattr(self.capture, name)

    monkeypatch.setattr(cv2, "VideoCapture", Counting)
    return retrieved


def _poses(T: int, conf: float = 0.8, **kw) -> PoseEstimates:
    keypoints = torch.arange(T, dtype=torch.float32)[:, None, None] + torch.zeros(T, 17, 2)
    return PoseEstimates(keypoints2d=keypoints, keypoints_conf=torch.full((T, 17), conf), **kw)


def test_output_size():
    assert output_size((720, 1280), None) is None
    assert output_size((720, 1280), 360) == (360, 640)
    assert output_size((540, 960), 0.5) == (270, 480)
    assert output_size((540, 960), (100, 200)) == (100, 200)
    with pytest.raises(ValueError, match="resize"):
        output_size((540, 960), "big")


def test_folder_of_frames(folder):
    scene = read_video(folder, stride=2, fps=12.0)
    assert scene.num_frames == 3 and scene.fps == 6.0 and scene.metadata["frame_indices"] == [0, 2, 4]
    assert scene.metadata["files"] == ["img_8.png", "img_10.png", "img_12.png"]
    want = cv2.cvtColor(cv2.imread(str(folder / "img_10.png")), cv2.COLOR_BGR2RGB)
    assert torch.equal(scene.frames[1], torch.from_numpy(want).permute(2, 0, 1))
    small = read_video(folder, max_frames=2, resize=12)
    assert small.frames.shape == (2, 3, 12, 16) and small.fps == 30.0


def test_video_file_with_poses(mp4, tmp_path):
    scene = read_video(mp4)
    assert scene.num_frames == 6 and scene.fps == 10.0 and (scene.height, scene.width) == (24, 32)
    capture = cv2.VideoCapture(str(mp4))
    first = cv2.cvtColor(capture.read()[1], cv2.COLOR_BGR2RGB)
    capture.release()
    assert torch.equal(scene.frames[0], torch.from_numpy(first).permute(2, 0, 1))
    save_poses(_poses(6), tmp_path / "poses.json")
    half = read_video(mp4, stride=2, resize=0.5, poses=tmp_path / "poses.json")
    assert half.frames.shape == (3, 3, 12, 16) and half.metadata["pose_estimates"][0]["frame_indices"] == [0, 2, 4]
    assert torch.allclose(half.keypoints2d[:, 0, 0], (torch.tensor([0.0, 2.0, 4.0]) + 0.5) * 0.5 - 0.5)
    # explicit frame_indices and image_size: rows matched by source frame, pixels rescaled from 64x48
    sparse = _poses(3, frame_indices=torch.tensor([0, 2, 4]), image_size=(48, 64))
    scene = read_video(mp4, stride=2, poses=sparse)
    assert torch.allclose(scene.keypoints2d[:, 0, 0], (torch.tensor([0.0, 1.0, 2.0]) + 0.5) * 0.5 - 0.5)
    with pytest.raises(DatasetFormatError, match=r"no pose estimates for video frames \[1, 3\]"):
        read_video(mp4, max_frames=4, poses=sparse)


@pytest.mark.parametrize("source", ["folder", "mp4"])
def test_first_skips_frames_without_decoding_them(source, folder, mp4, tmp_path, decoded):
    path = {"folder": folder, "mp4": mp4}[source]
    whole = read_video(path)
    part = read_video(path, first=2, max_frames=2)
    assert torch.equal(part.frames, whole.frames[2:4]) and part.metadata["frame_indices"] == [2, 3]
    strided = read_video(path, stride=2, first=1)  # source frames 1, 3, ...
    odd = list(range(1, whole.num_frames, 2))
    assert strided.metadata["frame_indices"] == odd and torch.equal(strided.frames, whole.frames[odd])
    with pytest.raises(ValueError, match="first=9 but the"):
        read_video(path, first=9)
    with pytest.raises(ValueError, match="first must be"):
        read_video(path, first=-1)
    if source == "mp4":  # with poses: the rows of the kept frames; the frames before are not decoded
        save_poses(_poses(6), tmp_path / "poses.npz")
        posed = read_video(path, first=3, poses=tmp_path / "poses.npz")
        assert torch.equal(posed.keypoints2d[:, 0, 0], torch.tensor([3.0, 4.0, 5.0]))
        decoded.clear()
        read_video(path, first=4)
        assert len(decoded) == 2  # frames 4 and 5 only


def test_frame_count_without_decoding(folder, mp4, tmp_path, decoded):
    for path in (folder, mp4):
        for options in ({}, {"stride": 2}, {"first": 1, "stride": 2}, {"max_frames": 2, "first": 3}, {"resize": 12}):
            assert video_frame_count(path, **options) == read_video(path, **options).num_frames, (path, options)
    decoded.clear()
    assert video_frame_count(mp4) == 6 and not decoded  # grabbed, never decoded
    (tmp_path / "junk.mp4").write_bytes(b"\x00" * 100)
    with pytest.raises(DatasetFormatError, match="junk.mp4"):
        video_frame_count(tmp_path / "junk.mp4")
    with pytest.raises(FileNotFoundError, match="missing.mp4"):
        video_frame_count(tmp_path / "missing.mp4")


def test_errors(tmp_path, folder, mp4):
    with pytest.raises(FileNotFoundError, match="missing.mp4"):
        read_video(tmp_path / "missing.mp4")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetFormatError, match="empty: no image frames"):
        read_video(tmp_path / "empty")
    (tmp_path / "junk.mp4").write_bytes(b"\x00" * 100)
    with pytest.raises(DatasetFormatError, match="junk.mp4"):
        read_video(tmp_path / "junk.mp4")
    (folder / "img_9.png").write_bytes(b"not a png")
    with pytest.raises(DatasetFormatError, match="img_9.png"):
        read_video(folder)
    save_poses(_poses(4), tmp_path / "short.npz")
    with pytest.raises(DatasetFormatError, match="short.npz: pose estimates for 4 frames.*video has 6 frames"):
        read_video(mp4, poses=tmp_path / "short.npz")
    save_poses(_poses(6, conf=0.0), tmp_path / "nobody.npz")
    with pytest.raises(DatasetFormatError, match="nobody.npz: nobody is ever found"):
        read_video(mp4, poses=tmp_path / "nobody.npz")
    with pytest.raises(ValueError, match="stride must be"):
        read_video(mp4, stride=0)


@pytest.mark.shared
def test_shared_football_frames(shared):
    folder = shared / "data" / "videos" / "football_720p_10f"
    scene = read_video(folder, stride=3)
    assert scene.frames.shape == (4, 3, 720, 1280) and scene.metadata["frame_indices"] == [0, 3, 6, 9]
    name = scene.metadata["files"][2]
    want = cv2.cvtColor(cv2.imread(str(folder / name)), cv2.COLOR_BGR2RGB)
    assert torch.equal(scene.frames[2], torch.from_numpy(want).permute(2, 0, 1))
    small = read_video(folder, stride=2, max_frames=2, resize=360)
    assert small.frames.shape == (2, 3, 360, 640) and small.fps == 15.0
    area = cv2.resize(want, (640, 360), interpolation=cv2.INTER_AREA)
    assert torch.equal(read_video(folder, stride=6, resize=360).frames[1], torch.from_numpy(area).permute(2, 0, 1))


@pytest.mark.shared
def test_shared_street_mp4(shared):
    path = shared / "data" / "videos" / "street_540p_5f.mp4"
    scene = read_video(path)
    assert scene.frames.shape == (5, 3, 540, 960)
    capture = cv2.VideoCapture(str(path))
    decoded = [cv2.cvtColor(capture.read()[1], cv2.COLOR_BGR2RGB) for _ in range(5)]
    capture.release()
    assert torch.equal(scene.frames[4], torch.from_numpy(decoded[4]).permute(2, 0, 1))
    half = read_video(path, stride=2, resize=(270, 480), poses=_poses(5))
    assert half.frames.shape == (3, 3, 270, 480) and half.metadata["frame_indices"] == [0, 2, 4]
    assert torch.allclose(half.keypoints2d[:, 0, 0], (torch.tensor([0.0, 2.0, 4.0]) + 0.5) * 0.5 - 0.5)


def test_apply_to_uses_native_size(mp4, tmp_path):
    """Estimates without image_size attached after reading (as ``lit-boot import`` does)."""
    scene = read_video(mp4, stride=2, resize=0.5)
    direct = read_video(mp4, stride=2, resize=0.5, poses=_poses(6))
    assert torch.equal(_poses(6).apply_to(scene).keypoints2d, direct.keypoints2d)
