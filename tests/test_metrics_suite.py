"""Tests for lit_boot.metrics.suite: the named metrics FlowTTT, the refiners and the orchestrator
report, on hand-built inputs with known answers."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from lit_boot.core import GroundTruth
from lit_boot.metrics import FlowMetrics, PoseMetrics, scene_flow_metrics, scene_pose_metrics
from lit_boot.synth import make_scene


def test_flow_metrics_split_person_background_and_leave_out_occluded_pixels():
    gt = torch.zeros(1, 2, 4, 4)
    pred = torch.zeros(1, 2, 4, 4)
    pred[0, 0, :2] = 1.0  # 1 px off on the top half (the person), exact below
    person = torch.zeros(1, 4, 4, dtype=torch.bool)
    person[0, :2] = True
    occluded = torch.zeros(1, 4, 4, dtype=torch.bool)
    occluded[0, 0] = True  # one person row hidden: not scored
    joints = torch.tensor([[[1.0, 1.0], [9.0, 9.0]]])  # the second joint is outside the image
    truth = GroundTruth(flow=gt, flow_occluded=occluded, person_mask=torch.cat([person, person]),
                        joints2d=torch.cat([joints, joints + torch.tensor([2.0, 0.0])]))  # fmt: skip
    out = scene_flow_metrics(truth, pred)
    assert out["epe_person"] == pytest.approx(1.0)  # the visible person row
    assert out["epe_background"] == pytest.approx(0.0)
    assert out["epe"] == pytest.approx(4 / 12)  # 4 of the 12 scored pixels are 1 px off
    assert out["epe_joints"] == pytest.approx(1.0)  # flow (1, 0) at (1, 1) vs a (2, 0) step; one joint inside
    assert out["epe_unmatched"] == pytest.approx(1.0)  # the hidden row: its 4 pixels 1 px off (Sintel's unmatched)
    assert out["epe_all_pixels"] == pytest.approx(8 / 16)  # every pixel (Sintel's all): 8 of 16 are 1 px off


def test_without_occlusions_in_the_gt_only_the_matched_epe_is_reported():
    truth = GroundTruth(flow=torch.zeros(1, 2, 3, 3))
    out = scene_flow_metrics(truth, torch.ones(1, 2, 3, 3))
    assert out == {"epe": pytest.approx(2**0.5)}  # no unmatched pixels to tell apart: no second name for it


def test_flow_metrics_pool_batches_and_prefix_their_names():
    torch.manual_seed(0)
    pred, gt = torch.randn(3, 2, 5, 6), torch.randn(3, 2, 5, 6)
    mask = torch.rand(3, 5, 6) > 0.3
    whole = FlowMetrics(prefix="val/")
    whole.update(pred, gt, mask)
    batched = FlowMetrics(prefix="val/")
    for i in range(3):
        batched.update(pred[i : i + 1], gt[i : i + 1], mask[i : i + 1])
    assert set(whole.compute()) == {"val/epe"}  # only what was updated
    torch.testing.assert_close(batched.compute()["val/epe"], whole.compute()["val/epe"])
    expected = (pred - gt).norm(dim=1)[mask].double().mean()
    torch.testing.assert_close(whole.compute()["val/epe"], expected)


def test_pose_metrics_known_offsets():
    gt = torch.randn(4, 14, 3) * 100
    shifted = gt + torch.tensor([5.0, 0.0, 0.0])  # a global shift: gone after root alignment
    moved = gt.clone()
    moved[:, 0] += torch.tensor([0.0, 30.0, 40.0])  # one joint 50 mm off (not a root joint)
    metrics = PoseMetrics(root=(2, 3))
    assert metrics.joints3d(shifted, gt)["mpjpe_mm"] == pytest.approx(0.0, abs=1e-4)
    assert metrics.joints3d(moved, gt)["mpjpe_mm"] == pytest.approx(50.0 / 14, rel=1e-5)
    assert "accel_mm_per_frame2" not in metrics.joints3d(moved[:2], gt[:2])  # needs 3 frames
    points = torch.zeros(2, 3, 2)
    assert metrics.points2d("kp2d_px", points + torch.tensor([3.0, 4.0]), points) == {"kp2d_px": pytest.approx(5.0)}


def test_scene_pose_metrics_follow_the_mode():
    scene = make_scene(motion="walk", frames=4, height=64, width=96, seed=0)
    three = scene_pose_metrics(scene, "3d")
    assert set(three) == {"mpjpe_mm", "pa_mpjpe_mm", "accel_mm_per_frame2", "proj2d_px"}
    assert three["mpjpe_mm"] == pytest.approx(70.0, abs=1e-3)  # the synthetic estimates' MPJPE
    exact = dataclasses.replace(scene, keypoints2d=scene.gt.keypoints2d)
    assert scene_pose_metrics(exact, "2d") == {"kp2d_px": pytest.approx(0.0, abs=1e-5)}
    assert scene_pose_metrics(dataclasses.replace(scene, gt=None), "3d") == {}


@pytest.mark.parametrize("mode", ["3d", "2d"])
def test_the_refiners_and_the_orchestrator_report_the_same_pose_numbers(mode):
    from lit_boot.pose import make_refiner

    scene = make_scene(motion="run", frames=4, height=64, width=96, seed=1)
    refiner = make_refiner(mode, save=False)
    refiner.prepare(scene, scene.gt.flow)
    expected = scene_pose_metrics(scene, mode)
    assert expected and refiner.evaluate() == pytest.approx(expected, rel=1e-6)
