from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import torch

from lit_boot.core.cameras import Cameras
from lit_boot.core.scene import GroundTruth, Scene
from lit_boot.data import scene_io
from lit_boot.data.scene_io import SceneFormatError, load_scene, save_scene

T, H, W = 3, 8, 10


def full_scene(seed: int = 0) -> Scene:
    g = torch.Generator().manual_seed(seed)
    gt = GroundTruth(
        flow=torch.randn(T - 1, 2, H, W, generator=g),
        flow_valid=torch.rand(T - 1, H, W, generator=g) > 0.3,
        flow_occluded=torch.rand(T - 1, H, W, generator=g) > 0.7,
        joints3d=torch.randn(T, 14, 3, generator=g, dtype=torch.float64) * 500,
        joints2d=torch.rand(T, 14, 2, generator=g) * W,
        joints_layout="lsp14",
        cameras=Cameras("pinhole", torch.randn(T, 7, generator=g)),
        person_mask=torch.rand(T, H, W, generator=g) > 0.5,
        keypoints2d=torch.rand(T, 17, 2, generator=g) * W,
    )
    return Scene(
        frames=torch.randint(0, 256, (T, 3, H, W), generator=g, dtype=torch.uint8),
        fps=24.5,
        name="hand made",
        joints3d=torch.randn(T, 14, 3, generator=g) * 300,
        joints3d_layout="lsp14",
        cameras=Cameras("weak_perspective", torch.rand(T, 3, generator=g), torch.rand(T, 3, generator=g), 256.0),
        keypoints2d=torch.rand(T, 17, 2, generator=g) * W,
        keypoints_conf=torch.rand(T, 17, generator=g),
        keypoints_layout="coco17",
        gt=gt,
        metadata={"source": "test", "ids": [1, 2, 3], "nested": {"a": 0.1, "b": None, "c": True}},
    )


def frames_only() -> Scene:
    return Scene(frames=torch.randint(0, 256, (T, 3, H, W), dtype=torch.uint8), fps=30)


def assert_same_tensor(a: torch.Tensor | None, b: torch.Tensor | None, what: str) -> None:
    if a is None or b is None:
        assert a is None and b is None, what
        return
    assert a.dtype == b.dtype and a.shape == b.shape, what
    assert torch.equal(a, b), what


def assert_same_cameras(a: Cameras | None, b: Cameras | None, what: str) -> None:
    if a is None or b is None:
        assert a is None and b is None, what
        return
    assert (a.model, a.crop_size) == (b.model, b.crop_size), what
    assert_same_tensor(a.params, b.params, f"{what}.params")
    assert_same_tensor(a.crops, b.crops, f"{what}.crops")


def assert_same_scene(a: Scene, b: Scene) -> None:
    for key in ("name", "fps", "joints3d_layout", "keypoints_layout", "metadata"):
        assert getattr(a, key) == getattr(b, key), key
    for key in ("frames", "joints3d", "keypoints2d", "keypoints_conf"):
        assert_same_tensor(getattr(a, key), getattr(b, key), key)
    assert_same_cameras(a.cameras, b.cameras, "cameras")
    assert (a.gt is None) == (b.gt is None)
    if a.gt is not None:
        assert a.gt.joints_layout == b.gt.joints_layout
        for key in ("flow", "flow_valid", "flow_occluded", "joints3d", "joints2d", "person_mask", "keypoints2d"):
            assert_same_tensor(getattr(a.gt, key), getattr(b.gt, key), f"gt.{key}")
        assert_same_cameras(a.gt.cameras, b.gt.cameras, "gt.cameras")


def snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    """Every entry under ``folder`` (and the folder itself) with its mtime and size."""
    return {
        str(p.relative_to(folder)): (p.stat().st_mtime_ns, p.stat().st_size if p.is_file() else -1)
        for p in [folder, *sorted(folder.rglob("*"))]
    }


def test_full_round_trip(tmp_path: Path) -> None:
    scene = full_scene()
    out = save_scene(scene, tmp_path / "s")
    assert out == tmp_path / "s"
    assert sorted(os.listdir(out)) == ["arrays.npz", "frames", "scene.json"]
    assert sorted(os.listdir(out / "frames")) == ["000000.png", "000001.png", "000002.png"]
    assert [p.name for p in tmp_path.iterdir()] == ["s"]  # no temporary folder left behind
    assert_same_scene(scene, load_scene(out))


