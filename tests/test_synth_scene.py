"""The synthetic scenes: exact ground truth, determinism, and the simulated estimates."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from lit_boot.core import COCO17, LSP14
from lit_boot.data import load_scene, save_scene
from lit_boot.metrics import mpjpe
from lit_boot.synth import MOTION_KINDS, EstimateConfig, SynthConfig, make_scene

SMALL = dict(frames=5, height=64, width=96)


@pytest.fixture(scope="module")
def walk():
    """A fast walk seen by a panning, dollying camera: person and background both move."""
    return make_scene(motion="run", seed=3, pan_deg_per_s=15.0, dolly_mm_per_s=400.0, **SMALL)


def warp_back(next_frame: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """Sample frame t+1 (3, H, W) at x + flow(x): frame t wherever the flow is right."""
    _, H, W = next_frame.shape
    ys, xs = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    grid = torch.stack([(xs + flow[0]) / (W - 1) * 2 - 1, (ys + flow[1]) / (H - 1) * 2 - 1], -1)
    return F.grid_sample(next_frame[None].float(), grid[None], padding_mode="border", align_corners=True)[0]


def test_same_seed_same_scene_bit_for_bit(walk):
    again = make_scene(motion="run", seed=3, pan_deg_per_s=15.0, dolly_mm_per_s=400.0, **SMALL)
    for a, b in [(walk.frames, again.frames), (walk.gt.flow, again.gt.flow), (walk.gt.flow_occluded, again.gt.flow_occluded),
                 (walk.joints3d, again.joints3d), (walk.cameras.params, again.cameras.params),
                 (walk.keypoints2d, again.keypoints2d), (walk.keypoints_conf, again.keypoints_conf)]:  # fmt: skip
        assert torch.equal(a, b)
    other = make_scene(motion="run", seed=4, pan_deg_per_s=15.0, dolly_mm_per_s=400.0, **SMALL)
    assert not torch.equal(walk.frames, other.frames)
    assert not torch.equal(walk.joints3d, other.joints3d)


def test_gt_flow_warps_next_frame_onto_this_one(walk):
    for t in range(walk.num_frames - 1):
        flow, visible = walk.gt.flow[t], ~walk.gt.flow_occluded[t]
        this, nxt = walk.frames[t].float(), walk.frames[t + 1].float()
        warped_err = (warp_back(walk.frames[t + 1], flow) - this).abs().mean(0)
        still_err = (nxt - this).abs().mean(0)
        assert warped_err[visible].mean() < 0.35 * still_err[visible].mean()
        person = visible & walk.gt.person_mask[t]
        assert warped_err[person].mean() < 0.6 * still_err[person].mean()
        assert flow[:, person].norm(dim=0).max() > 3.0  # the person really moves


def test_background_flow_is_the_camera_rotation_homography():
    """Pan only (no dolly): the static background moves by K R_rel K^-1, independent of depth."""
    scene = make_scene(motion="wave", seed=1, pan_deg_per_s=30.0, **SMALL)
    cam = scene.metadata["camera"]
    fx, fy, cx, cy = cam["fx_fy_cx_cy"]
    K = torch.tensor([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]], dtype=torch.float64)
    R = torch.tensor(cam["world_to_camera_R"], dtype=torch.float64)
    H, W = scene.height, scene.width
    ys, xs = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64), indexing="ij")
    pix = torch.stack([xs, ys, torch.ones_like(xs)], -1)
    for t in range(scene.num_frames - 1):
        Hm = K @ R[t + 1] @ R[t].T @ torch.linalg.inv(K)
        moved = pix @ Hm.T
        expected = (moved[..., :2] / moved[..., 2:]).permute(2, 0, 1) - pix[..., :2].permute(2, 0, 1)
        bg = ~scene.gt.person_mask[t] & ~scene.gt.flow_occluded[t]
        err = (scene.gt.flow[t].double() - expected).norm(dim=0)[bg]
        assert expected.norm(dim=0)[bg].mean() > 1.0  # the pan moves the background
        assert err.max() < 1e-2


def test_projected_gt_joints_are_the_gt_2d_joints(walk):
    projected = walk.gt.cameras.project(walk.gt.joints3d)
    torch.testing.assert_close(projected, walk.gt.joints2d, atol=1e-3, rtol=0)
    # The COCO keypoints share the limb joints with LSP-14.
    for name in ("left_shoulder", "right_elbow", "left_hip", "right_ankle"):
        torch.testing.assert_close(
            walk.gt.keypoints2d[:, COCO17.index(name)], walk.gt.joints2d[:, LSP14.index(name)], atol=1e-3, rtol=0
        )


def test_masks_and_occlusions(walk):
    assert walk.gt.person_mask.flatten(1).sum(1).min() > 50
    occ = walk.gt.flow_occluded
    assert 0.0 < occ.float().mean() < 0.25
    H, W = walk.height, walk.width
    ys, xs = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    tx, ty = xs + walk.gt.flow[:, 0], ys + walk.gt.flow[:, 1]
    outside = (tx < -0.5) | (tx > W - 0.5) | (ty < -0.5) | (ty > H - 0.5)
    assert outside.any() and occ[outside].all()  # leaving the image counts as hidden


def test_metro_like_estimates(walk):
    assert mpjpe(walk.joints3d, walk.gt.joints3d).mean().item() == pytest.approx(70.0, abs=1e-3)
    reprojected = walk.cameras.project(walk.joints3d)
    person_height = (walk.gt.joints2d[..., 1].amax(-1) - walk.gt.joints2d[..., 1].amin(-1)).mean()
    err = (reprojected - walk.gt.joints2d).norm(dim=-1).mean()
    assert err < 0.15 * person_height
    scene = make_scene(motion="walk", seed=0, estimates=EstimateConfig(mpjpe_mm=50.0), **SMALL)
    assert mpjpe(scene.joints3d, scene.gt.joints3d).mean().item() == pytest.approx(50.0, abs=1e-3)


def test_keypoint_failures_are_confident_and_wrong():
    cfg = EstimateConfig(lock_prob=0.5, jump_prob=0.05, miss_prob=0.1)
    scene = make_scene(motion="walk", seed=5, estimates=cfg, frames=12, height=96, width=96)
    err = (scene.keypoints2d - scene.gt.keypoints2d).norm(dim=-1)
    events = scene.metadata["keypoint_failures"]
    assert any(e["kind"] == "lock" for e in events) and any(e["kind"] == "jump" for e in events)
    for e in events:
        frames = e["frames"] if e["kind"] == "lock" else [e["frame"]]
        conf = scene.keypoints_conf[frames][:, e["joints"]]
        assert ((conf >= 0.7) | (conf == 0)).all()  # confident (unless later marked as missed)
        assert err[frames][:, e["joints"]].mean() > 0.5 * e["pixels"]  # and far off
    assert (scene.keypoints_conf == 0).any()  # missed detections


def test_clean_keypoints_have_no_failures_and_occlusion_lowers_confidence():
    cfg = EstimateConfig(lock_prob=0.0, jump_prob=0.0, miss_prob=0.0)
    scene = make_scene(motion="walk", seed=2, estimates=cfg, heading_deg=90.0, frames=8, height=96, width=96)
    assert scene.metadata["keypoint_failures"] == []
    assert (scene.keypoints2d - scene.gt.keypoints2d).norm(dim=-1).max() < 12.0
    conf = scene.keypoints_conf
    low = conf < 0.6  # the occluded range
    assert low.any() and (~low).any()  # a side view hides some joints
    assert conf[low].mean() < conf[~low].mean() - 0.3


@pytest.mark.parametrize("kind", MOTION_KINDS)
def test_every_motion_renders_a_moving_person(kind):
    scene = make_scene(motion=kind, seed=0, frames=4, height=48, width=48)
    assert scene.gt.person_mask.flatten(1).sum(1).min() > 30
    assert torch.isfinite(scene.gt.flow).all()
    assert scene.gt.flow.norm(dim=1)[scene.gt.person_mask[:-1]].max() > 0.3


@pytest.mark.shared
def test_bvh_hop_scene(shared):
    bvh = shared / "data" / "mocap" / "cmu_131" / "131_03.bvh"
    scene = make_scene(motion="bvh", bvh=str(bvh), bvh_start=2.0, frames=4, height=64, width=64)
    assert scene.name == "synth_131_03_s0"
    assert scene.gt.person_mask.flatten(1).sum(1).min() > 30
    assert scene.gt.flow.norm(dim=1)[scene.gt.person_mask[:-1]].mean() > 0.2


def test_noise_and_motion_blur():
    clean = make_scene(motion="run", seed=1, **SMALL)
    noisy = make_scene(motion="run", seed=1, noise_std=8.0, **SMALL)
    diff = noisy.frames.float() - clean.frames.float()
    assert 6.0 < diff.std().item() < 9.0
    blurred = make_scene(motion="run", seed=1, motion_blur=5, shutter=1.0, **SMALL)
    person = clean.gt.person_mask[:, None].expand_as(clean.frames)
    grad = lambda f: (f.float()[..., :, 1:] - f.float()[..., :, :-1]).abs()  # noqa: E731
    sharp, soft = grad(clean.frames)[person[..., 1:]].mean(), grad(blurred.frames)[person[..., 1:]].mean()
    assert soft < 0.9 * sharp


def test_config_errors_name_the_option():
    with pytest.raises(ValueError, match="SynthConfig.motion"):
        SynthConfig(motion="fly")
    with pytest.raises(ValueError, match="SynthConfig.bvh"):
        SynthConfig(motion="bvh")
    with pytest.raises(ValueError, match="SynthConfig.frames"):
        SynthConfig(frames=1)


def test_synthetic_scene_round_trips_through_a_folder(walk, tmp_path):
    loaded = load_scene(save_scene(walk, tmp_path / "scene"))
    assert torch.equal(loaded.frames, walk.frames) and torch.equal(loaded.gt.flow, walk.gt.flow)
    assert loaded.metadata == walk.metadata
