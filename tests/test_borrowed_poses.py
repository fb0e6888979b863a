"""A borrowed pose (lit_boot.estimate.borrowed_poses): where two people's boxes overlap, a pose on
one's track whose look is the other's is dropped; frames painted in known colours."""

import pytest
import torch

from lit_boot.estimate.borrowed_poses import borrowed_frames
from lit_boot.estimate.people_track import MAX_LOOK
from test_looks import BLUE, RED, pose_at

GREEN = (20, 230, 20)
T, H, W = 4, 60, 120


def painted(regions) -> torch.Tensor:
    """(T, 3, H, W) uint8, grey but for ``regions``: (t, x0, x1, colour) columns painted."""
    frames = torch.full((T, 3, H, W), 128, dtype=torch.uint8)
    for t, x0, x1, colour in regions:
        frames[t, :, :, x0:x1] = torch.tensor(colour, dtype=torch.uint8)[:, None, None]
    return frames


def pose(xs: list[float]) -> tuple[torch.Tensor, torch.Tensor]:
    """One person's keypoints (T, 6, 2) at x = xs[t] (test_looks' vertical line of 6 joints) and confidence (T, 6)."""
    kp = torch.stack([pose_at(x, 10.0) for x in xs])
    return kp[..., :2].clone(), kp[..., 2].clone()


def boxes(xs: list[float]) -> torch.Tensor:
    """(T, 5) a 20 px wide box centred at x = xs[t]."""
    return torch.tensor([[x - 10, 5.0, x + 10, 50.0, 0.9] for x in xs])


def test_a_pose_that_looks_like_the_overlapping_person_is_borrowed():
    """A (red) and B (blue) stand apart in frames 0-1; in frames 2-3 their boxes overlap. B's crop
    gives A's pose (on red) in frame 2 and its own (on blue) in frame 3."""
    a_x, b_x = [20.0, 20.0, 50.0, 50.0], [90.0, 90.0, 60.0, 60.0]
    frames = painted([(t, 10, 30, RED) for t in (0, 1)] + [(t, 80, 100, BLUE) for t in (0, 1)]
                     + [(t, 45, 55, RED) for t in (2, 3)] + [(3, 58, 70, BLUE)])  # fmt: skip
    (a_kp, a_conf), (b_kp, b_conf) = pose(a_x), pose(b_x)
    b_kp[2] = a_kp[2]  # B's crop shows A
    b_kp[3, :, 0] = 64.0
    out = borrowed_frames(frames, [a_kp, b_kp], [a_conf, b_conf], [boxes(a_x), boxes(b_x)], MAX_LOOK)
    assert out[0].tolist() == [False] * 4  # A's own pose everywhere
    assert out[1].tolist() == [False, False, True, False]


def test_nothing_is_borrowed_without_an_overlap_or_with_one_person():
    a_x, b_x = [20.0] * T, [90.0] * T
    frames = painted([(t, 10, 30, RED) for t in range(T)])
    (a_kp, a_conf), (b_kp, b_conf) = pose(a_x), pose(b_x)
    b_kp[:] = a_kp  # a red pose on B's track, but B's box is far from A's: not A's crop's business
    out = borrowed_frames(frames, [a_kp, b_kp], [a_conf, b_conf], [boxes(a_x), boxes(b_x)], MAX_LOOK)
    assert not any(bool(o.any()) for o in out)
    assert not bool(borrowed_frames(frames, [a_kp], [a_conf], [boxes(a_x)], MAX_LOOK)[0].any())


def test_a_person_never_seen_clear_keeps_a_pose_in_its_own_colours_only():
    """A (red) stands alone in frame 0; B overlaps A in frames 1-3 and is never seen clear (no own
    look): its pose is kept in a colour of its own (green, frame 1), borrowed where it is A's (red,
    frame 2), and nothing is said where it has no confident joints (frame 3)."""
    frames = painted([(t, 10, 25, RED) for t in range(T)] + [(1, 26, 40, GREEN)])
    (a_kp, a_conf), (b_kp, b_conf) = pose([15.0] * T), pose([0.0, 33.0, 20.0, 20.0])
    a_box, b_box = boxes([20.0] * T), boxes([28.0] * T)
    b_box[0, 4], b_conf[0], b_conf[3] = 0.0, 0.0, 0.0  # B absent in frame 0
    out = borrowed_frames(frames, [a_kp, b_kp], [a_conf, b_conf], [a_box, b_box], MAX_LOOK)
    assert out[0].tolist() == [False] * 4
    assert out[1].tolist() == [False, False, True, False]


def test_frames_other_than_uint8_rgb_are_refused_by_name():
    (kp, conf), box = pose([20.0] * T), boxes([20.0] * T)
    with pytest.raises(ValueError, match="uint8 RGB"):
        borrowed_frames(painted([]).float() / 255, [kp, kp], [conf, conf], [box, box])
