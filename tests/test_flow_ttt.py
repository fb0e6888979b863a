"""FlowTTT: targets, fine-tuning, options, logging, and the Lightning CLI (tiny scenes, CPU)."""

from __future__ import annotations

import lightning as L
import pytest
import torch

from lit_boot.cli import main
from lit_boot.data import load_scene, read_flo, save_scene
from lit_boot.flow import FlowTTT, SceneFlowData, SketchConfig, predict_flow, sketch_inputs
from lit_boot.flow.crops import PERSON_MARGIN, anchor_box, person_region, sketch_box
from lit_boot.synth import make_scene

FAST = dict(train_updates=2, predict_updates=3, sketch=SketchConfig(size=3, guard=False))


@pytest.fixture(scope="module")
def scene():
    return make_scene(motion="run", frames=3, height=64, width=96, seed=0)


def test_targets_are_the_sketch_painted_over_rafts_own_flow(scene):
    model = FlowTTT(weights=None, **FAST)
    report = model.prepare(scene, sketch_inputs(scene, "gt"))
    assert model.target_report == report
    base = torch.cat([predict_flow(model.raft.eval(), scene.frames[t], scene.frames[t + 1], 2) for t in range(2)])
    mask = model.sketch_masks
    assert mask.any() and not mask.all()
    torch.testing.assert_close(model.targets[~mask[:, None].expand_as(base)], base[~mask[:, None].expand_as(base)])
    assert report["target/epe_sketch_painted"] < report["target/epe_base_painted"]  # GT joints beat a random net


def test_a_prepared_module_fits_without_a_datamodule_and_an_unprepared_one_says_how(scene, trainer):
    from torch.utils.data import DataLoader

    from lit_boot.flow import ScenePairs

    torch.manual_seed(0)
    model = FlowTTT(weights=None, lr=1e-3, **FAST)
    loader = DataLoader(ScenePairs(scene), batch_size=1)
    with pytest.raises(RuntimeError, match=r"SceneFlowData datamodule .* or call prepare\(scene\) first"):
        trainer(limit_val_batches=0).fit(model, train_dataloaders=loader)
    report = model.prepare(scene)  # the stick-man of the scene's own poses (auto: projected 3D joints)
    assert report["target/painted_fraction"] > 0 and model.scene is scene
    before = {k: v.clone() for k, v in model.raft.state_dict().items()}
    fit = trainer(limit_val_batches=0)
    fit.fit(model, train_dataloaders=loader)
    assert fit.global_step == scene.num_frames - 1
    assert any(not torch.equal(before[k], v) for k, v in model.raft.state_dict().items())
    with pytest.raises(ValueError, match=r"base: expected shape \(2, 2, 64, 96\)"):
        model.targets_from(scene, torch.zeros(1, 2, 64, 96))


def test_target_updates_and_the_loss_settings(scene):
    model = FlowTTT(weights=None, target_updates=4, loss_beta=0.1, loss="sequence", gamma=0.5, sketch_weight=3.0,
                    **FAST)  # fmt: skip
    model.prepare(scene, sketch_inputs(scene, "gt"))
    base = torch.cat([predict_flow(model.raft.eval(), scene.frames[t], scene.frames[t + 1], 4) for t in range(2)])
    outside = ~model.sketch_masks[:, None].expand_as(base)
    torch.testing.assert_close(model.targets[outside], base[outside])  # painted over the 4-update flow
    loss = model.loss_fn  # built from FlowTTT's settings
    assert (loss.loss, loss.gamma, loss.beta, loss.sketch_weight, loss.gap) == ("sequence", 0.5, 0.1, 3.0, 0)


@pytest.mark.parametrize("grad_updates", [None, 1])  # truncated backprop: through the last update only
def test_fine_tuning_moves_the_flow_towards_the_target(scene, trainer, grad_updates):
    torch.manual_seed(0)
    model = FlowTTT(weights=None, lr=1e-3, grad_updates=grad_updates, **FAST)
    data = SceneFlowData(scene, pose_source="gt", shuffle=False)
    model.prepare(scene, sketch_inputs(scene, "gt"))
    targets = model.targets.clone()

    painted = model.sketch_masks[:, None].expand_as(targets)

    def distance() -> float:
        """Mean |flow - target| on the sketch's pixels."""
        model.raft.eval()
        with torch.no_grad():
            flows = torch.cat([predict_flow(model.raft, scene.frames[t], scene.frames[t + 1], 2) for t in range(2)])
        return (flows - targets).abs()[painted].mean().item()

    before = distance()
    trainer(epochs=3, limit_val_batches=0).fit(model, datamodule=data)
    assert distance() < 0.9 * before


def test_validation_logs_epe_and_drift(scene, trainer):
    model = FlowTTT(weights=None, **FAST)
    t = trainer()
    t.fit(model, datamodule=SceneFlowData(scene, pose_source="gt"))
    metrics = t.callback_metrics
    for key in ("val/epe", "val/epe_person", "val/epe_joints", "val/drift_px", "train/loss_epoch"):
        assert key in metrics and torch.isfinite(metrics[key]), key
    assert metrics["val/drift_px"] > 0  # the network changed


