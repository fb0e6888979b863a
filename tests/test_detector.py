"""The YOLOX person detector (lit_boot.estimate.detector), its weights lookup and the main-person track.

Decoding, letterboxing, NMS and the tracker are checked on hand-made numbers; the loader runs on
tiny ONNX models built here (a constant raw head, so the decoded boxes are known); one test runs
the real YOLOX-Nano of ../shared on a Sintel frame. Tests that run a model need onnxruntime (the
mediapipe extra) and skip without it (reason "needs the mediapipe extra", which CI refuses).
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from lit_boot.estimate import detector_weights
from lit_boot.estimate.detector import (
    OnnxRuntimeUnavailable,
    PersonDetector,
    decode_yolox,
    import_onnxruntime,
    letterbox,
    select_boxes,
    to_frame,
)
from lit_boot.estimate.person_track import main_person_boxes

needs_onnxruntime = pytest.mark.skipif(
    importlib.util.find_spec("onnxruntime") is None,
    reason='needs the mediapipe extra (onnxruntime): pip install -e ".[mediapipe]"',
)


@pytest.fixture(autouse=True)
def no_detector_checkpoints(tmp_path_factory, monkeypatch):
    """Hide checkpoints/ and $LIT_BOOT_CHECKPOINTS from the detector's lookup (conftest hides RAFT's)."""
    empty = tmp_path_factory.mktemp("no_detector_checkpoints")
    monkeypatch.setattr(detector_weights, "_default_dirs", lambda: [empty])
    monkeypatch.delenv("LIT_BOOT_CHECKPOINTS", raising=False)


def _anchors(h: int, w: int) -> int:
    return sum((h // s) * (w // s) for s in (8, 16, 32))


def _raw(h: int, w: int, entries: dict[int, tuple[float, float, float, float, float, float, int]]) -> np.ndarray:
    """A raw head output (1, A, 85): zeros but for anchors -> (dx, dy, log w, log h, obj, cls score, class)."""
    raw = np.zeros((1, _anchors(h, w), 85), np.float32)
    for a, (dx, dy, lw, lh, obj, cls, c) in entries.items():
        raw[0, a, :5] = dx, dy, lw, lh, obj
        raw[0, a, 5 + c] = cls
    return raw


# For a 64x64 input: anchors 0-63 are stride 8 (8x8 cells), 64-79 stride 16, 80-83 stride 32.
# Anchor 19 = stride 8, cell (x 3, y 2), no offset: centre (24, 16); size 4 x 3 cells -> 32 x 24 px.
PERSON_19 = {19: (0.0, 0.0, math.log(4), math.log(3), 0.9, 0.9, 0)}


def test_decode_gives_known_boxes_and_scores_at_each_stride():
    raw = _raw(64, 64, {
        1: (0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0),                  # stride 8, cell (1, 0): rows of x
        70: (0.5, 0.25, math.log(3), math.log(2), 0.8, 0.5, 0),  # stride 16, cell (2, 1)
        83: (0.0, 0.0, 0.0, 0.0, 0.5, 0.5, 7),                  # stride 32, cell (1, 1), class 7
    })  # fmt: skip
    boxes, scores = decode_yolox(raw, (64, 64))
    assert boxes.shape == (84, 4) and scores.shape == (84, 80)
    assert torch.allclose(boxes[1], torch.tensor([4.0, -4.0, 12.0, 4.0]))
    assert torch.allclose(boxes[70], torch.tensor([16.0, 4.0, 64.0, 36.0]))  # centre (40, 20), 48 x 32
    assert torch.allclose(boxes[83], torch.tensor([16.0, 16.0, 48.0, 48.0]))
    assert scores[70, 0] == pytest.approx(0.4) and scores[83, 7] == pytest.approx(0.25) and scores[83, 0] == 0


def test_decode_refuses_a_head_of_another_input_size():
    with pytest.raises(ValueError, match=r"raw: expected shape \(1, 84, 5 \+ classes\) for a 64x64 input"):
        decode_yolox(np.zeros((1, 3549, 85), np.float32), (64, 64))


def test_letterbox_is_bgr_top_left_and_padded_with_114():
    frame = torch.tensor([200, 10, 50], dtype=torch.uint8)[:, None, None].expand(3, 48, 96).contiguous()
    image, scale = letterbox(frame, (64, 64))
    assert image.shape == (3, 64, 64) and image.dtype == torch.float32 and scale == (32 / 48, 64 / 96)
    assert torch.equal(image[:, :32], torch.tensor([50.0, 10.0, 200.0])[:, None, None].expand(3, 32, 64))
    assert (image[:, 32:] == 114).all()


@pytest.mark.parametrize("portrait", [False, True], ids=["landscape", "portrait"])
def test_a_box_in_the_letterbox_maps_to_the_frames_pixels(portrait):
    # A white block on pixel columns 30..89 and rows 15..38 of a 48x96 frame: scaled by 2/3 into a
    # 64x64 input, its edges land on whole pixels there (20..60, 10..26); portrait: the transpose.
    frame = torch.zeros(3, 48, 96, dtype=torch.uint8)
    frame[:, 15:39, 30:90] = 255
    edges = [20, 10, 60, 26]  # x0, y0, x1, y1 in the letterbox (its left/top edge at 0)
    want = [29.5, 14.5, 89.5, 38.5]  # the block's outer edges, pixel centres at integers
    if portrait:
        frame, edges, want = frame.transpose(1, 2), edges[1::-1] + edges[:1:-1], want[1::-1] + want[:1:-1]
    image, scale = letterbox(frame.contiguous(), (64, 64))
    rows, cols = torch.nonzero(image[0] > 127.5, as_tuple=True)
    assert [int(cols.min()), int(rows.min()), int(cols.max()) + 1, int(rows.max()) + 1] == edges
    back = to_frame(torch.tensor([[*edges, 0.9]], dtype=torch.float32), scale, tuple(frame.shape[1:]))
    assert torch.allclose(back, torch.tensor([[*want, 0.9]]))


def test_boxes_are_clipped_to_the_frame_and_dropped_when_outside():
    lb = torch.tensor([[-8.0, 10.0, 40.0, 80.0, 0.9], [20.0, 40.0, 40.0, 60.0, 0.8]])  # 2nd: in the padding
    back = to_frame(lb, (32 / 48, 64 / 96), (48, 96))
    assert torch.allclose(back, torch.tensor([[-0.5, 14.5, 59.5, 47.5, 0.9]]))


def test_nms_keeps_the_best_person_boxes_above_the_threshold_only():
    boxes = torch.tensor([[0, 0, 10, 10], [1, 0, 11, 10], [20, 20, 30, 30], [40, 0, 50, 10], [40, 40, 50, 50.0]])
    scores = torch.zeros(5, 80)
    scores[:4, 0] = torch.tensor([0.9, 0.8, 0.3, 0.2])  # the 2nd overlaps the 1st (IoU 0.82); the 4th: too low
    scores[4, 2] = 0.95  # a car: not a person
    kept = select_boxes(boxes, scores, score=0.25, iou=0.45)
    assert torch.allclose(kept, torch.tensor([[0, 0, 10, 10, 0.9], [20, 20, 30, 30, 0.3]]))
    assert torch.allclose(select_boxes(boxes, scores, class_id=2)[:, 4], torch.tensor([0.95]))
    assert select_boxes(boxes, scores, iou=0.9).shape == (3, 5)  # looser NMS keeps the overlapping one
    with pytest.raises(ValueError, match="class_id: expected a class index below 80, got 80"):
        select_boxes(boxes, scores, class_id=80)


def _det(*rows: tuple[float, float, float, float, float]) -> torch.Tensor:
    return torch.tensor(rows, dtype=torch.float32).reshape(-1, 5)


def test_track_bridges_a_short_gap_by_interpolation():
    dets = [_det((10.0 * t, 0, 10.0 * t + 50, 100, 0.9)) for t in range(5)]
    dets[2] = _det()
    boxes, found = main_person_boxes(dets, max_gap=1)
    assert found.all() and torch.allclose(boxes[2], torch.tensor([20.0, 0, 70, 100]))
    _, found = main_person_boxes(dets, max_gap=0)
    assert found.tolist() == [True, True, False, True, True]


def test_track_follows_the_largest_person_not_a_small_confident_one():
    # The big person walks right; a small, more confident one stands far off; in frame 3 only
    # the small one is detected: the track skips it (bridged) instead of jumping to it.
    big = [(100.0 + 5 * t, 50, 200.0 + 5 * t, 250, 0.6) for t in range(6)]
    small = (600.0, 50, 620, 90, 0.99)
    dets = [_det(small, big[t]) for t in range(6)]
    dets[3] = _det(small)
    boxes, found = main_person_boxes(dets)
    assert found.all()
    assert torch.allclose(boxes, torch.tensor([b[:4] for b in big]))


def test_track_starts_at_the_most_prominent_frame_and_follows_backwards():
    # The person grows towards the camera: the seed is the last frame, the rest is found backwards;
    # a second, smaller but more confident person appears in frame 0 only, away from the track.
    dets = [_det((100.0 - 2 * t, 100.0 - 4 * t, 140.0 + 2 * t, 200.0 + 4 * t, 0.8)) for t in range(5)]
    dets[0] = _det((400.0, 0, 440, 80, 0.95), dets[0][0].tolist())
    boxes, found = main_person_boxes(dets, max_gap=0)
    assert found.all() and torch.allclose(boxes[0], torch.tensor([100.0, 100, 140, 200]))
    dets[0] = dets[0][:1]  # only the other one in frame 0: too far from the track to be taken
    assert main_person_boxes(dets)[1].tolist() == [False, True, True, True, True]


def test_track_frames_with_nobody_are_not_found_and_zero():
    dets = [_det((0.0, 0, 50, 100, 0.9)), _det((2.0, 0, 52, 100, 0.9))] + [_det()] * 5
    boxes, found = main_person_boxes(dets, max_gap=3)
    assert found.tolist() == [True, True] + [False] * 5 and (boxes[2:] == 0).all()
    boxes, found = main_person_boxes([_det()] * 3)
    assert not found.any() and boxes.shape == (3, 4)
    with pytest.raises(ValueError, match=r"detections\[1\]: expected a tensor of shape \(N, 5\)"):
        main_person_boxes([_det(), torch.zeros(2, 4)])


def _tiny_model(path: Path, raw: np.ndarray, input_shape: tuple[int, ...] = (1, 3, 64, 64)) -> Path:
    """A model with input 'images' ``input_shape`` and output 'output' = ``raw`` + 0 x mean(images)."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    nodes = [
        helper.make_node("ReduceMean", ["images"], ["mean"], keepdims=0),
        helper.make_node("Mul", ["mean", "zero"], ["nothing"]),
        helper.make_node("Add", ["head", "nothing"], ["output"]),
    ]
    graph = helper.make_graph(
        nodes, "tiny_yolox",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, list(input_shape))],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, list(raw.shape))],
        initializer=[numpy_helper.from_array(raw.astype(np.float32), "head"),
                     numpy_helper.from_array(np.zeros((), np.float32), "zero")],
    )  # fmt: skip
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)], ir_version=8)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


