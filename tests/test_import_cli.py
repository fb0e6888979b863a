"""``lit-boot import`` (datasets and videos into scene folders) and ``lit-boot bootstrap --data.video``."""

from __future__ import annotations

import importlib.util
import json
import re

import pytest
import torch

from lit_boot.cli import main
from lit_boot.data import load_scene, read_flo
from lit_boot.data.readers import PoseEstimates, save_poses

HAVE_MEDIAPIPE = importlib.util.find_spec("mediapipe") is not None
needs_mediapipe = pytest.mark.skipif(not HAVE_MEDIAPIPE, reason='needs the mediapipe extra: pip install -e ".[mediapipe]"')
FOOTBALL = "data/videos/football_720p_10f"


@pytest.mark.shared
def test_import_sintel_writes_a_scene_folder_with_its_gt(shared, tmp_path, capsys):
    root = shared / "data/sintel_samples"
    assert main(["import", "sintel", str(root), "alley_1", "--first", "2", "--last", "3", "--out", str(tmp_path / "s")]) == 0
    scene = load_scene(tmp_path / "s")
    assert scene.frames.shape == (2, 3, 436, 1024)
    torch.testing.assert_close(scene.gt.flow[0], read_flo(root / "training/flow/alley_1/frame_0002.flo"))
    assert "wrote" in capsys.readouterr().out
    code = main(["import", "sintel", str(root), "alley_1", "--out", str(tmp_path / "s")])
    assert code == 2 and str(tmp_path / "s") in capsys.readouterr().err  # never overwritten silently


@pytest.mark.shared
def test_import_video_with_a_pose_file_selects_and_rescales_the_rows(shared, tmp_path):
    T, H, W = 10, 720, 1280
    kp = torch.rand(T, 17, 2) * torch.tensor([W - 1.0, H - 1.0])
    poses = PoseEstimates(keypoints2d=kp, keypoints_conf=torch.ones(T, 17), image_size=(H, W), source="test")
    save_poses(poses, tmp_path / "poses.npz")
    args = ["import", "video", str(shared / FOOTBALL), "--stride", "3", "--resize", "0.25",
            "--poses", str(tmp_path / "poses.npz"), "--out", str(tmp_path / "v")]  # fmt: skip
    assert main(args) == 0
    scene = load_scene(tmp_path / "v")
    assert scene.frames.shape == (4, 3, 180, 320)  # frames 0, 3, 6, 9
    # pixel centres at integers: x' = (x + 0.5) * 0.25 - 0.5
    torch.testing.assert_close(scene.keypoints2d, (kp[[0, 3, 6, 9]] + 0.5) * 0.25 - 0.5, atol=1e-3, rtol=0)


def test_bootstrap_needs_exactly_one_of_scene_and_video(tmp_path, capsys):
    assert main(["bootstrap", "--out", str(tmp_path / "run")]) == 2
    assert "--data.scene" in capsys.readouterr().err and not (tmp_path / "run").exists()


@needs_mediapipe
@pytest.mark.mediapipe
@pytest.mark.shared
def test_bootstrap_a_video_alone_estimates_poses_then_runs(shared, tmp_path, capsys):
    args = ["bootstrap", "--data.video", str(shared / FOOTBALL), "--data.stride", "4", "--data.max_frames", "2",
            "--data.resize", "0.25",
            "--out", str(tmp_path / "run"), "--flow.weights", str(shared / "checkpoints/raft-small.pth"),
            "--flow.train_updates", "2", "--flow.predict_updates", "3", "--flow_epochs", "1", "--pose_steps", "10",
            "--progress_bar", "false", "--video", "false"]  # fmt: skip
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "| agreement_px |" in out
    assert (tmp_path / "run/poses.npz").is_file() and (tmp_path / "run/summary.json").is_file()
    assert json.loads((tmp_path / "run/summary.json").read_text())["speed"]["frames"] == 2  # --data.max_frames


def help_of(argv, capsys) -> str:
    with pytest.raises(SystemExit) as done:
        main(argv)
    assert done.value.code == 0
    return " ".join(capsys.readouterr().out.split())


def test_import_help_gives_each_reader_its_whole_first_paragraph_as_plain_text(capsys):
    listing = help_of(["import", "--help"], capsys)
    sintel = "Read frames first..last (inclusive, Sintel's numbering from 1; default: all) of one scene as a Scene"
    assert f"{sintel} at 24 fps." in listing
    assert "natural name order) as a Scene: source frames first, first + stride, first + 2 stride, ..." in listing
    for kind in ("sintel", "3dpw", "h36m", "video"):
        text = help_of(["import", kind, "--help"], capsys)
        assert "``" not in text and ":class:" not in text and ":func:" not in text and "<class" not in text
        assert "required, type: str | PathLike" in text  # the reader's positional path argument
    sintel = help_of(["import", "sintel", "--help"], capsys)
    assert "at 24 fps." in sintel and "--first FIRST first frame number, from 1" in sintel


def test_import_errors_are_one_line(tmp_path, capsys):
    cases = [(["import", "video", str(tmp_path / "v.mp4"), "--out", str(tmp_path / "s"), "--strid", "2"],
              "unrecognized arguments: --strid"),
             (["import", "sintel", str(tmp_path), "alley_1", "--out", str(tmp_path / "s"), "--first", "abc"],
              "--first: expected int, got 'abc'"),
             (["import", "sintel", str(tmp_path / "none"), "alley_1", "--out", str(tmp_path / "s")],
              str(tmp_path / "none")),
             (["import", "fly", "--out", str(tmp_path / "s")], "invalid choice: 'fly'")]  # fmt: skip
    for argv, words in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1 and err.startswith("lit-boot import: error: "), err
    assert not (tmp_path / "s").exists()


def test_options_that_need_estimate_are_refused_without_it(tmp_path, capsys):
    from lit_boot.cli.importing import with_poses

    video = tmp_path / "v.mp4"
    video.write_bytes(b"")  # never read: the options are refused first
    cases = [("--detector", "yolox_nano", "--detector: needs --estimate true"),
             ("--pose_model", str(tmp_path / "m.onnx"), "--pose_model: needs --estimate true"),
             ("--people", "all", "--people: needs --estimate true or --poses")]  # fmt: skip
    for flag, value, words in cases:
        assert main(["import", "video", str(video), "--out", str(tmp_path / "s"), flag, value]) == 2
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1, err
        # the other readers' path (a scene read first): the same words
        with pytest.raises(ValueError, match=re.escape(words)):
            with_poses(None, None, False, **{flag[2:]: value})
    assert not (tmp_path / "s").exists()
    assert with_poses("scene", None, False) == "scene"  # nothing asked of --estimate: the scene as it was
