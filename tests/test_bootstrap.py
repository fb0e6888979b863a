"""The orchestrator on tiny synthetic scenes (CPU): stages, outputs, resume, guard, ensembles."""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import logging

import cv2
import pytest
import torch

import lit_boot
from lit_boot.bootstrap import Bootstrap, BootstrapConfig, agreement, bootstrap
from lit_boot.bootstrap import runner as runner_module
from lit_boot.bootstrap.ensemble import average_poses
from lit_boot.data.readers import PoseEstimates
from lit_boot.pose import PoseResult

FAST = dict(flow_epochs=1, pose_steps=15, progress_bar=False)
#: A randomly initialised RAFT-small: for the tests that check the orchestration, not the accuracy.
RANDOM_RAFT = {"weights": None, "train_updates": 2, "predict_updates": 3}


def fast_flow(shared):
    """Real RAFT-small weights: for the tests that assert an improvement."""
    return {**RANDOM_RAFT, "weights": str(shared / "checkpoints/raft-small.pth")}


@pytest.fixture(scope="module")
def tiny_scene():
    return lit_boot.make_scene(motion="run", frames=4, height=64, width=96, seed=0)


def folder_digest(path):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(path.rglob("*")) if p.is_file()}


# --- settings ---------------------------------------------------------------------------------------


def test_config_stages_and_presets():
    assert BootstrapConfig().stages() == ["zoom", "flow_1", "pose_1", "flow_2"]
    assert BootstrapConfig(cycles=2, zoom={"method": "off"}).stages() == ["flow_1", "pose_1", "flow_2", "pose_2",
                                                                           "flow_3"]  # fmt: skip
    assert BootstrapConfig(mode="2d").epochs == 50 and BootstrapConfig().epochs == 8
    paper = BootstrapConfig(preset="paper").flow_kwargs(person_px=90)
    assert paper["sketch"] == {"footprint": "square", "size": 30, "points_per_bone": 22}
    # default: the paper's cross of radius 15 at 450 px people, scaled to the person
    assert BootstrapConfig().flow_kwargs(person_px=90)["sketch"]["size"] == 3
    assert BootstrapConfig().flow_kwargs(person_px=900)["sketch"]["size"] == 30
    assert BootstrapConfig().flow_kwargs(person_px=10)["sketch"]["size"] == 2
    # a user's size wins, other sketch keys kept from the preset
    user = BootstrapConfig(flow={"sketch": {"size": 7}, "lr": 1e-4}).flow_kwargs(person_px=90)
    assert user["sketch"] == {"footprint": "cross", "size": 7} and user["lr"] == 1e-4
    member = BootstrapConfig(flow={"lr": 1e-4}, flow_ensemble=[{"arch": "raft_large"}]).flow_kwargs(1)
    assert member["arch"] == "raft_large" and member["lr"] == 1e-4


@pytest.mark.parametrize(
    "bad, word", [({"mode": "4d"}, "mode"), ({"preset": "x"}, "preset"), ({"cycles": -1}, "cycles"),
                  ({"drift_guard": "x"}, "drift_guard"), ({"pose_steps": 0}, "pose_steps"),
                  ({"accelerator": "tpu"}, "^accelerator: "), ({"pose_accelerator": "cuda:0"}, "^pose_accelerator: "),
                  ({"precision": "16mixed"}, "^precision: "), ({"precision": 16.0}, "^precision: "),
                  ({"precision": True}, "^precision: ")],  # fmt: skip
)
def test_config_rejects_bad_values(bad, word):
    with pytest.raises(ValueError, match=word):
        BootstrapConfig(**bad)


def test_config_takes_every_accelerator_and_lightning_precision():
    for accelerator in ("auto", "cpu", "cuda", "gpu", "mps"):
        assert BootstrapConfig(accelerator=accelerator, pose_accelerator=accelerator).accelerator == accelerator
    for precision in (None, "32-true", "16-mixed", "bf16-mixed", "16-true", "bf16-true", "64-true", "32", "16", "bf16",
                      "64", 32, 16, 64):  # fmt: skip
        assert BootstrapConfig(precision=precision).precision == precision


