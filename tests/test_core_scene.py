"""Scene / GroundTruth validation (lit_boot.core.scene): every bad field names itself."""

from __future__ import annotations

import re

import pytest
import torch

from lit_boot.core.cameras import Cameras
from lit_boot.core.scene import GroundTruth, Scene, SceneValidationError

T, H, W = 4, 12, 16


def gt_fields(**overrides) -> dict:
    fields = dict(
        flow=torch.zeros(T - 1, 2, H, W),
        flow_valid=torch.ones(T - 1, H, W, dtype=torch.bool),
        flow_occluded=torch.zeros(T - 1, H, W, dtype=torch.bool),
        joints3d=torch.zeros(T, 14, 3),
        joints2d=torch.zeros(T, 14, 2),
        joints_layout="lsp14",
        cameras=Cameras("pinhole", torch.ones(T, 7)),
        person_mask=torch.zeros(T, H, W, dtype=torch.bool),
        keypoints2d=torch.zeros(T, 17, 2),
    )
    fields.update(overrides)
    return fields


def scene_fields(gt_kw: dict | None = None, **overrides) -> dict:
    fields = dict(
        frames=torch.zeros(T, 3, H, W, dtype=torch.uint8),
        fps=25.0,
        name="unit",
        joints3d=torch.zeros(T, 14, 3),
        joints3d_layout="lsp14",
        cameras=Cameras("weak_perspective", torch.ones(T, 3), torch.ones(T, 3)),
        keypoints2d=torch.zeros(T, 17, 2),
        keypoints_conf=torch.full((T, 17), 0.5),
        keypoints_layout="coco17",
        gt=GroundTruth(**gt_fields(**(gt_kw or {}))),
    )
    fields.update(overrides)
    return fields


def nan_at(shape, dtype=torch.float32, value=float("nan")) -> torch.Tensor:
    x = torch.zeros(shape, dtype=dtype)
    x.view(-1)[-1] = value
    return x


def as_regex(field: str) -> str:
    """Escape a field name, keeping ``.*`` as a wildcard."""
    return ".*".join(re.escape(part) for part in field.split(".*"))


def test_valid_scene_constructs():
    scene = Scene(**scene_fields())
    assert (scene.num_frames, scene.height, scene.width) == (T, H, W)
    scene.validate()  # idempotent


def test_minimal_scene_and_other_valid_layouts():
    Scene(frames=torch.zeros(1, 3, 2, 2, dtype=torch.uint8))
    Scene(
        **scene_fields(
            joints3d=torch.zeros(T, 17, 3, dtype=torch.float64),
            joints3d_layout="h36m17",
            keypoints2d=torch.zeros(T, 33, 2),
            keypoints_conf=torch.zeros(T, 33),
            keypoints_layout="mediapipe33",
            gt=GroundTruth(**gt_fields(keypoints2d=torch.zeros(T, 33, 2), joints3d=None, joints2d=None)),
        )
    )
    Scene(**scene_fields(gt=None, keypoints_conf=torch.ones(T, 17)))  # bounds 0 and 1 are allowed
    Scene(**scene_fields(gt=None, keypoints_conf=torch.zeros(T, 17)))


def test_scene_validation_error_is_value_error():
    assert issubclass(SceneValidationError, ValueError)


