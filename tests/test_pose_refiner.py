"""PoseRefiner (3D) and KeypointRefiner (2D-only): behaviour on hand-made and synthetic scenes."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from lit_boot.core import COCO17, LSP14, Cameras, GroundTruth, Scene, fit_weak_perspective
from lit_boot.pose import (
    KeypointRefiner,
    LossPlateauStopping,
    PoseData,
    PoseLossWeights,
    PoseRefiner,
    load_pose_result,
    make_trainer,
    refine_poses,
)
from lit_boot.pose.camera import CameraModel
from lit_boot.synth import make_scene

# A standing LSP-14 skeleton, root-relative, mm (x right, y down).
STANDING = torch.tensor([
    [-150, 850, 0], [-140, 450, 0], [-120, 0, 0], [120, 0, 0], [140, 450, 0], [150, 850, 0],
    [-350, -50, 0], [-300, -300, 0], [-200, -500, 0], [200, -500, 0], [300, -300, 0], [350, -50, 0],
    [0, -520, 0], [0, -800, 0],
], dtype=torch.float32)  # fmt: skip


def coco_from_lsp(points: torch.Tensor) -> torch.Tensor:
    """COCO-17 keypoints (T, 17, 2) with the LSP joints' positions (face points at the head top)."""
    out = torch.empty(points.shape[0], 17, 2)
    for k, name in enumerate(COCO17.names):
        out[:, k] = points[:, LSP14.names.index(name)] if name in LSP14.names else points[:, LSP14.names.index("head_top")]
    return out


def still_scene(camera: str = "weak_perspective", T: int = 4, H: int = 64, W: int = 96) -> Scene:
    """A motionless person whose estimates are exact: every loss term is 0 at the start."""
    if camera == "weak_perspective":
        scale = 224.0 / 60.0  # the person fills a 60 px crop
        crops = torch.tensor([[scale, W / 2 * scale, H / 2 * scale]]).repeat(T, 1)
        cameras = Cameras("weak_perspective", torch.tensor([[1.0, 0.0, 0.0]]).repeat(T, 1), crops)
        joints = STANDING.repeat(T, 1, 1)
    else:
        cameras = Cameras("pinhole", torch.tensor([[60.0, 60.0, W / 2, H / 2, 0.0, 0.0, 0.0]]).repeat(T, 1))
        joints = (STANDING + torch.tensor([0.0, 0.0, 4000.0])).repeat(T, 1, 1)
    # Project exactly as the refiner does, so the 2D term starts at exactly 0.
    projected = CameraModel(cameras).project(joints / 1000.0, CameraModel(cameras).initial())
    gt = GroundTruth(flow=torch.zeros(T - 1, 2, H, W), joints3d=joints.clone(), joints2d=projected.clone())
    return Scene(
        frames=torch.zeros(T, 3, H, W, dtype=torch.uint8), name="still", joints3d=joints, cameras=cameras,
        keypoints2d=coco_from_lsp(projected), keypoints_conf=torch.full((T, 17), 0.9), gt=gt,
    )  # fmt: skip


def fit(model, scene, steps: int, flows="gt", early_stop: bool = False, tmp_path=None):
    trainer = make_trainer(steps, early_stop, default_root_dir=tmp_path)
    trainer.fit(model, datamodule=PoseData(scene, flows, steps=steps))
    return model.result


@pytest.fixture(scope="module")
def walk():
    return make_scene(motion="walk", frames=8, height=64, width=96, seed=1)


@pytest.fixture(scope="module")
def jittered(walk):
    """The walk with pure per-frame jitter on the true joints (25 mm per coordinate) and
    weak-perspective cameras fitted to them."""
    g = torch.Generator().manual_seed(0)
    gt = walk.gt.joints3d
    est = gt - gt[:, list(LSP14.root)].mean(1, keepdim=True) + torch.randn(gt.shape, generator=g) * 25.0
    crops = walk.cameras.crops
    cams = Cameras("weak_perspective", fit_weak_perspective(est, walk.gt.joints2d, crops), crops)
    return dataclasses.replace(walk, joints3d=est.float(), cameras=cams)


