"""Kill bootstrap runs with SIGKILL at named points (driver of tests/test_kill_resume.py).

    python tests/kill_driver.py SCENE_DIR RUN_DIR OPTIONS_JSON POINT [POINT ...]

The driver imports lit-boot once and computes nothing itself. For each POINT in order it forks
a child that runs (or resumes) ``bootstrap(SCENE_DIR, RUN_DIR, **OPTIONS)`` and sends itself
SIGKILL at that point; no library code knows about it: the child patches a few functions
first. The last line printed is ``RESULT <json>``: per point, whether the child died of
SIGKILL, which stages had finished (stage.json written) after it, and its seconds.

Points: ``initial`` (RAFT inference of the initial stage), ``flow_1`` / ``flow_2`` (the second
FlowTTT training step of that stage), ``pose_1`` (the fifth refiner step), ``flow_2:commit``
(the stage's flows and weights written, its stage.json not yet), ``outputs`` (the final
summary.json written to its temporary file, not renamed into place).
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
import traceback
from pathlib import Path

from lit_boot.bootstrap import bootstrap
from lit_boot.bootstrap import runner
from lit_boot.flow import FlowTTT
from lit_boot.pose.base import RefinerBase


def die() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def arm(point: str, run: Path) -> None:
    """Patch, in this (child) process only, the place where ``point`` kills it."""
    stage, _, when = point.partition(":")
    current = {"stage": None, "calls": 0}
    header = runner.stage_header

    def tracking_header(index, total, name, what):
        current["stage"], current["calls"] = name, 0
        return header(index, total, name, what)

    runner.stage_header = tracking_header

    def kill_on_call(cls, method, nth):
        original = getattr(cls, method)

        def wrapper(self, *args, **kwargs):
            if current["stage"] == stage:
                current["calls"] += 1
                if current["calls"] == nth:
                    die()
            return original(self, *args, **kwargs)

        setattr(cls, method, wrapper)

    if when == "commit":
        write = runner.RunFolder.write_record

        def write_record(self, name, record):
            if name == stage:
                die()
            return write(self, name, record)

        runner.RunFolder.write_record = write_record
    elif stage == "outputs":
        replace = os.replace

        def killing_replace(src, dst, *args, **kwargs):
            if Path(dst) == run / "summary.json":
                die()
            return replace(src, dst, *args, **kwargs)

        os.replace = killing_replace
    elif stage == "initial":
        kill_on_call(FlowTTT, "predict_step", 1)
    elif stage.startswith("flow"):
        kill_on_call(FlowTTT, "training_step", 2)
    elif stage.startswith("pose"):
        kill_on_call(RefinerBase, "training_step", 5)
    else:
        raise ValueError(f"unknown kill point {point!r}")


def child(scene: str, run: Path, options: dict, point: str) -> None:
    try:
        arm(point, run)
        bootstrap(scene, run, **options)
    except BaseException:  # noqa: BLE001 - report and leave with a code the parent tells apart
        traceback.print_exc()
        os._exit(3)
    os._exit(0)  # the run ended without reaching the point


def main(argv: list[str]) -> None:
    scene, run, options, points = argv[0], Path(argv[1]), json.loads(argv[2]), argv[3:]
    report = []
    for point in points:
        sys.stdout.flush()
        sys.stderr.flush()
        start = time.perf_counter()
        pid = os.fork()
        if pid == 0:
            child(scene, run, options, point)
        _, status = os.waitpid(pid, 0)
        killed = os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL
        done = sorted(p.parent.name for p in run.glob("stages/*/stage.json"))
        seconds = round(time.perf_counter() - start, 2)
        report.append({"point": point, "killed": killed, "status": status, "done": done, "seconds": seconds})
    print("RESULT " + json.dumps(report), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
