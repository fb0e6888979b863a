"""MediaPipe on the person detector's crops (lit_boot.estimate.crop_pose): the crop's geometry and
its way back to frame pixels against a known point (no MediaPipe needed), and, with the real
models, a player shrunk onto a large gray canvas: MediaPipe on the whole frame misses him, the
crop finds him where the full-size frame put him."""

from __future__ import annotations

from contextlib import nullcontext
from types import SimpleNamespace

import pytest
import torch
import torch.nn.functional as F

from lit_boot.estimate.crop_pose import CROP_ATTEMPTS, crop_landmarks, crop_window, follow_landmarks
from test_estimate_mediapipe import VIDEO, needs_mediapipe


class BrightestPoint:
    """A stand-in for MediaPipe's Pose: every landmark at the crop's brightest pixel (normalised
    image coordinates, as MediaPipe gives them); nobody for the first ``misses`` calls."""

    def __init__(self, misses: int = 0) -> None:
        self.misses, self.sizes = misses, []

    def process(self, image):
        self.sizes.append(image.shape[:2])
        if self.misses > 0:
            self.misses -= 1
            return SimpleNamespace(pose_landmarks=None, pose_world_landmarks=None)
        gray = torch.from_numpy(image).float().sum(-1)
        y, x = divmod(int(gray.argmax()), gray.shape[1])
        h, w = gray.shape
        lm = SimpleNamespace(x=(x + 0.5) / w, y=(y + 0.5) / h, z=0.0, visibility=0.9, presence=1.0,
                             HasField=lambda name: True)  # fmt: skip
        return SimpleNamespace(pose_landmarks=SimpleNamespace(landmark=[lm] * 33),
                               pose_world_landmarks=SimpleNamespace(landmark=[lm] * 33))  # fmt: skip


def test_crop_window_is_a_square_about_the_box_with_the_margin():
    cx, cy, side = crop_window(torch.tensor([10.0, 20.0, 30.0, 60.0, 0.9]), margin=0.25)
    assert (cx, cy) == (20.0, 40.0) and side == pytest.approx(40.0 * 1.5)


def test_a_landmark_in_the_crop_comes_back_to_its_frame_pixel():
    frames = torch.zeros(3, 3, 90, 160, dtype=torch.uint8)
    points = [(37, 51), (120, 30), (5, 80)]  # (x, y) of each frame's bright pixel
    for t, (x, y) in enumerate(points):
        frames[t, :, y, x] = 255
    boxes = torch.tensor([[30.0, 40.0, 45.0, 70.0, 0.8], [100.0, 10.0, 140.0, 50.0, 0.7], [0.0, 60.0, 12.0, 89.0, 0.9]])
    todo = torch.tensor([True, True, False])  # the last frame was found already: left alone
    pose = BrightestPoint()
    out = crop_landmarks(pose, frames, boxes, todo, attempts=((0.25, 384),))
    assert out["found"].tolist() == [True, True, False] and out["attempt"].tolist() == [0, 0, -1]
    for t in range(2):  # the crop upsamples 384 / side: back in frame px within a crop pixel
        side = crop_window(boxes[t], 0.25)[2]
        err = (out["landmarks"][t, 0] - torch.tensor(points[t], dtype=torch.float)).abs().max()
        assert err <= side / 384 + 0.05, (t, out["landmarks"][t, 0], points[t])
    assert pose.sizes == [(384, 384), (384, 384)] and (out["landmarks"][2] == 0).all()


def test_framings_are_tried_in_turn_until_one_finds_somebody_and_a_frame_without_a_box_is_skipped():
    frames = torch.zeros(2, 3, 40, 40, dtype=torch.uint8)
    boxes = torch.tensor([[5.0, 5.0, 20.0, 30.0, 0.9], [0.0, 0.0, 0.0, 0.0, 0.0]])  # frame 1: nobody
    pose = BrightestPoint(misses=2)
    out = crop_landmarks(pose, frames, boxes, torch.ones(2, dtype=torch.bool))
    assert out["attempt"].tolist() == [2, -1] and out["found"].tolist() == [True, False]
    assert pose.sizes == [(s, s) for _, s in CROP_ATTEMPTS[:3]]
    assert out["visibility"][0].eq(0.9).all() and out["seconds"][1] == 0


