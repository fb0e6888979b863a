"""3DPW reader (lit_boot.data.readers.pw3d) on a tiny sequence in the official format, and the
SMPL-24 -> LSP-14 mapping it relies on."""

from __future__ import annotations

import math
import pickle
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from lit_boot.core.joints import LSP14, SMPL24, SMPL24_TO_LSP14, get_layout, map_joints, mapping_matrix
from lit_boot.data.readers import OPENPOSE18_TO_COCO17, DatasetFormatError, list_3dpw_sequences, read_3dpw
from lit_boot.data.scene_io import load_scene, save_scene

T, H, W = 4, 16, 24
K = np.array([[40.0, 0.0, 11.5], [0.0, 42.0, 7.5], [0.0, 0.0, 1.0]])


def _cam_poses() -> np.ndarray:
    """World -> camera: a rotation about y growing with t, then 3 m forward."""
    poses = np.zeros((T, 4, 4))
    for t in range(T):
        a = 0.1 * t
        poses[t, :3, :3] = [[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]]
        poses[t, :3, 3] = [0.1, -0.2, 3.0]
        poses[t, 3, 3] = 1.0
    return poses


def _write_sequence(root: Path, name: str = "downtown_walk_00", split: str = "test", **overrides) -> dict:
    rng = np.random.default_rng(0)
    data = {
        "sequence": name,
        "genders": ["m", "f"],
        "betas": [rng.normal(size=10), rng.normal(size=10)],
        "poses": [rng.normal(size=(T, 72)), rng.normal(size=(T, 72))],
        "trans": [rng.normal(size=(T, 3)), rng.normal(size=(T, 3))],
        "jointPositions": [rng.uniform(-0.5, 0.5, size=(T, 72)), rng.uniform(-0.5, 0.5, size=(T, 72))],
        "cam_intrinsics": K,
        "cam_poses": _cam_poses(),
        "campose_valid": [np.array([1, 1, 0, 1]), np.ones(T)],
        "poses2d": [rng.uniform(0, 20, size=(T, 3, 18)), rng.uniform(0, 20, size=(T, 3, 18))],
        "img_frame_ids": np.arange(T) * 2,
    }
    data["poses2d"][0][:, 2] = rng.uniform(-0.2, 1.2, size=(T, 18))  # confidences, some out of [0, 1]
    data.update(overrides)
    (root / "sequenceFiles" / split).mkdir(parents=True, exist_ok=True)
    with open(root / "sequenceFiles" / split / f"{name}.pkl", "wb") as f:
        pickle.dump(data, f, protocol=2)
    images = root / "imageFiles" / name
    images.mkdir(parents=True, exist_ok=True)
    for t in range(T):
        cv2.imwrite(str(images / f"image_{t:05d}.jpg"), np.full((H, W, 3), 40 * t + 20, dtype=np.uint8))
    return data


@pytest.fixture()
def pw3d(tmp_path: Path) -> tuple[Path, dict]:
    return tmp_path, _write_sequence(tmp_path)


def _camera_points(data: dict, person: int, t: int) -> np.ndarray:
    """The 24 SMPL joints of frame t in the camera frame, mm (by hand)."""
    pose = data["cam_poses"][t]
    world = data["jointPositions"][person][t].reshape(24, 3)
    return (world @ pose[:3, :3].T + pose[:3, 3]) * 1000.0


# --- SMPL-24 layout and mapping --------------------------------------------------------------------
def test_smpl_layout_and_mapping_to_lsp14() -> None:
    assert get_layout("smpl") is SMPL24 and SMPL24.num_joints == 24 and SMPL24.names[15] == "head"
    w = mapping_matrix("smpl", "lsp14")
    assert w.shape == (14, 24) and torch.equal(w.sum(1), torch.ones(14))
    for i, name in enumerate(LSP14.names):
        src = "head" if name == "head_top" else name  # SMPL has no head top: its head joint stands in
        assert SMPL24.names[int(w[i].argmax())] == src
    assert list(SMPL24_TO_LSP14) == [8, 5, 2, 1, 4, 7, 21, 19, 17, 16, 18, 20, 12, 15]
    joints = torch.randn(3, 24, 3)
    out, defined, conf = map_joints(joints, "smpl", "lsp14", confidence=torch.rand(3, 24))
    assert defined.all() and torch.equal(out, joints[:, list(SMPL24_TO_LSP14)]) and conf.shape == (3, 14)
    assert torch.equal(mapping_matrix("smpl", "smpl"), torch.eye(24))
    assert all(0 <= i < 24 for bone in SMPL24.sketch_bones for i in bone) and len(SMPL24.sketch_bones) == 23


