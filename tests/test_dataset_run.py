"""Dataset runs (lit_boot.dataset): engines, the manifest, merged metrics, reruns, lost workers.

Tiny synthetic scene folders (exact GT) and a random-weight RAFT, so no weights file is needed.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import torch

import lit_boot
from lit_boot.data import read_flows
from lit_boot.dataset import Task, run_dataset
from lit_boot.dataset.engines import LocalEngine, RayEngine
from lit_boot.dataset.manifest import Manifest, SettingsChangedError
from lit_boot.metrics import FlowMetrics

CONFIG = dict(flow_epochs=1, pose_steps=15, video=False, accelerator="cpu",
              flow={"weights": None, "train_updates": 2, "predict_updates": 3})  # fmt: skip
SIZES = [(4, 64, 96), (3, 64, 80), (5, 64, 96)]  # frames, height, width: pooling must weigh pixels


@pytest.fixture(scope="module")
def scene_dirs(tmp_path_factory):
    root = tmp_path_factory.mktemp("scenes")
    dirs = []
    for i, (frames, height, width) in enumerate(SIZES):
        scene = lit_boot.make_scene(motion=("run", "walk", "jump")[i], frames=frames, height=height, width=width, seed=i)
        lit_boot.save_scene(scene, root / f"s{i}")
        dirs.append(root / f"s{i}")
    return dirs


def tasks_of(dirs):
    return [Task(name=d.name, kind="scene", args={"path": str(d)}) for d in dirs]


@pytest.fixture(scope="module")
def reference(scene_dirs, tmp_path_factory):
    """The default: one worker process, the tasks in sequence; the others must reproduce it."""
    out = tmp_path_factory.mktemp("ref") / "data"
    return run_dataset(tasks_of(scene_dirs), out, CONFIG, workers=1, threads=1)


def pooled_epe(dirs, out, which="final"):
    """EPE over every pair of every scene in one FlowMetrics: what the merged metrics must equal."""
    metrics = FlowMetrics()
    for d in dirs:
        gt = lit_boot.load_scene(d).gt
        run = out / "scenes" / d.name
        flows = read_flows(run / "stages" / "initial" / "flows.npz") if which == "initial" else read_flows(run / "flows")
        metrics.update(flows, gt.flow, gt.flow_mask(), gt.person_mask[:-1])
    return {k: float(v) for k, v in metrics.compute().items()}


def test_merged_metrics_equal_one_process_over_all_scenes(reference, scene_dirs):
    assert reference.counts["done"] == 3 and not reference.counts["failed"]
    for which in ("initial", "final"):
        pooled = pooled_epe(scene_dirs, reference.out, which)
        for name in ("epe", "epe_person", "epe_background"):
            assert reference.metrics[which][name] == pytest.approx(pooled[name], rel=1e-9)
    per_scene = [r for r in json.loads((reference.out / "manifest.json").read_text())["tasks"].values()]
    means = sum(r["result"]["before_after"]["epe"][1] for r in per_scene) / len(per_scene)
    assert abs(means - reference.metrics["final"]["epe"]) > 1e-6  # pooling is not the mean of the scenes
    table = reference.table()
    assert all(f"| s{i} " in table for i in range(3)) and "dataset" in table
    assert (reference.out / "summary.csv").is_file() and (reference.out / "dataset.json").is_file()


def test_two_worker_processes_give_the_same_results(reference, scene_dirs, tmp_path):
    engine = LocalEngine(workers=2, gpus=["7", "8"])  # on a CPU run the GPU ids are only passed on
    assert engine.threads == max(1, len(os.sched_getaffinity(0)) // 2)  # the cores split fairly
    result = run_dataset(tasks_of(scene_dirs), tmp_path / "data", CONFIG, engine=engine)
    assert result.counts["done"] == 3
    tasks = json.loads((tmp_path / "data" / "manifest.json").read_text())["tasks"]
    workers = [tasks[f"s{i}"]["result"]["worker"] for i in range(3)]
    assert {w["gpus"] for w in workers[:2]} == {"7", "8"}  # one GPU per worker slot
    assert all(w["threads"] == engine.threads for w in workers) and len({w["pid"] for w in workers}) == 3
    for which in ("initial", "final"):
        for name, value in reference.metrics[which].items():
            assert result.metrics[which][name] == pytest.approx(value, rel=1e-4, abs=1e-6), (which, name)
    logs = sorted(p.name for p in (tmp_path / "data" / "tasks").glob("*.log"))
    assert logs == ["s0.log", "s1.log", "s2.log"]


def test_a_rerun_after_completion_runs_nothing(reference, scene_dirs):
    class Counting(LocalEngine):
        started: list = []

        def run(self, jobs, on_start, on_end):
            self.started.extend(j.name for j in jobs)
            super().run(jobs, on_start, on_end)

    before = (reference.out / "manifest.json").read_text()
    engine = Counting(workers=0)
    again = run_dataset(tasks_of(scene_dirs), reference.out, CONFIG, engine=engine)
    assert engine.started == [] and again.metrics == reference.metrics
    assert json.loads((reference.out / "manifest.json").read_text())["tasks"] == json.loads(before)["tasks"]


def test_other_settings_are_refused_not_mixed(reference, scene_dirs):
    with pytest.raises(SettingsChangedError, match="flow_epochs"):
        run_dataset(tasks_of(scene_dirs), reference.out, {**CONFIG, "flow_epochs": 2}, workers=0)


def _children_started(log_dir, name):
    text = (log_dir / f"{name}.log").read_text() if (log_dir / f"{name}.log").is_file() else ""
    return [int(p) for p in re.findall(rf"task {name}: start \(pid (\d+)\)", text)]


def _run_killing_s2_once(out, **run):
    """run_dataset(**run) into ``out`` while a thread SIGKILLs s2's first worker mid-task."""
    killed = []

    def kill_first_worker_of_s2():
        deadline = time.time() + 300
        while time.time() < deadline and not killed:
            pids = _children_started(out / "tasks", "s2")
            if pids and (out / "scenes" / "s2" / "stages").is_dir():  # mid-task: its run has begun
                os.kill(pids[0], signal.SIGKILL)
                killed.append(pids[0])
            time.sleep(0.05)

    killer = threading.Thread(target=kill_first_worker_of_s2)
    killer.start()
    try:
        result = run_dataset(out=out, **run)
    finally:
        killer.join()
    assert killed, "the test never saw s2's worker running"
    tasks = json.loads((out / "manifest.json").read_text())["tasks"]
    assert {n: r["state"] for n, r in tasks.items()} == {"s0": "done", "s1": "done", "s2": "done"}
    assert len(_children_started(out / "tasks", "s2")) == 2  # killed once, run again once
    assert len(result.records) == 3
    return result, tasks


