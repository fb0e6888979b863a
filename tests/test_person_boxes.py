"""The person's boxes: in the scene model, pose files and scene folders, and from the YOLOX person
detector through estimate_poses(detector=...)."""

from __future__ import annotations

import importlib.util

import pytest
import torch

import lit_boot
from lit_boot.core import SceneValidationError
from lit_boot.data.readers import PoseEstimates, load_poses, save_poses

BOXES = torch.tensor([[10.0, 20.0, 50.0, 90.0, 0.9], [0.0, 0.0, 0.0, 0.0, 0.0], [12.0, 22.0, 52.0, 92.0, 1.0]])


def _estimates(boxes: torch.Tensor = BOXES, conf: float = 1.0) -> PoseEstimates:
    return PoseEstimates(keypoints2d=torch.full((3, 17, 2), 30.0), keypoints_conf=torch.full((3, 17), conf),
                         person_boxes=boxes, image_size=(100, 200))  # fmt: skip


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_person_boxes_survive_a_pose_file(tmp_path, suffix):
    back = load_poses(save_poses(_estimates(), tmp_path / f"poses{suffix}"))
    assert torch.equal(back.person_boxes, BOXES)


def test_person_boxes_move_with_the_frames_and_reach_the_scene(tmp_path):
    scene = lit_boot.Scene(frames=torch.zeros(3, 3, 50, 100, dtype=torch.uint8))
    applied = _estimates().apply_to(scene)  # 200x100 -> 100x50: half the size
    # pixel centres at integer coordinates: u' = (u + 0.5) / 2 - 0.5
    assert applied.person_boxes[0].tolist() == pytest.approx([4.75, 9.75, 24.75, 44.75, 0.9])
    assert applied.person_boxes[1, 4] == 0
    saved = lit_boot.load_scene(lit_boot.save_scene(applied, tmp_path / "scene"))
    assert torch.equal(saved.person_boxes, applied.person_boxes)
    from lit_boot.dataset.chunks import slice_scene

    assert torch.equal(slice_scene(applied, 1, 3).person_boxes, applied.person_boxes[1:3])


def test_bad_person_boxes_are_named():
    frames = torch.zeros(3, 3, 50, 100, dtype=torch.uint8)
    with pytest.raises(SceneValidationError, match=r"Scene.person_boxes: expected shape \(3, 5\)"):
        lit_boot.Scene(frames=frames, person_boxes=torch.zeros(3, 4))
    with pytest.raises(SceneValidationError, match="person_boxes: expected scores"):
        lit_boot.Scene(frames=frames, person_boxes=BOXES * torch.tensor([1, 1, 1, 1, 2.0]))
    flipped = BOXES.clone()
    flipped[0, 2] = 0.0  # x1 < x0 where a person is found
    with pytest.raises(SceneValidationError, match="x0 <= x1"):
        lit_boot.Scene(frames=frames, person_boxes=flipped)


def test_a_person_box_is_somebody_even_where_no_keypoint_was_found():
    frames = torch.zeros(3, 3, 100, 200, dtype=torch.uint8)
    nobody = _estimates(conf=0.0)
    with_boxes = nobody.apply_to(lit_boot.Scene(frames=frames))
    with_boxes.require_pose("2d")  # the zoom stage can still refine the flow where the person is
    without = lit_boot.Scene(frames=frames, keypoints2d=nobody.keypoints2d, keypoints_conf=nobody.keypoints_conf)
    with pytest.raises(ValueError, match="no person in any frame"):
        without.require_pose("2d")


@pytest.mark.shared
@pytest.mark.skipif(importlib.util.find_spec("mediapipe") is None, reason='needs the mediapipe extra: pip install -e ".[mediapipe]"')
def test_the_detector_finds_the_person_mediapipe_misses(shared):
    """bandage_1: a close-up MediaPipe finds nobody in (SOURCES.md); the detector boxes the girl."""
    from lit_boot.data.readers import read_sintel
    from lit_boot.estimate import estimate_poses, summary_line

    scene = read_sintel(shared / "data/sintel_samples", "bandage_1", first=34, last=35)
    est = estimate_poses(scene, detector=shared / "checkpoints/yolox_nano.onnx")
    assert not est.found().any()
    boxes = est.person_boxes
    assert boxes.shape == (2, 5) and (boxes[:, 4] == 1).all()
    # she fills the right half of the frame (x about 400-990 of 1024, the whole height)
    assert (boxes[:, 0] > 300).all() and (boxes[:, 2] > 900).all() and (boxes[:, 3] - boxes[:, 1] > 350).all()
    assert est.metadata["detector_found"] == 2 and "the person detector's box in 2" in summary_line(est)


@pytest.mark.shared
@pytest.mark.skipif(importlib.util.find_spec("mediapipe") is None, reason='needs the mediapipe extra: pip install -e ".[mediapipe]"')
def test_import_video_with_the_detector_stores_the_boxes(shared, tmp_path, capsys):
    from lit_boot.cli import main

    frames = shared / "data/videos/football_720p_10f"
    out = tmp_path / "scene"
    code = main(["import", "video", str(frames), "--max_frames", "2", "--resize", "240", "--estimate", "true",
                 "--detector", str(shared / "checkpoints/yolox_nano.onnx"), "--out", str(out)])  # fmt: skip
    assert code == 0
    scene = lit_boot.load_scene(out)
    assert scene.person_boxes is not None and scene.person_boxes.shape == (2, 5) and (scene.person_boxes[:, 4] > 0).all()
    assert main(["import", "video", str(frames), "--detector", "yolox_nano", "--out", str(tmp_path / "x")]) == 2
    assert "--detector: needs --estimate true" in capsys.readouterr().err
