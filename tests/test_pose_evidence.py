"""The poses' no-GT measures (lit_boot.bootstrap.evaluate.pose_evidence) on poses built by hand."""

from __future__ import annotations

import dataclasses

import pytest
import torch

import lit_boot
from lit_boot.bootstrap import bootstrap
from lit_boot.bootstrap.evaluate import pose_evidence
from lit_boot.core import Cameras, get_layout


@pytest.fixture(scope="module")
def scene():
    return lit_boot.make_scene(motion="run", frames=5, height=64, width=96, seed=0)


def test_a_still_rigid_pose_has_no_jitter_and_constant_bones(scene):
    cams = scene.cameras
    first = Cameras(cams.model, cams.params[:1].expand(5, -1).clone(), cams.crops[:1].expand(5, -1).clone(),
                    cams.crop_size)  # fmt: skip
    still = dataclasses.replace(scene, joints3d=scene.joints3d[:1].expand_as(scene.joints3d).clone(), cameras=first)
    out = pose_evidence(still, "3d")
    assert out["jitter_mm_per_frame2"] == pytest.approx(0.0, abs=1e-4)
    assert out["bone_variation"] == pytest.approx(0.0, abs=1e-6)


def test_jitter_and_bone_variation_are_what_was_put_in(scene):
    joints = scene.joints3d[:1].expand_as(scene.joints3d).clone()
    joints[2] += torch.tensor([30.0, 40.0, 0.0])  # frame 2 jumps 50 mm and back: accelerations 50, 100, 50
    out = pose_evidence(dataclasses.replace(scene, joints3d=joints), "3d")
    assert out["jitter_mm_per_frame2"] == pytest.approx((50 + 100 + 50) / 3, rel=1e-4)
    stretched = scene.joints3d[:1].expand_as(scene.joints3d).clone()
    bones = get_layout("lsp14").length_bones
    ends = [j for bone in bones for j in bone]
    a, b = next((a, b) if ends.count(b) == 1 else (b, a) for a, b in bones if 1 in (ends.count(a), ends.count(b)))
    # a bone ending in a joint of no other bone, 20% longer in every other frame: L, 1.2 L, L, 1.2 L, L
    stretched[1::2, b] = stretched[1::2, a] + 1.2 * (stretched[1::2, b] - stretched[1::2, a])
    out = pose_evidence(dataclasses.replace(scene, joints3d=stretched), "3d")
    lengths = torch.tensor([1.0, 1.2, 1.0, 1.2, 1.0])
    expected = float(lengths.std() / lengths.mean()) / len(bones)  # that bone's variation, averaged over the bones
    assert out["bone_variation"] == pytest.approx(expected, rel=1e-3)


def test_the_reprojection_is_measured_against_the_detectors_keypoints_in_the_posed_frames(scene):
    base = pose_evidence(scene, "3d")["reprojection_px"]
    moved = scene.keypoints2d.clone()
    moved[..., 0] += 100.0  # every keypoint 100 px off
    far = pose_evidence(dataclasses.replace(scene, keypoints2d=moved), "3d")["reprojection_px"]
    assert far > base + 90
    conf = scene.keypoints_conf.clone()
    conf[1:] = 0  # a pose only in frame 0: the others are filled in and do not count
    one = pose_evidence(dataclasses.replace(scene, keypoints2d=moved, keypoints_conf=conf), "3d")
    assert one["reprojection_px"] > 90 and "jitter_mm_per_frame2" not in one  # no three posed frames in a row


def test_2d_mode_measures_the_keypoints_and_a_run_records_the_measures(scene, tmp_path):
    out = pose_evidence(scene, "2d")
    assert set(out) == {"bone_variation", "jitter_px_per_frame2"} and out["jitter_px_per_frame2"] > 0
    result = bootstrap(scene, tmp_path / "run", flow={"weights": None, "train_updates": 1, "predict_updates": 1},
                                flow_epochs=1, pose_steps=3, progress_bar=False, video=False)  # fmt: skip
    initial, pose = result.history[0], next(r for r in result.history if r["stage"] == "pose_1")
    for name in ("reprojection_px", "bone_variation", "jitter_mm_per_frame2"):
        assert name in initial and name in pose
    assert initial["jitter_mm_per_frame2"] == pytest.approx(pose_evidence(scene, "3d")["jitter_mm_per_frame2"])
