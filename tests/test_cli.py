"""The lit-boot command line: ``lit-boot synth``; help, strict options, errors and output of every command."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from lit_boot.cli import main
from lit_boot.cli.console import drop_native_noise
from lit_boot.data import load_scene, read_png
from lit_boot.synth import EstimateConfig, SynthConfig, make_scene

ARGS = ["--frames", "3", "--height", "48", "--width", "64", "--seed", "2"]
CONFIGS = Path(__file__).resolve().parents[1] / "configs"


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
    assert "--motion: expected one of" in capsys.readouterr().err
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


# --- help, start-up time, strict options, one-line errors, quiet output (issue 12) ------------------

HEAVY = ("torch", "lightning", "cv2", "matplotlib", "kornia", "torchvision")
NOISE = ("Tip", "GPU available", "TPU available", "litlogger", "litmodels", "DeprecationWarning", "pytree",
         "Seed set to", "LightningCLI's args")  # fmt: skip


def run_cli(*args, cwd=None, env=None):
    """``python -m lit_boot.cli ARGS`` in a fresh process (quiet unless LIT_BOOT_VERBOSE is set in env)."""
    env = {k: v for k, v in os.environ.items() if k != "LIT_BOOT_VERBOSE"} | (env or {})
    return subprocess.run([sys.executable, "-m", "lit_boot.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=600, cwd=cwd, env=env)  # fmt: skip


@pytest.mark.parametrize("argv", [[], ["--help"], ["demo", "--help"], ["estimate-pose", "--help"],
                                  ["import", "--help"], ["synth", "--help"], ["bootstrap", "--help"],
                                  ["report", "--help"], ["ids", "--help"]])  # fmt: skip
def test_import_and_help_load_no_heavy_module(argv):
    code = ("import sys\nfrom lit_boot.cli import main\nimport lit_boot\n"
            f"try:\n    main({argv!r})\nexcept SystemExit as e:\n    assert e.code == 0, e.code\n"
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")  # fmt: skip
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"
    assert "usage: lit-boot" in done.stdout


def test_top_level_help_describes_every_command(capsys):
    from lit_boot.cli import COMMANDS

    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        line = next(line for line in out.splitlines() if line.strip().startswith(name + " "))
        assert len(line.split(maxsplit=1)[1]) > 30, line  # a description, not just the name
    assert "--verbose" in out
    assert main(["nonsense"]) == 2
    err = capsys.readouterr().err
    assert "unknown command 'nonsense'" in err and "synth" in err and len(err.strip().splitlines()) == 1


def test_lit_boot_is_lazy_with_the_same_public_names():
    import lit_boot

    assert {"Scene", "make_scene", "Bootstrap", "FlowTTT", "read_video", "__version__"} <= set(lit_boot.__all__)
    assert set(lit_boot.__all__) <= set(dir(lit_boot)) and "metrics" in dir(lit_boot)
    assert lit_boot.Scene is __import__("lit_boot.core", fromlist=["Scene"]).Scene
    assert lit_boot.metrics.__name__ == "lit_boot.metrics"
    with pytest.raises(AttributeError, match="no_such_name"):
        lit_boot.no_such_name  # noqa: B018


def test_bootstrap_help_explains_the_presets(capsys):
    with pytest.raises(SystemExit) as done:
        main(["bootstrap", "--help"])
    assert done.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "module doc" not in out and "``" not in out and ":class:" not in out
    preset = out.rsplit("--preset PRESET", 1)[1].split("--cycles", 1)[0]
    assert "default: the paper's text" in preset and "paper: the authors' code" in preset


@pytest.mark.parametrize(
    "argv, option",
    [(["synth", "--out", "x", "--frame", "3"], "--frame"), (["demo", "--epoch", "1"], "--epoch"),
     (["bootstrap", "--data.scene", "x", "--flow_epoch", "1"], "--flow_epoch"),
     (["estimate-pose", "v.mp4", "--out", "p.npz", "--strid", "2"], "--strid"),
     (["fit", "--trainer.max_epoch", "1"], "--trainer.max_epoch")],  # fmt: skip
)
def test_abbreviated_options_are_errors(argv, option, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert f"unrecognized arguments: {option}" in err and len(err.splitlines()) == 1
    assert not any(tmp_path.iterdir())


def test_bad_values_are_one_line_naming_the_option(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["synth", "--out", "x", "--frames", "abc"]) == 2
    assert "--frames: expected int, got 'abc'" in capsys.readouterr().err
    assert main(["estimate-pose", str(tmp_path / "none.mp4"), "--out", "p.npz"]) == 2
    err = capsys.readouterr().err.strip()
    assert str(tmp_path / "none.mp4") in err and len(err.splitlines()) == 1
    (tmp_path / "v").mkdir()
    assert main(["estimate-pose", str(tmp_path / "v"), "--out", "p.npz", "--people", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--people: expected all, largest or a number" in err and len(err.splitlines()) == 1
    (tmp_path / "v").rmdir()
    assert main(["fit", "--config", str(CONFIGS / "flow_ttt.yaml"), "--data.scene", "x", "--model.lr", "abc"]) == 2
    assert "--model.lr: expected float, got 'abc'" in capsys.readouterr().err
    assert main(["fit", "--config", str(CONFIGS / "flow_ttt.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert "--data.scene is required" in err and len(err.splitlines()) == 1
    assert not any(tmp_path.iterdir())


def test_native_noise_is_dropped_and_the_rest_passed_on(capfd):
    with drop_native_noise():
        os.write(2, b"INFO: Created TensorFlow Lite XNNPACK delegate for CPU.\nkept line\n")
        os.write(2, b"W0000 00:00:1796152292.972336    9411 inference_feedback_manager.cc:114] Feedback manager "
                    b"requires a model with a single signature inference. Disabling support.\nprogress\r")  # fmt: skip
    assert capfd.readouterr().err == "kept line\nprogress\r"


def tiny_scene(path):
    assert main(["synth", "--out", str(path), "--frames", "3", "--height", "64", "--width", "64"]) == 0
    return path


def fit_args(scene, weights):
    return ["fit", "--config", str(CONFIGS / "flow_ttt.yaml"), "--data.scene", str(scene),
            "--model.weights", str(weights), "--model.train_updates", "2", "--model.predict_updates", "3",
            "--trainer.max_epochs", "1"]  # fmt: skip


@pytest.mark.shared
def test_fit_prints_only_its_own_lines_unless_verbose(shared, tmp_path, capsys):
    scene = tiny_scene(tmp_path / "scene")
    capsys.readouterr()
    done = run_cli(*fit_args(scene, shared / "checkpoints/raft-small.pth"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    printed = done.stdout + done.stderr
    assert not [word for word in NOISE if word in printed], printed
    assert "Epoch 0: 100%" in printed  # the progress bar stays
    assert "run folder: runs/scene/FlowTTT" in done.stdout
    assert list((tmp_path / "runs/scene/FlowTTT").rglob("*.ckpt"))
    # --verbose gives Lightning's lines back (here on a run that fails at once: no scene)
    loud = run_cli("--verbose", *fit_args(tmp_path / "none", shared / "checkpoints/raft-small.pth"), cwd=tmp_path)
    assert loud.returncode == 2 and "GPU available" in loud.stdout + loud.stderr


@pytest.mark.shared
@pytest.mark.parametrize("bad", ["missing", "not_raft"])
def test_fit_with_bad_weights_is_one_line_and_leaves_no_run_folder(bad, shared, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    scene = tiny_scene(tmp_path / "scene")
    weights = tmp_path / "weights.pth"
    if bad == "not_raft":
        torch.save({"encoder.weight": torch.zeros(2)}, weights)
    capsys.readouterr()
    assert main(fit_args(scene, weights)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(weights) in err and "Namespace(" not in err, err
    assert ("does not exist" if bad == "missing" else "neither a torchvision RAFT state dict") in err
    assert err.startswith("lit-boot fit: error: could not build --model lit_boot.flow.FlowTTT: ")
    assert not (tmp_path / "runs").exists()


@pytest.mark.shared
def test_failed_fit_leaves_no_run_folder_and_the_corrected_rerun_works(shared, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    weights = shared / "checkpoints/raft-small.pth"
    assert main(fit_args(tmp_path / "scene", weights)) == 2  # no scene yet
    err = capsys.readouterr().err.strip()
    assert err == f"lit-boot fit: error: {tmp_path / 'scene'}: no such scene folder"
    assert not (tmp_path / "runs").exists()
    tiny_scene(tmp_path / "scene")
    assert main(fit_args(tmp_path / "scene", weights)) == 0
    assert len(list((tmp_path / "runs/scene/FlowTTT").rglob("*.ckpt"))) == 1
    # a failure in a run folder that exists removes only the version folder it made
    before = sorted((tmp_path / "runs").rglob("*"))
    assert main([*fit_args(tmp_path / "scene", weights), "--data.batch_size", "0"]) == 2
    assert sorted((tmp_path / "runs").rglob("*")) == before


@pytest.mark.shared
@pytest.mark.mediapipe
@pytest.mark.skipif(importlib.util.find_spec("mediapipe") is None, reason="needs the mediapipe extra")
def test_estimate_pose_prints_one_line_without_mediapipe_start_up_noise(shared, tmp_path):
    done = run_cli("estimate-pose", shared / "data/videos/street_540p_5f.mp4", "--out", tmp_path / "p.npz")
    assert done.returncode == 0, done.stderr
    assert done.stderr == "" and done.stdout.strip().endswith(f"wrote {tmp_path / 'p.npz'}")
    assert len(done.stdout.strip().splitlines()) == 1


def test_the_options_written_out_for_a_fast_help_agree_with_the_library():
    """bootstrap's --data.* and estimate-pose's options are written out in the CLI (their modules
    import torch, and --help must not): they must keep the library's names and defaults."""
    import inspect

    from lit_boot.cli.importing import estimate_pose_parser
    from lit_boot.cli.runs import bootstrap_parser
    from lit_boot.data.readers import read_video
    from lit_boot.estimate.mediapipe_pose import estimate_poses

    def defaults(function, names):
        params = inspect.signature(function).parameters
        return {name: params[name].default for name in names}

    data = bootstrap_parser().get_defaults()["data"]
    video_keys = ("stride", "max_frames", "resize")
    assert {k: data[k] for k in video_keys} == defaults(read_video, video_keys)
    estimate = vars(estimate_pose_parser().get_defaults())
    keys = [k for k in estimate if k in inspect.signature(estimate_poses).parameters and k != "video"]
    assert {"stride", "max_frames", "resize", "model_complexity", "min_detection_confidence", "on_jump"} <= set(keys)
    assert {k: estimate[k] for k in keys} == defaults(estimate_poses, keys)


def test_output_cut_off_by_its_reader_ends_quietly():
    """``lit-boot --help | head``: the reader went away before lit-boot wrote; no BrokenPipe traceback."""
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before lit-boot writes a byte
    try:
        done = subprocess.run([sys.executable, "-m", "lit_boot.cli", "--help"], stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=120)  # fmt: skip
    finally:
        os.close(write_end)
    assert (done.returncode, done.stderr) == (141, "")
