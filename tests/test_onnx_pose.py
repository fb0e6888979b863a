"""A top-down SimCC pose model through onnxruntime (lit_boot.estimate.onnx_pose), on tiny ONNX models
built here: the crop's geometry and SimCC's decoding on known numbers, and a model that puts each
keypoint on the brightest column and row of its crop, so a bright dot's place in the frame is the
known answer. Needs onnxruntime and onnx (the mediapipe and dev extras); skips without them."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from lit_boot.estimate import estimate_poses
from lit_boot.estimate import mediapipe_pose
from lit_boot.estimate.onnx_pose import OnnxPoseCrops, SimccPoseModel, crop_transform, decode_simcc

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("onnxruntime") is None or importlib.util.find_spec("onnx") is None,
    reason='needs the mediapipe extra (onnxruntime) and onnx: pip install -e ".[dev,mediapipe]"',
)
K = 17


def _save(path: Path, nodes, inputs, outputs, initializers) -> Path:
    import onnx
    from onnx import helper

    graph = helper.make_graph(nodes, "tiny_simcc", inputs, outputs, initializer=initializers)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)], ir_version=8)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def brightest_model(path: Path, h: int = 32, w: int = 24, keypoints: int = K, y_first: bool = False,
                    input_shape: list | None = None) -> Path:  # fmt: skip
    """Input 'input' (1, 3, h, w); simcc_x (1, keypoints, w) = the softmax of each column's sum,
    simcc_y (1, keypoints, h) of each row's, one bin per px: every keypoint at the crop's brightest
    column and row, confident where one stands out; ``y_first``: simcc_y is the first output;
    ``input_shape``: the input's declared shape instead of (1, 3, h, w)."""
    from onnx import TensorProto, helper, numpy_helper

    nodes = [
        helper.make_node("ReduceSum", ["input", "axes_x"], ["cols"], keepdims=0),  # (1, w)
        helper.make_node("ReduceSum", ["input", "axes_y"], ["rows"], keepdims=0),  # (1, h)
        helper.make_node("Unsqueeze", ["cols", "axis1"], ["cols3"]),
        helper.make_node("Unsqueeze", ["rows", "axis1"], ["rows3"]),
        helper.make_node("Expand", ["cols3", "shape_x"], ["sum_x"]),
        helper.make_node("Expand", ["rows3", "shape_y"], ["sum_y"]),
        helper.make_node("Softmax", ["sum_x"], ["simcc_x"], axis=-1),
        helper.make_node("Softmax", ["sum_y"], ["simcc_y"], axis=-1),
    ]
    consts = {"axes_x": np.array([1, 2]), "axes_y": np.array([1, 3]), "axis1": np.array([1]),
              "shape_x": np.array([1, keypoints, w]), "shape_y": np.array([1, keypoints, h])}  # fmt: skip
    outputs = [helper.make_tensor_value_info("simcc_x", TensorProto.FLOAT, [1, keypoints, w]),
               helper.make_tensor_value_info("simcc_y", TensorProto.FLOAT, [1, keypoints, h])]
    declared = input_shape or [1, 3, h, w]
    return _save(path, nodes, [helper.make_tensor_value_info("input", TensorProto.FLOAT, declared)],
                 outputs[::-1] if y_first else outputs,
                 [numpy_helper.from_array(v.astype(np.int64), k) for k, v in consts.items()])  # fmt: skip


def dots(T: int, H: int, W: int, places: list[tuple[int, int]]) -> torch.Tensor:
    """Frames (T, 3, H, W) uint8, black but for a white 5 x 5 px dot centred at each (x, y) of
    ``places`` (large enough to outlast a crop's downsampling)."""
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    for x, y in places:
        frames[:, :, y - 2 : y + 3, x - 2 : x + 3] = 255
    return frames


def test_the_crop_is_centred_on_the_box_padded_and_of_the_inputs_aspect():
    A = crop_transform((10, 20, 40, 80), (256, 192), 1.25)  # a 30 x 60 box; the input 3:4
    centre = A @ np.array([25.0, 50.0, 1.0])
    assert centre == pytest.approx([95.5, 127.5])  # the input's centre, pixel centres at integers
    assert A[0, 0] == pytest.approx(A[1, 1])  # one scale: no stretch
    # 60 px x 1.25 = 75 px tall onto 256 rows; the width follows the aspect: 56.25 px onto 192
    assert A[1, 1] == pytest.approx(256 / 75)
    top = A @ np.array([25.0, 50 - 37.5, 1.0])
    assert top[1] == pytest.approx(-0.5)  # the crop's top edge is the input's