# --- measurements ------------------------------------------------------------------------------------


def test_agreement_is_zero_for_poses_moving_with_the_flow_and_measures_the_offset():
    flows = torch.zeros(2, 2, 32, 48)
    flows[:, 0], flows[:, 1] = 2.0, -1.0
    points = torch.tensor([[[10.0, 10.0], [20.0, 15.0]]]).repeat(3, 1, 1)
    points[1] += torch.tensor([2.0, -1.0])
    points[2] += torch.tensor([4.0, -2.0])
    keep = torch.ones(3, 2, dtype=torch.bool)
    assert agreement(flows, points, keep) == pytest.approx(0.0, abs=1e-5)
    shifted = points.clone()
    shifted[1:] += torch.tensor([3.0, 4.0])  # frame 1 and 2 off by 5 px: pair 0 disagrees by 5, pair 1 by 0
    assert agreement(flows, shifted, keep) == pytest.approx(2.5, abs=1e-4)
    keep[0] = False  # pair 0 no longer counts
    assert agreement(flows, shifted, keep) == pytest.approx(0.0, abs=1e-5)


def test_pose_points_follow_the_mode(tiny_scene):
    p3, k3 = tiny_scene.pose_points("3d")
    assert p3.shape == (4, 14, 2) and k3.all() and tiny_scene.pose_layout("3d") == "lsp14"
    torch.testing.assert_close(p3, tiny_scene.cameras.project(tiny_scene.joints3d.float()))
    p2, k2 = tiny_scene.pose_points("2d")
    assert p2.shape == (4, 17, 2) and torch.equal(k2, tiny_scene.keypoints_conf > 0)
    assert tiny_scene.pose_layout("2d") == "coco17"
    with pytest.raises(ValueError, match="3D mode needs 3D joints with cameras"):
        dataclasses.replace(tiny_scene, cameras=None).pose_points("3d")
    with pytest.raises(ValueError, match="mode: expected one of"):
        tiny_scene.pose_points("4d")


def test_average_poses_means_the_estimates(tiny_scene, tmp_path):
    other = tiny_scene.joints3d + 10.0
    estimates = PoseEstimates(joints3d=other, cameras=tiny_scene.cameras)
    PoseResult("3d", estimates).save(tmp_path / "a")
    mean = average_poses(tiny_scene, [str(tmp_path / "a")], "3d")  # a refiner's folder
    assert torch.allclose(mean.joints3d, tiny_scene.joints3d + 5.0)
    mean = average_poses(tiny_scene, [str(tmp_path / "a" / "poses.npz")], "3d")  # or a pose file
    assert torch.allclose(mean.joints3d, tiny_scene.joints3d + 5.0)
    PoseResult("3d", estimates.take([0, 1])).save(tmp_path / "b")
    with pytest.raises(ValueError, match="joints3d shape"):
        average_poses(tiny_scene, [str(tmp_path / "b")], "3d")


# --- runs ---------------------------------------------------------------------------------------------


