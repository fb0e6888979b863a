"""Faults never cost a user their data: bad inputs write nothing, a failed run never blocks the
corrected rerun, NaN / inf in training rolls back to the last good state, and two runs never
write into one folder at once (tiny scenes, CPU; SIGKILL resume: tests/test_kill_resume.py)."""

from __future__ import annotations

import hashlib
import json
import os
import socket
import subprocess
import sys

import lightning as L
import pytest
import torch

import lit_boot
from lit_boot.bootstrap import bootstrap
from lit_boot.bootstrap import runner as runner_module
from lit_boot.bootstrap.lock import RunLock, RunLockedError
from lit_boot.data import read_flows
from lit_boot.finite import FiniteGuard
from lit_boot.flow import FlowTTT, SceneFlowData, SketchConfig, SketchLoss
from lit_boot.optim import adam
from lit_boot.pose import PoseData, PoseRefiner, load_pose_result, make_trainer

RANDOM_RAFT = {"weights": None, "train_updates": 2, "predict_updates": 3}  # no weights file needed
FAST = dict(flow_epochs=1, pose_steps=15, progress_bar=False, video=False, accelerator="cpu")


@pytest.fixture(scope="module")
def tiny_scene():
    return lit_boot.make_scene(motion="run", frames=4, height=64, width=96, seed=0)


def folder_digest(path):
    files = [p for p in sorted(path.rglob("*")) if p.is_file()]
    return {str(p.relative_to(path)): hashlib.sha256(p.read_bytes()).hexdigest() for p in files}


class Snapshots(L.Callback):
    """The tensors FiniteGuard tracks, copied after every training step, by global step."""

    def __init__(self):
        self.after: dict[int, list[torch.Tensor]] = {}

    def on_train_start(self, trainer, pl_module):
        self.after[trainer.global_step] = [t.detach().clone() for t in FiniteGuard.tracked(pl_module)]

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx):
        self.after[trainer.global_step] = [t.detach().clone() for t in FiniteGuard.tracked(pl_module)]


def same(a: list[torch.Tensor], b: list[torch.Tensor]) -> bool:
    return all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


def guard_of(trainer: L.Trainer) -> FiniteGuard:
    return next(c for c in trainer.callbacks if isinstance(c, FiniteGuard))


# --- NaN / inf in training: FiniteGuard --------------------------------------------------------------


def test_flow_ttt_stops_at_a_nan_loss_with_the_last_good_weights(tiny_scene):
    torch.manual_seed(0)
    model = FlowTTT(lr=1e-3, sketch=SketchConfig(size=3, guard=False), **RANDOM_RAFT)
    loss, calls = model.loss_fn.forward, []

    def nan_at_the_third_step(*args):
        calls.append(1)
        return loss(*args) * (float("nan") if len(calls) == 3 else 1.0)

    model.loss_fn.forward = nan_at_the_third_step
    snapshots = Snapshots()
    trainer = L.Trainer(max_epochs=2, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                        enable_model_summary=False, limit_val_batches=0, callbacks=[snapshots])  # fmt: skip
    with pytest.warns(UserWarning, match="non-finite loss at step 2.*weights of step 2 restored"):
        trainer.fit(model, datamodule=SceneFlowData(tiny_scene, pose_source="joints3d"))
    assert guard_of(trainer).fault == {"what": "loss", "step": 2, "good_steps": 2, "value": "nan"}
    assert len(calls) == 3 and trainer.global_step == 3  # stopped after the bad step (6 were planned)
    now = FiniteGuard.tracked(model)
    assert not all(t.isfinite().all() for t in snapshots.after[3] if t.is_floating_point())  # the bad step's
    assert same(now, snapshots.after[2]) and not same(now, snapshots.after[1])  # the last good step's weights


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_the_guards_largest_value_sees_a_single_non_finite_entry(bad):
    from lit_boot.finite import _max_abs

    tensors = [torch.randn(3, 4), torch.zeros(0), torch.randn(5, dtype=torch.float64)]
    assert float(_max_abs(tensors)) == pytest.approx(max(float(t.abs().max()) for t in tensors if t.numel()))
    tensors[2][3] = bad
    assert not torch.isfinite(_max_abs(tensors))
    assert float(_max_abs([torch.zeros(0)])) == 0.0


