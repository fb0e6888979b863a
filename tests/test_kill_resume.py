"""A bootstrap run killed with SIGKILL in any stage resumes to the uninterrupted run's result.

tests/kill_driver.py runs the same tiny run (3D mode, one cycle: initial, zoom, flow_1, pose_1,
flow_2, on the CPU, seeded, random-init RAFT so no weights are needed) in forked children and
kills each with SIGKILL at a named point, every child resuming what the previous one left;
this process runs the same settings uninterrupted, then resumes the killed run to the end and
compares everything but the timings: they are equal bit for bit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

import lit_boot
from lit_boot.bootstrap import bootstrap
from lit_boot.data import read_flo

DRIVER = Path(__file__).with_name("kill_driver.py")
OPTIONS = dict(flow={"weights": None, "train_updates": 2, "predict_updates": 3}, flow_epochs=1, pose_steps=15,
               progress_bar=False, video=False, accelerator="cpu", seed=3)  # fmt: skip
#: kill point -> the stages finished after the child killed there
POINTS = {
    "initial": [],
    "flow_1": ["initial", "zoom"],
    "pose_1": ["flow_1", "initial", "zoom"],
    "flow_2": ["flow_1", "initial", "pose_1", "zoom"],
    "flow_2:commit": ["flow_1", "initial", "pose_1", "zoom"],
    "outputs": ["flow_1", "flow_2", "initial", "pose_1", "zoom"],
}

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="the driver forks (POSIX)")


@pytest.fixture
def one_thread():
    """CPU results are bitwise reproducible at a fixed thread count: the driver runs with one."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def without_timings(record: dict) -> dict:
    info = {k: v for k, v in record["info"].items() if k not in ("seconds", "raft_seconds")}
    if "zoom" in info:  # the zoom stage's own timing
        info["zoom"] = {k: v for k, v in info["zoom"].items() if k != "seconds"}
    return {**record, "info": info}


def test_a_run_killed_in_any_stage_resumes_to_the_uninterrupted_result(tmp_path, one_thread):
    scene_dir = lit_boot.save_scene(lit_boot.make_scene(motion="run", frames=4, height=64, width=96, seed=0),
                                    tmp_path / "scene")  # fmt: skip
    run = tmp_path / "killed"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(DRIVER.parents[1])}
    driver = subprocess.Popen(
        [sys.executable, str(DRIVER), str(scene_dir), str(run), json.dumps(OPTIONS), *POINTS],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
    )  # fmt: skip
    reference = bootstrap(scene_dir, tmp_path / "reference", **OPTIONS)  # meanwhile, uninterrupted
    output, _ = driver.communicate(timeout=600)
    lines = [line for line in output.splitlines() if line.startswith("RESULT ")]
    assert lines, output[-4000:]
    report = json.loads(lines[-1].removeprefix("RESULT "))
    assert [r["killed"] for r in report] == [True] * len(POINTS), output[-4000:]
    assert {r["point"]: r["done"] for r in report} == POINTS  # each kill landed in its stage
    assert (run / "stages/flow_2/flows.npz").is_file()
    assert list(run.glob(".summary.json.*.partial.json"))  # the last kill's unfinished write
    assert not (run / "summary.json").exists()

    resumed = bootstrap(scene_dir, run, **OPTIONS)

    assert not list(run.rglob("*.partial*"))  # the leftover was cleared
    assert torch.equal(resumed.initial_flows, reference.initial_flows)
    assert torch.equal(resumed.flows, reference.flows) and not torch.equal(resumed.flows, resumed.initial_flows)
    assert torch.equal(resumed.poses.joints3d, reference.poses.joints3d)
    assert torch.equal(resumed.poses.cameras.params, reference.poses.cameras.params)
    for t in range(3):
        name = f"flows/flow_{t:06d}.flo"
        assert torch.equal(read_flo(run / name), read_flo(tmp_path / "reference" / name))
    weights = [torch.load(d / "raft_finetuned.pt", weights_only=True) for d in (run, tmp_path / "reference")]
    assert weights[0].keys() == weights[1].keys() and all(torch.equal(weights[0][k], weights[1][k]) for k in weights[0])
    with np.load(run / "poses.npz") as a, np.load(tmp_path / "reference/poses.npz") as b:
        assert a.files == b.files and all(np.array_equal(a[k], b[k]) for k in a.files)
    summaries = [json.loads((d / "summary.json").read_text()) for d in (run, tmp_path / "reference")]
    assert [without_timings(r) for r in summaries[0]["stages"]] == [without_timings(r) for r in summaries[1]["stages"]]
    assert summaries[0]["before_after"] == summaries[1]["before_after"]
