"""The pose stage for every person at once: one batched refinement equals each person's own run."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from lit_boot.core import Person
from lit_boot.metrics import scene_pose_metrics
from lit_boot.pose import KeypointRefiner, PoseData, PoseRefiner, make_trainer
from lit_boot.synth import SynthConfig, make_scene

STEPS = 30


@pytest.fixture(scope="module")
def crowd():
    """Three people with the default estimate noise (jitter, misses), exact GT per person."""
    return make_scene(SynthConfig(motion="walk", seed=5, frames=5, height=64, width=128, people=3))


def fit(model, scene, steps=STEPS, flows="gt"):
    make_trainer(steps, early_stop=False).fit(model, datamodule=PoseData(scene, flows, steps=steps))
    return model.result


@pytest.mark.parametrize("mode", ["2d", "3d"])
def test_every_person_refined_at_once_follows_their_own_runs(crowd, mode):
    """The loss is the sum of the people's losses and Adam is element-wise: the batched result of
    each person is that person's single-person run (same steps, no early stop)."""
    make = KeypointRefiner if mode == "2d" else PoseRefiner
    batched = fit(make(save=False), crowd)
    assert [p.track_id for p in batched.estimates.people()] == [p.track_id for p in crowd.people()]
    for p, person in enumerate(batched.estimates.people()):
        alone = fit(make(save=False), dataclasses.replace(crowd.person(p), gt=None), flows=crowd.gt.flow)
        if mode == "2d":
            torch.testing.assert_close(person.keypoints2d, alone.keypoints2d, atol=1e-3, rtol=0)
            assert not torch.allclose(person.keypoints2d, crowd.people()[p].keypoints2d, atol=1e-2)  # it moved
        else:
            torch.testing.assert_close(person.joints3d, alone.joints3d, atol=1e-2, rtol=0)  # mm
            torch.testing.assert_close(person.cameras.params, alone.cameras.params, atol=1e-4, rtol=1e-4)


@pytest.mark.parametrize("mode", ["2d", "3d"])
def test_every_person_gets_better_with_exact_flow_and_is_scored(crowd, mode):
    """2D: every person's keypoint error falls; 3D: every person's jitter (acceleration error)
    falls (as for one person, the paper's 3D lambdas do not lower the 2D error of these scenes)."""
    make = KeypointRefiner if mode == "2d" else PoseRefiner
    result = fit(make(save=False), crowd, steps=200)
    name = "kp2d_px" if mode == "2d" else "accel_mm_per_frame2"
    ids = [p.track_id for p in crowd.people()]
    per_person = [name] + [f"{name}_person{i}" for i in ids[1:]]
    before, after = result.metrics_before, result.metrics_after
    for key in per_person:
        assert after[key] < before[key], key
    assert min(after[k] for k in per_person) <= after[f"{name}_all"] <= max(after[k] for k in per_person)
    assert after[f"{name}_all"] == pytest.approx(sum(after[k] for k in per_person) / len(ids), rel=1e-5)
    refined = result.apply_to(crowd)  # the same figures from the scene the runner records
    assert scene_pose_metrics(refined, mode) == pytest.approx(after, rel=1e-4)
    others = refined.others
    assert [o.track_id for o in others] == ids[1:]
    assert all(o.keypoints2d is not None and o.person_boxes is not None for o in others)  # kept where not refined
    if mode == "3d":
        assert not torch.equal(others[0].joints3d, crowd.others[0].joints3d)
        assert torch.equal(others[0].keypoints2d, crowd.others[0].keypoints2d)


def test_people_main_leaves_the_others_as_estimated(crowd):
    result = fit(KeypointRefiner(save=False, people="main"), crowd)
    assert [p.track_id for p in result.estimates.people()] == [p.track_id for p in crowd.people()]
    for mine, theirs in zip(result.estimates.others, crowd.others):
        assert torch.equal(mine.keypoints2d, theirs.keypoints2d)
    assert not torch.equal(result.keypoints2d, crowd.keypoints2d)
    assert set(result.metrics_after) == {"kp2d_px"}
    with pytest.raises(ValueError, match="people: expected one of"):
        KeypointRefiner(people="everyone")


def test_a_person_without_ground_truth_is_refined_and_not_scored(crowd):
    gt = dataclasses.replace(crowd.gt, others=crowd.gt.others[:1])  # the last person has no truth
    scene = dataclasses.replace(crowd, gt=gt)
    result = fit(KeypointRefiner(save=False), scene, steps=5)
    last = crowd.others[-1].track_id
    assert f"kp2d_px_person{crowd.others[0].track_id}" in result.metrics_after
    assert not any(k.endswith(f"_person{last}") for k in result.metrics_after)
    assert not torch.equal(result.estimates.others[-1].keypoints2d, crowd.others[-1].keypoints2d)


def test_a_single_person_scene_keeps_its_names_and_shapes(crowd):
    alone = crowd.person(0)
    alone = dataclasses.replace(alone, gt=dataclasses.replace(alone.gt, others=()))
    result = fit(PoseRefiner(save=False), alone, steps=3)
    assert result.estimates.others == () and result.joints3d.shape == alone.joints3d.shape
    assert not any(k.endswith("_all") for k in result.metrics_after)
    assert isinstance(Person.of(result.estimates), Person)