@needs_onnxruntime
def test_a_tiny_onnx_model_detects_its_known_box_in_frame_pixels(tmp_path):
    # The head holds one person at (8, 4, 40, 28) in the 64x64 letterbox of a 48x96 frame (scale
    # 2/3), a weaker duplicate beside it and a class-1 box: one person, at its edges / (2/3) - 0.5.
    head = _raw(64, 64, {**PERSON_19, 20: (-0.25, 0.0, math.log(4), math.log(3), 0.9, 0.5, 0),
                         40: (0.0, 0.0, 0.0, 0.0, 0.9, 0.9, 1)})  # fmt: skip
    det = PersonDetector(_tiny_model(tmp_path / "tiny.onnx", head), threads=1)
    assert det.input_size == (64, 64) and det.num_classes == 80
    frames = torch.randint(0, 256, (2, 3, 48, 96), dtype=torch.uint8)
    found = det.detect_frames(frames)
    want = torch.tensor([[11.5, 5.5, 59.5, 41.5, 0.81]])
    assert len(found) == 2 and all(torch.allclose(f, want, atol=1e-4) for f in found)


@needs_onnxruntime
def test_the_input_size_is_read_from_the_model(tmp_path):
    # A 32x64 input: 4x8 + 2x4 + 1x2 = 42 anchors; the letterbox of a 48x96 frame is then scale 2/3 too.
    head = _raw(32, 64, PERSON_19)  # anchor 19: stride 8, cell (3, 2) of an 8-wide grid, as above
    det = PersonDetector(_tiny_model(tmp_path / "wide.onnx", head, (1, 3, 32, 64)), threads=1)
    assert det.input_size == (32, 64)
    found = det.detect(torch.zeros(3, 48, 96, dtype=torch.uint8))
    assert torch.allclose(found, torch.tensor([[11.5, 5.5, 59.5, 41.5, 0.81]]), atol=1e-4)
    # An export whose input size is not fixed needs it given; a fixed one must not be contradicted.
    dynamic = _tiny_model(tmp_path / "dynamic.onnx", _raw(64, 64, PERSON_19), (1, 3, "height", "width"))
    with pytest.raises(ValueError, match=r"input_size: dynamic\.onnx's input size is not fixed .*; pass \(h, w\)"):
        PersonDetector(dynamic, threads=1)
    given = PersonDetector(dynamic, threads=1, input_size=(64, 64))
    assert given.input_size == (64, 64) and given.detect(torch.zeros(3, 48, 96, dtype=torch.uint8)).shape == (1, 5)
    with pytest.raises(ValueError, match=r"input_size: the model wide\.onnx takes 32x64, got \(64, 64\)"):
        PersonDetector(det.path, threads=1, input_size=(64, 64))


