"""FlowTTT's loss (lit_boot.flow.losses.SketchLoss) on hand-made tensors: no RAFT is built."""

from __future__ import annotations

import pytest
import torch

from lit_boot.flow import SketchLoss


def test_below_beta_the_loss_is_quadratic_and_above_it_linear():
    loss = SketchLoss(beta=0.1)
    target, weight = torch.zeros(1, 2, 2, 2), torch.ones(1, 2, 2)
    small, large = torch.full_like(target, 0.05), torch.full_like(target, 2.0)
    assert loss([small], target, weight).item() == pytest.approx(0.5 * 0.05**2 / 0.1)  # 0.5 r^2 / beta
    assert loss([large], target, weight).item() == pytest.approx(2.0 - 0.05)  # r - beta / 2
    assert SketchLoss()([large], target, weight).item() == pytest.approx(2.0 - 0.5)  # beta 1: the authors'


def test_the_loss_is_the_weighted_mean_over_pixels_of_both_components():
    target = torch.zeros(1, 2, 1, 3)
    flow = torch.tensor([[[[2.0, 4.0, 6.0]], [[2.0, 2.0, 2.0]]]])  # per pixel: r - 1/2 of u and v, averaged
    per_pixel = torch.tensor([1.5, 2.5, 3.5])  # ((2 - .5) + (2 - .5)) / 2, ((4 - .5) + 1.5) / 2, ...
    weight = torch.tensor([[[1.0, 0.0, 3.0]]])
    expected = float((per_pixel * weight[0, 0]).sum() / weight.sum())  # (1.5 + 10.5) / 4 = 3.0
    assert SketchLoss()([flow], target, weight).item() == pytest.approx(expected) == pytest.approx(3.0)


def test_final_scores_the_last_flow_and_sequence_every_flow_weighted_by_gamma():
    target, weight = torch.zeros(1, 2, 2, 2), torch.ones(1, 2, 2)
    flows = [torch.full_like(target, r) for r in (4.0, 3.0, 2.0)]  # each: r - 1/2 per pixel
    assert SketchLoss(loss="final")(flows, target, weight).item() == pytest.approx(1.5)
    sequence = SketchLoss(loss="sequence", gamma=0.5)(flows, target, weight).item()
    assert sequence == pytest.approx(0.25 * 3.5 + 0.5 * 2.5 + 1.0 * 1.5)
    assert SketchLoss(loss="sequence", gamma=0.5)(flows[-1:], target, weight).item() == pytest.approx(1.5)


def test_the_weights_hold_the_far_pixels_free_the_gap_and_weigh_the_sketch():
    mask = torch.zeros(1, 40, 40, dtype=torch.bool)
    mask[0, 20, 10:30] = True  # a painted bone
    weight = SketchLoss(sketch_weight=5.0, gap=3).weights(mask)[0]
    assert torch.all(weight[mask[0]] == 5.0)
    assert torch.all(weight[17:20, 10:30] == 0) and torch.all(weight[21:24, 10:30] == 0)  # within 3 px: no loss
    assert torch.all(weight[20, 7:10] == 0) and torch.all(weight[20, 6] == 1)  # beside the bone's end too
    assert torch.all(weight[:17] == 1) and torch.all(weight[24:] == 1)  # beyond: held to the base flow
    plain = SketchLoss(sketch_weight=5.0).weights(mask)[0]
    assert torch.all(plain[~mask[0]] == 1)  # without a gap every unpainted pixel is held
    assert torch.equal(SketchLoss().weights(mask), torch.ones(1, 40, 40))  # the paper: every pixel alike


def test_bad_settings_are_refused_with_their_name():
    with pytest.raises(ValueError, match=r"loss: expected one of \('final', 'sequence'\), got 'l2'"):
        SketchLoss(loss="l2")
    with pytest.raises(ValueError, match="gap: expected >= 0 px, got -1"):
        SketchLoss(gap=-1)
    with pytest.raises(ValueError, match="beta: expected >= 0 px"):
        SketchLoss(beta=-0.1)
    with pytest.raises(ValueError, match="flows: expected at least one flow"):
        SketchLoss()([], torch.zeros(1, 2, 2, 2), torch.ones(1, 2, 2))
    with pytest.raises(TypeError):
        SketchLoss("final")  # every setting is keyword-only
