"""Reliability: bootstrap runs SIGKILLed at random moments, then resumed, against an
uninterrupted run of the same settings.

Usage:
  OMP_NUM_THREADS=1 python benchmarks/kill_resume.py [--trials 20] [--kills 3] [--frames 6]
      [--height 96 --width 128] [--weights ../shared/checkpoints/raft-small.pth] [--seed 0]

One synthetic scene, 3D mode, one cycle (initial, flow_1, pose_1, flow_2), CPU, seeded. This
process computes nothing itself (it forks, so it must stay free of torch work): a child runs the
reference; per trial, children run (or resume) the same settings into a fresh folder and are
killed with SIGKILL after a random delay (uniform over 0.6 times the reference's duration) up to
``--kills`` times, then one runs to the end. Per kill it notes where the run was (the first stage
without stage.json, or "outputs"); per trial whether every output equals the reference's
(final flows and poses, fine-tuned weights, every stage's flows/poses, summary metrics; timings
excluded) and whether interrupted writes left anything behind. Prints one JSON line.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import tempfile
import time
from pathlib import Path

import numpy as np

from lit_boot.bootstrap import bootstrap
from lit_boot.synth import make_scene
from lit_boot.data import save_scene

STAGES = ["initial", "flow_1", "pose_1", "flow_2"]


def run_child(scene: Path, run: Path, options: dict) -> int:
    """Fork a child running the bootstrap; its pid."""
    pid = os.fork()
    if pid == 0:
        try:
            bootstrap(scene, run, **options)
        except BaseException:  # noqa: BLE001
            os._exit(3)
        os._exit(0)
    return pid


def where(run: Path) -> str:
    """The first stage without stage.json, else "outputs"."""
    for name in STAGES:
        if not (run / "stages" / name / "stage.json").is_file():
            return name
    return "outputs" if not (run / "summary.json").is_file() else "done"


def arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as data:
        return {k: np.array(data[k]) for k in data.files}


def same_outputs(a: Path, b: Path) -> bool:
    """Whether two run folders hold the same results (timings excluded)."""
    files = ["raft_finetuned.pt", *(p.relative_to(a).as_posix() for p in sorted((a / "flows").glob("*.flo")))]
    if any((a / f).read_bytes() != (b / f).read_bytes() for f in files):
        return False
    for f in ["poses.npz", *(f"stages/{s}/flows.npz" for s in ("initial", "flow_1", "flow_2")), "stages/pose_1/poses.npz"]:
        x, y = arrays(a / f), arrays(b / f)
        if x.keys() != y.keys() or any(not np.array_equal(x[k], y[k]) for k in x):
            return False
    strip = lambda r: {**r, "info": {k: v for k, v in r["info"].items() if k != "seconds"}}  # noqa: E731
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    return [strip(r) for r in sa["stages"]] == [strip(r) for r in sb["stages"]] and sa["before_after"] == sb["before_after"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--kills", type=int, default=3, help="SIGKILLs per trial before the run may finish")
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--height", type=int, default=96)
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--weights", default=None, help="RAFT weights file (default: random initialisation)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    options = dict(flow={"weights": args.weights, "train_updates": 4, "predict_updates": 6}, flow_epochs=2,
                   pose_steps=100, progress_bar=False, video=False, accelerator="cpu", seed=args.seed)  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="lit_boot_kill_") as tmp:
        tmp = Path(tmp)
        scene = tmp / "scene"
        pid = os.fork()
        if pid == 0:  # torch work happens in children only
            save_scene(make_scene(motion="run", frames=args.frames, height=args.height, width=args.width, seed=0), scene)
            os._exit(0)
        os.waitpid(pid, 0)
        start = time.perf_counter()
        _, status = os.waitpid(run_child(scene, tmp / "reference", options), 0)
        duration = time.perf_counter() - start
        assert status == 0, "the reference run failed"
        kills: dict[str, int] = {}
        identical = leftovers = 0
        for trial in range(args.trials):
            run = tmp / f"trial_{trial}"
            for _ in range(args.kills):
                pid = run_child(scene, run, options)
                time.sleep(rng.uniform(0.0, 0.6 * duration))
                if os.waitpid(pid, os.WNOHANG) == (0, 0):  # still running
                    place = where(run)
                    os.kill(pid, signal.SIGKILL)
                    os.waitpid(pid, 0)
                    kills[place] = kills.get(place, 0) + 1
            _, status = os.waitpid(run_child(scene, run, options), 0)
            identical += status == 0 and same_outputs(run, tmp / "reference")
            leftovers += bool(list(run.rglob("*.partial*")))
        print(json.dumps({"trials": args.trials, "reference_s": round(duration, 2), "kills": sum(kills.values()),
                          "kills_by_place": kills, "identical_results": identical, "runs_with_leftovers": leftovers}))


if __name__ == "__main__":
    main()