def test_validation_reports_the_orchestrators_numbers_under_its_names(trainer):
    from lit_boot.metrics import scene_flow_metrics

    scene = make_scene(motion="run", frames=3, height=64, width=96, seed=2, pan_deg_per_s=30.0)
    assert scene.gt.flow_occluded.any()  # the occluded pixels must be left out by both
    model = FlowTTT(weights=None, **FAST)
    data = SceneFlowData(scene, pose_source="gt", shuffle=False)
    model.prepare(scene, sketch_inputs(scene, "gt"))
    t = trainer()
    logged = t.validate(model, datamodule=data, verbose=False)[0]
    model.raft.eval()
    with torch.no_grad():
        flows = torch.cat([predict_flow(model.raft, scene.frames[i], scene.frames[i + 1], 3) for i in range(2)])
    expected = scene_flow_metrics(scene.gt, flows)
    assert set(expected) == {"epe", "epe_unmatched", "epe_all_pixels", "epe_person", "epe_background", "epe_joints"}
    for name, value in expected.items():
        assert logged[f"val/{name}"] == pytest.approx(value, rel=1e-4), name


def test_update_block_only_and_frozen_batchnorm(scene, trainer):
    model = FlowTTT(arch="raft_small", weights=None, train_parts="update_block", lr=1e-3, **FAST)
    encoder = {k: v.clone() for k, v in model.raft.feature_encoder.state_dict().items()}
    update = {k: v.clone() for k, v in model.raft.update_block.state_dict().items()}
    trainer(limit_val_batches=0).fit(model, datamodule=SceneFlowData(scene, pose_source="gt"))
    assert all(torch.equal(v, model.raft.feature_encoder.state_dict()[k]) for k, v in encoder.items())
    assert any(not torch.equal(v, model.raft.update_block.state_dict()[k]) for k, v in update.items())
    large = FlowTTT(arch="raft_large", weights=None, freeze_batchnorm=True, **FAST)
    large.train()
    bns = [m for m in large.raft.modules() if isinstance(m, torch.nn.BatchNorm2d)]
    assert bns and not any(m.training for m in bns)


def test_crop_training_holds_the_rest_of_the_frame(scene, trainer):
    model = FlowTTT(weights=None, crop_margin=8, hold_weight=1.0, lr=1e-3, **FAST)
    t = trainer(limit_val_batches=0)
    t.fit(model, datamodule=SceneFlowData(scene, pose_source="gt"))
    assert torch.isfinite(t.callback_metrics["train/loss_epoch"])
    box = sketch_box(model.sketch_masks[0], 8)
    y0, y1, x0, x1 = box
    assert (y1 - y0) < scene.height or (x1 - x0) < scene.width  # a real crop
    anchor = anchor_box(box, scene.height, scene.width)
    assert (anchor[1] - anchor[0], anchor[3] - anchor[2]) == (y1 - y0, x1 - x0)


def test_bad_options_are_refused():
    with pytest.raises(ValueError, match="loss"):
        FlowTTT(weights=None, loss="l2")
    with pytest.raises(ValueError, match="train_parts"):
        FlowTTT(weights=None, train_parts="encoder")
    with pytest.raises(ValueError, match=r"grad_updates: expected None or 1..2"):
        FlowTTT(weights=None, train_updates=2, grad_updates=3)
    with pytest.raises(ValueError, match="pose_source"):
        SceneFlowData("nowhere", pose_source="mocap")
    with pytest.raises(TypeError):
        FlowTTT("raft_small", None)  # every setting is keyword-only