def test_decode_simcc_takes_each_axis_best_bin_and_the_lower_score():
    sx, sy = np.zeros((2, 20), np.float32), np.zeros((2, 30), np.float32)
    sx[0, 10], sy[0, 7], sx[1, 3], sy[1, 29] = 0.9, 0.6, 1.7, 1.2
    points, conf = decode_simcc(sx, sy, 2.0)
    assert points.tolist() == [[5.0, 3.5], [1.5, 14.5]]
    assert conf.tolist() == pytest.approx([0.6, 1.0])  # the lower of the two; clamped to 1


@pytest.mark.parametrize("y_first", [False, True])
def test_a_dot_is_found_where_it_is_in_the_frame(tmp_path, y_first):
    model = SimccPoseModel(brightest_model(tmp_path / "m.onnx", y_first=y_first))  # outputs found by name
    assert model.input_size == (32, 24) and model.ratio == 1.0
    frames = dots(1, 90, 120, [(70, 40)])
    for box in ([50, 10, 90, 80], [60, 30, 75, 60], [40, 0, 110, 89]):  # the dot off-centre in each
        kp = model.keypoints(frames[0], torch.tensor(box, dtype=torch.float32))
        assert kp.shape == (K, 3)
        # one input px covers (box side x 1.25) / input side frame px; the dot's brightest column
        # and row may be any over its 5 px: within half of it and one input px
        px = max((box[2] - box[0]) / 24, (box[3] - box[1]) / 32) * 1.25 + 2.5
        assert (kp[:, 0] - 70).abs().max() <= px and (kp[:, 1] - 40).abs().max() <= px
        assert (kp[:, 2] > 0.1).all()  # found: the softmax shared over the dot's columns, above a flat 1 / 24


def test_every_tracked_person_gets_the_pose_in_their_own_box_without_mediapipe(tmp_path, monkeypatch):
    class TwoPeople:  # a PersonBoxDetector: two people walking right, far apart
        def detect_frames(self, frames):
            return [torch.tensor([[20.0 + 3 * t, 10, 60 + 3 * t, 80, 0.9], [100.0 + 3 * t, 10, 140 + 3 * t, 80, 0.8]])
                    for t in range(frames.shape[0])]  # fmt: skip

    def no_mediapipe():
        raise AssertionError("MediaPipe was imported")

    monkeypatch.setattr(mediapipe_pose, "import_mediapipe", no_mediapipe)
    T = 4  # each person's dot moves with its box
    frames = torch.cat([dots(1, 90, 170, [(40 + 3 * t, 40), (125 + 3 * t, 30)]) for t in range(T)])
    est = estimate_poses(frames, people="all", detector=TwoPeople(), pose_model=brightest_model(tmp_path / "m.onnx"))
    assert est.num_people == 2 and est.source == "onnx-pose:m.onnx" and est.joints3d is None
    by_x = sorted(est.people(), key=lambda p: float(p.keypoints2d[0, 0, 0]))
    for person, (x, y) in zip(by_x, [(40, 40), (125, 30)]):
        for t in range(T):
            assert (person.keypoints2d[t, :, 0] - (x + 3 * t)).abs().max() <= 2.1
            assert (person.keypoints2d[t, :, 1] - y).abs().max() <= 3.5
    one = estimate_poses(frames, detector=TwoPeople(), pose_model=tmp_path / "m.onnx")  # people: the largest
    assert one.num_people == 1


def test_a_frame_without_a_box_has_no_pose_and_keep_frames_drops_frames(tmp_path):
    crops = OnnxPoseCrops(brightest_model(tmp_path / "m.onnx"))
    frames = dots(3, 40, 40, [(20, 20)])
    boxes = torch.tensor([[10.0, 10, 30, 30, 1], [0, 0, 0, 0, 0], [10, 10, 30, 30, 1]])
    est = crops.estimate_person(frames, boxes)
    assert est.found().tolist() == [True, False, True]
    assert crops.keep_frames(est, torch.tensor([True, True, False])).found().tolist() == [True, False, False]


