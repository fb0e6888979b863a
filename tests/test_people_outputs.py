"""The overlay and the report draw every person: the others in their tracks' colours."""

from __future__ import annotations

import torch

from lit_boot.bootstrap.overlay import OTHER_RGB, draw_poses, other_people, overlay_frames
from lit_boot.core import Person, Scene

T, H, W = 3, 48, 96


def standing(cx: float) -> torch.Tensor:
    y = torch.tensor([-18, -19, -19, -18, -18, -10, -10, -2, -2, 5, 5, 2, 2, 10, 10, 18, 18.0])
    x = torch.tensor([0, -1, 1, -2, 2, -5, 5, -7, 7, -8, 8, -3, 3, -3, 3, -3, 3.0])
    return torch.stack([x + cx, y + 24], -1).expand(T, 17, 2).clone()


def scene() -> Scene:
    conf = torch.ones(T, 17)
    gone = conf.clone()
    gone[1] = 0  # the other person is not found in frame 1
    return Scene(torch.zeros(T, 3, H, W, dtype=torch.uint8), keypoints2d=standing(25), keypoints_conf=conf,
                 others=(Person(track_id=3, keypoints2d=standing(70), keypoints_conf=gone),))  # fmt: skip


def coloured(image: torch.Tensor, rgb: tuple[int, int, int]) -> torch.Tensor:
    return (image == torch.tensor(rgb, dtype=torch.uint8)[:, None, None]).all(0)


def test_the_other_people_are_drawn_in_their_colour_where_found():
    s = scene()
    others = other_people(s, "2d")
    assert len(others) == 1 and torch.isnan(others[0][1]).all() and not torch.isnan(others[0][0]).any()
    main = {"before": s.keypoints2d, "after": None}
    for t, found in ((0, True), (1, False)):
        image = draw_poses(s.frames[0], main, t, s.pose_layout("2d"), (1.0, 1.0), others)
        blue = coloured(image, OTHER_RGB[0])
        assert bool(blue.any()) == found
        if found:
            assert (blue.nonzero()[:, 1] >= 55).all()  # on the other person (x 62-78), not the main one
        assert coloured(image, (255, 0, 0))[:, :45].any()  # the main person in red


def test_the_overlay_draws_them_and_says_so_in_its_key():
    s = scene()
    flows = torch.zeros(T - 1, 2, H, W)
    plain = overlay_frames(s.frames, flows, flows, s.keypoints2d, s.keypoints2d, "coco17")
    with_others = overlay_frames(s.frames, flows, flows, s.keypoints2d, s.keypoints2d, "coco17",
                                 others=other_people(s, "2d"))  # fmt: skip
    assert with_others.shape[0] == plain.shape[0] and with_others.shape[-1] == plain.shape[-1]
    assert coloured(with_others[0], OTHER_RGB[0]).any() and not coloured(plain[0], OTHER_RGB[0]).any()
    key = slice(2 * H, None)  # the legend below the two rows of panels (H x W each, not scaled here)
    assert coloured(with_others[0][:, key], OTHER_RGB[0]).any() and not coloured(plain[0][:, key], OTHER_RGB[0]).any()