def test_cli_fit_then_predict_writes_checkpoint_and_flows(scene, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    save_scene(scene, tmp_path / "scene")
    common = ["--config", str(pytest.importorskip("pathlib").Path(__file__).parents[1] / "configs" / "flow_ttt.yaml"),
              "--data.scene", str(tmp_path / "scene"), "--model.weights", "null",
              "--model.train_updates", "2", "--model.predict_updates", "2", "--model.sketch.size", "3",
              "--trainer.enable_progress_bar", "false"]  # fmt: skip
    assert main(["fit", *common, "--trainer.max_epochs", "1"]) == 0
    run = tmp_path / "runs" / "scene" / "FlowTTT"
    checkpoints = list(run.rglob("*.ckpt"))
    assert len(checkpoints) == 1 and list(run.rglob("events.out.tfevents*"))
    assert main(["predict", *common, "--ckpt_path", str(checkpoints[0])]) == 0
    flows = sorted((run / "predictions").glob("flow_*.flo"))
    assert len(flows) == scene.num_frames - 1 and len(list((run / "predictions").glob("flow_*.png"))) == len(flows)
    assert read_flo(flows[0]).shape == (2, scene.height, scene.width)
    assert load_scene(tmp_path / "scene").num_frames == scene.num_frames  # the input is untouched


def test_flow_writer_npz_and_overwrite_protection(scene, tmp_path):
    import numpy as np

    from lit_boot.flow import FlowWriter

    model = FlowTTT(weights=None, **FAST)
    out = tmp_path / "pred"
    writer = FlowWriter(output_dir=str(out), format="npz", png=False)
    t = L.Trainer(logger=False, enable_progress_bar=False, callbacks=[writer])
    t.predict(model, datamodule=SceneFlowData(scene, pose_source="gt"), return_predictions=False)
    with np.load(out / "flows.npz") as npz:
        assert npz["flow"].shape == (scene.num_frames - 1, 2, scene.height, scene.width)
        assert npz["index"].tolist() == list(range(scene.num_frames - 1))
    with pytest.raises(FileExistsError, match="pred"):
        t.predict(model, datamodule=SceneFlowData(scene, pose_source="gt"), return_predictions=False)


def test_person_region_is_the_sketch_dilated_by_the_margin():
    masks = torch.zeros(2, 20, 30, dtype=torch.bool)
    masks[0, 10, 15] = True  # frame 1 has no sketch: no person region
    region = person_region(masks, margin=3)
    assert region.shape == masks.shape and region.dtype == torch.bool
    assert region[0].sum() == 7 * 7 and region[0, 7:14, 12:19].all()
    assert not region[1].any()
    assert person_region(masks, margin=1)[0].sum() == 9 and torch.equal(person_region(masks, margin=0), masks)
    corner = torch.zeros(1, 40, 40, dtype=torch.bool)
    corner[0, 0, 0] = True  # the default margin, 16 px, cut at the frame's border
    region = person_region(corner)
    assert PERSON_MARGIN == 16 and region.sum() == 17 * 17 and region[0, :17, :17].all()
    with pytest.raises(ValueError, match=r"masks: expected \(B, H, W\) bool"):
        person_region(masks.float())


def test_nothing_painted_skips_training_and_keeps_the_flow(scene, trainer):
    nobody = make_scene(motion="run", frames=3, height=64, width=96, seed=0)
    nobody.keypoints_conf[0::2] = 0.0  # a detector that found nobody in frames 0 and 2: no two consecutive
    model = FlowTTT(weights=None, lr=1e-2, **FAST)
    before = {k: v.clone() for k, v in model.raft.state_dict().items()}
    fit = trainer(epochs=2)
    with pytest.warns(UserWarning, match="nothing painted"):
        fit.fit(model, datamodule=SceneFlowData(nobody, pose_source="keypoints2d"))
    assert fit.global_step == 0 and model.target_report["target/painted_fraction"] == 0.0
    assert all(torch.equal(before[k], v) for k, v in model.raft.state_dict().items())


def test_plateau_stop_ends_a_fit_whose_loss_stopped_falling(scene, trainer):
    data = SceneFlowData(scene, pose_source="gt")
    still = FlowTTT(weights=None, lr=1e-30, plateau_patience=2, **FAST)  # lr ~0 (0 is refused): the loss never falls
    t = trainer(epochs=10, limit_val_batches=0)
    t.fit(still, datamodule=data)
    assert t.current_epoch == 3  # the first epoch sets the best; two more without a fall stop it
    assert t.callback_metrics["train/loss_rel"] == pytest.approx(1.0)
    torch.manual_seed(0)
    learning = FlowTTT(weights=None, lr=1e-3, plateau_patience=2, plateau_delta=0.0, **FAST)
    t = trainer(epochs=4, limit_val_batches=0)
    t.fit(learning, datamodule=data)
    assert t.current_epoch == 4 and t.callback_metrics["train/loss_rel"] < 1.0  # still falling: runs on
    with pytest.raises(ValueError, match="plateau_patience: expected None or >= 1"):
        FlowTTT(weights=None, plateau_patience=0)


def test_hold_consistent_holds_only_the_pixels_rafts_own_check_passes(scene, trainer):
    from lit_boot.flow.evidence import forward_backward_check

    model = FlowTTT(weights=None, hold="consistent", **FAST)
    assert model.base_flows(scene)[1] is not None  # one more RAFT pass per pair, backward
    base = torch.zeros(2, 2, 64, 96)
    backward = torch.zeros(2, 2, 64, 96)
    backward[:, 0, :, :40] = 5.0  # the left part fails the forward-backward check
    report = model.targets_from(scene, base, backward, inputs=sketch_inputs(scene, "gt"))
    expected = ~forward_backward_check(base, backward)[1]
    assert torch.equal(model.held, expected) and 0 < report["target/held_fraction"] < 1
    assert not model.held[:, :, :30].any() and model.held[:, 1:-1, 50:90].all()
    seen = []
    real = model.loss_fn.forward

    def spy(flows, target, weight):
        seen.append(weight.detach().cpu())
        return real(flows, target, weight)

    model.loss_fn.forward = spy
    from torch.utils.data import DataLoader

    from lit_boot.flow.data import ScenePairs

    trainer(epochs=1).fit(model, DataLoader(ScenePairs(scene), batch_size=2))
    weight = seen[0]
    free = ~(model.sketch_masks | model.held)
    assert free.any() and (weight[free] == 0).all()  # RAFT's flow fails its check there: no loss
    assert (weight[model.held & ~model.sketch_masks] > 0).all()
    with pytest.raises(ValueError, match="hold: expected one of"):
        FlowTTT(weights=None, hold="some")