def test_a_model_that_is_not_a_coco_simcc_model_is_refused_by_name(tmp_path):
    with pytest.raises(ValueError, match=r"five\.onnx: expected outputs simcc_x \[1, 17, 24 x r\]"):
        SimccPoseModel(brightest_model(tmp_path / "five.onnx", keypoints=5))
    with pytest.raises(ValueError, match=r"free\.onnx: expected one input of fixed shape \[1, 3, h, w\]"):
        SimccPoseModel(brightest_model(tmp_path / "free.onnx", input_shape=[1, 3, "height", "width"]))
    (tmp_path / "bad.onnx").write_bytes(b"not a model")
    with pytest.raises(ValueError, match=r"bad\.onnx: not an ONNX model onnxruntime can load"):
        SimccPoseModel(tmp_path / "bad.onnx")
    with pytest.raises(FileNotFoundError, match=r"pose model file .*none\.onnx does not exist"):
        SimccPoseModel(tmp_path / "none.onnx")
    with pytest.raises(ValueError, match="padding: expected 1 or more"):
        SimccPoseModel(brightest_model(tmp_path / "m.onnx"), padding=0.5)


def test_the_warp_is_opencvs_with_pixel_centres_at_integers():
    # the crop_transform's input pixel of a frame point is where cv2.warpAffine puts that point
    frame = np.zeros((60, 80), np.float32)
    frame[25, 33] = 1.0
    A = crop_transform((20, 10, 50, 50), (64, 48), 1.25)
    crop = cv2.warpAffine(frame, A, (48, 64), flags=cv2.INTER_LINEAR)
    v, u = np.unravel_index(crop.argmax(), crop.shape)
    expected = A @ np.array([33.0, 25.0, 1.0])
    assert abs(u - expected[0]) <= 1 and abs(v - expected[1]) <= 1


def test_estimate_pose_writes_every_persons_pose_from_the_onnx_model(tmp_path, capsys):
    from test_detector import PERSON_19, _raw, _tiny_model

    from lit_boot.cli import main
    from lit_boot.data.readers import load_poses

    # a tiny YOLOX finding one person at (8, 4, 40, 28) in 64x64 frames; a dot at its centre (24, 16)
    yolox = _tiny_model(tmp_path / "yolox.onnx", _raw(64, 64, PERSON_19))
    frames = tmp_path / "frames"
    frames.mkdir()
    for t, frame in enumerate(dots(3, 64, 64, [(24, 16)])):
        cv2.imwrite(str(frames / f"{t:03d}.png"), frame.permute(1, 2, 0).numpy())
    pose_model = brightest_model(tmp_path / "rtmpose.onnx")
    argv = ["estimate-pose", str(frames), "--out", str(tmp_path / "p.npz"), "--detector", str(yolox)]
    assert main([*argv, "--pose_model", str(pose_model), "--people", "all"]) == 0
    assert "wrote" in capsys.readouterr().out
    est = load_poses(tmp_path / "p.npz")
    assert est.num_people == 1 and est.source == "onnx-pose:rtmpose.onnx" and bool(est.found().all())
    assert (est.keypoints2d - torch.tensor([24.0, 16.0])).abs().max() <= 3.5
    assert main([*argv, "--pose_model", str(tmp_path / "none.onnx")]) == 2
    assert "--pose_model" in capsys.readouterr().err
    # the same through lit-boot import video, into a scene folder
    scene = ["import", "video", str(frames), "--out", str(tmp_path / "scene"), "--detector", str(yolox)]
    assert main([*scene, "--estimate", "true", "--people", "all", "--pose_model", str(pose_model)]) == 0
    from lit_boot.data import load_scene

    loaded = load_scene(tmp_path / "scene")
    assert loaded.joints3d is None and (loaded.keypoints2d - torch.tensor([24.0, 16.0])).abs().max() <= 3.5
    alone = ["import", "video", str(frames), "--out", str(tmp_path / "other"), "--pose_model", str(pose_model)]
    assert main(alone) == 2  # without --estimate
    assert "--pose_model: needs --estimate true" in capsys.readouterr().err
