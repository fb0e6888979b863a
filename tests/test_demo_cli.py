"""``lit-boot demo``: its sizes, the plan line it prints first, and when it starts again (the run
itself is replaced by a stand-in; tests/test_bootstrap.py runs the real one)."""

from __future__ import annotations

import json
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
    assert "2 epochs per flow stage" in lines[0] and "about 1 min on 2 free CPU cores" in lines[0]
    assert "--quick" not in lines[0]
    assert lines[1].startswith("scene 'synth_run_s0': 3 frames, 48x32 px")
    (call,) = fake_run
    assert call["flow_epochs"] == 2 and call["out"] == Path("runs/demo_quick/bootstrap") and call["overwrite"]
    assert json.loads(Path("runs/demo_quick/demo.json").read_text())["epochs"] == 2


def test_default_demo_says_it_takes_minutes_and_names_quick(fake_run: list[dict], capsys) -> None:
    assert main(["demo", *SMALL]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert "8 epochs per flow stage" in first and "(--quick: about 1 min)" in first
    assert fake_run[0]["flow_epochs"] == 8 and fake_run[0]["out"] == Path("runs/demo/bootstrap")


def test_demo_estimate_and_restart_rules(fake_run: list[dict], capsys) -> None:
    assert main(["demo", "--out", "d"]) == 0
    first = capsys.readouterr().out.splitlines()[0]  # 8 frames, 8 epochs: 112 training steps
    assert "(8 frames, 256x128, exact GT)" in first and "about 3 min" in first
    assert main(["demo", "--out", "d"]) == 0  # the same scene and size: resume
    assert main(["demo", "--out", "d", "--epochs", "3"]) == 0  # another size: start again
    assert [c["overwrite"] for c in fake_run] == [True, False, True]
    assert [c["flow_epochs"] for c in fake_run] == [8, 8, 3]
