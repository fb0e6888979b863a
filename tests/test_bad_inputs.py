"""Issue 12, bad input never costs a user their data: the bad-input matrix, one test per row.

Each row runs the lit-boot command a user would run on that input, in process: exit status 2,
one line on stderr naming the file or argument and what was expected, no traceback, and nothing
written or changed (every file under the test's folder, the working directory included, is
snapshotted by content and mtime before and after).
"""

from __future__ import annotations

import errno
import hashlib
import json
import math
import re
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import torch
from torchvision.models.optical_flow import raft_large, raft_small

import lit_boot
from lit_boot.bootstrap import BootstrapConfig
from lit_boot.cli import main
from lit_boot.core import Scene
from lit_boot.data import memory, save_scene, write_flo, write_png
from lit_boot.data.readers import POSES_FORMAT
from lit_boot.flow.raft import predict_flow
from lit_boot.synth import make_scene

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
T, H, W = 3, 48, 64


def _scene() -> Scene:
    return make_scene(motion="run", frames=T, height=H, width=W, seed=0)


def _frames(folder: Path, sizes: dict[int, tuple[int, int]] | None = None) -> Path:
    """T PNG frames 0000.png ... (frame t of size ``sizes[t]`` = (h, w) where given)."""
    folder.mkdir(parents=True)
    for t, frame in enumerate(_scene().frames):
        h, w = (sizes or {}).get(t, (H, W))
        write_png(folder / f"{t:04d}.png", frame[:, :h, :w].contiguous())
    return folder


def _poses(path: Path, frames: int = T, joints: int = 17, value: float | None = None, conf: float = 0.9) -> Path:
    """A raw lit-boot pose file (written without validation): keypoints inside the frame, all
    set to ``value`` when given."""
    keypoints = np.tile(np.linspace([5.0, 5.0], [W - 5.0, H - 5.0], joints, dtype=np.float32), (frames, 1, 1))
    if value is not None:
        keypoints[:] = value
    header = {"format": POSES_FORMAT, "version": 1, "keypoints_layout": "coco17", "joints3d_layout": "lsp14",
              "cameras": None, "image_size": None, "source": "test", "metadata": {}}  # fmt: skip
    np.savez(path, header=np.array(json.dumps(header)), frame_indices=np.arange(frames),
             keypoints2d=keypoints, keypoints_conf=np.full((frames, joints), conf, np.float32))  # fmt: skip
    return path


def _sintel(root: Path, second_flo: Callable[[bytes], bytes]) -> Path:
    """A 3-frame Sintel copy whose second .flo holds ``second_flo(valid bytes)``."""
    training = root / "training"
    _frames(training / "final" / "walk")
    for t in range(T):
        (training / "final" / "walk" / f"{t:04d}.png").rename(training / "final" / "walk" / f"frame_{t + 1:04d}.png")
    flows = training / "flow" / "walk"
    flows.mkdir(parents=True)
    good = write_flo(flows / "frame_0001.flo", _scene().gt.flow[0]).read_bytes()
    (flows / "frame_0002.flo").write_bytes(second_flo(good))
    return root


def _nan_flo(good: bytes) -> bytes:
    return good[:12] + np.full(2 * H * W, np.nan, "<f4").tobytes()


def _bootstrap(scene: Path, out: Path, *extra: str) -> list[str]:
    return ["bootstrap", "--config", str(CONFIGS / "bootstrap.yaml"), "--data.scene", str(scene), "--out", str(out),
            "--progress_bar", "false", *extra]  # fmt: skip


def _import_video(source: Path, out: Path, *extra: str) -> list[str]:
    return ["import", "video", str(source), "--out", str(out), *extra]