# --- reading ------------------------------------------------------------------------------------------
def test_gt_joints_in_camera_mm_and_projection(pw3d: tuple[Path, dict]) -> None:
    root, data = pw3d
    scene = read_3dpw(root, "downtown_walk_00", invalid="keep")
    assert (scene.num_frames, scene.height, scene.width, scene.fps) == (T, H, W, 30.0)
    assert scene.name == "3dpw_downtown_walk_00_p0" and scene.metadata["split"] == "test"
    gt = scene.gt
    assert gt.joints_layout == "lsp14" and gt.cameras.model == "pinhole"
    for t in range(T):
        cam = _camera_points(data, 0, t)[list(SMPL24_TO_LSP14)]
        torch.testing.assert_close(gt.joints3d[t].double(), torch.from_numpy(cam), rtol=1e-5, atol=1e-3)
        # a known 3D point projects with K by hand to the stored 2D point
        x, y, z = cam[6]  # right wrist
        u, v = K[0, 0] * x / z + K[0, 2], K[1, 1] * y / z + K[1, 2]
        torch.testing.assert_close(gt.joints2d[t, 6].double(), torch.tensor([u, v]).double(), atol=1e-3, rtol=0)
    assert torch.allclose(gt.cameras.project(gt.joints3d), gt.joints2d)
    assert scene.metadata["campose_valid"] == [True, True, False, True]
    # frames: the JPEGs, in order (constant grey 20, 60, 100, 140)
    assert [round(float(f.float().mean())) for f in scene.frames] == pytest.approx([20, 60, 100, 140], abs=2)


def test_detected_keypoints_are_openpose_mapped_to_coco(pw3d: tuple[Path, dict]) -> None:
    root, data = pw3d
    scene = read_3dpw(root, "downtown_walk_00", invalid="keep")
    rows = data["poses2d"][0]  # (T, 3, 18)
    assert scene.keypoints_layout == "coco17"
    # COCO left_eye (1) is OpenPose leye (15); COCO right_ankle (16) is OpenPose rankle (10)
    torch.testing.assert_close(scene.keypoints2d[:, 1].double(), torch.from_numpy(rows[:, :2, 15]))
    torch.testing.assert_close(scene.keypoints2d[:, 16].double(), torch.from_numpy(rows[:, :2, 10]))
    conf = np.clip(rows[:, 2, list(OPENPOSE18_TO_COCO17)], 0, 1)
    torch.testing.assert_close(scene.keypoints_conf.double(), torch.from_numpy(conf), rtol=0, atol=1e-6)


def test_invalid_campose_frames(pw3d: tuple[Path, dict]) -> None:
    root, _ = pw3d
    dropped = read_3dpw(root, "downtown_walk_00")  # default: drop
    assert dropped.num_frames == 3 and dropped.metadata["frames"] == [0, 1, 3]
    assert [round(float(f.float().mean())) for f in dropped.frames] == pytest.approx([20, 60, 140], abs=2)
    with pytest.raises(DatasetFormatError, match=r"downtown_walk_00.pkl: campose_valid\[0\] is 0 at frames \[2\]"):
        read_3dpw(root, "downtown_walk_00", invalid="error")
    assert read_3dpw(root, "downtown_walk_00", invalid="error", last=1).num_frames == 2
    assert read_3dpw(root, "downtown_walk_00", person=1, invalid="error").num_frames == T


def test_selection_person_split_resize(pw3d: tuple[Path, dict]) -> None:
    root, data = pw3d
    scene = read_3dpw(root, "downtown_walk_00", person=1, split="test", stride=2, max_frames=1, first=1)
    assert scene.metadata["frames"] == [1] and scene.fps == 15.0 and scene.name.endswith("_p1")
    cam = _camera_points(data, 1, 1)[list(SMPL24_TO_LSP14)]
    torch.testing.assert_close(scene.gt.joints3d[0].double(), torch.from_numpy(cam), rtol=1e-5, atol=1e-3)
    native = read_3dpw(root, "downtown_walk_00", invalid="keep")
    small = read_3dpw(root, "downtown_walk_00", invalid="keep", size=(8, 12))
    assert small.frames.shape == (T, 3, 8, 12)
    torch.testing.assert_close(small.gt.joints2d, (native.gt.joints2d + 0.5) * 0.5 - 0.5)
    torch.testing.assert_close(small.keypoints2d, (native.keypoints2d + 0.5) * 0.5 - 0.5)
    torch.testing.assert_close(small.gt.joints3d, native.gt.joints3d)
    smpl = read_3dpw(root, "downtown_walk_00", joints_layout="smpl", last=0)
    assert smpl.gt.joints3d.shape == (1, 24, 3) and smpl.gt.joints_layout == "smpl"
    assert list_3dpw_sequences(root) == ["downtown_walk_00"] and list_3dpw_sequences(root, "train") == []
    back = load_scene(save_scene(scene, root / "saved"))
    assert back.metadata == scene.metadata and torch.equal(back.gt.cameras.params, scene.gt.cameras.params)