def test_folder_contents(tmp_path: Path) -> None:
    scene = full_scene()
    save_scene(scene, tmp_path / "s")
    meta = json.loads((tmp_path / "s" / "scene.json").read_text())
    assert meta["format"] == "lit-boot-scene" and meta["version"] == 2 and meta["others"] == []
    assert (meta["num_frames"], meta["height"], meta["width"]) == (T, H, W)
    assert meta["cameras"] == {"model": "weak_perspective", "crop_size": 256.0}
    assert meta["gt"] == {"joints_layout": "lsp14", "cameras": {"model": "pinhole", "crop_size": 224.0}}
    assert meta["metadata"] == scene.metadata
    assert meta["fields"]["gt_joints3d"] == "float64" and meta["fields"]["gt_flow_valid"] == "bool"
    with np.load(tmp_path / "s" / "arrays.npz") as npz:
        assert sorted(npz.files) == sorted(meta["fields"])
        assert "gt_cameras_crops" not in npz.files  # pinhole: no crops
        assert npz["keypoints2d"].shape == (T, 17, 2)


def test_frames_only_round_trip(tmp_path: Path) -> None:
    scene = frames_only()
    back = load_scene(save_scene(scene, tmp_path / "s"))
    assert_same_scene(scene, back)
    assert json.loads((tmp_path / "s" / "scene.json").read_text())["fields"] == {}


def test_empty_ground_truth_round_trip(tmp_path: Path) -> None:
    scene = frames_only()
    scene.gt = GroundTruth(joints_layout="h36m17")
    assert_same_scene(scene, load_scene(save_scene(scene, tmp_path / "s")))


def test_overwrite_protection(tmp_path: Path) -> None:
    target = tmp_path / "s"
    save_scene(frames_only(), target)
    before = snapshot(target)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        save_scene(full_scene(), target)
    assert snapshot(target) == before
    save_scene(full_scene(), target, overwrite=True)
    assert_same_scene(full_scene(), load_scene(target))
    assert [p.name for p in tmp_path.iterdir()] == ["s"]  # old one deleted, nothing left aside


def test_empty_folder_is_used(tmp_path: Path) -> None:
    (tmp_path / "s").mkdir()
    scene = frames_only()
    assert_same_scene(scene, load_scene(save_scene(scene, tmp_path / "s")))


def test_refuses_to_replace_a_foreign_folder_or_file(tmp_path: Path) -> None:
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("precious")
    with pytest.raises(FileExistsError, match="mine.*not a saved scene"):
        save_scene(frames_only(), folder, overwrite=True)
    assert (folder / "notes.txt").read_text() == "precious"
    file = tmp_path / "file"
    file.write_text("x")
    with pytest.raises(FileExistsError, match="not a folder"):
        save_scene(frames_only(), file, overwrite=True)
    assert file.read_text() == "x"


def test_load_writes_nothing(tmp_path: Path) -> None:
    target = save_scene(full_scene(), tmp_path / "s")
    before = snapshot(target)
    load_scene(target)
    load_scene(str(target))
    assert snapshot(target) == before