def test_a_killed_worker_is_retried_and_nothing_is_lost_or_duplicated(reference, scene_dirs, tmp_path):
    result, tasks = _run_killing_s2_once(tmp_path / "data", tasks=tasks_of(scene_dirs), config=CONFIG, workers=2,
                                         threads=1, retries=2)  # fmt: skip
    assert tasks["s2"]["attempts"] == 1 and tasks["s0"]["attempts"] == 0
    for name, value in reference.metrics["final"].items():
        assert result.metrics["final"][name] == pytest.approx(value, rel=1e-4, abs=1e-6), name


def test_a_bad_video_fails_its_own_task_and_the_others_go_on(scene_dirs, tmp_path):
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"not a video at all")
    tasks = [*tasks_of(scene_dirs[:1]), Task(name="broken", kind="video", args={"path": str(bad)})]
    result = run_dataset(tasks, tmp_path / "data", CONFIG, workers=0)
    tasks = json.loads((tmp_path / "data" / "manifest.json").read_text())["tasks"]
    assert tasks["s0"]["state"] == "done" and tasks["broken"]["state"] == "failed"
    assert "broken.mp4" in tasks["broken"]["error"]
    assert result.counts == {"done": 1, "failed": 1, "pending": 0, "running": 0}
    assert "broken.mp4" in (tmp_path / "data" / "summary.csv").read_text()


