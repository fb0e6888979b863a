"""What a scene's evidence lets a run do (lit_boot.bootstrap.plan) and the frames without a pose: a
3D run on a scene with only boxes, or only 2D keypoints, runs what can run; a 3D pose filled in
from a neighbour frame is not drawn and not held to the estimates."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch

import lit_boot
from lit_boot.bootstrap import BootstrapConfig, bootstrap
from lit_boot.bootstrap.plan import plan_run
from lit_boot.core import Person
from lit_boot.flow.data import sketch_inputs
from lit_boot.pose import PoseRefiner

FAST = dict(flow_epochs=1, pose_steps=5, progress_bar=False, video=False)
RANDOM_RAFT = {"weights": None, "train_updates": 2, "predict_updates": 2}


@pytest.fixture(scope="module")
def scene():
    return lit_boot.make_scene(motion="run", frames=4, height=64, width=96, seed=0)


def boxes_only(scene):
    """The scene as a detector that found the person's box but no pose would give it: keypoints of
    confidence 0, no 3D joints, a box in every frame."""
    points = scene.keypoints2d
    boxes = torch.cat([points.amin(1) - 2, points.amax(1) + 2, torch.ones(scene.num_frames, 1)], 1)
    nobody = torch.zeros_like(scene.keypoints_conf)
    return dataclasses.replace(scene, joints3d=None, cameras=None, keypoints_conf=nobody, person_boxes=boxes)


def test_each_stage_runs_where_its_evidence_is(scene):
    full = plan_run(BootstrapConfig(), scene)
    assert (full.mode, full.stages) == ("3d", ("zoom", "flow_1", "pose_1", "flow_2"))
    assert full.why == "3D mode: a 3D pose in 4 of 4 frames"
    keypoints = plan_run(BootstrapConfig(), dataclasses.replace(scene, joints3d=None, cameras=None))
    assert (keypoints.mode, keypoints.requested, keypoints.stages) == ("2d", "3d", full.stages)
    assert "no 3D joints with cameras: the 2D stages run" in keypoints.why
    for mode in ("3d", "2d"):
        boxes = plan_run(BootstrapConfig(mode=mode), boxes_only(scene))
        assert boxes.stages == ("zoom",) and "only the person detector's boxes (4 of 4 frames)" in boxes.why
    with pytest.raises(ValueError, match="the zoom stage .* is off: nothing can run"):
        plan_run(BootstrapConfig(zoom={"method": "off"}), boxes_only(scene))
    nobody = dataclasses.replace(boxes_only(scene), person_boxes=None)
    with pytest.raises(ValueError, match="no person in any frame"):
        plan_run(BootstrapConfig(), nobody)


def test_a_3d_run_with_only_boxes_runs_the_zoom_stage_and_says_so(scene, tmp_path, caplog):
    with caplog.at_level("INFO", logger="lit_boot"):
        result = bootstrap(boxes_only(scene), tmp_path / "run", flow=RANDOM_RAFT, **FAST)
    assert [r["stage"] for r in result.history] == ["initial", "zoom"]
    assert any("only the person detector's boxes" in r.getMessage() for r in caplog.records)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["plan"]["stages"] == ["zoom"] and summary["config"]["mode"] == "3d"  # as asked, and what ran
    assert "what ran and why: no pose in any frame" in (tmp_path / "run" / "report.html").read_text()


def test_a_filled_3d_pose_is_not_drawn(scene):
    filled = scene.keypoints_conf.clone()
    filled[2] = 0  # frame 2: nobody found; its 3D joints are only a neighbour's
    inputs = sketch_inputs(dataclasses.replace(scene, keypoints_conf=filled), "joints3d")
    assert inputs.confidence_t[:, 0].tolist() == [1.0, 1.0, 0.0]  # pair 2 -> 3 starts at the filled frame
    assert inputs.confidence_t1[:, 0].tolist() == [1.0, 0.0, 1.0]  # pair 1 -> 2 ends at it
    assert Person.of(scene).posed().all()
    assert not Person.of(dataclasses.replace(scene, keypoints_conf=filled)).posed()[2]


def test_a_filled_3d_pose_is_not_held_to_the_estimates(scene):
    filled = scene.keypoints_conf.clone()
    filled[1] = 0
    refiner = PoseRefiner(save=False, loss_weights=None)
    refiner.build(dataclasses.replace(scene, keypoints_conf=filled), flows=torch.zeros(3, 2, 64, 96))
    names = refiner.objective.names
    start = sum(refiner.objective.sizes[: names.index("3d")])
    weights = refiner.objective.weights[start : start + refiner.objective.sizes[names.index("3d")]].view(4, 14, 3)
    assert (weights[1] == 0).all() and (weights[[0, 2, 3]] > 0).all()  # only frame 1's deviation term is off
