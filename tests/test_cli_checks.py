"""The rough edges a new user hit (issue 26): every value error names its option and comes before
torch is imported; a typo gets "did you mean"; ``--a-b`` is ``--a_b`` in every command; a video
given as a scene folder points to ``--data.video``; a write refused in a read-only folder names the
file, not a hidden temporary one; nobody in the frames is said as such."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from test_estimate_mediapipe import needs_mediapipe

from lit_boot.cli import main
from lit_boot.cli.checks import check_video_options, name_option
from lit_boot.cli.console import CliError, error_line, normalize_options, suggest_options
from lit_boot.data.atomic import atomic_write_bytes

HEAVY = ("torch", "lightning", "cv2", "matplotlib")


def fresh_main(argv: list[str], cwd: Path) -> tuple[int, str, list[str]]:
    """``main(argv)`` in a fresh interpreter: (exit status, stderr, the heavy modules it imported)."""
    code = ("import json, sys\nfrom lit_boot.cli import main\n"
            f"rc = main({argv!r})\n"
            f"print(json.dumps([rc, sorted(m for m in {HEAVY!r} if m in sys.modules)]))")  # fmt: skip
    done = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=300)
    rc, heavy = json.loads(done.stdout.strip().splitlines()[-1])
    return rc, done.stderr, heavy


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory) -> Path:
    """A folder standing in for a scene folder (the checks below fail before it is read)."""
    path = tmp_path_factory.mktemp("scene")
    (path / "frames").mkdir()
    return path


@pytest.fixture(scope="module")
def clip(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("video") / "clip.mp4"
    path.write_bytes(b"not decoded: the checks come first")
    return path


def cases(scene: Path, clip: Path) -> list[tuple[list[str], str]]:
    """(argv, what the one error line must say)."""
    return [
        (["bootstrap", "--data.scene", str(scene), "--flow-epochs", "0"], "--flow_epochs: expected >= 1"),
        (["bootstrap", "--data.scene", str(scene), "--self_check.tile", "0"], "--self_check.tile: expected >= 1"),
        (["bootstrap", "--data.scene", str(scene), "--self_check.max_change_px", "huge"],
         "--self_check.max_change_px: expected float or 'auto', got 'huge'"),
        (["bootstrap", "--data.scene", str(scene), "--self_check.max_change_px", "-1"],
         "--self_check.max_change_px: expected 'auto', None or > 0 px, got -1.0"),
        (["bootstrap", "--data.scene", str(scene), "--zoom.max_cost", "lots"],
         "--zoom.max_cost: expected float or 'auto', got 'lots'"),
        (["bootstrap", "--data.scene", str(scene), "--zoom.max_cost", "0"],
         "--zoom.max_cost: expected 'auto' or > 0 frames, got 0.0"),
        (["bootstrap", "--data.scene", str(clip)], f"not a scene folder; for a video use --data.video {clip}"),
        (["bootstrap", "--data.scene", str(scene / "nope")], "--data.scene"),
        (["bootstrap", "--data.video", str(clip), "--data.max_frames", "0"], "--data.max_frames: expected an integer"),
        (["bootstrap", "--data.video", str(clip), "--data.resize", "-240"], "--data.resize: expected a height in px"),
        (["bootstrap", "--data.video", str(clip), "--data.stride", "0"], "--data.stride: expected an integer >= 1"),
        (["bootstrap", "--data.scene", str(scene), "--flow_epoch", "2"], "did you mean --flow_epochs?"),
        (["estimate-pose", str(clip), "--out", "p.npz", "--max-frames", "0"], "--max_frames: expected an integer >= 1"),
        (["estimate-pose", str(clip), "--out", "p.npz", "--resize", "-240"], "--resize: expected a height in px > 0"),
        (["estimate-pose", str(clip.parent / "nope.mp4"), "--out", "p.npz"], "no such video file"),
        (["synth", "--out", "s", "--frames", "0"], "--frames: expected at least 2 frames"),
        (["synth", "--out", "s", "--estimates.mpjpe_mm", "-1"], "--estimates.mpjpe_mm: expected values >= 0"),
        (["synth", "--out", "s", "--height", "4"], "--height: expected at least 16 px"),
        (["demo", "--frames", "1"], "--frames: expected at least 2 frames"),
        (["demo", "--epochs", "0"], "--epochs: expected an integer >= 1"),
        (["report", "nope"], "RUN_DIR nope: no such folder"),
    ]  # fmt: skip


def test_value_errors_name_their_option_before_torch_is_imported(scene_dir, clip, tmp_path) -> None:
    for argv, expected in cases(scene_dir, clip):
        rc, err, heavy = fresh_main(argv, tmp_path)
        assert rc == 2 and expected in err, (argv, err)
        assert len(err.strip().splitlines()) == 1 and "-427x" not in err, (argv, err)
        assert heavy == [], (argv, heavy)  # torch and Lightning not loaded: the line comes at once
    assert not any(tmp_path.iterdir())  # nothing written


def test_both_spellings_of_an_option_everywhere() -> None:
    argv = ["--flow-epochs", "2", "--data.max-frames=3", "--trainer.max-epochs", "1", "--resize", "-240"]
    assert normalize_options(argv) == ["--flow_epochs", "2", "--data.max_frames=3", "--trainer.max_epochs", "1",
                                       "--resize", "-240"]  # fmt: skip
    assert normalize_options(["--", "--a-b", "-h"]) == ["--", "--a-b", "-h"]  # after "--": left alone


def test_did_you_mean(capsys) -> None:
    known = ["--flow_epochs", "--pose_steps", "--data.scene"]
    assert suggest_options("unrecognized arguments: --flow_epoch 2", known).endswith("; did you mean --flow_epochs?")
    both = suggest_options("unrecognized arguments: --flow_epoch 2 --pose_step=3 --zzz", known)
    assert both.endswith("did you mean --flow_epochs (for --flow_epoch), --pose_steps (for --pose_step)?")
    assert suggest_options("unrecognized arguments: --zzz", known) == "unrecognized arguments: --zzz"
    assert main(["import", "video", "x.mp4", "--out", "y", "--max_frame", "2"]) == 2
    assert "did you mean --max_frames?" in capsys.readouterr().err


def test_settings_errors_are_named_by_option() -> None:
    options = ["--flow_epochs", "--self_check.tile", "--estimates.mpjpe_mm"]
    named = name_option(ValueError("flow_epochs: expected >= 1 or None, got 0"), options)
    assert isinstance(named, CliError) and str(named) == "--flow_epochs: expected >= 1 or None, got 0"
    assert str(name_option(ValueError("SynthConfig.estimates.mpjpe_mm: x"), options)) == "--estimates.mpjpe_mm: x"
    assert str(name_option(ValueError("arch: expected one of"), options, {"arch": "--flow.arch"})) == (
        "--flow.arch: expected one of")
    unknown = ValueError("scene 'x': 3D mode needs 3D joints")
    assert name_option(unknown, options) is unknown
    with pytest.raises(CliError, match=r"--data.resize: .* got \(0, 3\)"):
        check_video_options("data.", 1, None, (0, 3))
    check_video_options("data.", 2, 5, [240, 320])  # fine


def test_a_refused_write_names_the_file_not_a_hidden_temporary(tmp_path) -> None:
    (tmp_path / "a_file").write_text("x")
    target = tmp_path / "a_file" / "config.json"  # a folder that cannot hold files, as a read-only one
    with pytest.raises(OSError) as caught:
        atomic_write_bytes(target, b"{}")
    assert caught.value.filename == str(target)
    assert error_line(caught.value) == f"{target}: Not a directory"
    denied = PermissionError(13, "Permission denied", "/runs/x/config.json")
    assert error_line(denied) == "/runs/x/config.json: Permission denied"


@pytest.mark.mediapipe
@needs_mediapipe
def test_nobody_in_the_frames_is_said_as_such_and_nothing_is_written(tmp_path, capsys) -> None:
    import cv2
    import numpy as np

    frames = tmp_path / "empty_room"
    frames.mkdir()
    for i in range(3):  # a wall, no person
        cv2.imwrite(str(frames / f"{i:06d}.png"), np.full((96, 128, 3), 120 + 10 * i, np.uint8))
    assert main(["estimate-pose", str(frames), "--out", str(tmp_path / "poses.npz")]) == 2
    err = capsys.readouterr().err
    assert "found no person in any of the 3 frames" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "poses.npz").exists()
    assert main(["bootstrap", "--data.video", str(frames), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert "found no person in any of the 3 frames" in err and "3D mode needs" not in err
    assert not (tmp_path / "run").exists()
