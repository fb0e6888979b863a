"""Pose estimates: lit-boot pose files, METRO, DCPose, COCO keypoint JSON and the dispatcher."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest
import torch

from lit_boot.core import Cameras, Scene, SceneValidationError
from lit_boot.core.cameras import project_weak_perspective
from lit_boot.core.joints import H36M_J17_TO_J14
from lit_boot.data.readers import DatasetFormatError, PoseEstimates, load_poses, read_estimates, save_poses
from lit_boot.data.readers.estimates import read_coco_keypoints, read_dcpose, read_metro


def _estimates(T: int = 3, **kw) -> PoseEstimates:
    g = torch.Generator().manual_seed(0)
    cams = Cameras("weak_perspective", torch.tensor([[0.9, 0.01, 0.2]] * T), torch.tensor([[0.5, 300.0, 200.0]] * T))
    fields = dict(keypoints2d=torch.rand(T, 17, 2, generator=g) * 100, keypoints_conf=torch.rand(T, 17, generator=g),
                  joints3d=torch.randn(T, 14, 3, generator=g) * 300, cameras=cams, image_size=(480, 640),
                  source="test", metadata={"note": [1, 2]})  # fmt: skip
    return PoseEstimates(**(fields | kw))


def _scene(T: int, H: int = 240, W: int = 320, **metadata) -> Scene:
    return Scene(frames=torch.zeros(T, 3, H, W, dtype=torch.uint8), metadata=metadata)


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_pose_file_round_trip(tmp_path, suffix):
    est = _estimates(frame_indices=torch.tensor([2, 5, 9]))
    back = load_poses(save_poses(est, tmp_path / f"p{suffix}"))
    for key in ("keypoints2d", "keypoints_conf", "joints3d", "frame_indices"):
        assert torch.equal(getattr(back, key), getattr(est, key)), key
    assert torch.equal(back.cameras.crops, est.cameras.crops) and back.cameras.model == "weak_perspective"
    assert (back.image_size, back.source, back.metadata) == ((480, 640), "test", {"note": [1, 2]})
    only2d = PoseEstimates(keypoints2d=torch.zeros(2, 17, 2), keypoints_conf=torch.ones(2, 17))
    assert load_poses(save_poses(only2d, tmp_path / f"q{suffix}")).joints3d is None


def test_pose_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.npz"):
        load_poses(tmp_path / "nope.npz")
    header = {"format": "lit-boot-pose-estimates", "version": 1}
    cases = {
        "other.json": ({"format": "something"}, "not a 'lit-boot-pose-estimates'"),
        "future.json": (header | {"version": 3, "frame_indices": [0]}, "unsupported version 3"),
        "noids.json": (header | {"version": 2, "frame_indices": [0]}, "missing key 'track_ids'"),
        "axis.json": (header | {"version": 2, "frame_indices": [0], "track_ids": [0, 1],
                                "keypoints2d": [[[[0, 0]] * 17]], "keypoints_conf": [[[1] * 17]]},
                      "keypoints2d: expected 2 people"),  # fmt: skip
        "noidx.json": (header | {"joints3d": [[[0, 0, 0]] * 14]}, "missing key 'frame_indices'"),
        "shape.json": (header | {"frame_indices": [0], "keypoints2d": [[[0, 0]] * 5], "keypoints_conf": [[1] * 5]},
                       "keypoints2d: expected shape"),  # fmt: skip
    }
    for name, (content, message) in cases.items():
        (tmp_path / name).write_text(json.dumps(content))
        with pytest.raises(DatasetFormatError, match=f"{name}.*{message}"):
            load_poses(tmp_path / name)
    (tmp_path / "broken.npz").write_bytes(b"not a zip")
    with pytest.raises(DatasetFormatError, match="broken.npz"):
        load_poses(tmp_path / "broken.npz")


def test_validate_names_the_field():
    with pytest.raises(SceneValidationError, match="keypoints_conf: expected values in"):
        _estimates(keypoints_conf=torch.full((3, 17), 1.5))
    with pytest.raises(SceneValidationError, match="frame_indices: expected non-negative, strictly increasing"):
        _estimates(frame_indices=torch.tensor([0, 0, 1]))
    with pytest.raises(SceneValidationError, match="give keypoints2d"):
        PoseEstimates()


def test_apply_to_selects_and_rescales():
    est = _estimates(T=6)  # 640x480, frames 0..5
    scene = est.apply_to(_scene(3, 240, 320, frame_indices=[1, 3, 5]))
    assert torch.allclose(scene.keypoints2d, (est.keypoints2d[[1, 3, 5]] + 0.5) * 0.5 - 0.5)
    # the rescaled cameras project to the rescaled pixels of the original cameras
    want = (est.cameras.project(est.joints3d)[[1, 3, 5]] + 0.5) * 0.5 - 0.5
    assert torch.allclose(scene.cameras.project(scene.joints3d), want, atol=1e-3)
    assert scene.metadata["pose_estimates"][-1]["frame_indices"] == [1, 3, 5]
    pinhole = Cameras("pinhole", torch.tensor([[500.0, 500.0, 319.5, 239.5, 0.0, 0.0, 4000.0]] * 6))
    half = _estimates(T=6, cameras=pinhole).rescaled((240, 320))
    assert torch.allclose(half.cameras.project(est.joints3d), (pinhole.project(est.joints3d) + 0.5) * 0.5 - 0.5)
    with pytest.raises(SceneValidationError, match="do not cover the scene"):
        est.apply_to(_scene(4, frame_indices=[0, 2, 4, 6]))
    with pytest.raises(SceneValidationError, match="aspect ratio"):
        est.apply_to(_scene(6, 240, 640))


def _metro_truth(T: int):
    """Known METRO joints (m), cameras, proc_params and their pixels, computed here independently."""
    rng = np.random.default_rng(1)
    joints = rng.normal(0, 0.3, (T, 17, 3))
    cam = np.column_stack([rng.uniform(0.8, 1.0, T), rng.normal(0, 0.05, (T, 2))])
    scale, start = rng.uniform(0.3, 0.6, T), rng.uniform(150, 400, (T, 2))
    crop_xy = (cam[:, None, :1] * (joints[..., :2] + cam[:, None, 1:]) + 1.0) * 0.5 * 224  # HMR get_original
    pixels = (crop_xy + start[:, None] - 112) / scale[:, None, None]
    return joints, cam, scale, start, pixels


def test_metro_per_frame_folder_and_stacked_file(tmp_path):
    joints, cam, scale, start, pixels = _metro_truth(3)
    folder = tmp_path / "metro"
    folder.mkdir()
    for t in range(3):  # frame_10 after frame_9: natural order; a batch dim of 1 as METRO writes
        out = {"pred_3d_joints_from_smpl": joints[t, list(H36M_J17_TO_J14)][None], "pred_camera": cam[t][None],
               "proc_param": {"scale": scale[t], "start_pt": start[t], "img_size": 224}}  # fmt: skip
        name = folder / f"frame_{8 + t}"
        if t == 1:
            pickle.dump(out, open(name.with_suffix(".pkl"), "wb"))
        else:
            np.savez(name.with_suffix(".npz"), **out)
    est = read_metro(folder, image_size=(720, 1280))
    assert est.metadata["files"] == ["frame_8.npz", "frame_9.pkl", "frame_10.npz"]
    stacked = tmp_path / "metro.npz"
    np.savez(stacked, pred_3d_joints_from_smpl=joints, pred_camera=cam,
             proc_param=np.array([{"scale": s, "start_pt": p} for s, p in zip(scale, start)]))  # fmt: skip
    est17 = read_estimates(stacked)  # 17 H36M joints -> LSP-14
    for e in (est, est17):
        assert e.source == "metro" and e.joints3d.shape == (3, 14, 3) and e.cameras.crop_size == 224
        assert np.allclose(e.joints3d.numpy(), joints[:, list(H36M_J17_TO_J14)] * 1000, atol=1e-2)
        uv = project_weak_perspective(e.joints3d, e.cameras.params, e.cameras.crops)
        assert np.allclose(uv.numpy(), pixels[:, list(H36M_J17_TO_J14)], atol=1e-2)
    np.savez(tmp_path / "bad_metro.npz", pred_3d_joints_from_smpl=joints)
    with pytest.raises(DatasetFormatError, match="bad_metro.npz.*pred_camera"):
        read_metro(tmp_path / "bad_metro.npz")


def _kp(x: float, y: float, score: float = 0.9, spread: float = 10.0) -> list[list[float]]:
    return [[x + spread * (k % 4), y + spread * (k // 4), score] for k in range(17)]


def test_dcpose_single_file_and_folder(tmp_path):
    info = [{"image_path": "f10.jpg", "keypoints": _kp(100, 100)},
            {"image_path": "f2.jpg", "keypoints": _kp(20, 20, spread=2)},  # small
            {"image_path": "f2.jpg", "keypoints": _kp(95, 95)},  # large: picked first
            {"image_path": "f10.jpg", "keypoints": _kp(400, 400, spread=20)}]  # fmt: skip
    (tmp_path / "dc.json").write_text(json.dumps({"Info": info}))
    est = read_estimates(tmp_path / "dc.json")
    assert est.source == "dcpose" and est.metadata["frames"] == ["f2.jpg", "f10.jpg"]
    assert est.metadata["chosen_person"] == [1, 0]  # tracked: nearest to the frame before
    assert torch.allclose(est.keypoints2d[1, 0], torch.tensor([100.0, 100.0]))
    assert read_dcpose(tmp_path / "dc.json", person="largest").metadata["chosen_person"] == [1, 1]
    folder = tmp_path / "dcpose"
    folder.mkdir()
    for t, people in enumerate([[_kp(10, 10, 1.3)], []]):
        (folder / f"{t}.json").write_text(json.dumps({"Info": [{"keypoints": p} for p in people]}))
    est = read_estimates(folder)
    assert est.keypoints_conf[0].eq(1.0).all() and est.keypoints_conf[1].eq(0).all()  # clipped; nobody: zeros
    (tmp_path / "bad_dc.json").write_text(json.dumps({"Info": [{"image_path": "a.jpg"}]}))
    with pytest.raises(DatasetFormatError, match="bad_dc.json.*lacks 'keypoints'"):
        read_estimates(tmp_path / "bad_dc.json")


def test_coco_results_and_annotations(tmp_path):
    flat = lambda kp: [v for p in kp for v in p]  # noqa: E731
    results = [{"image_id": 7, "category_id": 1, "keypoints": flat(_kp(50, 50, 0.5)), "score": 0.2},
               {"image_id": 7, "category_id": 1, "keypoints": flat(_kp(5, 5, 0.7, 1)), "score": 0.9},
               {"image_id": 3, "category_id": 2, "keypoints": flat(_kp(0, 0)), "score": 1.0}]  # fmt: skip
    (tmp_path / "res.json").write_text(json.dumps(results))
    est = read_estimates(tmp_path / "res.json", image_ids=[3, 7, 9], person="score")
    assert est.source == "coco" and est.num_frames == 3
    assert est.keypoints_conf[0].eq(0).all() and est.keypoints_conf[2].eq(0).all()  # category 2 / no detection
    assert torch.allclose(est.keypoints_conf[1], torch.full((17,), 0.7))  # the higher score wins
    kp = _kp(30, 40, 2)
    kp[0][2], kp[1][2] = 0, 1
    annotations = {"images": [{"id": 11, "file_name": "b_10.jpg", "height": 48, "width": 64},
                              {"id": 12, "file_name": "b_9.jpg", "height": 48, "width": 64}],
                   "annotations": [{"image_id": 11, "category_id": 1, "keypoints": flat(kp)},
                                   {"image_id": 12, "iscrowd": 1, "keypoints": flat(kp)}]}  # fmt: skip
    (tmp_path / "ann.json").write_text(json.dumps(annotations))
    est = read_coco_keypoints(tmp_path / "ann.json")
    assert est.metadata["image_ids"] == [12, 11] and est.image_size == (48, 64)
    assert est.keypoints_conf[0].eq(0).all() and est.keypoints_conf[1].tolist() == [0.0] + [1.0] * 16
    (tmp_path / "bad_coco.json").write_text(json.dumps([{"image_id": 1, "keypoints": [1, 2, 3]}]))
    with pytest.raises(DatasetFormatError, match=r"bad_coco.json.*expected shape \(17, 3\)"):
        read_estimates(tmp_path / "bad_coco.json")


def test_dispatcher(tmp_path):
    save_poses(_estimates(), tmp_path / "ours.npz")
    assert read_estimates(tmp_path / "ours.npz").source == "test"
    (tmp_path / "what.json").write_text(json.dumps({"hello": 1}))
    with pytest.raises(DatasetFormatError, match="what.json.*accepted: lit-boot pose file.*METRO.*DCPose.*COCO"):
        read_estimates(tmp_path / "what.json")
    with pytest.raises(ValueError, match="kind: expected one of"):
        read_estimates(tmp_path / "ours.npz", kind="openpose")
    with pytest.raises(TypeError, match="kind 'poses' does not take"):
        read_estimates(tmp_path / "ours.npz", person="largest")
    with pytest.raises(FileNotFoundError, match="gone.json"):
        read_estimates(tmp_path / "gone.json")