def test_both_optimisations_use_the_fused_adam_on_cpu():
    model = FlowTTT(train_parts="update_block", **RANDOM_RAFT)
    flow = model.configure_optimizers()
    assert flow.defaults["fused"] and adam([torch.nn.Parameter(torch.zeros(3))], lr=0.1).defaults["fused"]
    trained = {id(p) for group in flow.param_groups for p in group["params"]}
    assert trained == {id(p) for p in model.raft.update_block.parameters()}


def test_adam_on_cpu_steps_as_torch_without_asking_for_an_accelerator(monkeypatch):
    """lit-boot's Adam skips torch's graph-capture check on CPU parameters (an NVML query per
    step) and otherwise steps exactly as torch's."""
    torch.manual_seed(0)
    ours = torch.nn.Parameter(torch.randn(5))
    theirs = torch.nn.Parameter(ours.detach().clone())
    mine, reference = adam([ours], lr=0.1), torch.optim.Adam([theirs], lr=0.1, fused=True)
    for _ in range(3):
        for p, opt in ((ours, mine), (theirs, reference)):
            opt.zero_grad()
            (p**3).sum().backward()
            opt.step()
    assert torch.equal(ours, theirs) and not torch.equal(ours, torch.zeros(5))

    def asked() -> bool:
        raise AssertionError("the accelerator was queried")

    monkeypatch.setattr(torch.accelerator, "is_available", asked)
    with pytest.raises(AssertionError, match="queried"):
        reference.step()  # torch's own Adam asks at every step
    mine.step()


def test_pose_refiner_keeps_the_last_finite_poses_at_a_nan_loss(tiny_scene):
    refiner = PoseRefiner(save=False)
    total_loss = refiner.total_loss

    def nan_at_step_5(with_terms=False):
        loss, terms = total_loss(with_terms)
        return (loss * float("nan"), terms) if refiner.training and refiner.global_step == 5 else (loss, terms)

    refiner.total_loss = nan_at_step_5
    snapshots = Snapshots()
    trainer = make_trainer(10, early_stop=False, callbacks=[snapshots])
    with pytest.warns(UserWarning, match="non-finite loss at step 5"):
        trainer.fit(refiner, datamodule=PoseData(tiny_scene, "gt", steps=10))
    assert guard_of(trainer).fault["what"] == "loss" and trainer.global_step == 6
    assert same(FiniteGuard.tracked(refiner), snapshots.after[5]) and not same(snapshots.after[5], snapshots.after[4])
    assert refiner.result.steps == 5 and torch.equal(refiner.result.joints3d, snapshots.after[5][0][:, 0] * 1000.0)


def test_an_infinite_gradient_stops_the_refiner_too(tiny_scene):
    class InfiniteGradient(L.Callback):
        def on_after_backward(self, trainer, pl_module):
            if trainer.global_step == 3:
                pl_module.joints.grad[0, 0, 0] = float("inf")

    refiner, snapshots = PoseRefiner(save=False), Snapshots()
    trainer = make_trainer(10, early_stop=False, callbacks=[InfiniteGradient(), snapshots])
    with pytest.warns(UserWarning, match="non-finite gradient at step 3"):
        trainer.fit(refiner, datamodule=PoseData(tiny_scene, "gt", steps=10))
    assert guard_of(trainer).fault["what"] == "gradient" and refiner.result.steps == 3
    assert same(FiniteGuard.tracked(refiner), snapshots.after[3])