BAD_SCENE = {
    # wrong shapes
    "frames 3D": (dict(frames=torch.zeros(T, H, W, dtype=torch.uint8)), "Scene.frames:"),
    "frames 1 channel": (dict(frames=torch.zeros(T, 1, H, W, dtype=torch.uint8)), "Scene.frames:"),
    "frames T=0": (dict(frames=torch.zeros(0, 3, H, W, dtype=torch.uint8), joints3d=None, cameras=None,
                        keypoints2d=None, keypoints_conf=None, gt=None), "Scene.frames:"),  # fmt: skip
    "joints3d 17 joints for lsp14": (dict(joints3d=torch.zeros(T, 17, 3)), "Scene.joints3d:"),
    "joints3d 2D": (dict(joints3d=torch.zeros(T, 14, 2)), "Scene.joints3d:"),
    "keypoints2d 14 for coco17": (dict(keypoints2d=torch.zeros(T, 14, 2)), "Scene.keypoints2d:"),
    "keypoints_conf extra dim": (dict(keypoints_conf=torch.zeros(T, 17, 1)), "Scene.keypoints_conf:"),
    # wrong dtypes
    "float frames": (dict(frames=torch.zeros(T, 3, H, W)), "Scene.frames:"),
    "int joints3d": (dict(joints3d=torch.zeros(T, 14, 3, dtype=torch.int64)), "Scene.joints3d:"),
    "bool keypoints_conf": (dict(keypoints_conf=torch.ones(T, 17, dtype=torch.bool)), "Scene.keypoints_conf:"),
    "int camera params": (dict(cameras=Cameras("pinhole", torch.ones(T, 7, dtype=torch.int64))), "Scene.cameras.params:"),
    "numpy joints3d": (dict(joints3d=torch.zeros(T, 14, 3).numpy()), "Scene.joints3d:"),
    # NaN / inf
    "NaN joints3d": (dict(joints3d=nan_at((T, 14, 3))), "Scene.joints3d:"),
    "inf keypoints2d": (dict(keypoints2d=nan_at((T, 17, 2), value=float("inf"))), "Scene.keypoints2d:"),
    "NaN keypoints_conf": (dict(keypoints_conf=nan_at((T, 17))), "Scene.keypoints_conf:"),
    "NaN camera params": (dict(cameras=Cameras("pinhole", nan_at((T, 7)))), "Scene.cameras.params:"),
    "NaN camera crops": (dict(cameras=Cameras("weak_perspective", torch.ones(T, 3), nan_at((T, 3)))),
                         "Scene.cameras.crops:"),  # fmt: skip
    # mismatched T
    "joints3d T+1": (dict(joints3d=torch.zeros(T + 1, 14, 3)), "Scene.joints3d:"),
    "keypoints2d T-1": (dict(keypoints2d=torch.zeros(T - 1, 17, 2)), "Scene.keypoints2d:"),
    "keypoints_conf T+1": (dict(keypoints_conf=torch.zeros(T + 1, 17)), "Scene.keypoints_conf:"),
    "cameras T+1": (dict(cameras=Cameras("weak_perspective", torch.ones(T + 1, 3), torch.ones(T + 1, 3))),
                    "Scene.cameras.params:"),  # fmt: skip
    # keypoints without confidences (and vice versa)
    "keypoints without conf": (dict(keypoints_conf=None), "Scene.keypoints_conf"),
    "conf without keypoints": (dict(keypoints2d=None), "Scene.keypoints2d"),
    # confidences outside [0, 1]
    "conf > 1": (dict(keypoints_conf=torch.full((T, 17), 1.01)), "Scene.keypoints_conf:"),
    "conf < 0": (dict(keypoints_conf=nan_at((T, 17), value=-0.1)), "Scene.keypoints_conf:"),
    # unknown layouts
    "joints3d layout": (dict(joints3d_layout="smpl24"), "Scene.joints3d_layout:.*smpl24"),
    "keypoints layout": (dict(keypoints_layout="openpose25"), "Scene.keypoints_layout:.*openpose25"),
    # other fields
    "fps 0": (dict(fps=0), "Scene.fps:"),
    "fps string": (dict(fps="30"), "Scene.fps:"),
    "cameras not Cameras": (dict(cameras=torch.ones(T, 3)), "Scene.cameras:"),
    "gt not GroundTruth": (dict(gt={"flow": None}), "Scene.gt:"),
}


@pytest.mark.parametrize("overrides,field", BAD_SCENE.values(), ids=BAD_SCENE.keys())
def test_bad_scene_field_names_it(overrides, field):
    with pytest.raises(SceneValidationError, match=as_regex(field)):
        Scene(**scene_fields(**overrides))