@needs_onnxruntime
@pytest.mark.parametrize(
    "case, pattern",
    [
        ("missing", r"detector model file .*absent\.onnx does not exist"),
        ("not_onnx", r"bad\.onnx: not an ONNX model onnxruntime can load"),
        ("wrong_output",
         r"wrong\.onnx: expected an output of shape \[1, 84, 5 \+ classes\] .*got output \[1, 10, 85\]"),
        ("wrong_input", r"gray\.onnx: expected one input of shape \[1, 3, h, w\] .*got images \[1, 1, 64, 64\]"),
        ("odd_size", r"odd\.onnx: expected an input size in multiples of 32 px, got 60x64"),
        ("decoded", r"decoded\.onnx: the output's box sizes look like pixels, not log sizes .*--decode_in_inference"),
    ],
)  # fmt: skip
def test_a_bad_model_file_is_one_clear_error_naming_it(tmp_path, case, pattern):
    path = {"missing": tmp_path / "absent.onnx", "not_onnx": tmp_path / "bad.onnx"}.get(case)
    if case == "not_onnx":
        path.write_bytes(b"this is not a model")
    elif case == "wrong_output":
        path = _tiny_model(tmp_path / "wrong.onnx", np.zeros((1, 10, 85), np.float32))
    elif case == "wrong_input":
        path = _tiny_model(tmp_path / "gray.onnx", _raw(64, 64, {}), (1, 1, 64, 64))
    elif case == "odd_size":
        path = _tiny_model(tmp_path / "odd.onnx", np.zeros((1, 10, 85), np.float32), (1, 3, 60, 64))
    elif case == "decoded":  # an export that decodes itself: centres and sizes in pixels
        path = _tiny_model(tmp_path / "decoded.onnx", np.full((1, 84, 85), 40.0, np.float32))
    with pytest.raises((ValueError, FileNotFoundError), match=pattern) as err:
        PersonDetector(path, threads=1).detect(torch.zeros(3, 48, 96, dtype=torch.uint8))
    assert "\n" not in str(err.value)