@pytest.mark.parametrize("stage", ["pose_1", "flow_2"])
def test_a_stage_with_a_nan_is_rolled_back_and_recorded(stage, tiny_scene, tmp_path, monkeypatch, caplog):
    if stage == "pose_1":
        total_loss = PoseRefiner.total_loss

        def nan_loss(self, with_terms=False):
            loss, terms = total_loss(self, with_terms)
            return (loss * float("nan"), terms) if self.training and self.global_step == 3 else (loss, terms)

        monkeypatch.setattr(PoseRefiner, "total_loss", nan_loss)
    else:
        loss, calls = SketchLoss.forward, []

        def nan_loss(self, *args):  # flow_1 takes 3 steps: the 5th is flow_2's second
            calls.append(1)
            return loss(self, *args) * (float("nan") if len(calls) == 5 else 1.0)

        monkeypatch.setattr(SketchLoss, "forward", nan_loss)
    run = tmp_path / "run"
    with pytest.warns(UserWarning, match="FiniteGuard: non-finite loss"):
        result = bootstrap(tiny_scene, run, flow=RANDOM_RAFT, **FAST)
    last = result.history[-1]
    assert last["stage"] == stage and last["rolled_back"] and len(result.history) == 4 + (stage == "flow_2")
    step = 3 if stage == "pose_1" else 1
    assert last["guard"] == {"guard": "finite", "action": "rollback", "what": "loss", "step": step, "good_steps": step,
                             "value": "nan"}  # fmt: skip
    logged = caplog.text  # a warning of lit_boot.bootstrap.runner (the CLI shows it)
    assert "finite guard: " in logged and f"{stage} rolled back (its output discarded), run stopped" in logged
    summary = json.loads((run / "summary.json").read_text())
    # the finite guard's event last; before it only the drift guard's records (the run went on)
    assert summary["drift_guard_events"][-1] == {"stage": stage, **last["guard"]}
    assert all(e["action"] == "record" for e in summary["drift_guard_events"][:-1])
    assert summary["stages"][-1]["rolled_back"]
    flow_1 = read_flows(run / "stages/flow_1/flows.npz")
    assert torch.equal(result.flows, flow_1)  # the previous flows kept
    assert (run / "raft_finetuned.pt").read_bytes() == (run / "stages/flow_1/raft_0.pt").read_bytes()
    if stage == "flow_2":
        assert torch.equal(result.poses.joints3d, load_pose_result(run / "stages/pose_1").joints3d)
        assert torch.equal(load_pose_result(run).joints3d, result.poses.joints3d)
        return
    assert result.poses is None and torch.equal(result.scene.joints3d, tiny_scene.joints3d)
    assert not (run / "poses.npz").exists() and not (run / "stages/pose_1/poses.npz").exists()
    monkeypatch.undo()
    again = bootstrap(tiny_scene, run, flow=RANDOM_RAFT, **FAST)  # a rerun reprints: the record is kept
    assert [r["stage"] for r in again.history] == ["initial", "zoom", "flow_1", "pose_1"] and again.history[-1]["rolled_back"]


# --- bad input writes nothing; a failed run never blocks the corrected rerun -----------------------------


def test_bad_inputs_create_no_run_folder(tiny_scene, tmp_path):
    run = tmp_path / "run"
    garbage = tmp_path / "garbage.pth"
    garbage.write_bytes(b"not a checkpoint")
    nan_weights = tmp_path / "nan.pth"
    state = lit_boot.flow.load_raft("raft_small", None).state_dict()
    state[next(k for k, v in state.items() if v.is_floating_point())].fill_(float("nan"))
    torch.save(state, nan_weights)
    bad = [
        (tmp_path / "no_scene", {}, "no_scene"),
        (tiny_scene, {"flow": {"weights": str(tmp_path / "missing.pth")}}, "missing.pth"),
        (tiny_scene, {"flow": {"weights": str(garbage)}}, "garbage.pth"),
        (tiny_scene, {"flow": {"weights": str(nan_weights)}}, "NaN"),
        (tiny_scene, {"flow": {**RANDOM_RAFT, "loss": "l3"}}, "loss"),
        (tiny_scene, {"flow": RANDOM_RAFT, "pose": {"lr": -1.0}}, "lr"),
        (tiny_scene, {"flow": RANDOM_RAFT, "pose_ensemble": [str(tmp_path / "no_poses")]}, "no_poses"),
    ]  # fmt: skip
    for scene, options, word in bad:
        with pytest.raises((OSError, ValueError, TypeError), match=word):
            bootstrap(scene, run, **{**FAST, **options})
        assert not run.exists(), options
    result = bootstrap(tiny_scene, run, flow=RANDOM_RAFT, cycles=0, **FAST)  # the corrected rerun
    assert [r["stage"] for r in result.history] == ["initial", "zoom", "flow_1"]