BAD_GT = {
    "flow T pairs": (dict(flow=torch.zeros(T, 2, H, W)), "GroundTruth.flow:"),
    "flow channels last": (dict(flow=torch.zeros(T - 1, H, W, 2)), "GroundTruth.flow:"),
    "flow wrong H": (dict(flow=torch.zeros(T - 1, 2, H + 1, W)), "GroundTruth.flow:"),
    "flow NaN": (dict(flow=nan_at((T - 1, 2, H, W))), "GroundTruth.flow:"),
    "flow int": (dict(flow=torch.zeros(T - 1, 2, H, W, dtype=torch.int32)), "GroundTruth.flow:"),
    "flow_valid T pairs": (dict(flow_valid=torch.ones(T, H, W, dtype=torch.bool)), "GroundTruth.flow_valid:"),
    "flow_valid uint8": (dict(flow_valid=torch.ones(T - 1, H, W, dtype=torch.uint8)), "GroundTruth.flow_valid:"),
    "flow_occluded float": (dict(flow_occluded=torch.zeros(T - 1, H, W)), "GroundTruth.flow_occluded:"),
    "joints3d T+1": (dict(joints3d=torch.zeros(T + 1, 14, 3)), "GroundTruth.joints3d:"),
    "joints3d NaN": (dict(joints3d=nan_at((T, 14, 3))), "GroundTruth.joints3d:"),
    "joints2d 17 for lsp14": (dict(joints2d=torch.zeros(T, 17, 2)), "GroundTruth.joints2d:"),
    "person_mask float": (dict(person_mask=torch.zeros(T, H, W)), "GroundTruth.person_mask:"),
    "person_mask wrong W": (dict(person_mask=torch.zeros(T, H, W + 1, dtype=torch.bool)), "GroundTruth.person_mask:"),
    "keypoints2d 14 for coco17": (dict(keypoints2d=torch.zeros(T, 14, 2)), "GroundTruth.keypoints2d:"),
    "keypoints2d inf": (dict(keypoints2d=nan_at((T, 17, 2), value=float("-inf"))), "GroundTruth.keypoints2d:"),
    "cameras T-1": (dict(cameras=Cameras("pinhole", torch.ones(T - 1, 7))), "GroundTruth.cameras.params:"),
    "cameras not Cameras": (dict(cameras="pinhole"), "GroundTruth.cameras:"),
}


@pytest.mark.parametrize("overrides,field", BAD_GT.values(), ids=BAD_GT.keys())
def test_bad_ground_truth_field_names_it(overrides, field):
    with pytest.raises(SceneValidationError, match=as_regex(field)):
        Scene(**scene_fields(gt_kw=overrides))


def test_gt_flow_error_gives_expected_shape():
    with pytest.raises(SceneValidationError, match=re.escape(f"GroundTruth.flow: expected shape ({T - 1}, 2, {H}, {W})")):
        Scene(**scene_fields(gt_kw=dict(flow=torch.zeros(T, 2, H, W))))


def test_gt_unknown_joints_layout_names_field():
    with pytest.raises(SceneValidationError, match=r"GroundTruth\.joints_layout.*smpl24"):
        Scene(**scene_fields(gt_kw=dict(joints_layout="smpl24")))


def test_gt_joints_follow_gt_joints_layout():
    gt = dict(joints_layout="h36m17", joints3d=torch.zeros(T, 17, 3), joints2d=torch.zeros(T, 17, 2))
    Scene(**scene_fields(gt_kw=gt))  # the scene's own joints3d stay lsp14
    with pytest.raises(SceneValidationError, match=r"GroundTruth\.joints3d:"):
        Scene(**scene_fields(gt_kw=dict(joints_layout="h36m17", joints2d=torch.zeros(T, 17, 2))))