def test_interrupted_save(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # A crash from an earlier run left a temporary folder behind.
    stale = tmp_path / ".s.0123456789ab.partial"
    (stale / "frames").mkdir(parents=True)
    (stale / "frames" / "000000.png").write_bytes(b"half")

    # An exception in the middle of a save leaves no target and cleans its temporary folder.
    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(scene_io.np, "savez", boom)
    with pytest.raises(KeyboardInterrupt):
        save_scene(full_scene(), tmp_path / "s")
    assert sorted(p.name for p in tmp_path.iterdir()) == [stale.name]
    monkeypatch.undo()
    save_scene(full_scene(), tmp_path / "s")
    assert_same_scene(full_scene(), load_scene(tmp_path / "s"))


def test_interrupted_overwrite_keeps_old_scene(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = save_scene(frames_only(), tmp_path / "s")
    monkeypatch.setattr(scene_io.np, "savez", lambda *a, **k: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        save_scene(full_scene(), target, overwrite=True)
    assert load_scene(target).gt is None


def test_metadata_must_survive_json(tmp_path: Path) -> None:
    scene = frames_only()
    scene.metadata = {"pair": (1, 2)}
    with pytest.raises(ValueError, match="metadata"):
        save_scene(scene, tmp_path / "s")
    scene.metadata = {"t": torch.zeros(1)}
    with pytest.raises(ValueError, match="JSON"):
        save_scene(scene, tmp_path / "s")
    assert not any(tmp_path.iterdir())


# --- load errors --------------------------------------------------------------------------


@pytest.fixture
def saved(tmp_path: Path) -> Path:
    return save_scene(full_scene(), tmp_path / "saved")


def edit_meta(folder: Path, **changes) -> None:
    meta = json.loads((folder / "scene.json").read_text())
    meta.update(changes)
    (folder / "scene.json").write_text(json.dumps(meta))


def test_missing_folder(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nowhere"):
        load_scene(tmp_path / "nowhere")


def test_missing_scene_json(saved: Path) -> None:
    (saved / "scene.json").unlink()
    with pytest.raises(FileNotFoundError, match=f"{saved}.*scene.json"):
        load_scene(saved)


def test_corrupted_scene_json(saved: Path) -> None:
    (saved / "scene.json").write_text('{"format": "lit-boot-scene", "vers')
    with pytest.raises(SceneFormatError, match="scene.json.*not valid JSON"):
        load_scene(saved)


def test_scene_json_missing_key(saved: Path) -> None:
    meta = json.loads((saved / "scene.json").read_text())
    del meta["fps"]
    (saved / "scene.json").write_text(json.dumps(meta))
    with pytest.raises(SceneFormatError, match="scene.json.*fps"):
        load_scene(saved)


def test_wrong_format_name(saved: Path) -> None:
    edit_meta(saved, format="something-else")
    with pytest.raises(SceneFormatError, match=f"{saved}.*something-else"):
        load_scene(saved)


def test_newer_version(saved: Path) -> None:
    edit_meta(saved, version=3)
    with pytest.raises(SceneFormatError, match=f"{saved}.*version 3 is newer"):
        load_scene(saved)


def test_a_version_1_scene_reads_as_one_person(saved: Path) -> None:
    data = json.loads((saved / "scene.json").read_text())
    data.pop("track_id"), data.pop("others")  # version 1 had neither
    data["version"] = 1
    (saved / "scene.json").write_text(json.dumps(data))
    scene = load_scene(saved)
    assert scene.num_people == 1 and scene.track_id == 0


def test_frame_count_mismatch(saved: Path) -> None:
    edit_meta(saved, num_frames=4)
    with pytest.raises(SceneFormatError, match=f"{saved}.*num_frames=4.*3 PNG"):
        load_scene(saved)


def test_missing_frame_file(saved: Path) -> None:
    (saved / "frames" / "000001.png").unlink()
    with pytest.raises(SceneFormatError, match="num_frames=3.*2 PNG"):
        load_scene(saved)


def test_unreadable_png(saved: Path) -> None:
    (saved / "frames" / "000001.png").write_bytes(b"not a png at all")
    with pytest.raises(SceneFormatError, match="000001.png.*unreadable"):
        load_scene(saved)


def test_frame_of_wrong_size(saved: Path) -> None:
    from lit_boot.data.visualize import write_png

    write_png(saved / "frames" / "000002.png", torch.zeros(3, H + 1, W, dtype=torch.uint8))
    with pytest.raises(SceneFormatError, match="000002.png.*10x8"):
        load_scene(saved)


def test_missing_npz_key(saved: Path) -> None:
    with np.load(saved / "arrays.npz") as npz:
        arrays = {k: npz[k] for k in npz.files if k != "gt_flow"}
    np.savez(saved / "arrays.npz", **arrays)
    with pytest.raises(SceneFormatError, match=r"arrays.npz.*\['gt_flow'\]"):
        load_scene(saved)


def test_corrupted_npz(saved: Path) -> None:
    (saved / "arrays.npz").write_bytes(b"garbage")
    with pytest.raises(SceneFormatError, match="arrays.npz"):
        load_scene(saved)


def test_inconsistent_arrays(saved: Path) -> None:
    with np.load(saved / "arrays.npz") as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["joints3d"] = arrays["joints3d"][:, :5]
    np.savez(saved / "arrays.npz", **arrays)
    with pytest.raises(SceneFormatError, match=f"{saved}.*joints3d"):
        load_scene(saved)
