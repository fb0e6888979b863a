"""Ctrl-C during a run (issue 26): one line naming the last finished stage, exit status 130, and
the same command resumes, saying which stages it loaded.

``lit-boot bootstrap`` runs in a fresh interpreter on a tiny synthetic scene (random RAFT weights,
CPU) that sends itself SIGINT inside a stage: in the zoom stage (no Trainer: the KeyboardInterrupt
reaches the runner as it is) and in the pose and flow stages' training steps (inside Lightning's
Trainer, which turns it into sys.exit(1) and ignores further Ctrl-C)."""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import lit_boot
from lit_boot.bootstrap import RunInterrupted
from lit_boot.bootstrap.interrupt import interruptible

RANDOM_RAFT = {"weights": None, "train_updates": 2, "predict_updates": 3}

#: Runs lit-boot's main with SIGINT sent from inside stage $SIGINT_AT (none: uninterrupted).
DRIVER = textwrap.dedent("""
    import os, signal, sys
    from lit_boot.bootstrap import runner, zoom
    from lit_boot.cli import main
    from lit_boot.flow import FlowTTT
    from lit_boot.pose.base import RefinerBase

    point, current = os.environ.get("SIGINT_AT", ""), {"stage": None}
    header = runner.stage_header

    def tracking(index, total, name, what):
        current["stage"] = name
        return header(index, total, name, what)

    def ctrl_c_in(cls, method, nth):
        original, calls = getattr(cls, method), [0]

        def wrapper(*args, **kwargs):
            if current["stage"] == point:
                calls[0] += 1
                if calls[0] == nth:
                    os.kill(os.getpid(), signal.SIGINT)
            return original(*args, **kwargs)

        setattr(cls, method, wrapper)

    runner.stage_header = tracking
    ctrl_c_in(FlowTTT, "training_step", 2)
    ctrl_c_in(RefinerBase, "training_step", 3)
    ctrl_c_in(zoom, "zoom_flows", 1)
    sys.exit(main(sys.argv[1:]))
""")


def lit_boot_bootstrap(tmp_path: Path, at: str) -> subprocess.CompletedProcess:
    argv = ["bootstrap", "--data.scene", str(tmp_path / "scene"), "--out", str(tmp_path / "run"),
            "--flow", json.dumps(RANDOM_RAFT), "--flow_epochs", "1", "--pose_steps", "15", "--video", "false",
            "--accelerator", "cpu"]  # fmt: skip
    env = {**os.environ, "OMP_NUM_THREADS": "1", "SIGINT_AT": at}
    env.pop("LIT_BOOT_VERBOSE", None)
    return subprocess.run([sys.executable, "-c", DRIVER, *argv], cwd=tmp_path, capture_output=True, text=True,
                          env=env, timeout=600)  # fmt: skip


def done(run: Path) -> list[str]:
    order = ["initial", "zoom", "flow_1", "pose_1", "flow_2"]
    return [name for name in order if (run / "stages" / name / "stage.json").is_file()]


def test_ctrl_c_in_any_stage_is_one_line_exit_130_and_the_same_command_resumes(tmp_path: Path) -> None:
    lit_boot.save_scene(lit_boot.make_scene(motion="run", frames=3, height=64, width=96, seed=0), tmp_path / "scene")
    run = tmp_path / "run"
    resumed = None  # the stages the previous command finished: the next one says it loads them
    for at, last in (("zoom", "initial"), ("pose_1", "flow_1"), ("flow_2", "pose_1")):
        stopped = lit_boot_bootstrap(tmp_path, at)
        assert stopped.returncode == 130, (at, stopped.stdout[-2000:], stopped.stderr[-3000:])
        assert stopped.stderr == f"lit-boot bootstrap: interrupted after {last}; rerun the same command to resume\n"
        assert done(run)[-1] == last and not (run / "summary.json").exists()
        if resumed is not None:
            assert f"[lit-boot] resuming {run}: {', '.join(resumed)} already done (loaded, not run again)" \
                in stopped.stdout.splitlines()  # fmt: skip
        else:
            assert "resuming" not in stopped.stdout
        resumed = done(run)
    finished = lit_boot_bootstrap(tmp_path, "")
    assert finished.returncode == 0, finished.stderr[-3000:]
    assert f"[lit-boot] resuming {run}: initial, zoom, flow_1, pose_1 already done (loaded, not run again)" \
        in finished.stdout.splitlines()  # fmt: skip
    assert done(run) == ["initial", "zoom", "flow_1", "pose_1", "flow_2"] and (run / "summary.json").is_file()
    headers = [line.split(":")[0] for line in finished.stdout.splitlines() if line.startswith("[lit-boot] stage ")]
    assert headers == ["[lit-boot] stage 4/4 flow_2"]  # only flow_2 ran


def lightning_like() -> None:
    """What Lightning's Trainer does with Ctrl-C: catch it, ignore further SIGINT, sys.exit(1)."""
    try:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(5)  # the handler raises at once
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        sys.exit(1)


def test_interruptible_names_the_stage_and_restores_the_handler(tmp_path: Path) -> None:
    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(RunInterrupted) as caught:
        with interruptible(tmp_path, lambda: "flow_1"):
            lightning_like()
    assert caught.value.stage == "flow_1" and caught.value.out == tmp_path and caught.value.__cause__ is None
    assert isinstance(caught.value, KeyboardInterrupt) and "interrupted after flow_1" in str(caught.value)
    assert signal.getsignal(signal.SIGINT) is before  # Lightning's SIG_IGN undone
    with pytest.raises(RunInterrupted, match="before the first stage finished"):
        with interruptible(tmp_path, lambda: None):
            raise KeyboardInterrupt
    with pytest.raises(SystemExit):  # an exit without Ctrl-C is left alone
        with interruptible(tmp_path, lambda: "flow_1"):
            sys.exit(3)
    assert signal.getsignal(signal.SIGINT) is before


def test_a_rerun_logs_what_it_resumed(tmp_path: Path, caplog) -> None:
    from lit_boot.bootstrap import bootstrap

    scene = lit_boot.make_scene(motion="run", frames=3, height=64, width=96, seed=0)
    options = dict(flow=RANDOM_RAFT, flow_epochs=1, pose_steps=10, video=False, accelerator="cpu", cycles=0,
                   zoom={"method": "off"})  # fmt: skip
    caplog.set_level(logging.INFO, logger="lit_boot")
    bootstrap(scene, tmp_path / "run", **options)
    assert "resuming" not in caplog.text
    caplog.clear()
    bootstrap(scene, tmp_path / "run", **options)
    lines = [r.getMessage() for r in caplog.records if "resuming" in r.getMessage()]
    assert lines == [f"[lit-boot] resuming {tmp_path / 'run'}: initial, flow_1 already done (loaded, not run again)"]


def test_ctrl_c_outside_a_run_is_one_line_too(monkeypatch, capsys) -> None:
    from lit_boot.cli import main, synthetic

    def interrupted(argv):
        raise KeyboardInterrupt

    monkeypatch.setattr(synthetic, "synth", interrupted)
    assert main(["synth", "--out", "x"]) == 130
    assert capsys.readouterr().err == "lit-boot synth: interrupted\n"