@pytest.mark.parametrize("camera", ["weak_perspective", "pinhole"])
def test_a_still_scene_with_perfect_estimates_stays_put(camera, tmp_path):
    scene = still_scene(camera)
    result = fit(PoseRefiner(save=False), scene, steps=40, tmp_path=tmp_path)
    assert result.steps == 40
    torch.testing.assert_close(result.joints3d, scene.joints3d, atol=1e-4, rtol=0)
    torch.testing.assert_close(result.cameras.params, scene.cameras.params, atol=1e-6, rtol=1e-6)
    assert result.metrics_after["mpjpe_mm"] < 1e-3
    assert result.loss["total"] == 0.0


def test_the_authors_early_stop_ends_a_flat_run(tmp_path):
    result = fit(PoseRefiner(save=False), still_scene(), steps=200, early_stop=True, tmp_path=tmp_path)
    assert result.stopped_early and result.steps == 11  # 10 unchanged steps after the first
    stop = LossPlateauStopping(patience=3)
    model = PoseRefiner(save=False)
    make_trainer(200, early_stop=False, callbacks=[stop]).fit(model, datamodule=PoseData(still_scene(), "gt"))
    assert stop.stopped_step == 4 and model.result.steps == 4 and model.result.stopped_early


def test_jittered_joints_get_closer_to_the_truth_with_exact_flow(jittered, tmp_path):
    result = fit(PoseRefiner(save=False), jittered, steps=300, tmp_path=tmp_path)
    before, after = result.metrics_before, result.metrics_after
    assert after["mpjpe_mm"] < 0.8 * before["mpjpe_mm"]
    assert after["accel_mm_per_frame2"] < 0.5 * before["accel_mm_per_frame2"]
    assert result.joints3d.shape == jittered.joints3d.shape and torch.isfinite(result.joints3d).all()


def test_terms_switch_off_and_l3d_alone_changes_nothing(jittered):
    model = PoseRefiner(loss_weights=PoseLossWeights(opt=0, keypoints2d=0, pos=0, cam=0, bone=0), save=False)
    make_trainer(20, early_stop=False).fit(model, datamodule=PoseData(jittered, flows=None, steps=20))
    assert set(model.final_loss()) == {"3d", "total"}
    torch.testing.assert_close(model.result.joints3d, jittered.joints3d, atol=1e-4, rtol=0)


def test_the_bone_term_at_its_default_weight_is_the_hand_derived_value():
    scene = still_scene()
    grown = scene.joints3d.clone()
    grown[2, LSP14.names.index("right_ankle")] += torch.tensor([0.0, 30.0, 0.0])  # the right shin 3 cm longer at t=2
    scene = dataclasses.replace(scene, joints3d=grown)
    model = PoseRefiner(save=False)  # the paper's lambdas
    model.prepare(scene, torch.zeros(3, 2, 64, 96))
    _, terms = model.total_loss(with_terms=True)
    i = torch.tensor(LSP14.length_bones)
    lengths = (grown[:, i[:, 0]] - grown[:, i[:, 1]]).norm(dim=-1).double() / 1000.0  # (T, B) m
    change = lengths.diff(dim=0)  # two pairs change by about +-3 cm, under SmoothL1's beta of 1: quadratic
    assert change.abs().max() > 0.02 and PoseLossWeights().bone == 1.0e4
    expected = 1.0e4 * (0.5 * change.square()).sum() / 3  # lambda * mean over the 3 pairs of the summed SmoothL1
    assert terms["bone"].item() == pytest.approx(expected.item(), rel=1e-4)