def _weights_row(make: Callable[[Path], Path]) -> Callable[[Path, Path, pytest.MonkeyPatch], list[str]]:
    def build(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
        save_scene(_scene(), src / "scene")
        return _bootstrap(src / "scene", out / "run", "--flow.weights", str(make(src)))

    return build


def _bootstrap_with(*extra: str) -> Callable[[Path, Path, pytest.MonkeyPatch], list[str]]:
    def build(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
        save_scene(_scene(), src / "scene")
        return _bootstrap(src / "scene", out / "run", *extra)

    return build


def _text_file(path: Path) -> Path:
    path.write_text("notes, not weights\n")
    return path


def _state_file(path: Path, state: dict) -> Path:
    torch.save(state, path)
    return path


def _read_only(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
    real = Path.mkdir

    def mkdir(self: Path, *args, **kwargs):  # root ignores chmod: refuse as a read-only folder would
        if self == out or out in self.parents:
            raise PermissionError(errno.EACCES, "Permission denied", str(self))
        return real(self, *args, **kwargs)

    _frames(src / "frames")
    mp.setattr(Path, "mkdir", mkdir)
    return _import_video(src / "frames", out / "scene")


def _disk_full(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
    def full(path, data):  # scene.json, written last: frames and arrays.npz are already there
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    _frames(src / "frames")
    mp.setattr("lit_boot.data.scene_io.atomic_write_bytes", full)
    return _import_video(src / "frames", out / "scene")


def _low_memory(mp: pytest.MonkeyPatch, frames: int) -> None:
    """Memory for ``frames`` frames of the test size, and not one more."""
    mp.setattr(memory, "available_memory", lambda: memory.estimate_memory(frames, H, W).total)


def _run_folder(src: Path, out: Path, config: str, shared: Path) -> list[str]:
    """A run folder with a finished stage whose config.json holds ``config``."""
    save_scene(_scene(), src / "scene")
    (out / "run" / "stages" / "initial").mkdir(parents=True)
    (out / "run" / "stages" / "initial" / "stage.json").write_text("{}")
    (out / "run" / "config.json").write_text(config)
    return _bootstrap(src / "scene", out / "run", "--flow.weights", str(shared / "checkpoints" / "raft-small.pth"))


def _other_settings(src: Path, version: str = lit_boot.__version__) -> str:
    return json.dumps({"lit_boot": version, "scene": str(src / "scene"),
                       "config": {**BootstrapConfig().to_dict(), "cycles": 2}})  # fmt: skip


@dataclass
class Row:
    """One bad input: ``build(src, out, monkeypatch)`` makes it and returns the command line;
    ``expect``: regular expressions the error line must match; ``shared``: the build takes the
    shared folder too (real weights)."""

    build: Callable[..., list[str]]
    expect: tuple[str, ...]
    shared: bool = False


def _missing_scene(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
    return _bootstrap(src / "nope", out / "run")


def _empty_scene(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
    (src / "empty").mkdir()
    return _bootstrap(src / "empty", out / "run")


def _one_frame(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
    save_scene(Scene(frames=_scene().frames[:1]), src / "one")
    return _bootstrap(src / "one", out / "run")


def _sintel_row(second_flo: Callable[[bytes], bytes]) -> Callable:
    def build(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
        return ["import", "sintel", str(_sintel(src / "sintel", second_flo)), "walk", "--out", str(out / "scene")]

    return build


def _nan_flows_for_pose_fit(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
    save_scene(_scene(), src / "scene")
    (src / "flows").mkdir()
    good = write_flo(src / "flows" / "flow_000000.flo", _scene().gt.flow[0]).read_bytes()
    (src / "flows" / "flow_000001.flo").write_bytes(_nan_flo(good))
    return ["fit", "--config", str(CONFIGS / "pose_refiner.yaml"), "--data.scene", str(src / "scene"),
            "--data.flows", str(src / "flows"), "--trainer.max_steps", "2"]  # fmt: skip


def _video_with_poses(**poses) -> Callable:
    def build(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
        _frames(src / "frames")
        return _import_video(src / "frames", out / "scene", "--poses", str(_poses(src / "poses.npz", **poses)))

    return build


def _text_mp4(command: str) -> Callable:
    def build(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
        (src / "clip.mp4").write_text("this is a text file, not a video\n")
        if command == "estimate-pose":
            pytest.importorskip("mediapipe")
            return ["estimate-pose", str(src / "clip.mp4"), "--out", str(out / "poses.npz")]
        return _import_video(src / "clip.mp4", out / "scene")

    return build


def _corrupt_png(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
    frame = _frames(src / "frames") / "0001.png"
    frame.write_bytes(frame.read_bytes()[:60])
    return _import_video(src / "frames", out / "scene")


def _odd_sizes(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
    return _import_video(_frames(src / "frames", {1: (40, 50)}), out / "scene")


def _low_memory_video(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
    _low_memory(mp, 2)
    return _import_video(_frames(src / "frames"), out / "scene")


def _low_memory_scene(src: Path, out: Path, mp: pytest.MonkeyPatch) -> list[str]:
    save_scene(_scene(), src / "scene")
    _low_memory(mp, 1)
    return _bootstrap(src / "scene", out / "run")


SINTEL = r"sintel/training/flow/walk/frame_0002\.flo: "
ROWS = {
    "missing-scene-folder": Row(_missing_scene, (r"in/nope: no such scene folder",)),
    "empty-scene-folder": Row(_empty_scene, (r"in/empty: not a saved scene: scene\.json is missing",)),
    "truncated-flo": Row(_sintel_row(lambda b: b[:100]), (SINTEL + r"\.flo file truncated: expected 24588 .*100",)),
    "foreign-flo": Row(_sintel_row(lambda b: b"RIFF" + b[4:]), (SINTEL + r"not a Middlebury .*expected 202021\.25",)),
    "nan-flo": Row(_sintel_row(_nan_flo), (SINTEL + r"corrupted: every value is NaN or infinite",)),
    "nan-flo-pose-refiner": Row(_nan_flows_for_pose_fit, (r"flows/flow_000001\.flo: \.flo file holds NaN or inf",)),
    "text-file-named-mp4-import": Row(_text_mp4("import"), (r"clip\.mp4: unreadable video",)),
    "text-file-named-mp4-estimate-pose": Row(_text_mp4("estimate-pose"), (r"clip\.mp4: unreadable video",)),
    "corrupt-png-frame": Row(_corrupt_png, (r"frames/0001\.png: unreadable image",)),
    "mismatched-frame-sizes": Row(_odd_sizes, (r"0001\.png: image of 50x40 px, but 0000\.png is 64x48 px",)),
    "weights-not-raft": Row(_weights_row(lambda s: _state_file(s / "foreign.pth", {"encoder.weight": torch.zeros(2)})),
                            (r"foreign\.pth: neither a torchvision RAFT state dict",)),
    "weights-not-a-torch-file": Row(_weights_row(lambda s: _text_file(s / "notes.pth")),
                                    (r"error: \S*in/notes\.pth: not a PyTorch weights file \(expected a torch\.save'd RAFT "
                                     r"state dict such as raft-small\.pth; torch\.load failed with \w+\)$",)),
    "weights-a-pickled-model": Row(_weights_row(lambda s: _state_file(s / "model.pth", torch.nn.Linear(2, 2))),
                                   (r"model\.pth: holds pickled Python objects, not only tensors .*state_dict\(\)\)$",)),
    "accelerator-unknown": Row(_bootstrap_with("--accelerator", "tpu"),
                               (r"--accelerator: expected one of \('auto', 'cpu', 'cuda', 'gpu', 'mps'\), got 'tpu'",)),
    "pose-accelerator-unknown": Row(_bootstrap_with("--pose_accelerator", "npu"), (r"--pose_accelerator: .*got 'npu'",)),
    "precision-unknown": Row(_bootstrap_with("--precision", "16mixed"),
                             (r"--precision: expected None .* 32-true, 16-mixed, bf16-mixed, .*got '16mixed'",)),
    "flow-lr-zero": Row(_bootstrap_with("--flow.lr", "0"), (r"--flow\.lr: expected > 0, got 0",)),
    "raft-weights-other-size": Row(_weights_row(lambda s: _state_file(s / "large.pth", raft_large().state_dict())),
                                   (r"large\.pth: holds raft_large weights, but raft_small was asked for",)),
    "known-weights-name-other-bytes": Row(
        _weights_row(lambda s: _state_file(s / "raft-small.pth", raft_small().state_dict())),
        (r"raft-small\.pth: sha256 [0-9a-f]{64}, but the sha256 of raft-small\.pth is c7d41b9c",)),
    "poses-wrong-frame-count": Row(_video_with_poses(frames=2),
                                   (r"poses\.npz: pose estimates for 2 frames .*the video has 3 frames",)),
    "poses-wrong-joint-count": Row(_video_with_poses(joints=15),
                                   (r"poses\.npz: .*keypoints2d: expected shape \(3, 17, 2\), got \(3, 15, 2\)",)),
    "poses-nan-keypoints": Row(_video_with_poses(value=float("nan")), (r"poses\.npz: .*keypoints2d: expected finite",)),
    "poses-infinite-keypoints": Row(_video_with_poses(value=float("inf")),
                                    (r"poses\.npz: .*keypoints2d: expected finite",)),
    "poses-all-zero-confidence": Row(_video_with_poses(conf=0.0), (r"poses\.npz: nobody is ever found",)),
    "poses-far-outside-image": Row(_video_with_poses(value=1e6),
                                   (r"poses\.npz: .*lie more than one image size outside the 64x48 px frames",
                                    r"expected x in \[-64, 128\]")),  # fmt: skip
    "scene-of-one-frame": Row(_one_frame, (r"needs at least 2 frames, has 1",)),
    "read-only-output": Row(_read_only, (r"out/scene: could not save the scene: Permission denied",)),
    "disk-full-output": Row(_disk_full, (r"out/scene: could not save the scene: no space left on the device; the "
                                         r"scene needs up to \d+ KiB.*partial copy was removed",)),  # fmt: skip
    "too-little-memory-video": Row(_low_memory_video,
                                   (r"frames: 3 frames of 64x48 px need about .* --stride 2 .*--max_frames 2",)),
    "too-little-memory-scene-folder": Row(_low_memory_scene, (r"in/scene: 3 frames of 64x48 px need about",)),
    "run-folder-other-settings": Row(lambda s, o, m, sh: _run_folder(s, o, _other_settings(s), sh),
                                     (r"out/run: holds a run with other settings \(cycles.* differ\)",),
                                     shared=True),
    "run-folder-other-version": Row(lambda s, o, m, sh: _run_folder(s, o, _other_settings(s, "0.0.1"), sh),
                                    (r"out/run: holds a run with other settings \(lit-boot version \(0\.0\.1, now ",),
                                    shared=True),
    "run-folder-corrupt-config": Row(lambda s, o, m, sh: _run_folder(s, o, "{not json", sh),
                                     (r"out/run: holds a run with other settings",), shared=True),
    "run-folder-config-not-an-object": Row(lambda s, o, m, sh: _run_folder(s, o, "[1, 2]", sh),
                                           (r"out/run/config\.json",), shared=True),
}


def snapshot(root: Path) -> dict[str, tuple[str, int] | None]:
    """Every entry under ``root``: files as (sha256, mtime_ns), folders as None."""
    return {str(p.relative_to(root)): None if p.is_dir() else (hashlib.sha256(p.read_bytes()).hexdigest(),
            p.stat().st_mtime_ns) for p in sorted(root.rglob("*"))}  # fmt: skip


@pytest.mark.parametrize("name", list(ROWS))
def test_bad_input(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys, request) -> None:
    row = ROWS[name]
    src, out = tmp_path / "in", tmp_path / "out"
    src.mkdir(), out.mkdir()
    monkeypatch.chdir(tmp_path)  # stray runs/ folders count as written
    extra = (request.getfixturevalue("shared"),) if row.shared else ()
    argv = row.build(src, out, monkeypatch, *extra)
    capsys.readouterr()
    before = snapshot(tmp_path)
    status = main(argv)
    stderr = capsys.readouterr().err
    lines = stderr.strip().splitlines()
    assert status == 2 and len(lines) == 1, stderr
    assert lines[0].startswith(f"lit-boot {argv[0]}: error: ") and "Traceback" not in stderr, stderr
    for pattern in row.expect:
        assert re.search(pattern, lines[0]), (pattern, lines[0])
    after = snapshot(tmp_path)
    assert {k: after.get(k) for k in before} == before, "an input changed"
    new = sorted(set(after) - set(before))
    assert not new, f"written: {new}"


def test_frames_smaller_than_raft_minimum_are_padded(tmp_path: Path, capsys) -> None:
    """RAFT needs 128 px (16 cells at 1/8 for its 4-level pyramid); lit-boot pads, so tiny
    frames import and get a flow of their own size: not an error."""
    frames = tmp_path / "tiny"
    frames.mkdir()
    for t in range(2):
        write_png(frames / f"{t}.png", torch.randint(0, 256, (3, 6, 8), dtype=torch.uint8))
    assert main(_import_video(frames, tmp_path / "scene")) == 0
    torch.manual_seed(0)
    with torch.no_grad():
        flow = predict_flow(raft_small().eval(), torch.zeros(3, 6, 8), torch.ones(3, 6, 8) / 2, num_flow_updates=1)
    assert flow.shape == (1, 2, 6, 8) and torch.isfinite(flow).all()


def test_console_error_is_one_line_even_from_ffmpeg(tmp_path: Path) -> None:
    """FFmpeg's own log ("moov atom not found") is silenced: stderr is the error line alone."""
    (tmp_path / "clip.mp4").write_text("not a video\n")
    done = subprocess.run([sys.executable, "-m", "lit_boot.cli", "import", "video", str(tmp_path / "clip.mp4"),
                           "--out", str(tmp_path / "scene")], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(f"lit-boot import: error: {tmp_path / 'clip.mp4'}: unreadable video")
    assert sorted(tmp_path.iterdir()) == [tmp_path / "clip.mp4"]


def test_memory_estimate_and_advice(monkeypatch: pytest.MonkeyPatch) -> None:
    """300 frames of 720p against 12 GiB: the error gives the need, its parts, and options that fit."""
    pyramid = lambda cells: cells**2 * 4 * 4 // 3  # noqa: E731  RAFT's correlation pyramid, bytes
    need = memory.estimate_memory(300, 720, 1280)
    assert need.frames == 300 * 720 * 1280 * 3 and need.flows == 2 * 299 * 2 * 720 * 1280 * 4
    # the zoom stage's crop (four frames of pixels, at most ZOOM_PIXELS) outweighs the fine-tune's three pyramids
    assert need.model == pyramid(2**21 // 64) * 8 // 5 + 256 * 2**20 > 3 * pyramid(90 * 160) + 256 * 2**20
    # at 1080p the fine-tune's pyramids (at 1/8 of the frame) are the larger; at 128x256 the zoom's four frames
    assert memory.estimate_memory(2, 1080, 1920).model == 3 * pyramid(135 * 240) + 256 * 2**20
    assert memory.estimate_memory(2, 128, 256).model == pyramid(4 * 128 * 256 // 64) * 8 // 5 + 256 * 2**20
    monkeypatch.setattr(memory, "available_memory", lambda: 12 * 2**30)
    with pytest.raises(memory.NotEnoughMemoryError) as info:
        memory.check_memory("clip.mp4", 300, 720, 1280, advice="try")
    message = str(info.value)
    assert re.match(r"clip\.mp4: 300 frames of 1280x720 px need about 13\.\d GiB of memory \(frames 791 MiB, flows "
                    r"4\.\d GiB, RAFT 8\.\d GiB\) but 12\.0 GiB is available; try --stride", message), message
    options = re.findall(r"--(stride|max_frames|resize) (\d+)", message)
    assert [o for o, _ in options] == ["stride", "max_frames", "resize"]
    for option, n in options:  # each suggestion fits
        T, H, W = {"stride": (math.ceil(300 / int(n)), 720, 1280), "max_frames": (int(n), 720, 1280),
                   "resize": (300, int(n), round(1280 * int(n) / 720))}[option]  # fmt: skip
        assert memory.estimate_memory(T, H, W).total <= 12 * 2**30, option
    memory.check_memory("clip.mp4", 30, 360, 640)  # fits: no error
    monkeypatch.setenv(memory.MEMORY_CHECK_ENV, "0")
    memory.check_memory("clip.mp4", 300, 720, 1280)  # the check turned off
    monkeypatch.undo()
    assert memory.available_memory() > 0  # /proc/meminfo here


def test_nan_flows_never_reach_the_pose_refiner(tmp_path: Path) -> None:
    """A NaN .flo in --data.flows used to reach PoseRefiner, whose backward pass then crashed the
    process (SIGSEGV); read_flo now refuses it, naming the file."""
    from lit_boot.data import FloFormatError, read_flo
    from lit_boot.pose.flows import load_flows

    scene = _scene()
    write_flo(tmp_path / "flow_000000.flo", scene.gt.flow[0])
    (tmp_path / "flow_000001.flo").write_bytes(_nan_flo((tmp_path / "flow_000000.flo").read_bytes()))
    with pytest.raises(FloFormatError, match=r"flow_000001\.flo: .*NaN or infinite flow at 3072 of 3072 pixels"):
        load_flows(tmp_path, scene)
    assert torch.isnan(read_flo(tmp_path / "flow_000001.flo", allow_nonfinite=True)).all()


@pytest.mark.shared
def test_memory_checked_before_decoding_a_video(shared: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The frame count and size come from the file's header: nothing is decoded before the check."""
    from lit_boot.data.readers import read_video

    video = shared / "data" / "videos" / "street_540p_5f.mp4"
    monkeypatch.setattr(memory, "available_memory", lambda: memory.estimate_memory(2, 540, 960).total)
    monkeypatch.setattr("lit_boot.data.readers.video.decode_video", lambda *a, **k: pytest.fail("decoded"))
    with pytest.raises(memory.NotEnoughMemoryError, match=r"street_540p_5f\.mp4: 5 frames of 960x540 px need about .*"
                                                          r"read fewer or smaller frames: --stride 3 .*--max_frames 2"):
        read_video(video)
    monkeypatch.undo()
    assert read_video(video, stride=3).num_frames == 2