@pytest.mark.shared
def test_run_produces_every_output_and_improves_the_pose(shared, tiny_scene, tmp_path):
    scene_dir = lit_boot.save_scene(tiny_scene, tmp_path / "scene")
    before = folder_digest(scene_dir)
    result = Bootstrap(scene_dir, tmp_path / "run", flow=fast_flow(shared), **FAST).run()
    assert folder_digest(scene_dir) == before  # the input is never written
    run = tmp_path / "run"
    for name in ("config.json", "summary.json", "metrics.png", "overlay.mp4", "poses.npz", "pose_report.json",
                 "raft_finetuned.pt", "flows/flow_000000.flo", "flows/flow_000002.png"):  # fmt: skip
        assert (run / name).is_file(), name
    assert [r["stage"] for r in result.history] == ["initial", "zoom", "flow_1", "pose_1", "flow_2"]
    summary = json.loads((run / "summary.json").read_text())
    assert summary["speed"]["frames"] == 4 and summary["speed"]["ratio_to_raft"] > 1
    assert {"epe", "epe_person", "epe_joints", "mpjpe_mm", "agreement_px"} <= set(summary["before_after"])
    mpjpe0, mpjpe1 = summary["before_after"]["mpjpe_mm"]
    assert mpjpe1 < mpjpe0  # jittered estimates get smoother and closer to GT
    assert result.flows.shape == (3, 2, 64, 96) and not torch.equal(result.flows, result.initial_flows)
    assert torch.allclose(result.scene.joints3d, result.poses.joints3d)
    video = cv2.VideoCapture(str(run / "overlay.mp4"))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 3
    assert (run / "logs/tensorboard/summary").is_dir() and (run / "logs/csv/flow_1/metrics.csv").is_file()
    # the final weights load into a fresh network and give the final flow
    state = torch.load(run / "raft_finetuned.pt", weights_only=True)
    assert set(state) == set(lit_boot.flow.load_raft("raft_small", None).state_dict())