def test_missing_things(pw3d: tuple[Path, dict], tmp_path: Path) -> None:
    root, _ = pw3d
    with pytest.raises(FileNotFoundError, match=r"'nowhere' not found.*test/nowhere.pkl"):
        read_3dpw(root, "nowhere")
    with pytest.raises(FileNotFoundError, match=r"train/downtown_walk_00.pkl"):
        read_3dpw(root, "downtown_walk_00", split="train")
    with pytest.raises(ValueError, match=r"person 2 out of range, the sequence has 2 people"):
        read_3dpw(root, "downtown_walk_00", person=2)
    with pytest.raises(ValueError, match="split"):
        read_3dpw(root, "downtown_walk_00", split="val")
    with pytest.raises(FileNotFoundError, match="sequenceFiles"):
        read_3dpw(tmp_path / "sequenceFiles" / "test", "downtown_walk_00")


def test_malformed_pickles_name_the_file(tmp_path: Path) -> None:
    _write_sequence(tmp_path, "bad_keys")
    path = tmp_path / "sequenceFiles" / "test" / "bad_keys.pkl"
    with open(path, "rb") as f:
        data = pickle.load(f, encoding="latin1")
    del data["cam_poses"]
    path.write_bytes(pickle.dumps(data, protocol=2))
    with pytest.raises(DatasetFormatError, match=r"bad_keys.pkl: missing keys \['cam_poses'\]"):
        read_3dpw(tmp_path, "bad_keys")
    _write_sequence(tmp_path, "bad_shape", jointPositions=[np.zeros((T, 71)), np.zeros((T, 72))])
    message = r"bad_shape.pkl: jointPositions\[0\]: expected shape \(4, 72\), got \(4, 71"
    with pytest.raises(DatasetFormatError, match=message):
        read_3dpw(tmp_path, "bad_shape")
    _write_sequence(tmp_path, "garbage")
    (tmp_path / "sequenceFiles" / "test" / "garbage.pkl").write_bytes(b"\x80\x02not a pickle")
    with pytest.raises(DatasetFormatError, match=r"garbage.pkl: unreadable pickle"):
        read_3dpw(tmp_path, "garbage")
    joints = np.zeros((T, 72))
    joints[1, 5] = np.nan
    _write_sequence(tmp_path, "nan_joints", jointPositions=[joints, joints])
    with pytest.raises(DatasetFormatError, match=r"nan_joints.pkl: the data make an invalid scene: GroundTruth.joints"):
        read_3dpw(tmp_path, "nan_joints")


def test_images_inconsistent_with_annotations(pw3d: tuple[Path, dict]) -> None:
    root, _ = pw3d
    images = root / "imageFiles" / "downtown_walk_00"
    (images / "image_00001.jpg").write_bytes(b"not a jpeg")
    with pytest.raises(DatasetFormatError, match=r"image_00001.jpg: unreadable image"):
        read_3dpw(root, "downtown_walk_00")
    (images / "image_00003.jpg").unlink()
    message = r"downtown_walk_00: holds 3 image_\*.jpg files, but .*downtown_walk_00.pkl annotates 4"
    with pytest.raises(DatasetFormatError, match=message):
        read_3dpw(root, "downtown_walk_00")


def test_every_person_of_a_sequence(tmp_path):
    _write_sequence(tmp_path, campose_valid=[np.array([1, 1, 0, 1]), np.array([0, 1, 1, 1])])
    scene = read_3dpw(tmp_path, "downtown_walk_00", person="all")
    assert scene.metadata["frames"] == [1, 3]  # frames valid for every person
    assert scene.num_people == 2 and scene.track_id == 0 and scene.others[0].track_id == 1
    assert [o.track_id for o in scene.gt.others] == [1]
    second = read_3dpw(tmp_path, "downtown_walk_00", person=1, first=1)  # frames 1, 2, 3 of person 1
    rows = [0, 2]  # its frames 1 and 3
    torch.testing.assert_close(scene.gt.others[0].joints3d, second.gt.joints3d[rows])
    torch.testing.assert_close(scene.others[0].keypoints2d, second.keypoints2d[rows])
    assert second.track_id == 1 and scene.name == "3dpw_downtown_walk_00"
    first = read_3dpw(tmp_path, "downtown_walk_00", person=0, invalid="keep")
    torch.testing.assert_close(scene.gt.joints3d, first.gt.joints3d[[1, 3]])
    with pytest.raises(ValueError, match="person: expected a person index or 'all'"):
        read_3dpw(tmp_path, "downtown_walk_00", person="everyone")