@pytest.mark.shared
@pytest.mark.mediapipe
@needs_mediapipe
def test_a_small_player_missed_on_the_whole_frame_is_found_on_the_detectors_crop(shared):
    from lit_boot.data.readers.video import read_video
    from lit_boot.estimate import estimate_poses

    frames = read_video(shared / VIDEO, max_frames=2).frames  # 1280x720: MediaPipe finds the player
    full = estimate_poses(frames)
    assert full.found().all()
    canvas = torch.full_like(frames, 128)  # the frames at a quarter of their size, on a gray canvas
    oy, ox = 300, 600
    canvas[:, :, oy : oy + 180, ox : ox + 320] = F.interpolate(frames.float(), scale_factor=0.25, mode="area").round().byte()
    expected = (full.keypoints2d + 0.5) * 0.25 - 0.5 + torch.tensor([ox, oy])  # where the player now is
    detector = shared / "checkpoints/yolox_nano.onnx"
    plain = estimate_poses(canvas, detector=detector)
    assert not plain.found().any()  # MediaPipe alone misses the small player ...
    assert (plain.person_boxes[:, 4] > 0).all()  # ... which the person detector finds
    est = estimate_poses(canvas, detector=detector, crops=True)
    assert est.found().all() and est.metadata["crop_found"] == 2 and est.metadata["crop_frames"] == [0, 1]
    sure = (full.keypoints_conf > 0.5) & (est.keypoints_conf > 0.5)
    err = (est.keypoints2d - expected).norm(dim=-1)[sure]
    assert sure.sum() >= 16 and err.median() < 4.0, (sure.sum(), err.median())  # the player is ~70 px tall


class Made:
    """``make_pose`` for :func:`follow_landmarks`: a new stand-in Pose (a context manager) each call, counted."""

    def __init__(self, kind=BrightestPoint) -> None:
        self.kind, self.made = kind, []

    def __call__(self):
        pose = self.kind()
        self.made.append(pose)
        return nullcontext(pose)


def test_a_followed_person_has_one_crop_side_and_a_new_pose_after_frames_without_a_box():
    frames = torch.zeros(5, 3, 90, 160, dtype=torch.uint8)
    points = [(37, 51), (40, 50), (0, 0), (60, 45), (64, 44)]
    for t, (x, y) in enumerate(points):
        frames[t, :, y, x] = 255 if t != 2 else 0
    boxes = torch.tensor([[25.0, 30.0, 45.0, 70.0, 0.9], [28.0, 30.0, 50.0, 72.0, 0.9], [0.0, 0.0, 0.0, 0.0, 0.0],
                          [50.0, 25.0, 70.0, 64.0, 0.8], [54.0, 24.0, 76.0, 66.0, 0.9]])  # fmt: skip
    made = Made()
    out = follow_landmarks(made, frames, boxes)
    assert out["found"].tolist() == [True, True, False, True, True]
    assert len(made.made) == 2 and [len(p.sizes) for p in made.made] == [2, 2]  # a new Pose after the gap
    side = 40.0 * 1.5  # the boxes' median larger side (40 px), 0.25 of it on both sides
    for t in (0, 1, 3, 4):  # centred on each box, one side: the bright pixel comes back within a crop pixel
        err = (out["landmarks"][t, 0] - torch.tensor(points[t], dtype=torch.float)).abs().max()
        assert err <= side / 384 + 0.05, (t, out["landmarks"][t, 0], points[t])
    assert all(size == (384, 384) for p in made.made for size in p.sizes)