def test_a_task_that_ran_out_of_memory_is_run_again(scene_dirs, tmp_path, monkeypatch):
    from lit_boot.dataset import worker

    real, calls = worker._bootstrap, []

    def full_once(task, run_dir, config):  # the GPU was full the first time (another task on it)
        calls.append(task.name)
        if calls.count(task.name) == 1 and task.name == "s1":
            raise torch.OutOfMemoryError("CUDA out of memory. Tried to allocate 2.00 GiB")
        return real(task, run_dir, config)

    monkeypatch.setattr(worker, "_bootstrap", full_once)
    result = run_dataset(tasks_of(scene_dirs), tmp_path / "data", CONFIG, workers=0, retries=1)
    tasks = json.loads((tmp_path / "data" / "manifest.json").read_text())["tasks"]
    assert calls.count("s1") == 2 and tasks["s1"]["state"] == "done" and tasks["s1"]["attempts"] == 1
    assert result.counts["done"] == len(scene_dirs)
    log = (tmp_path / "data" / "tasks" / "s1.log").read_text()
    assert "ran out of memory" in log


def test_chunks_are_stitched_and_counted_once(tmp_path):
    scene = lit_boot.make_scene(motion="walk", frames=7, height=64, width=96, seed=3)
    lit_boot.save_scene(scene, tmp_path / "long")
    task = Task(name="long", kind="scene", args={"path": str(tmp_path / "long")})
    result = run_dataset([task], tmp_path / "data", CONFIG, workers=0, chunk_frames=4, chunk_overlap=2)
    tasks = json.loads((tmp_path / "data" / "manifest.json").read_text())["tasks"]
    chunks = tasks["long"]["chunks"]
    assert len(chunks) >= 2 and all(tasks[c]["state"] == "done" for c in chunks) and tasks["long"]["state"] == "done"
    assert [r["name"] for r in result.records] == ["long"] and result.records[0]["frames"] == 7
    flows = read_flows(tmp_path / "data" / "scenes" / "long" / "flows.npz")
    assert flows.shape == (6, 2, 64, 96)
    metrics = FlowMetrics()
    metrics.update(flows, scene.gt.flow, scene.gt.flow_mask(), scene.gt.person_mask[:-1])
    assert result.metrics["final"]["epe"] == pytest.approx(float(metrics.compute()["epe"]), rel=1e-9)
    poses = lit_boot.read_estimates(tmp_path / "data" / "scenes" / "long" / "poses.npz")
    assert poses.joints3d.shape[0] == 7 and torch.isfinite(poses.joints3d).all()


def test_ray_with_a_local_instance_gives_the_same_results_and_retries_a_killed_worker(
    reference, scene_dirs, tmp_path, monkeypatch
):
    ray = pytest.importorskip("ray", reason="needs the ray extra")
    running, most = set(), []
    mark = Manifest.mark

    def watched(self, name, state, **kw):  # how many tasks the manifest says are running at once
        (running.add if state == "running" else running.discard)(name)
        most.append(len(running))
        return mark(self, name, state, **kw)

    monkeypatch.setattr(Manifest, "mark", watched)
    try:
        result, tasks = _run_killing_s2_once(tmp_path / "data", tasks=tasks_of(scene_dirs), config=CONFIG,
                                             engine=RayEngine(workers=2, retries=2))  # Ray retries the lost task
    finally:
        ray.shutdown()
    assert tasks["s2"]["attempts"] == 0  # Ray's retry, not the driver's
    assert len(scene_dirs) > 2 and max(most) == 2  # 2 slots: a queued task is not "running"
    for which in ("initial", "final"):
        for name, value in reference.metrics[which].items():
            assert result.metrics[which][name] == pytest.approx(value, rel=1e-4, abs=1e-6), (which, name)


