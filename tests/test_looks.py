"""Looks (lit_boot.estimate.looks) and a person found again by its look after a long gap (track_people(looks=...))."""

import pytest
import torch

from lit_boot.estimate.looks import LOOK_BINS, detection_looks, joint_look, look_distance
from lit_boot.estimate.people_track import track_people

RED, BLUE = (230, 20, 20), (20, 20, 230)


def two_colour_frame(h: int = 40, w: int = 80) -> torch.Tensor:
    """(3, h, w) uint8: red on the left half, blue on the right."""
    frame = torch.zeros(3, h, w, dtype=torch.uint8)
    frame[:, :, : w // 2] = torch.tensor(RED, dtype=torch.uint8)[:, None, None]
    frame[:, :, w // 2 :] = torch.tensor(BLUE, dtype=torch.uint8)[:, None, None]
    return frame


def pose_at(x: float, y: float, conf: float = 0.9, joints: int = 6) -> torch.Tensor:
    """(joints, 3) keypoints in a small vertical line at x, y (px), all with confidence ``conf``."""
    return torch.tensor([[x, y + 2.0 * k, conf] for k in range(joints)])


def colour_bin(rgb: tuple[int, int, int]) -> int:
    r, g, b = (c * LOOK_BINS // 256 for c in rgb)
    return (r * LOOK_BINS + g) * LOOK_BINS + b


def test_a_look_is_the_colours_near_the_joints_and_looks_compare_by_hellinger():
    frame = two_colour_frame()
    left, right = joint_look(frame, pose_at(10, 10), side=30), joint_look(frame, pose_at(60, 10), side=30)
    assert left.shape == (LOOK_BINS**3,) and float(left.sum()) == pytest.approx(1.0)
    assert float(left[colour_bin(RED)]) == pytest.approx(1.0)  # only the left half's pixels
    assert float(right[colour_bin(BLUE)]) == pytest.approx(1.0)
    assert float(look_distance(left, left)) == pytest.approx(0.0, abs=1e-6)
    assert float(look_distance(left, right)) == pytest.approx(1.0)
    # joints on the border: half red, half blue, halfway between in Bhattacharyya terms
    middle = joint_look(frame, pose_at(39.5, 10), side=30)
    assert float(middle[colour_bin(RED)]) == pytest.approx(0.5, abs=0.1)
    assert 0.3 < float(look_distance(middle, left)) < 0.8


def test_no_look_without_enough_confident_joints_or_pixels():
    frame = two_colour_frame()
    assert float(joint_look(frame, pose_at(10, 10, joints=3), side=30).sum()) == 0  # three joints
    assert float(joint_look(frame, pose_at(10, 10, conf=0.1), side=30).sum()) == 0  # none confident
    assert float(joint_look(frame, pose_at(500, 500), side=30).sum()) == 0  # outside the frame
    frames = torch.stack([frame, frame])
    dets = [torch.tensor([[0.0, 0, 30, 30, 0.9], [40, 0, 80, 30, 0.8]]), torch.zeros(0, 5)]
    kps = [torch.stack([pose_at(10, 10), pose_at(60, 10, conf=0.0)]), torch.zeros(0, 6, 3)]
    looks = detection_looks(frames, dets, kps)
    assert [tuple(x.shape) for x in looks] == [(2, LOOK_BINS**3), (0, LOOK_BINS**3)]
    assert float(looks[0][0, colour_bin(RED)]) == pytest.approx(1.0) and float(looks[0][1].sum()) == 0
    with pytest.raises(ValueError, match="uint8"):
        detection_looks(frames.float() / 255, dets, kps)  # colours in [0, 1] would all fall in one bin


def hidden_for_long(T: int = 16, hidden: range = range(4, 12), back_at: float = 0.0):
    """Person A walks right (8 px a frame), unseen in frames ``hidden`` (longer than max_gap),
    found again where its motion takes it (+ ``back_at`` px); person B stands still far below.
    Returns the detections and each one's owner (0: A, 1: B)."""
    dets, owners = [], []
    for t in range(T):
        rows, who = [[190.0, 150, 210, 190, 0.8]], [1]
        if t not in hidden:
            x = 20 + 8 * t + (back_at if t >= hidden.stop else 0)
            rows, who = [[x - 10, 20, x + 10, 60, 0.9]] + rows, [0] + who
        dets.append(torch.tensor(rows))
        owners.append(who)
    return dets, owners


def looks_for(owners: list[list[int]], per_owner: list[torch.Tensor], hidden: range, back: torch.Tensor | None = None):
    """Each detection's look: its owner's, or ``back`` for A's detections after ``hidden``."""
    return [torch.stack([back if (back is not None and o == 0 and t >= hidden.stop) else per_owner[o] for o in who])
            for t, who in enumerate(owners)]  # fmt: skip


def one_hot(i: int) -> torch.Tensor:
    return torch.nn.functional.one_hot(torch.tensor(i), LOOK_BINS**3).float()


def test_a_person_hidden_for_long_is_found_again_by_its_look():
    hidden = range(4, 12)
    dets, owners = hidden_for_long(hidden=hidden)
    looks = looks_for(owners, [one_hot(0), one_hot(1)], hidden)
    assert track_people(dets).shape[0] == 3  # A's two stretches are two people without looks
    tracks = track_people(dets, looks=looks)
    assert tracks.shape[0] == 2
    a = tracks[(tracks[:, 0, 4] > 0.85).nonzero()[0, 0]]  # A's track (score 0.9)
    assert (a[:4, 4] > 0).all() and (a[12:, 4] > 0).all() and (a[4:12, 4] == 0).all()  # no box guessed in the gap


def test_another_look_or_a_place_its_motion_does_not_reach_is_someone_else():
    hidden = range(4, 12)
    dets, owners = hidden_for_long(hidden=hidden)
    other = 0.5 * one_hot(0) + 0.5 * one_hot(2)  # half the colours: Hellinger distance 0.54 > MAX_LOOK
    assert float(look_distance(one_hot(0), other)) > 0.4
    assert track_people(dets, looks=looks_for(owners, [one_hot(0), one_hot(1)], hidden, back=other)).shape[0] == 3
    assert track_people(dets, looks=looks_for(owners, [one_hot(0), one_hot(1)], hidden), max_look=0.0).shape[0] == 3
    far, owners = hidden_for_long(hidden=hidden, back_at=-200.0)  # back where it was, walking on
    assert track_people(far, looks=looks_for(owners, [one_hot(0), one_hot(1)], hidden)).shape[0] == 3


def test_a_stray_detection_is_not_someone_found_again():
    hidden = range(1, 12)  # A in frame 0 alone (a track of one frame: dropped), then from frame 12 on
    dets, owners = hidden_for_long(hidden=hidden)
    tracks = track_people(dets, looks=looks_for(owners, [one_hot(0), one_hot(1)], hidden))
    assert tracks.shape[0] == 2
    assert not bool((tracks[:, 0, 4] > 0.85).any())  # frame 0's box of A is nobody's
    assert int((tracks[:, 12:, 4] > 0.85).sum()) == 4  # A from frame 12 on


def test_looks_are_checked_against_the_detections():
    dets, owners = hidden_for_long()
    looks = looks_for(owners, [one_hot(0), one_hot(1)], range(4, 12))
    with pytest.raises(ValueError, match=r"looks\[2\]"):
        track_people(dets, looks=looks[:2] + [torch.zeros(1, LOOK_BINS**3)] + looks[3:])
    with pytest.raises(ValueError, match="one tensor per frame"):
        track_people(dets, looks=looks[:-1])
    with pytest.raises(ValueError, match="max_look"):
        track_people(dets, looks=looks, max_look=1.5)