def test_frames_without_detections_give_finite_results(walk):
    conf = walk.keypoints_conf.clone()
    conf[2:5] = 0.0  # three frames without any detection
    scene = dataclasses.replace(walk, keypoints_conf=conf)
    for mode in ("3d", "2d"):
        result = refine_poses(scene, "gt", mode=mode, steps=30, early_stop=False, confidence="real")
        poses = result.joints3d if mode == "3d" else result.keypoints2d
        assert torch.isfinite(poses).all() and all(v == v for v in result.loss.values())


def test_keypoint_joints_are_configurable_and_checked(walk):
    model = PoseRefiner(keypoint_joints=["left_wrist"], save=False)
    model.prepare(walk, walk.gt.flow)
    assert (model.keypoint_weight[:, LSP14.names.index("left_wrist")] > 0).any()
    assert model.keypoint_weight.sum(0).count_nonzero() == 1
    with pytest.raises(ValueError, match="head_top"):
        PoseRefiner(keypoint_joints=["head_top"]).prepare(walk, walk.gt.flow)
    with pytest.raises(ValueError, match="confidence"):
        PoseRefiner(confidence="maybe")


def test_2d_mode_improves_keypoints_with_exact_flow(walk, tmp_path):
    model = KeypointRefiner(output_dir=str(tmp_path / "out"))
    result = fit(model, walk, steps=150, tmp_path=tmp_path)
    assert result.mode == "2d" and result.keypoints2d.shape == walk.keypoints2d.shape
    assert result.metrics_after["kp2d_px"] < 0.85 * result.metrics_before["kp2d_px"]
    saved = load_pose_result(tmp_path / "out")
    torch.testing.assert_close(saved.keypoints2d, result.keypoints2d)


def test_result_is_saved_and_applies_to_the_scene(jittered, tmp_path):
    result = fit(PoseRefiner(), jittered, steps=5, tmp_path=tmp_path)
    saved = load_pose_result(tmp_path)  # no logger: the run folder is default_root_dir
    torch.testing.assert_close(saved.joints3d, result.joints3d)
    torch.testing.assert_close(saved.cameras.params, result.cameras.params)
    assert saved.metrics_before == result.metrics_before and saved.settings["loss_weights"]["bone"] == 1e4
    refined = result.apply_to(jittered)
    assert torch.equal(refined.joints3d, result.joints3d) and refined.gt is jittered.gt


def test_losses_are_logged_every_n_steps_and_metrics_at_the_end(jittered, tmp_path):
    from lightning.pytorch.loggers import CSVLogger

    model = PoseRefiner(save=False, eval_every_n_steps=10)
    trainer = make_trainer(20, early_stop=False, logger=CSVLogger(tmp_path), log_every_n_steps=5)
    trainer.fit(model, datamodule=PoseData(jittered, "gt"))
    logged = trainer.callback_metrics
    assert {"loss/opt", "loss/3d", "loss/2d", "loss/pos", "loss/cam", "loss/bone", "loss/total"} <= set(logged)
    assert {"val/mpjpe_mm", "val/pa_mpjpe_mm", "val/accel_mm_per_frame2", "val/proj2d_px"} <= set(logged)
    text = (tmp_path / "lightning_logs" / "version_0" / "metrics.csv").read_text()
    assert "loss/bone" in text and "val/mpjpe_mm" in text


def test_missing_flow_needs_the_flow_term_off(walk):
    with pytest.raises(ValueError, match="no flows given"):
        PoseRefiner().prepare(walk, None)
    with pytest.raises(RuntimeError, match="PoseData"):
        make_trainer(2, early_stop=False).fit(PoseRefiner(save=False))


