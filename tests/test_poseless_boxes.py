"""A box without a pose beside a box with one is held out of tracking (lit_boot.estimate.poseless_boxes)."""

from __future__ import annotations

import torch

from lit_boot.estimate.poseless_boxes import HOLDS, OVERLAP, inside_share, poseless_beside_posed


def _pose(x: float, conf: float = 0.9) -> torch.Tensor:
    """(17, 3) keypoints in a column at x px, all with confidence ``conf``."""
    ys = torch.linspace(20.0, 100.0, 17)
    return torch.stack([torch.full((17,), x), ys, torch.full((17,), conf)], -1)


def test_inside_share_is_the_share_of_the_inner_box_inside():
    outer = torch.tensor([[0.0, 0.0, 10.0, 10.0]])
    inner = torch.tensor([[5.0, 0.0, 15.0, 10.0], [2.0, 2.0, 4.0, 4.0], [20.0, 0.0, 30.0, 10.0]])
    assert torch.allclose(inside_share(outer, inner), torch.tensor([[0.5, 1.0, 0.0]]))


def test_a_poseless_box_beside_a_posed_one_is_dropped_unless_it_holds_it():
    posed = [20.0, 10.0, 60.0, 110.0, 0.9]
    beside = [42.0, 10.0, 62.0, 110.0, 0.5]  # IoU 18 / 42 with the posed box, holds 45% of it
    holding = [18.0, 5.0, 100.0, 115.0, 0.6]  # a man beside whose box holds the posed one
    far = [150.0, 10.0, 190.0, 110.0, 0.8]
    dets = torch.tensor([posed, beside, holding, far])
    none = torch.zeros(17, 3)
    kps = torch.stack([_pose(40.0), none, _pose(40.0, conf=0.2), none])  # 0.2: below the confidence that counts
    frames = [dets, dets[[1, 3]], dets[[0, 3]], torch.zeros(0, 5)]
    keypoints = [kps, kps[[1, 3]], torch.stack([_pose(40.0), _pose(170.0)]), torch.zeros(0, 17, 3)]
    drop = poseless_beside_posed(frames, keypoints)
    assert [d.tolist() for d in drop] == [[False, True, False, False], [False, False], [False, False], []]
    # the overlap and the holding share decide: just below OVERLAP, or a box holding HOLDS of it, stays
    side = 80.0 * OVERLAP / (1 + OVERLAP) - 0.5  # two 40 px boxes overlapping this much: an IoU just below
    barely = torch.tensor([posed, [60.0 - side, 10.0, 100.0 - side, 110.0, 0.5]])
    assert not poseless_beside_posed([barely], [kps[[0, 1]]])[0].any()
    barely[1, [0, 2]] -= 1.0  # an IoU just above
    assert poseless_beside_posed([barely], [kps[[0, 1]]])[0].tolist() == [False, True]
    wide = 40.0 * HOLDS + 0.5  # the pose-less box holds a little more than HOLDS of the posed one
    holds = torch.tensor([posed, [60.0 - wide, 10.0, 62.0, 110.0, 0.5]])
    assert not poseless_beside_posed([holds], [kps[[0, 1]]])[0].any()
    holds[1, 0] += 1.0  # a little less than HOLDS
    assert poseless_beside_posed([holds], [kps[[0, 1]]])[0].tolist() == [False, True]
