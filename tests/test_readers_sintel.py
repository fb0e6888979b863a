"""MPI-Sintel reader (lit_boot.data.readers.sintel) on a tiny tree in the official layout,
plus the real partial copy in ../shared."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from lit_boot.metrics import scene_flow_metrics
from lit_boot.data.flo import read_flo, write_flo
from lit_boot.data.readers import (
    SINTEL_HUMAN_PASS,
    SINTEL_HUMAN_SCENES,
    DatasetFormatError,
    list_sintel_scenes,
    read_sintel,
)
from lit_boot.data.scene_io import SceneFormatError, load_scene, save_scene
from lit_boot.data.visualize import read_png, scene_preview, write_png

H, W = 16, 24


def _mask(path: Path, rows: slice, cols: slice) -> torch.Tensor:
    mask = torch.zeros(H, W, dtype=torch.bool)
    mask[rows, cols] = True
    write_png(path, (mask.to(torch.uint8) * 255)[None].expand(3, H, W).contiguous())
    return mask


def write_sintel_tree(root: Path, scene: str = "walk", frames: int = 3) -> dict:
    """<root>/training/{final,clean}/<scene>/frame_0001...png (``frames`` of them, H x W), GT for
    1->2 only (the other pairs have none), and an empty final/run; also used by test_readme.py."""
    gen = torch.Generator().manual_seed(0)
    training = root / "training"
    for sub in [f"{kind}/{scene}" for kind in ("final", "clean", "flow", "invalid", "occlusions")] + ["final/run"]:
        (training / sub).mkdir(parents=True)
    images = torch.randint(0, 256, (frames, 3, H, W), dtype=torch.uint8, generator=gen)
    for i, frame in enumerate(images, start=1):
        write_png(training / "final" / scene / f"frame_{i:04d}.png", frame)
        write_png(training / "clean" / scene / f"frame_{i:04d}.png", 255 - frame)
    flow = torch.randn(2, H, W, generator=gen) * 3
    write_flo(training / "flow" / scene / "frame_0001.flo", flow)
    invalid = _mask(training / "invalid" / scene / "frame_0001.png", slice(0, 4), slice(0, 6))
    occluded = _mask(training / "occlusions" / scene / "frame_0001.png", slice(8, 16), slice(10, 24))
    return {"root": root, "training": training, "frames": images, "flow": flow,
            "invalid": invalid, "occluded": occluded}  # fmt: skip


@pytest.fixture()
def tree(tmp_path: Path) -> dict:
    """training/{final,clean}/walk/frame_0001..0003.png, GT for 1->2 only (2->3 is missing)."""
    return write_sintel_tree(tmp_path / "sintel")


def test_round_trip_frames_flow_masks(tree: dict) -> None:
    scene = read_sintel(tree["root"], "walk")
    assert (scene.num_frames, scene.height, scene.width, scene.fps) == (3, H, W, 24.0)
    assert torch.equal(scene.frames, tree["frames"])
    gt = scene.gt
    assert gt.flow.shape == (2, 2, H, W) and gt.flow.dtype == torch.float32
    assert torch.equal(gt.flow[0], tree["flow"])
    assert torch.equal(gt.flow_valid[0], ~tree["invalid"])
    assert torch.equal(gt.flow_occluded[0], tree["occluded"])
    # pair 2 -> 3 has no .flo: zero flow, invalid everywhere
    assert not gt.flow_valid[1].any() and not gt.flow_occluded[1].any() and not gt.flow[1].any()
    assert scene.metadata["gt_pairs"] == [[1, 2]] and scene.metadata["frames"] == [1, 2, 3]
    assert scene.metadata["missing_masks"] == [] and scene.joints3d is None and scene.keypoints2d is None


def test_scene_saves_and_loads_back(tree: dict, tmp_path: Path) -> None:
    scene = read_sintel(tree["root"], "walk")
    back = load_scene(save_scene(scene, tmp_path / "saved"))
    assert back.metadata == scene.metadata and torch.equal(back.gt.flow_valid, scene.gt.flow_valid)


def test_clean_pass_and_listing(tree: dict) -> None:
    assert torch.equal(read_sintel(tree["root"], "walk", pass_name="clean").frames, 255 - tree["frames"])
    assert list_sintel_scenes(tree["root"]) == ["run", "walk"]
    assert list_sintel_scenes(tree["root"], "clean") == ["walk"]
    assert SINTEL_HUMAN_SCENES == ("alley_2", "bamboo_2", "cave_2", "cave_4") and SINTEL_HUMAN_PASS == "final"


def test_frame_range_without_gt_pairs(tree: dict) -> None:
    scene = read_sintel(tree["root"], "walk", first=2, last=3)
    assert scene.num_frames == 2 and torch.equal(scene.frames, tree["frames"][1:])
    assert scene.gt is None and scene.metadata["gt_pairs"] == []
    assert read_sintel(tree["root"], "walk", last=2).gt.flow_valid.shape == (1, H, W)


def test_missing_pairs_do_not_count_in_flow_metrics(tree: dict) -> None:
    scene = read_sintel(tree["root"], "walk")
    flows = scene.gt.flow.clone()
    flows[0] += 1.0  # EPE sqrt(2) on the GT pair
    flows[1] += 100.0  # the pair without GT must not count
    assert scene_flow_metrics(scene.gt, flows)["epe"] == pytest.approx(2**0.5, rel=1e-5)


def test_resize_scales_flow_and_masks(tree: dict) -> None:
    scene = read_sintel(tree["root"], "walk", size=(8, 12))
    assert scene.frames.shape == (3, 3, 8, 12)
    # centre-aligned nearest: output pixel (x, y) samples input (2x+1, 2y+1) at a factor 1/2
    torch.testing.assert_close(scene.gt.flow[0], tree["flow"][:, 1::2, 1::2] * 0.5)
    assert torch.equal(scene.gt.flow_valid[0], ~tree["invalid"][1::2, 1::2])
    assert torch.equal(scene.gt.flow_occluded[0], tree["occluded"][1::2, 1::2])


def test_missing_masks_and_non_finite_flow(tree: dict) -> None:
    (tree["training"] / "occlusions" / "walk" / "frame_0001.png").unlink()
    flow = tree["flow"].clone()
    flow[:, 10, 20] = float("nan")
    flow[0, 11, 20] = 1e10
    write_flo(tree["training"] / "flow" / "walk" / "frame_0001.flo", flow)
    scene = read_sintel(tree["root"], "walk")
    assert scene.metadata["missing_masks"] == ["occlusions/walk/frame_0001.png"]
    assert not scene.gt.flow_occluded.any()
    assert not scene.gt.flow_valid[0, 10, 20] and not scene.gt.flow_valid[0, 11, 20]
    assert torch.isfinite(scene.gt.flow).all() and scene.gt.flow_valid[0, 12, 20]


def test_reading_writes_nothing(tree: dict) -> None:
    before = sorted((p, p.stat().st_mtime_ns) for p in tree["root"].rglob("*"))
    read_sintel(tree["root"], "walk", size=(8, 12))
    assert sorted((p, p.stat().st_mtime_ns) for p in tree["root"].rglob("*")) == before


def test_missing_root_pass_and_scene(tree: dict, tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nowhere"):
        read_sintel(tmp_path / "nowhere", "walk")
    with pytest.raises(FileNotFoundError, match="training"):
        read_sintel(tmp_path, "walk")
    with pytest.raises(FileNotFoundError, match=r"jump.*holds \['run', 'walk'\]"):
        read_sintel(tree["root"], "jump")
    with pytest.raises(ValueError, match="pass_name"):
        read_sintel(tree["root"], "walk", pass_name="albedo")
    with pytest.raises(ValueError, match=r"frames 2..7 requested, but the frames run 1..3"):
        read_sintel(tree["root"], "walk", first=2, last=7)
    with pytest.raises(DatasetFormatError, match="no frames found"):
        read_sintel(tree["root"], "run")


@pytest.mark.parametrize(
    "relpath,content,match",
    [
        ("flow/walk/frame_0001.flo", b"PIEH" + bytes(20), "frame_0001.flo"),  # corrupted header/payload
        ("final/walk/frame_0002.png", b"not a png", r"frame_0002.png: unreadable image"),
    ],
)
def test_malformed_files_name_the_file(tree: dict, relpath: str, content: bytes, match: str) -> None:
    (tree["training"] / relpath).write_bytes(content)
    with pytest.raises(SceneFormatError, match=match):
        read_sintel(tree["root"], "walk")


def test_inconsistent_sizes_and_gaps(tree: dict) -> None:
    training = tree["training"]
    write_flo(training / "flow" / "walk" / "frame_0001.flo", torch.zeros(2, H, W + 1))
    with pytest.raises(DatasetFormatError, match=r"frame_0001.flo: flow of 25x16 px, expected 24x16"):
        read_sintel(tree["root"], "walk")
    write_flo(training / "flow" / "walk" / "frame_0001.flo", tree["flow"])
    write_png(training / "invalid" / "walk" / "frame_0001.png", torch.zeros(3, H - 1, W, dtype=torch.uint8))
    with pytest.raises(DatasetFormatError, match=r"invalid/walk/frame_0001.png: mask of 24x15 px"):
        read_sintel(tree["root"], "walk")
    write_png(training / "final" / "walk" / "frame_0003.png", torch.zeros(3, H, W + 2, dtype=torch.uint8))
    with pytest.raises(DatasetFormatError, match=r"frame_0003.png: image of 26x16 px, but frame_0001.png is 24x16"):
        read_sintel(tree["root"], "walk")
    (training / "final" / "walk" / "frame_0002.png").unlink()
    with pytest.raises(DatasetFormatError, match=r"frames \[2\] are missing"):
        read_sintel(tree["root"], "walk")


# --- the real partial copy -----------------------------------------------------------------------
SAMPLES = {"alley_1": 2, "market_5": 2, "bandage_1": 35, "temple_3": 22}  # GT pair n -> n+1 (SOURCES.md)


@pytest.mark.shared
@pytest.mark.parametrize("scene_name", sorted(SAMPLES))
def test_shared_samples_load_with_their_gt(shared: Path, scene_name: str) -> None:
    root = shared / "data" / "sintel_samples"
    gt_first = SAMPLES[scene_name]
    assert scene_name in list_sintel_scenes(root)
    scene = read_sintel(root, scene_name, first=gt_first, last=gt_first + 1)  # the GT pair only: fast
    assert (scene.num_frames, scene.height, scene.width) == (2, 436, 1024)
    assert scene.metadata["gt_pairs"] == [[gt_first, gt_first + 1]]
    flo = root / "training" / "flow" / scene_name / f"frame_{gt_first:04d}.flo"
    assert torch.equal(scene.gt.flow[0], read_flo(flo))
    assert scene.gt.flow_valid[0].float().mean() > 0.99 and scene.gt.flow_occluded[0].any()
    frame = root / "training" / "final" / scene_name / f"frame_{gt_first:04d}.png"
    assert torch.equal(scene.frames[0], read_png(frame))


@pytest.mark.shared
def test_shared_whole_sample_marks_pairs_without_gt(shared: Path) -> None:
    root = shared / "data" / "sintel_samples"
    scene = read_sintel(root, "alley_1")
    assert scene.metadata["frames"] == [1, 2, 3, 4] and scene.metadata["gt_pairs"] == [[2, 3]]
    assert scene.gt.flow_valid.flatten(1).any(1).tolist() == [False, True, False]
    assert torch.equal(scene.gt.flow[1], read_flo(root / "training" / "flow" / "alley_1" / "frame_0002.flo"))


@pytest.mark.shared
def test_shared_partial_sample_summary_and_preview_show_only_the_valid_gt(shared: Path) -> None:
    scene = read_sintel(shared / "data" / "sintel_samples", "alley_1", size=(109, 256))
    assert "GT on 1 of 3 pairs" in scene.summary()
    no_gt, with_gt = scene_preview(scene, 0), scene_preview(scene, 1)
    W = scene.width
    grey = no_gt[:, :, W : 2 * W]
    assert torch.equal(grey[0], grey[1]) and torch.equal(grey[1], grey[2])  # no GT: the frame in grey,
    assert grey.float().std() > 10  # not the blank white of an all-zero flow
    colour = with_gt[:, :, W : 2 * W].int()
    assert (colour[0] - colour[1]).abs().max() > 20  # the GT pair: colour-coded flow