def test_a_run_that_finished_no_stage_is_replaced_by_a_rerun_with_other_settings(tiny_scene, tmp_path, monkeypatch):
    def crash(*args, **kwargs):
        raise RuntimeError("crashed")

    run = tmp_path / "run"
    monkeypatch.setattr(runner_module, "predict_flows", crash)
    with pytest.raises(RuntimeError, match="crashed"):
        bootstrap(tiny_scene, run, flow=RANDOM_RAFT, cycles=0, **FAST)
    assert (run / "config.json").is_file() and not list(run.rglob("stage.json"))
    monkeypatch.undo()
    result = bootstrap(tiny_scene, run, flow=RANDOM_RAFT, cycles=0, **{**FAST, "flow_epochs": 2})
    assert json.loads((run / "config.json").read_text())["config"]["flow_epochs"] == 2
    assert result.history[-1]["stage"] == "flow_1"
    (run / ".lock").unlink()  # as a run of an older version left it
    before = folder_digest(run)
    with pytest.raises(ValueError, match="flow_epochs"):  # a finished stage: other settings are refused
        bootstrap(tiny_scene, run, flow=RANDOM_RAFT, cycles=0, **FAST)
    assert folder_digest(run) == before  # and nothing is written, not even the lock file


def test_a_folder_that_holds_no_run_is_never_written_even_with_overwrite(tiny_scene, tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    with pytest.raises(FileExistsError, match="holds no lit-boot run"):
        bootstrap(tiny_scene, mine, flow=RANDOM_RAFT, overwrite=True, **FAST)
    assert [p.name for p in mine.iterdir()] == ["thesis.tex"]


# --- one run at a time per folder ------------------------------------------------------------------------


def test_a_second_run_into_a_locked_folder_is_refused_and_writes_nothing(tiny_scene, tmp_path):
    run = tmp_path / "run"
    bootstrap(tiny_scene, run, flow=RANDOM_RAFT, cycles=0, **FAST)
    with RunLock(run):  # another open of the lock conflicts, in this process too
        before = folder_digest(run)
        for overwrite in (False, True):
            with pytest.raises(RunLockedError, match=f"{run}.*pid {os.getpid()} on {socket.gethostname()}"):
                bootstrap(tiny_scene, run, flow=RANDOM_RAFT, cycles=0, overwrite=overwrite, **FAST)
        assert folder_digest(run) == before


def test_the_lock_of_a_killed_process_does_not_block(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    holder = ("import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT); "
              "fcntl.flock(fd, fcntl.LOCK_EX); os.write(fd, b'pid %d on elsewhere' % os.getpid()); "
              "print('locked', flush=True); time.sleep(60)")  # fmt: skip
    process = subprocess.Popen([sys.executable, "-c", holder, str(run / ".lock")], stdout=subprocess.PIPE, text=True)
    try:
        assert process.stdout.readline() == "locked\n"
        with pytest.raises(RunLockedError, match=f"pid {process.pid} on elsewhere"):
            RunLock(run).acquire()
    finally:
        process.kill()  # SIGKILL: no clean-up runs in the holder
        process.wait()
    with RunLock(run) as lock:
        assert lock.held and f"pid {os.getpid()} " in (run / ".lock").read_text()


def test_an_atomic_write_cut_short_leaves_the_old_file_whole_and_no_leftover(tmp_path, monkeypatch):
    from lit_boot.data import atomic
    from lit_boot.data.atomic import atomic_directory, atomic_file, atomic_write_bytes

    target = tmp_path / "summary.json"
    target.write_bytes(b"old")
    with pytest.raises(KeyboardInterrupt), atomic_file(target) as tmp:
        assert tmp != target and tmp.parent == target.parent  # written beside the target, not into it
        tmp.write_bytes(b"new but half")
        raise KeyboardInterrupt  # as if killed mid-write
    assert target.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]

    def killed(src, dst):  # killed just before the rename: everything was written, but not in place
        raise KeyboardInterrupt

    monkeypatch.setattr(atomic.os, "replace", killed)
    with pytest.raises(KeyboardInterrupt):
        atomic_write_bytes(target, b"new")
    assert target.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]
    monkeypatch.undo()
    assert atomic_write_bytes(target, b"new") == target and target.read_bytes() == b"new"

    folder = tmp_path / "flows"
    folder.mkdir()
    (folder / "flow_000000.flo").write_bytes(b"old")
    with pytest.raises(KeyboardInterrupt), atomic_directory(folder, overwrite=True) as tmp:
        assert tmp != folder
        (tmp / "flow_000000.flo").write_bytes(b"new")
        raise KeyboardInterrupt
    assert [p.read_bytes() for p in folder.iterdir()] == [b"old"] and len(list(tmp_path.iterdir())) == 2


