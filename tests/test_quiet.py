"""From Python, lit-boot prints nothing at the default logging level (issue 26): no "GPU
available", no Lightning tips, no dependency deprecation warnings, no progress bars. Each run is a
fresh interpreter, as a user's script is (Lightning adds its own stream handler at import)."""

from __future__ import annotations

import logging
import re
import subprocess
import sys
import textwrap
import warnings

import pytest

from lit_boot.quiet import LIGHTNING_INFO_LOGGERS, keep_lightning, quiet_lightning

NOISE = ("GPU available", "TPU available", "Tip", "litlogger", "deprecated", "Warning", "it/s", "Epoch", "%|")


def run_python(tmp_path, body: str) -> subprocess.CompletedProcess:
    code = textwrap.dedent(f"""
        import lit_boot
        from lit_boot.bootstrap import bootstrap
        from lit_boot.quiet import quiet_lightning
        scene = lit_boot.make_scene(motion="run", frames=3, height=64, width=96, seed=0)
        RANDOM_RAFT = {{"weights": None, "train_updates": 2, "predict_updates": 3}}
        FAST = dict(flow_epochs=1, pose_steps=10, video=False, accelerator="cpu")
    """) + textwrap.dedent(body)  # fmt: skip
    env = {"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    return subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600,
                          env=env)  # fmt: skip


def test_a_run_inside_quiet_lightning_prints_nothing_but_what_the_user_asks_for(tmp_path) -> None:
    done = run_python(tmp_path, """
        with quiet_lightning():
            bootstrap(scene, "run_a", flow=RANDOM_RAFT, progress_bar=False, **FAST)
        import logging
        logging.basicConfig(level=logging.INFO)  # the user asks for lit-boot's lines
        with quiet_lightning():
            bootstrap(scene, "run_b", flow=RANDOM_RAFT, progress_bar=False, **FAST)
    """)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout == ""
    assert re.search(r"\[lit-boot\] stage \d/\d flow_1", done.stderr)  # lit-boot's own records, when logging is on
    lines = [line for line in done.stderr.splitlines() if "lit_boot" not in line]
    assert not [line for line in lines if any(n in line for n in NOISE)], lines


def test_a_plain_run_from_python_prints_nothing(tmp_path) -> None:
    done = run_python(tmp_path, """
        bootstrap(scene, "run", flow=RANDOM_RAFT, **FAST)
    """)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (done.stdout, done.stderr) == ("", "")


def test_quiet_lightning_restores_the_levels_and_filters() -> None:
    logger = logging.getLogger(LIGHTNING_INFO_LOGGERS[0])
    level, filters = logger.level, list(warnings.filters)
    with quiet_lightning():
        assert logger.getEffectiveLevel() == logging.WARNING
    assert logger.level == level and warnings.filters == filters


def test_keep_lightning_and_the_environment_keep_everything(monkeypatch) -> None:
    logger = logging.getLogger(LIGHTNING_INFO_LOGGERS[0])
    monkeypatch.setattr(logger, "level", logging.INFO)  # as Lightning sets it when imported
    level = logging.INFO
    with keep_lightning(), quiet_lightning():  # lit-boot --verbose
        assert logger.getEffectiveLevel() == level
    monkeypatch.setenv("LIT_BOOT_VERBOSE", "1")
    with quiet_lightning():
        assert logger.getEffectiveLevel() == level
    monkeypatch.setenv("LIT_BOOT_VERBOSE", "0")
    with quiet_lightning():
        assert logger.getEffectiveLevel() == logging.WARNING