def test_interrupted_run_resumes_after_the_last_finished_stage(tiny_scene, tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("interrupted")

    monkeypatch.setattr(runner_module, "refine_poses_stage", broken)
    with pytest.raises(RuntimeError, match="interrupted"):
        bootstrap(tiny_scene, tmp_path / "run", flow=RANDOM_RAFT, video=False, **FAST)
    assert (tmp_path / "run/stages/flow_1/stage.json").is_file()
    assert not (tmp_path / "run/stages/pose_1").exists()
    monkeypatch.undo()
    built, starts = [], []  # the weights the resumed run's network is made with, and flow stages start from
    make, fine_tune = runner_module.make_flow_model, runner_module.fine_tune_flow

    def making(kwargs):
        model = make(kwargs)
        built.append({k: v.clone() for k, v in model.raft.state_dict().items()})
        return model

    def counting(model, *args, **kwargs):
        starts.append({k: v.clone() for k, v in model.raft.state_dict().items()})
        return fine_tune(model, *args, **kwargs)

    monkeypatch.setattr(runner_module, "make_flow_model", making)
    monkeypatch.setattr(runner_module, "fine_tune_flow", counting)
    result = bootstrap(tiny_scene, tmp_path / "run", flow=RANDOM_RAFT, video=False, **FAST)
    assert len(starts) == 1  # flow_2 only: flow_1 was loaded
    # ... and flow_2 continues from flow_1's tuned weights (restart_flow false), not from the network as made
    tuned = torch.load(tmp_path / "run/stages/flow_1/raft_0.pt", weights_only=True)
    assert not all(torch.equal(built[0][k], v) for k, v in tuned.items())  # flow_1 changed the weights
    assert all(torch.equal(starts[0][k], v) for k, v in tuned.items())
    assert [r["stage"] for r in result.history] == ["initial", "zoom", "flow_1", "pose_1", "flow_2"]
    # the summary dashboard holds each stage once, although the first run logged some of them too
    with open(tmp_path / "run/logs/csv/summary/metrics.csv") as f:
        assert [int(row["step"]) for row in csv.DictReader(f)] == [0, 1, 2, 3, 4]
    assert len(list((tmp_path / "run/logs/tensorboard/summary").glob("events.out.tfevents.*"))) == 1
    with pytest.raises(ValueError, match="cycles"):
        bootstrap(tiny_scene, tmp_path / "run", flow=RANDOM_RAFT, video=False, cycles=2, **FAST)


def test_drift_guard_rolls_back_a_stage_that_worsens_the_image_evidence(tiny_scene, tmp_path, monkeypatch, caplog,
                                                                        capsys):  # fmt: skip
    caplog.set_level(logging.INFO, logger="lit_boot")
    photo = iter([1.0, 0.9])  # initial, flow_1: the flow explains the frames better
    tracks = iter([1.0, 1.2])  # initial, pose_1: the joint tracks 20% worse
    monkeypatch.setattr(runner_module, "photo_error", lambda *a, **k: next(photo))
    monkeypatch.setattr(runner_module, "pose_track_error", lambda *a, **k: next(tracks))
    result = bootstrap(tiny_scene, tmp_path / "run", flow=RANDOM_RAFT, video=False, drift_guard="rollback",
                       drift_tolerance=0.1, zoom={"method": "off"}, **FAST)  # fmt: skip
    assert [r["stage"] for r in result.history] == ["initial", "flow_1", "pose_1"]
    assert result.history[-1]["rolled_back"] and result.poses is None
    assert torch.equal(result.scene.joints3d, tiny_scene.joints3d)  # the pose stage's output discarded
    summary = json.loads((tmp_path / "run/summary.json").read_text())
    assert summary["drift_guard_events"] == [{"stage": "pose_1", "guard": "drift", "evidence": "track_error",
                                              "before": 1.0, "after": 1.2, "action": "rollback"}]  # fmt: skip
    assert "joint tracks' census error rose 1.000 -> 1.200; pose_1 rolled back" in caplog.text  # logged, not printed
    assert "stage 1/3 flow_1" in caplog.text and "stage 1/3" not in capsys.readouterr().out


def test_drift_guard_records_a_stage_that_undoes_the_previous_ones_gain(tiny_scene, tmp_path, monkeypatch, caplog):
    caplog.set_level(logging.INFO, logger="lit_boot")
    photo = iter([1.0, 0.8, 0.9])  # initial, flow_1 (better), flow_2 (undoes half of flow_1's gain)
    monkeypatch.setattr(runner_module, "photo_error", lambda *a, **k: next(photo))
    monkeypatch.setattr(runner_module, "pose_track_error", lambda *a, **k: 1.0)
    result = bootstrap(tiny_scene, tmp_path / "run", flow=RANDOM_RAFT, video=False, zoom={"method": "off"}, **FAST)
    assert [r["stage"] for r in result.history] == ["initial", "flow_1", "pose_1", "flow_2"]  # the run went on
    summary = json.loads((tmp_path / "run/summary.json").read_text())
    assert summary["drift_guard_events"] == [{"stage": "flow_2", "guard": "drift", "evidence": "photo_error",
                                              "before": 0.8, "after": 0.9, "action": "record"}]  # fmt: skip
    assert "census error rose 0.800 -> 0.900 (recorded" in caplog.text


def test_drift_guard_tolerance_and_record(tmp_path):
    from lit_boot.bootstrap.guard import drift_guard

    history = [{"stage": "initial", "kind": "initial", "photo_error": 10.0, "track_error": 5.0},
               {"stage": "flow_1", "kind": "flow", "photo_error": 20.0, "rolled_back": True}]  # fmt: skip
    flow = {"stage": "flow_2", "kind": "flow", "photo_error": 10.4}
    # compared with the last kept stage that has the figure (the rolled-back flow_1 does not count)
    assert drift_guard(BootstrapConfig(drift_guard="stop", drift_tolerance=0.05), flow, history) is None
    event = drift_guard(BootstrapConfig(drift_guard="stop", drift_tolerance=0.03), flow, history)
    assert event == {"guard": "drift", "evidence": "photo_error", "before": 10.0, "after": 10.4, "action": "stop"}
    recorded = drift_guard(BootstrapConfig(drift_guard="record"), flow, history)  # the default: kept, not acted on
    assert recorded == {**event, "action": "record"}
    with pytest.raises(ValueError, match="drift_tolerance"):
        BootstrapConfig(drift_tolerance=-0.1)


def test_stage_records_hold_the_image_evidence(tiny_scene, tmp_path):
    from lit_boot.bootstrap.evaluate import photo_error, pose_track_error

    result = bootstrap(tiny_scene, tmp_path / "run", flow=RANDOM_RAFT, video=False, cycles=0, **FAST)
    initial, zoom, flow_1 = result.history
    assert 0 < zoom["photo_error"] <= initial["photo_error"]  # refused where the frames say RAFT's is better
    assert 0 < flow_1["photo_error"] < 48 and 0 < initial["track_error"] < 48
    # the GT flow explains the frames better than zero motion, the GT joint tracks better than
    # the same tracks with 2 px of jitter
    gt = tiny_scene.gt
    frames = tiny_scene.frames
    assert photo_error(frames, gt.flow) < photo_error(frames, torch.zeros_like(gt.flow))
    joints = gt.joints2d.float()
    keep = torch.ones(joints.shape[:2], dtype=torch.bool)
    jitter = joints + 2 * torch.randn(joints.shape, generator=torch.Generator().manual_seed(0))
    assert pose_track_error(frames, joints, keep) < pose_track_error(frames, jitter, keep) - 2


def test_2d_mode_with_a_flow_ensemble(tiny_scene, tmp_path):
    result = bootstrap(tiny_scene, tmp_path / "run", mode="2d", flow=RANDOM_RAFT, video=False,
                       flow_ensemble=[{"lr": 1e-4}], **FAST)  # fmt: skip
    assert result.poses.mode == "2d" and result.poses.keypoints2d.shape == (4, 17, 2)
    assert (tmp_path / "run/raft_finetuned.pt").is_file() and (tmp_path / "run/raft_finetuned_m1.pt").is_file()
    zoom, record = result.history[1:3]
    assert zoom["kind"] == "zoom" and record["kind"] == "flow" and "kp2d_px" in result.history[3]


def test_the_flow_ensemble_averages_every_members_flow(tiny_scene, tmp_path, monkeypatch):
    members: dict[int, int] = {}

    def constant(model, scene, **kwargs):  # member m "predicts" 1 + 2 m px everywhere, in every stage
        m = members.setdefault(id(model), len(members))
        return torch.full((scene.num_frames - 1, 2, scene.height, scene.width), 1.0 + 2.0 * m)

    monkeypatch.setattr(runner_module, "predict_flows", constant)
    result = bootstrap(tiny_scene, tmp_path / "run", flow=RANDOM_RAFT, video=False, cycles=0,
                       flow_ensemble=[{"lr": 1e-4}, {"lr": 1e-4}], self_check={"method": "off"}, **FAST)  # fmt: skip
    assert len(members) == 3
    assert torch.equal(result.initial_flows, torch.full_like(result.initial_flows, 3.0))  # (1 + 3 + 5) / 3
    assert torch.equal(result.flows, torch.full_like(result.flows, 3.0))  # the flow stage's too


# --- command line ---------------------------------------------------------------------------------


def test_bootstrap_cli_names_a_missing_scene_and_writes_nothing(tmp_path, capsys):
    from lit_boot.cli import main

    config = str(runner_module.Path(__file__).resolve().parents[1] / "configs/bootstrap.yaml")
    code = main(["bootstrap", "--config", config, "--data.scene", str(tmp_path / "nope"), "--out", str(tmp_path / "run")])
    assert code == 2 and str(tmp_path / "nope") in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.shared
def test_demo_runs_the_method_and_a_rerun_resumes(shared, tmp_path, capsys, monkeypatch):
    from lit_boot.cli import main

    monkeypatch.setenv("LIT_BOOT_CHECKPOINTS", str(shared / "checkpoints"))
    args = ["demo", "--out", str(tmp_path / "demo"), "--frames", "2", "--height", "64", "--width", "96", "--epochs", "1"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "| epe_person |" in out and "| mpjpe_mm |" in out and "stage 4/4 flow_2" in out
    assert (tmp_path / "demo/bootstrap/summary.json").is_file()
    assert main(args) == 0  # resumes: every stage is loaded, none runs
    assert "stage 1/4" not in capsys.readouterr().out