def test_remove_partials_clears_unfinished_writes_only(tmp_path):
    from lit_boot.data.atomic import atomic_write_bytes, remove_partials

    (tmp_path / "stages/flow_1").mkdir(parents=True)
    atomic_write_bytes(tmp_path / "stages/flow_1/flows.npz", b"done")
    leftovers = [tmp_path / ".summary.json.0123456789ab.partial.json",
                 tmp_path / "stages/flow_1/.raft_0.pt.abcdefabcdef.partial.pt"]
    for path in leftovers:
        path.write_bytes(b"half")
    (tmp_path / ".flows.fedcba987654.partial").mkdir()
    (tmp_path / ".flows.fedcba987654.partial/flow_000000.flo").write_bytes(b"half")
    aside = tmp_path / ".poses.001122334455.old"  # a folder moved aside may be the only copy: kept
    aside.mkdir()
    removed = remove_partials(tmp_path)
    assert sorted(removed) == sorted([*leftovers, tmp_path / ".flows.fedcba987654.partial"])
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["flows.npz"] and aside.is_dir()


def test_an_overwrite_cut_short_leaves_a_run_any_rerun_takes_over(tmp_path, monkeypatch):
    from lit_boot.bootstrap import folder as folder_module
    from lit_boot.bootstrap.folder import RunFolder

    run = tmp_path / "run"
    (run / "stages/flow_1").mkdir(parents=True)
    (run / "stages/flow_1/stage.json").write_text("{}")
    (run / "summary.json").write_text("{}")
    (run / "config.json").write_text(json.dumps({"scene": "a", "config": {"cycles": 1}}))
    rename, moves = os.rename, []

    def crash_after_the_first_move(src, dst):
        if moves:
            raise KeyboardInterrupt  # as if killed here
        moves.append(src)
        return rename(src, dst)

    monkeypatch.setattr(folder_module.os, "rename", crash_after_the_first_move)
    with pytest.raises(KeyboardInterrupt):
        RunFolder(run, overwrite=True).prepare({"scene": "a", "config": {"cycles": 2}})
    monkeypatch.undo()
    assert [p.name for p in moves] == ["stages"] and (run / "config.json").is_file()
    RunFolder(run).check({"scene": "a", "config": {"cycles": 3}})  # a run that finished no stage: not refused
    RunFolder(run).prepare({"scene": "a", "config": {"cycles": 3}})  # finished no stage: replaced
    assert sorted(p.name for p in run.iterdir()) == ["config.json"]
    assert json.loads((run / "config.json").read_text())["config"] == {"cycles": 3}