@needs_onnxruntime
def test_bad_frames_are_refused(tmp_path):
    det = PersonDetector(_tiny_model(tmp_path / "tiny.onnx", _raw(64, 64, PERSON_19)), threads=1)
    with pytest.raises(ValueError, match=r"frame: expected a uint8 RGB tensor of shape \(3, H, W\), got torch.float32"):
        det.detect(torch.zeros(3, 48, 96))
    with pytest.raises(ValueError, match=r"frames: expected a uint8 RGB tensor of shape \(T, 3, H, W\), got \(3, 48"):
        det.detect_frames(torch.zeros(3, 48, 96, dtype=torch.uint8))
    with pytest.raises(ValueError, match=r"providers: expected some of \[.*CPUExecutionProvider.*\], got \['NoSuch"):
        PersonDetector(det.path, providers=["NoSuchExecutionProvider"])


def test_without_onnxruntime_the_error_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "onnxruntime", None)  # import fails as if not installed
    with pytest.raises(OnnxRuntimeUnavailable, match=r'needs onnxruntime .*pip install "lit-boot\[mediapipe\]"'):
        import_onnxruntime()
    with pytest.raises(OnnxRuntimeUnavailable):
        PersonDetector("yolox_nano")


def test_the_name_is_found_in_the_checkpoint_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("LIT_BOOT_CHECKPOINTS", str(tmp_path))
    (tmp_path / "yolox_nano.onnx").write_bytes(b"placed by the user")
    monkeypatch.setattr(detector_weights, "download_file", lambda url, target: pytest.fail("downloaded"))
    assert detector_weights.resolve_detector_weights("yolox_nano") == tmp_path / "yolox_nano.onnx"


