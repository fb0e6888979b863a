"""Every ```python block of README.md and of the docs pages (docs/*.md) runs as written, on tiny data.

The blocks are found by parsing the markdown (one test per block, named after the heading
above it) and run in-process, each in a fresh empty working directory. What a block names
(a scene folder, ``clip.mp4``, ``data/Sintel`` ...) is made there first, tiny and in the
official format, by the builders in ``PREPARE``, keyed by the path as the block spells it: a
new block that names something else fails on the missing file until a builder is added here.
RAFT weight names resolve to the shared raft-small.pth (``$LIT_BOOT_CHECKPOINTS``), so blocks
that train or run RAFT need ../shared; blocks that call MediaPipe need the mediapipe extra.
"""

from __future__ import annotations

import importlib.util
import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from test_readers_3dpw import _write_sequence
from test_readers_estimates import _kp, _metro_truth
from test_readers_h36m import _write_dataset
from test_readers_sintel import write_sintel_tree

import lit_boot
from lit_boot.bootstrap.report import write_video
from lit_boot.core.joints import H36M_J17_TO_J14
from lit_boot.data.readers import PoseEstimates, save_poses
from lit_boot.data import write_flows

README = Path(__file__).resolve().parents[1] / "README.md"
DOCS = sorted((README.parent / "docs").glob("*.md"))  # the docs site's pages (not the API reference)

#: Frames of the tiny clip.mp4 (and of the DCPose / METRO files that must match it).
CLIP_FRAMES = 2


@dataclass(frozen=True)
class Block:
    heading: str  # the nearest heading above the block
    line: int  # the file's line of the block's first code line (1-based)
    code: str
    source: Path = README  # the markdown file


def python_blocks(text: str, source: Path = README) -> list[Block]:
    """The ```python fenced blocks of a markdown text, with the heading above each."""
    blocks: list[Block] = []
    heading, fence, start, lines = "", None, 0, []
    for number, line in enumerate(text.splitlines(), start=1):
        if fence is None:
            m = re.match(r"^(```+|~~~+)\s*(\S*)", line)
            if m:
                fence, start, lines = (m.group(1), m.group(2).lower()), number + 1, []
            elif line.startswith("#"):
                heading = line.lstrip("#").strip()
        elif line.strip() == fence[0]:
            if fence[1] in ("python", "py"):
                blocks.append(Block(heading, start, "\n".join(lines) + "\n", source))
            fence = None
        else:
            lines.append(line)
    return blocks


