"""The lit-boot command line: ``lit-boot synth``."""

from __future__ import annotations

import subprocess
import sys

import torch

from lit_boot.cli import main
from lit_boot.data import load_scene, read_png
from lit_boot.synth import EstimateConfig, SynthConfig, make_scene

ARGS = ["--frames", "3", "--height", "48", "--width", "64", "--seed", "2"]


def test_synth_writes_the_scene_the_api_makes(tmp_path, capsys):
    out = tmp_path / "scene"
    assert main(["synth", "--out", str(out), *ARGS, "--motion", "jump", "--estimates.mpjpe_mm", "55"]) == 0
    printed = capsys.readouterr().out
    assert "3 frames, 64x48 px" in printed and f"wrote {out}" in printed
    loaded = load_scene(out)
    expected = make_scene(SynthConfig(motion="jump", frames=3, height=48, width=64, seed=2,
                                      estimates=EstimateConfig(mpjpe_mm=55.0)))  # fmt: skip
    assert torch.equal(loaded.frames, expected.frames)
    assert torch.equal(loaded.gt.flow, expected.gt.flow)
    assert torch.equal(loaded.joints3d, expected.joints3d)
    assert read_png(out / "preview.png").shape == (3, 48, 3 * 64)


def test_synth_refuses_to_overwrite_unless_asked(tmp_path, capsys):
    out = tmp_path / "scene"
    assert main(["synth", "--out", str(out), *ARGS]) == 0
    before = (out / "arrays.npz").stat().st_mtime_ns
    assert main(["synth", "--out", str(out), *ARGS]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and str(out) in err and "--overwrite" in err
    assert (out / "arrays.npz").stat().st_mtime_ns == before
    assert main(["synth", "--out", str(out), *ARGS, "--seed", "3", "--overwrite", "true"]) == 0
    assert load_scene(out).metadata["config"]["seed"] == 3


def test_bad_options_give_one_line_errors(tmp_path, capsys):
    assert main(["synth", "--out", str(tmp_path / "a"), "--motion", "fly"]) == 2
    assert "SynthConfig.motion" in capsys.readouterr().err
    assert main(["synth", "--out", str(tmp_path / "b"), "--motion", "bvh", "--bvh", str(tmp_path / "none.bvh")]) == 2
    assert "none.bvh" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
    assert main(["nonsense"]) == 2
    assert main([]) == 0 and "usage: lit-boot" in capsys.readouterr().out


def test_console_script_prints_its_config():
    done = subprocess.run(
        [sys.executable, "-m", "lit_boot.cli", "synth", "--out", "x", "--motion", "run", "--print_config"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "motion: run" in done.stdout and "mpjpe_mm: 70.0" in done.stdout
