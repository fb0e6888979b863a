"""Tests for lit_boot.metrics.states: per-scene metric states, merged over scenes, give the
pooled metrics one process over every scene would (not the mean of the scenes' values)."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch
import torch.nn.functional as F

from lit_boot.core import LSP14
from lit_boot.metrics import (
    METRIC_NAMES,
    AccelerationError,
    FlowMetrics,
    MeanPerJointPositionError,
    PoseMetrics,
    compute_metric_states,
    merge_metric_states,
    scene_flow_metrics,
    scene_metric_states,
    scene_pose_metrics,
)
from lit_boot.synth import make_scene

FLOW_NAMES = {"epe", "epe_unmatched", "epe_all_pixels", "epe_person", "epe_background", "epe_joints"}
POSE_NAMES = {"3d": {"mpjpe_mm", "pa_mpjpe_mm", "accel_mm_per_frame2", "proj2d_px"}, "2d": {"kp2d_px"}}


def _perturbed(scene, seed: int, mm: float, px: float):
    """The scene with its estimates moved further off by seeded noise (so scenes differ)."""
    g = torch.Generator().manual_seed(seed)
    joints3d = scene.joints3d + mm * torch.randn(scene.joints3d.shape, generator=g, dtype=scene.joints3d.dtype)
    keypoints = scene.keypoints2d + px * torch.randn(scene.keypoints2d.shape, generator=g)
    return dataclasses.replace(scene, joints3d=joints3d, keypoints2d=keypoints)


@pytest.fixture(scope="module")
def scenes():
    """Three scenes of different sizes and lengths, with flows of different quality; the third
    has no GT flow (only ``epe_joints`` among the flow metrics)."""
    specs = [("walk", 4, 64, 96, 0, 0.3, 5.0), ("run", 6, 48, 80, 1, 1.5, 40.0), ("wave", 5, 56, 64, 2, 0.8, 15.0)]
    out = []
    for motion, frames, height, width, seed, noise, mm in specs:
        scene = make_scene(motion=motion, frames=frames, height=height, width=width, seed=seed)
        scene = _perturbed(scene, seed, mm, mm / 10)
        g = torch.Generator().manual_seed(100 + seed)
        flows = scene.gt.flow + noise * torch.randn(scene.gt.flow.shape, generator=g)
        out.append((scene, flows))
    scene, flows = out[2]
    out[2] = (dataclasses.replace(scene, gt=dataclasses.replace(scene.gt, flow=None)), flows)
    return out


def _pooled(scenes, mode: str) -> dict[str, float]:
    """The reference: one process over every scene, each metric updated with one scene after
    the other (as batches): one FlowMetrics, one metric per pose error."""
    flow = FlowMetrics()
    for scene, flows in scenes:
        gt = scene.gt
        flow.update(flows.float(), gt.flow.float() if gt.flow is not None else None, gt.flow_mask(),
                    gt.person_mask[:-1], gt.joints2d[:-1].float(), gt.joints2d[1:].float(),
                    gt.unmatched_mask())  # fmt: skip
    out = {name: float(value) for name, value in flow.compute().items()}
    z0 = lambda points: F.pad(points.float(), (0, 1))  # noqa: E731  2D points as 3D ones, z = 0
    if mode == "2d":
        points = MeanPerJointPositionError("none")
        for scene, _ in scenes:
            points.update(z0(scene.keypoints2d), z0(scene.gt.keypoints2d))
        return out | {"kp2d_px": float(points.compute())}
    metrics = {
        "mpjpe_mm": MeanPerJointPositionError("root", root=LSP14.root),
        "pa_mpjpe_mm": MeanPerJointPositionError("procrustes", root=LSP14.root),
        "accel_mm_per_frame2": AccelerationError(root=LSP14.root),
        "proj2d_px": MeanPerJointPositionError("none"),
    }
    for scene, _ in scenes:
        pred, gt = scene.joints3d.float(), scene.gt.joints3d.float()
        for name in ("mpjpe_mm", "pa_mpjpe_mm", "accel_mm_per_frame2"):
            metrics[name].update(pred, gt)
        metrics["proj2d_px"].update(z0(scene.cameras.project(pred)), z0(scene.gt.joints2d))
    return out | {name: float(metric.compute()) for name, metric in metrics.items()}


@pytest.mark.parametrize("mode", ["3d", "2d"])
def test_one_scene_states_give_the_scene_metrics(scenes, mode):
    scene, flows = scenes[0]
    states = scene_metric_states(scene, flows, mode)
    assert set(states) == FLOW_NAMES | POSE_NAMES[mode]
    assert all(set(values) == {"epe_sum", "count"} for name, values in states.items() if name in FLOW_NAMES)
    assert all(set(values) == {"error_sum", "count"} for name, values in states.items() if name not in FLOW_NAMES)
    assert all(type(v) is float for values in states.values() for v in values.values())
    expected = scene_flow_metrics(scene.gt, flows) | scene_pose_metrics(scene, mode)
    assert compute_metric_states(states) == pytest.approx(expected, rel=1e-9)
    assert set(states) <= set(METRIC_NAMES)


@pytest.mark.parametrize("mode", ["3d", "2d"])
def test_merged_states_give_the_pooled_metrics_not_the_mean_of_scenes(scenes, mode):
    states = [scene_metric_states(scene, flows, mode) for scene, flows in scenes]
    assert "epe" not in states[2] and "epe_joints" in states[2]  # no GT flow in the third scene
    merged = compute_metric_states(merge_metric_states(states))
    pooled = _pooled(scenes, mode)
    assert set(merged) == FLOW_NAMES | POSE_NAMES[mode]
    assert merged == pytest.approx(pooled, rel=1e-9)
    if mode == "3d":  # also all frames in one update (float32 sums inside it: ~1e-7 off)
        cat = lambda values: torch.cat([v.float() for v in values])  # noqa: E731
        pred, gt = cat(s.joints3d for s, _ in scenes), cat(s.gt.joints3d for s, _ in scenes)
        whole = PoseMetrics(root=LSP14.root).joints3d(pred, gt)
        assert merged["mpjpe_mm"] == pytest.approx(whole["mpjpe_mm"], rel=1e-6)
    per_scene = [compute_metric_states(s) for s in states]
    for name in merged:
        values = [s[name] for s in per_scene if name in s]
        mean = sum(values) / len(values)
        assert abs(merged[name] - mean) > 1e-3 * abs(merged[name]), name  # pooling weighs pixels / joints


@pytest.mark.parametrize("mode", ["3d", "2d"])
def test_states_survive_a_json_round_trip(scenes, mode):
    states = [scene_metric_states(scene, flows, mode) for scene, flows in scenes]
    loaded = json.loads(json.dumps(states))
    assert loaded == states
    merged = merge_metric_states(states)
    assert json.loads(json.dumps(merged)) == merged
    assert compute_metric_states(merge_metric_states(loaded)) == compute_metric_states(merged)


def test_merge_and_compute_edge_cases():
    assert merge_metric_states([]) == {} and compute_metric_states({}) == {}
    one, other = {"epe": {"epe_sum": 10.0, "count": 5.0}}, {"mpjpe_mm": {"error_sum": 3.0, "count": 1.0}}
    merged = merge_metric_states([one, other])
    assert compute_metric_states(merged) == {"epe": 2.0, "mpjpe_mm": 3.0}
    assert compute_metric_states({"epe": {"epe_sum": 0.0, "count": 0.0}})["epe"] != 0.0  # NaN: nothing seen
    with pytest.raises(ValueError, match="differ"):
        merge_metric_states([{"epe": {"epe_sum": 1.0, "count": 1.0}}, {"epe": {"error_sum": 1.0, "count": 1.0}}])
    with pytest.raises(ValueError, match="expected"):
        compute_metric_states({"epe": {"error_sum": 1.0, "count": 1.0}})
    with pytest.raises(ValueError, match="unknown metric"):
        compute_metric_states({"psnr": {"sum": 1.0, "count": 1.0}})