def _slug(heading: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", heading.lower()).strip("-") or "top"


BLOCKS = [block for page in (README, *DOCS) for block in python_blocks(page.read_text(encoding="utf-8"), page)]


def _ids(blocks: list[Block]) -> list[str]:
    ids: list[str] = []
    for block in blocks:
        slug = _slug(block.heading) if block.source == README else f"{block.source.stem}-{_slug(block.heading)}"
        ids.append(slug if slug not in ids else f"{slug}-{sum(i.startswith(slug) for i in ids) + 1}")
    return ids


# --- what the blocks name, made tiny -----------------------------------------------------------------
def _scene(path: Path, frames: int) -> None:
    if not path.exists():
        lit_boot.save_scene(lit_boot.make_scene(motion="run", frames=frames, height=128, width=128, seed=0), path)


def _predictions(path: Path) -> None:
    """flow_*.flo as `lit-boot predict` writes them (here the scene's GT flow)."""
    _scene(Path("runs/demo_scene"), 3)
    write_flows(path, lit_boot.load_scene("runs/demo_scene").gt.flow, png=False)


def _clip(path: Path) -> None:
    """clip.mp4 (a synthetic person, 144x256: 16:9, as the METRO files' 720x1280) and
    clip_poses.npz (its simulated estimates)."""
    scene = lit_boot.make_scene(motion="walk", frames=CLIP_FRAMES, height=144, width=256, seed=1)
    write_video(scene.frames, path, scene.fps)
    estimates = PoseEstimates(keypoints2d=scene.keypoints2d, keypoints_conf=scene.keypoints_conf,
                              joints3d=scene.joints3d, cameras=scene.cameras, image_size=(144, 256),
                              source="synthetic")  # fmt: skip
    save_poses(estimates, "clip_poses.npz")


def _dcpose(path: Path) -> None:
    info = [{"image_path": f"{t:06d}.jpg", "keypoints": _kp(40 + 3 * t, 30)} for t in range(CLIP_FRAMES)]
    path.write_text(json.dumps({"Info": info}))


def _coco_results(path: Path) -> None:
    flat = lambda kp: [v for point in kp for v in point]  # noqa: E731
    results = [{"image_id": i, "category_id": 1, "keypoints": flat(_kp(10 * i, 20)), "score": 0.9} for i in (3, 7)]
    path.write_text(json.dumps(results))  # image 9: nobody


def _metro_folder(path: Path) -> None:
    """METRO's per-frame output: LSP-order joints (m), camera, crop parameters."""
    path.mkdir(parents=True)
    joints, cam, scale, start, _ = _metro_truth(CLIP_FRAMES)
    for t in range(CLIP_FRAMES):
        crop = {"scale": scale[t], "start_pt": start[t], "img_size": 224}
        lsp = joints[t, list(H36M_J17_TO_J14)][None]
        np.savez(path / f"frame_{t}.npz", pred_3d_joints_from_smpl=lsp, pred_camera=cam[t][None], proc_param=crop)


def _h36m(path: Path) -> None:
    path.mkdir(parents=True)
    _write_dataset(path)


#: (path as a block spells it, builder); run in this order for every block that names the path.
PREPARE = [
    ("runs/demo_scene", lambda p: _scene(p, 3)),
    ("runs/demo_scene/FlowTTT/predictions", _predictions),
    ("runs/demo/scene", lambda p: _scene(p, 2)),
    ("clip.mp4", _clip),
    ("dcpose.json", _dcpose),
    ("results.json", _coco_results),
    ("metro_out/", _metro_folder),
    ("data/Sintel", lambda p: write_sintel_tree(p, "alley_2", frames=10)),
    ("data/3DPW", lambda p: _write_sequence(p, name="downtown_walking_00")),
    ("data/h36m", _h36m),
]

NEEDS_WEIGHTS = ("FlowTTT(", "load_raft(", "bootstrap(", "Bootstrap(")
NEEDS_MEDIAPIPE = ("estimate_poses(", "lit_boot.estimate")
HAVE_MEDIAPIPE = importlib.util.find_spec("mediapipe") is not None


def _params() -> list:
    params = []
    for block, name in zip(BLOCKS, _ids(BLOCKS)):
        marks = []
        if any(s in block.code for s in NEEDS_WEIGHTS):
            marks.append(pytest.mark.shared)
        if any(s in block.code for s in NEEDS_MEDIAPIPE):
            marks += [pytest.mark.mediapipe, pytest.mark.skipif(not HAVE_MEDIAPIPE, reason="needs the mediapipe extra")]
        params.append(pytest.param(block, id=name, marks=marks))
    return params


def test_readme_has_python_blocks() -> None:
    assert len(BLOCKS) >= 5, f"README.md + docs: expected the Python examples, found {len(BLOCKS)} ```python blocks"
    assert all(block.code.strip() for block in BLOCKS)


@pytest.mark.parametrize("block", _params())
def test_readme_block_runs(block: Block, request, tmp_path, monkeypatch) -> None:
    if any(s in block.code for s in NEEDS_WEIGHTS):
        monkeypatch.setenv("LIT_BOOT_CHECKPOINTS", str(request.getfixturevalue("shared") / "checkpoints"))
    monkeypatch.chdir(tmp_path)
    for path, build in PREPARE:
        if path in block.code and not Path(path).exists():
            build(Path(path))
    # Line numbers in tracebacks are the markdown file's.
    code = compile("\n" * (block.line - 1) + block.code, str(block.source), "exec")
    exec(code, {"__name__": "__main__"})