def test_a_missing_name_is_downloaded_from_the_yolox_release(tmp_path, monkeypatch):
    monkeypatch.setenv("LIT_BOOT_CHECKPOINTS", str(tmp_path / "ckpt"))
    calls = []

    def fake(url: str, target: Path) -> None:
        calls.append(url)
        target.parent.mkdir(parents=True)
        target.write_bytes(b"downloaded")

    monkeypatch.setattr(detector_weights, "download_file", fake)
    assert detector_weights.resolve_detector_weights("yolox_nano") == tmp_path / "ckpt" / "yolox_nano.onnx"
    assert calls == ["https://github.com/Megvii-BaseDetection/YOLOX/releases/download/0.1.1rc0/yolox_nano.onnx"]


def test_offline_the_error_names_the_file_to_place(tmp_path, monkeypatch):
    monkeypatch.setenv("LIT_BOOT_CHECKPOINTS", str(tmp_path))

    def offline(url: str, target: Path) -> None:
        raise OSError("network is unreachable")

    monkeypatch.setattr(detector_weights, "download_file", offline)
    with pytest.raises(FileNotFoundError, match=rf"Place yolox_nano.onnx in {tmp_path}") as err:
        detector_weights.resolve_detector_weights("yolox_nano")
    assert "could not be downloaded" in str(err.value) and "network is unreachable" in str(err.value)
    with pytest.raises(ValueError, match=r"model: 'yolox_tiny' is neither an ONNX file nor a known detector name"):
        detector_weights.resolve_detector_weights("yolox_tiny")


@needs_onnxruntime
@pytest.mark.shared
def test_yolox_nano_finds_the_girl_in_a_sintel_frame(shared):
    from lit_boot.data import read_png

    frame = read_png(shared / "data/sintel_samples/training/final/alley_1/frame_0002.png")  # 436 x 1024
    det = PersonDetector(shared / "checkpoints/yolox_nano.onnx", threads=1)
    found = det.detect(frame)
    # Where she is, read once by eye from the frame drawn with a 50 px grid (cv2.line/putText):
    # from her left shoulder (x 375) to her hair's right edge (x 695), from the top of her hair
    # (y 68) to the frame's bottom (she is cut off there). The detector also finds, weaker
    # (0.30), a hand holding an apple at the bottom right.
    girl = torch.tensor([375.0, 68.0, 695.0, 435.5])
    lo, hi = torch.maximum(found[0, :2], girl[:2]), torch.minimum(found[0, 2:4], girl[2:])
    inter = (hi - lo).clamp_min(0).prod()
    iou = inter / ((found[0, 2:4] - found[0, :2]).prod() + (girl[2:] - girl[:2]).prod() - inter)
    assert found[0, 4] > 0.5 and iou > 0.8, (found, iou)