def test_the_command_prints_the_table_and_only_its_own_lines(reference, scene_dirs, tmp_path, capsys):
    from lit_boot.cli import main

    flow = json.dumps(CONFIG["flow"])
    args = ["bootstrap-many", "scenes", str(scene_dirs[0].parent), "--out", str(tmp_path / "data"), "--workers", "0",
            "--flow_epochs", "1", "--pose_steps", "15", "--video", "false", "--accelerator", "cpu", "--flow", flow]  # fmt: skip
    assert main(args) == 0
    out, err = capsys.readouterr()
    assert "| dataset | 3/3 done |" in out and "3 done; wrote" in out
    assert "GPU available" not in out + err and "Tip" not in out + err  # Lightning's lines stay in the task logs
    summary = json.loads((tmp_path / "data" / "dataset.json").read_text())
    assert summary["metrics"]["final"]["epe"] == pytest.approx(reference.metrics["final"]["epe"], rel=1e-4)
    assert main(["bootstrap-many", "nonsense", str(tmp_path)]) == 2
    assert "source 'nonsense'" in capsys.readouterr().err


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return not Path(f"/proc/{pid}/stat").is_file() or Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"


def test_a_killed_driver_takes_its_workers_along_and_a_rerun_completes(scene_dirs, tmp_path):
    out = tmp_path / "data"
    args = [sys.executable, "-m", "lit_boot.cli", "bootstrap-many", "scenes", str(scene_dirs[0].parent), "--out",
            str(out), "--workers", "2", "--threads", "1", "--flow_epochs", "1", "--video", "false", "--accelerator",
            "cpu", "--flow", json.dumps(CONFIG["flow"]),
            "--pose_steps", "1500", "--early_stop", "false"]  # a pose stage of seconds: the tasks outlast the kill  # fmt: skip
    driver = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline, running = time.time() + 300, []
    while time.time() < deadline and not running:  # one task done, another one mid-run
        done = [n for n in ("s0", "s1", "s2") if (out / "tasks" / f"{n}.json").is_file()]
        running = [pid for n in ("s0", "s1", "s2") if n not in done and (out / "scenes" / n / "stages").is_dir()
                   for pid in _children_started(out / "tasks", n)] if done else []  # fmt: skip
        time.sleep(0.05)
    assert running, "never saw one task done and another running"
    driver.send_signal(signal.SIGKILL)
    driver.wait()
    deadline = time.time() + 3  # the workers' watch polls every second
    while time.time() < deadline and any(_alive(pid) for pid in running):
        time.sleep(0.1)
    assert not any(_alive(pid) for pid in running), "a worker outlived its killed driver"
    assert not all((out / "tasks" / f"{n}.json").is_file() for n in ("s0", "s1", "s2"))
    rerun = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr[-2000:]
    tasks = json.loads((out / "manifest.json").read_text())["tasks"]
    assert {n: r["state"] for n, r in tasks.items()} == {"s0": "done", "s1": "done", "s2": "done"}
    assert "| dataset | 3/3 done |" in rerun.stdout and "2 done" not in rerun.stdout
    assert all(r["result"]["frames"] == SIZES[i][0] for i, r in enumerate(tasks.values()))


def test_a_multi_person_video_runs_chunked_and_keeps_every_person(tmp_path):
    scene = lit_boot.make_scene(motion="walk", frames=7, height=64, width=96, seed=3, people=2)
    lit_boot.save_scene(scene, tmp_path / "crowd")
    task = Task(name="crowd", kind="scene", args={"path": str(tmp_path / "crowd")})
    result = run_dataset([task], tmp_path / "data", CONFIG, workers=0, chunk_frames=4, chunk_overlap=2)
    assert result.records[0]["state"] == "done" and result.records[0]["frames"] == 7
    poses = lit_boot.read_estimates(tmp_path / "data" / "scenes" / "crowd" / "poses.npz")
    assert poses.num_people == 2 and [p.track_id for p in poses.people()] == [p.track_id for p in scene.people()]
    assert all(p.joints3d.shape[0] == 7 and torch.isfinite(p.joints3d).all() for p in poses.people())
    assert not torch.allclose(poses.others[0].joints3d, scene.others[0].joints3d)  # refined too
    assert "mpjpe_mm_all" in result.metrics["final"]