@pytest.mark.parametrize("camera", ["weak_perspective", "pinhole"])
def test_module_terms_push_joints_the_expected_way(camera):
    """Through the camera: a detection 5 px right of the wrist pulls the wrist right; a flow of
    2 px to the right pulls the later frame right and the earlier one left."""
    scene = still_scene(camera, T=2)
    wrist = LSP14.names.index("left_wrist")
    scene.keypoints2d[:, COCO17.names.index("left_wrist"), 0] += 5.0
    scene.gt.flow[:, 0] = 2.0
    for term, weights in [("2d", PoseLossWeights(opt=0, joints3d=0, pos=0, cam=0, bone=0)),
                          ("opt", PoseLossWeights(keypoints2d=0, joints3d=0, pos=0, cam=0, bone=0))]:  # fmt: skip
        model = PoseRefiner(loss_weights=weights, save=False)
        model.prepare(scene, scene.gt.flow)
        loss, terms = model.total_loss(with_terms=True)
        assert set(terms) == {term}
        loss.backward()
        g = model.joints.grad[:, 0, :, 0]  # d loss / d x (metres) of person 0
        if term == "2d":
            assert (g[:, wrist] < 0).all() and (g[:, :wrist] == 0).all()
        else:
            assert (g[1] < 0).all() and (g[0] > 0).all()


def test_torch_threads_are_set_for_the_fit_and_restored_even_after_errors(jittered):
    before = torch.get_num_threads()
    seen = []
    model = PoseRefiner(save=False, num_threads=1)
    original = model.residuals

    def spy():
        seen.append(torch.get_num_threads())
        if len(seen) == 3:
            raise RuntimeError("boom")
        return original()

    model.residuals = spy
    with pytest.raises(RuntimeError, match="boom"):
        make_trainer(5, early_stop=False).fit(model, datamodule=PoseData(jittered, "gt"))
    assert seen[-1] == 1 and torch.get_num_threads() == before


@pytest.mark.parametrize("camera", ["weak_perspective", "pinhole"])
def test_the_camera_smoothness_term_is_the_hand_derived_value_and_pulls_a_jittered_camera_back(camera):
    """One frame's camera variables jump by (1.5, 0.3, -0.2) (weak perspective: s, tx, ty;
    pinhole: the translation in metres) and back: each of the 2 pairs touching it costs
    SmoothL1 (beta 1) 1.0 + 0.045 + 0.02 = 1.065, so at the paper's lambda 0.1, averaged over the
    3 pairs, the cam term is 0.1 * 2.13 / 3; its gradient at the jittered frame is
    0.1 / 3 * 2 * (1, 0.3, -0.2) (towards its neighbours) and the opposite half at each of them."""
    scene = still_scene(camera)
    params = scene.cameras.params.clone()
    jump = torch.tensor([1.5, 0.3, -0.2])
    if camera == "weak_perspective":
        params[2] += jump  # (s, tx, ty): the variables themselves
    else:
        params[2, 4:7] += jump * 1000.0  # the translation in mm; the variables are metres
    scene = dataclasses.replace(scene, cameras=dataclasses.replace(scene.cameras, params=params))
    model = PoseRefiner(save=False)  # the paper's lambdas
    model.prepare(scene, torch.zeros(3, 2, 64, 96))
    _, terms = model.total_loss(with_terms=True)
    assert PoseLossWeights().cam == 0.1 and "cam" in terms  # the term is on
    assert terms["cam"].item() == pytest.approx(0.1 * 2 * 1.065 / 3, rel=1e-5)
    alone = PoseRefiner(loss_weights=PoseLossWeights(opt=0, joints3d=0, keypoints2d=0, pos=0, bone=0), save=False)
    alone.prepare(scene, None)
    loss, terms = alone.total_loss(with_terms=True)
    assert set(terms) == {"cam"}
    loss.backward()
    pull = 0.1 / 3 * torch.tensor([1.0, 0.3, -0.2])  # SmoothL1' = clamp(r, -1, 1) per pair
    expected = torch.stack([torch.zeros(3), -pull, 2 * pull, -pull])[:, None]  # (T, P, 3)
    torch.testing.assert_close(alone.camera_vars.grad, expected, atol=1e-6, rtol=1e-5)