def test_gt_keypoints_use_scene_keypoints_layout():
    # coco17 (the default): 17 keypoints pass, 14 fail
    Scene(**scene_fields(gt_kw=dict(keypoints2d=torch.zeros(T, 17, 2))))
    # lsp14 keypoints: now 14 pass and 17 fail
    lsp = dict(keypoints2d=torch.zeros(T, 14, 2), keypoints_conf=torch.ones(T, 14), keypoints_layout="lsp14")
    Scene(**scene_fields(gt_kw=dict(keypoints2d=torch.zeros(T, 14, 2)), **lsp))
    with pytest.raises(SceneValidationError, match=re.escape(f"GroundTruth.keypoints2d: expected shape ({T}, 14, 2)")):
        Scene(**scene_fields(gt_kw=dict(keypoints2d=torch.zeros(T, 17, 2)), **lsp))


def test_validate_catches_mutation_after_construction():
    scene = Scene(**scene_fields())
    scene.joints3d = nan_at((T, 14, 3))
    with pytest.raises(SceneValidationError, match=r"Scene\.joints3d:"):
        scene.validate()


def test_summary_mentions_frames_size_and_flow():
    flow = torch.zeros(T - 1, 2, H, W)
    flow[:, 0], flow[:, 1] = 3.0, 4.0  # |flow| = 5 everywhere
    flow[0, :, 0, 0] = torch.tensor([6.0, 8.0])  # one pixel at 10
    scene = Scene(**scene_fields(gt_kw=dict(flow=flow), name="walk", fps=12.5))
    text = scene.summary()
    assert "'walk'" in text
    assert f"{T} frames" in text
    assert f"{W}x{H} px" in text
    assert "12.5 fps" in text
    assert "lsp14 (14 joints), cameras: weak_perspective" in text
    assert f"coco17, mean confidence 0.50 (a person in {T} of {T} frames)" in text
    mean = (5.0 * (flow[0, 0].numel() * (T - 1) - 1) + 10.0) / (flow[0, 0].numel() * (T - 1))
    assert f"GT flow magnitude: mean {mean:.2f} px, max 10.00 px" in text


def test_summary_counts_the_frames_with_a_pose_and_with_a_person_box():
    conf, boxes = torch.zeros(T, 17), torch.zeros(T, 5)
    conf[1, 3], boxes[1:, :] = 0.7, torch.tensor([1.0, 1.0, 5.0, 4.0, 0.9])
    text = Scene(**scene_fields(keypoints_conf=conf, person_boxes=boxes)).summary()
    assert f"(a person in 1 of {T} frames)" in text and f"person boxes: in {T - 1} of {T} frames" in text


def test_summary_of_bare_scene():
    text = Scene(frames=torch.zeros(2, 3, 5, 7, dtype=torch.uint8), fps=30).summary()
    assert text == "scene 'scene': 2 frames, 7x5 px, 30 fps"


def test_a_pose_estimator_that_found_nobody_is_named_as_such():
    nobody = dict(keypoints_conf=torch.zeros(T, 17))
    with pytest.raises(ValueError, match="'unit': no person in any frame .*found nobody"):
        Scene(**scene_fields(**nobody)).require_pose("2d")
    with pytest.raises(ValueError, match="no person in any frame"):  # 3D: no joints because nobody was found
        Scene(**scene_fields(joints3d=None, cameras=None, **nobody)).require_pose("3d")
    Scene(**scene_fields(**nobody)).require_pose("3d")  # 3D joints given: they are the pose
    with pytest.raises(ValueError, match="3D mode needs 3D joints"):  # keypoints found, no 3D: as before
        Scene(**scene_fields(joints3d=None, cameras=None)).require_pose("3d")
    boxes = torch.tensor([[1.0, 1.0, 5.0, 4.0, 0.9]]).repeat(T, 1)  # the detector found the person, no pose
    with pytest.raises(ValueError, match="no pose in any frame .*detector's boxes; in mode '2d' the zoom"):
        Scene(**scene_fields(joints3d=None, cameras=None, person_boxes=boxes, **nobody)).require_pose("3d")
    Scene(**scene_fields(joints3d=None, cameras=None, person_boxes=boxes, **nobody)).require_pose("2d")
    Scene(**scene_fields()).require_pose("2d")
