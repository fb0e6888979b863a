"""The pose stage's public surface: top-level exports, saved settings, bad inputs, validation."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import lightning as L
import pytest
import torch

import lit_boot
import lit_boot.pose
from lit_boot.cli import main
from lit_boot.data import save_scene
from lit_boot.pose import (
    FlowSourceError,
    KeypointLossWeights,
    KeypointRefiner,
    PoseData,
    PoseLossWeights,
    PoseRefiner,
    make_trainer,
    refine_poses,
)
from lit_boot.synth import make_scene

POSE_DIR = Path(lit_boot.pose.__file__).parent
EXPORTS = ["PoseRefiner", "KeypointRefiner", "PoseLossWeights", "KeypointLossWeights", "PoseData", "PoseResult",
           "load_pose_result", "refine_poses"]  # fmt: skip


@pytest.fixture(scope="module")
def scene():
    return make_scene(motion="run", frames=6, height=64, width=96, seed=0)


@pytest.fixture(scope="module")
def scene_dir(scene, tmp_path_factory):
    folder = tmp_path_factory.mktemp("pose_api") / "run_scene"
    save_scene(scene, folder)
    return folder


def quiet_trainer() -> L.Trainer:
    return L.Trainer(logger=False, enable_progress_bar=False, enable_model_summary=False, enable_checkpointing=False)


def test_the_top_level_package_exports_the_pose_api():
    for name in EXPORTS:
        assert getattr(lit_boot, name) is getattr(lit_boot.pose, name) and name in lit_boot.__all__


def test_the_pose_stage_never_imports_the_flow_stage():
    for path in POSE_DIR.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                absolute = node.module or ""
                relative = node.level == 2 and absolute.split(".")[0] == "flow"
                assert not relative and not absolute.startswith("lit_boot.flow"), f"{path.name} imports the flow stage"
            elif isinstance(node, ast.Import):
                assert not any(a.name.startswith("lit_boot.flow") for a in node.names), path.name


def test_hparams_hold_every_init_arg_with_the_lambdas_as_a_dict():
    model = PoseRefiner(lr=0.01, loss_weights={"opt": 0.5}, confidence="real", pixel_scale=6.0, keypoint_joints=["left_wrist"])
    expected = {"lr": 0.01, "keypoint_joints": ["left_wrist"], "confidence": "real", "confidence_threshold": 0.0,
                "flow_inside_only": True, "pixel_scale": 6.0, "eval_every_n_steps": 100, "save": True,
                "output_dir": None, "num_threads": 1, "people": "all",
                "loss_weights": dataclasses.asdict(PoseLossWeights(opt=0.5))}  # fmt: skip
    assert dict(model.hparams) == expected and dict(model.hparams_initial) == expected  # loggers get the lambdas too
    assert model.loss_weights == PoseLossWeights(opt=0.5) and model.image_size == (1, 1)
    model2d = KeypointRefiner(loss_weights=KeypointLossWeights(smooth=2.0), confidence="none")
    assert dict(model2d.hparams) == {"lr": 0.1, "confidence": "none", "confidence_threshold": 0.0,
                                     "flow_inside_only": True, "eval_every_n_steps": 100, "save": True,
                                     "output_dir": None, "num_threads": 1, "people": "all",
                                     "loss_weights": {"opt": 300.0, "init": 400.0, "smooth": 2.0}}  # fmt: skip


def test_a_subclass_keeps_its_own_init_args_in_hparams():
    class Scaled(PoseRefiner):
        def __init__(self, factor: float = 2.0, **kwargs):
            super().__init__(**kwargs)
            self.factor = factor

    hparams = Scaled(factor=3.0, lr=0.02).hparams
    assert hparams["factor"] == 3.0 and hparams["lr"] == 0.02 and hparams["loss_weights"]["bone"] == 1e4


def test_bad_settings_name_the_argument():
    with pytest.raises(ValueError, match=r"loss_weights: unknown lambda 'init'; expected some of \['opt'"):
        PoseRefiner(loss_weights={"init": 1.0})
    with pytest.raises(TypeError, match="loss_weights: expected a KeypointLossWeights"):
        KeypointRefiner(loss_weights=PoseLossWeights())
    with pytest.raises(ValueError, match="confidence: expected one of"):
        KeypointRefiner(confidence="maybe")
    with pytest.raises(ValueError, match="pixel_scale"):
        PoseRefiner(pixel_scale=0)


def test_bad_flows_name_the_argument_or_path_and_what_was_expected(scene, tmp_path):
    run = dict(steps=2, early_stop=False)
    with pytest.raises(FlowSourceError, match=r"flows: expected flows of shape \(5, 2, 64, 96\), got \(5, 64, 96\)"):
        refine_poses(scene, torch.zeros(5, 64, 96), **run)
    with pytest.raises(FlowSourceError, match=r"flows: expected 5 flows \(one per pair of the scene's 6 frames\), got 4"):
        refine_poses(scene, torch.zeros(4, 2, 64, 96), **run)
    with pytest.raises(FlowSourceError, match=r"flows: flows are 48x32 px, expected 96x64"):
        refine_poses(scene, torch.zeros(5, 2, 32, 48), mode="2d", **run)
    missing = tmp_path / "no_flows_here"
    with pytest.raises(FileNotFoundError, match=f"{missing}: no such flow folder or .npz file"):
        refine_poses(scene, missing, **run)
    with pytest.raises(FileNotFoundError, match="no_scene_here"):
        refine_poses(tmp_path / "no_scene_here", "gt", **run)
    with pytest.raises(TypeError, match=r"flows: expected a folder .* or a \(5, 2, 64, 96\) tensor, got int"):
        PoseData(scene, 5).setup("fit")
    data = PoseData(scene, scene.gt.flow.numpy())  # an array is taken like a tensor
    data.setup("fit")
    torch.testing.assert_close(data.flows, scene.gt.flow)


def test_3d_mode_needs_3d_joints_and_2d_mode_keypoints(scene):
    no_joints = dataclasses.replace(scene, joints3d=None, cameras=None)
    with pytest.raises(ValueError, match=r"PoseRefiner: scene 'synth_run_s0' has no 3D joints with cameras \(use KeypointRefiner\)"):
        refine_poses(no_joints, "gt", steps=2, early_stop=False)
    assert refine_poses(no_joints, "gt", mode="2d", steps=2, early_stop=False).keypoints2d.shape == (6, 17, 2)
    no_keypoints = dataclasses.replace(scene, keypoints2d=None, keypoints_conf=None)
    with pytest.raises(ValueError, match="has no 2D keypoints"):
        refine_poses(no_keypoints, "gt", mode="2d", steps=2, early_stop=False)


def test_validate_evaluates_the_current_poses_without_changing_them(scene):
    model = PoseRefiner(save=False)
    initial = quiet_trainer().validate(model, datamodule=PoseData(scene, "gt"), verbose=False)[0]
    assert initial["val/mpjpe_mm"] == pytest.approx(70.0, abs=1e-3)  # the synthetic estimates' MPJPE
    assert {"val/pa_mpjpe_mm", "val/accel_mm_per_frame2", "val/proj2d_px", "loss/opt", "loss/bone",
            "loss/total"} <= set(initial)  # fmt: skip
    torch.testing.assert_close(model.joints.detach()[:, 0], scene.joints3d / 1000.0)  # person 0 of 1
    make_trainer(40, early_stop=False).fit(model, datamodule=PoseData(scene, "gt"))
    assert model.result.metrics_before["mpjpe_mm"] == pytest.approx(initial["val/mpjpe_mm"], rel=1e-5)
    refined = model.joints.detach().clone()
    after = quiet_trainer().validate(model, datamodule=PoseData(scene, "gt"), verbose=False)[0]
    assert after["val/mpjpe_mm"] == pytest.approx(model.result.metrics_after["mpjpe_mm"], rel=1e-5)
    assert after["val/mpjpe_mm"] != pytest.approx(initial["val/mpjpe_mm"], abs=0.1)  # the poses did move
    assert after["loss/total"] < initial["loss/total"]
    assert torch.equal(model.joints.detach(), refined)
    other = make_scene(motion="walk", frames=4, height=64, width=96, seed=1)  # another scene: rebuilt from it
    quiet_trainer().validate(model, datamodule=PoseData(other, "gt"), verbose=False)
    torch.testing.assert_close(model.joints.detach()[:, 0], other.joints3d / 1000.0)


def printed_metric(text: str, name: str) -> float:
    line = next(line for line in text.splitlines() if line.split() and line.split()[0] == name)
    return float(line.split()[-1])


@pytest.mark.parametrize("config, metric", [("pose_refiner", "mpjpe_mm"), ("pose_refiner_2d", "kp2d_px")])
def test_cli_validate_prints_the_initial_estimates_errors(config, metric, scene, scene_dir, tmp_path, capsys):
    argv = ["validate", "--config", f"configs/{config}.yaml", "--data.scene", str(scene_dir), "--data.flows", "gt",
            "--trainer.default_root_dir", str(tmp_path), "--trainer.logger", "false",
            "--trainer.enable_progress_bar", "false"]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    model = PoseRefiner() if config == "pose_refiner" else KeypointRefiner()
    model.prepare(scene, scene.gt.flow)
    assert printed_metric(out, f"val/{metric}") == pytest.approx(model.evaluate()[metric], rel=1e-5)
    assert printed_metric(out, "loss/total") == pytest.approx(model.final_loss()["total"], rel=1e-4)
    assert not list(tmp_path.rglob("pose_report.json"))  # validation saves nothing


def test_the_top_level_package_exports_the_flow_bootstrap_and_reader_api():
    import lit_boot.bootstrap as bootstrap_pkg
    import lit_boot.data.readers as readers
    import lit_boot.flow as flow

    homes = {flow: ("FlowTTT", "SketchConfig"), bootstrap_pkg: ("Bootstrap", "BootstrapConfig", "BootstrapResult"),
             readers: ("read_video", "read_estimates", "PoseEstimates")}  # fmt: skip
    for module, names in homes.items():
        for name in names:
            assert getattr(lit_boot, name) is getattr(module, name) and name in lit_boot.__all__
    assert lit_boot.bootstrap is bootstrap_pkg  # the subpackage is not shadowed by a function
    undocumented = [n for n in lit_boot.__all__ if n != "__version__" and not getattr(lit_boot, n).__doc__]
    assert not undocumented
