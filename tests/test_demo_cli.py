"""``lit-boot demo``: its sizes, the plan line it prints first, when it starts again (the run itself
is replaced by a stand-in; tests/test_bootstrap.py runs the real one), and what a command prints:
lit-boot's own lines (log records included), no dependency noise (a stand-in, and a tiny real demo)."""

from __future__ import annotations

import json
import logging
import re
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

import lit_boot.bootstrap
from lit_boot.cli import main


class FakeRun:
    """Records Bootstrap's arguments; its result prints a table."""

    calls: list[dict] = []

    def __init__(self, scene, out, overwrite=False, **options) -> None:
        FakeRun.calls.append({"scene": Path(scene), "out": Path(out), "overwrite": overwrite, **options})
        self.run_dir = Path(out)

    def run(self) -> FakeRun:
        return self

    def table(self) -> str:
        return "| metric | unit | before | after | change (lower is better) |"


@pytest.fixture
def fake_run(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> list[dict]:
    monkeypatch.setattr(lit_boot.bootstrap, "Bootstrap", FakeRun)
    monkeypatch.chdir(tmp_path)
    FakeRun.calls = []
    return FakeRun.calls


SMALL = ["--frames", "3", "--height", "32", "--width", "48"]


def test_quick_demo_prints_its_plan_first_and_trains_2_epochs(fake_run: list[dict], capsys) -> None:
    assert main(["demo", "--quick", *SMALL]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("lit-boot demo: a synthetic 'run' scene (3 frames, 48x32, exact GT)")
    assert "2 epochs per flow stage" in lines[0] and "about 30 s on 2 free CPU cores" in lines[0]
    assert "--quick" not in lines[0]
    assert lines[1].startswith("scene 'synth_run_s0': 3 frames, 48x32 px")
    (call,) = fake_run
    assert call["flow_epochs"] == 2 and call["out"] == Path("runs/demo_quick/bootstrap") and call["overwrite"]
    assert json.loads(Path("runs/demo_quick/demo.json").read_text())["epochs"] == 2


def test_default_demo_says_how_long_it_takes_and_names_quick(fake_run: list[dict], capsys) -> None:
    assert main(["demo", *SMALL]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert "8 epochs per flow stage" in first and "(--quick: 2 epochs)" in first
    assert fake_run[0]["flow_epochs"] == 8 and fake_run[0]["out"] == Path("runs/demo/bootstrap")


def test_demo_estimate_and_restart_rules(fake_run: list[dict], capsys) -> None:
    assert main(["demo", "--out", "d"]) == 0
    first = capsys.readouterr().out.splitlines()[0]  # 8 frames, 8 epochs: 112 training steps
    assert "(8 frames, 256x128, exact GT)" in first and "about 30 s" in first
    assert main(["demo", "--out", "d"]) == 0  # the same scene and size: resume
    assert "from scratch about 30 s" in capsys.readouterr().out.splitlines()[0]  # nothing finished yet
    (Path("d") / "bootstrap").mkdir()
    (Path("d") / "bootstrap" / "summary.json").write_text("{}")  # as a finished run leaves it
    assert main(["demo", "--out", "d"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert "holds this demo's finished run" in first and "nothing is run" in first and "from scratch" not in first
    assert main(["demo", "--out", "d", "--epochs", "3"]) == 0  # another size: start again
    assert [c["overwrite"] for c in fake_run] == [True, False, False, True]
    assert [c["flow_epochs"] for c in fake_run] == [8, 8, 8, 3]


# --- what a command prints: lit-boot's log lines, no dependency noise (issue 14) ---------------------

NOISE = ("GPU available", "TPU available", "💡", "Tip:", "Warning")


def noise_in(lines: list[str]) -> list[str]:
    return [line for line in lines if any(word in line for word in NOISE)]


@contextmanager
def dependency_output() -> Iterator[list[str]]:
    """Within the block: Lightning's log records (wherever its handlers would write them) and the
    warnings that get past the command's filters (as Python prints them: "Category: message")."""
    seen: list[str] = []
    recorder = logging.Handler()
    recorder.emit = lambda record: seen.append(record.getMessage())  # type: ignore[method-assign]
    loggers = [logging.getLogger(name) for name in ("lightning.pytorch", "lightning.fabric")]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for logger in loggers:
            logger.addHandler(recorder)
        try:
            yield seen
        finally:
            for logger in loggers:
                logger.removeHandler(recorder)
    seen += [f"{w.category.__name__}: {w.message}" for w in caught]


class LoggingRun(FakeRun):
    """Logs a stage header as the runner does, and makes the noise Lightning and torch make."""

    def run(self) -> LoggingRun:
        logging.getLogger("lit_boot.bootstrap.runner").info("[lit-boot] stage 1/3 flow_1: FlowTTT x1")
        rank_zero = logging.getLogger("lightning.pytorch.utilities.rank_zero")
        rank_zero.info("GPU available: False, used: False")
        rank_zero.info("💡 Tip: For seamless cloud logging and experiment tracking, try installing litlogger")
        warnings.warn_explicit("`isinstance(treespec, LeafSpec)` is deprecated", FutureWarning, "_pytree.py", 1,
                               module="lightning.pytorch.utilities._pytree")  # fmt: skip
        return self


def test_a_command_prints_lit_boot_log_lines_and_no_dependency_noise(fake_run, monkeypatch, capfd) -> None:
    monkeypatch.setattr(lit_boot.bootstrap, "Bootstrap", LoggingRun)
    monkeypatch.delenv("LIT_BOOT_VERBOSE", raising=False)
    ours = logging.getLogger("lit_boot")
    before = (list(ours.handlers), ours.level, ours.propagate)
    for _ in range(2):  # the handler is removed after each command: one line per record, every time
        with dependency_output() as seen:
            assert main(["demo", "--quick", *SMALL]) == 0
        out, err = capfd.readouterr()
        assert out.splitlines().count("[lit-boot] stage 1/3 flow_1: FlowTTT x1") == 1
        assert not noise_in((out + err).splitlines() + seen), (out + err, seen)
    assert (list(ours.handlers), ours.level, ours.propagate) == before
    with dependency_output() as seen:  # --verbose: all of it
        assert main(["--verbose", "demo", "--quick", *SMALL]) == 0
    assert "GPU available: False, used: False" in seen and "FutureWarning: `isinstance" in " ".join(seen)


@pytest.mark.shared
def test_a_real_demo_prints_its_stages_and_no_dependency_noise(shared, tmp_path, monkeypatch, capfd) -> None:
    monkeypatch.setenv("LIT_BOOT_CHECKPOINTS", str(shared / "checkpoints"))
    monkeypatch.delenv("LIT_BOOT_VERBOSE", raising=False)
    with dependency_output() as seen:
        assert main(["demo", "--out", str(tmp_path / "demo"), "--frames", "2", "--height", "64", "--width", "96",
                     "--epochs", "1"]) == 0  # fmt: skip
    out, err = capfd.readouterr()
    for stage in ("initial", "flow_1", "pose_1", "flow_2"):  # numbered k/n: the preset may add stages (zoom)
        headers = [line for line in out.splitlines() if re.match(rf"\[lit-boot\] stage \d+/\d+ {stage}: ", line)]
        assert len(headers) == 1, (stage, out)
    assert not noise_in((out + err).splitlines() + seen), (out + err, seen)
    assert "| epe_person |" in out
