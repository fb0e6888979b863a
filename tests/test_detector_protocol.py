"""Another person detector plugs in (lit_boot.estimate.detector.PersonBoxDetector): any object
with ``detect_frames``, its boxes checked, a path or name still building YOLOX."""

from __future__ import annotations

import pytest
import torch

from lit_boot.estimate import estimate_poses, person_boxes
from lit_boot.estimate.detector import as_detector, detector_name
from lit_boot.estimate.person_track import frame_detections
from test_estimate_mediapipe import needs_mediapipe

T, H, W = 4, 60, 80


class Walking:
    """A detector of one's own (no ``path``): one person walking right, 5 px per frame, a stray
    low-score box in frame 1, nobody in frame 2 (an empty list, as a plain detector may give)."""

    def detect_frames(self, frames):
        out = []
        for t in range(frames.shape[0]):
            rows = [] if t == 2 else [[10.0 + 5 * t, 10.0, 30.0 + 5 * t, 50.0, 0.9]]
            if t == 1:
                rows.append([60.0, 0.0, 70.0, 10.0, 0.3])
            out.append(rows)
        return out


def test_any_detector_with_detect_frames_plugs_in_and_its_boxes_are_checked():
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    found = frame_detections(Walking(), frames)
    assert [tuple(d.shape) for d in found] == [(1, 5), (2, 5), (0, 5), (1, 5)] and found[0].dtype == torch.float32
    boxes = person_boxes(frames, Walking())  # the main person: the walker, frame 2 bridged
    assert boxes[:, 4].tolist() == [1.0] * T
    assert torch.allclose(boxes[:, 0], torch.tensor([10.0, 15.0, 20.0, 25.0]))
    assert as_detector(walking := Walking()) is walking
    assert detector_name(walking) == "Walking"


class Broken:
    def __init__(self, per_frame):
        self.per_frame, self.path = per_frame, "broken.onnx"

    def detect_frames(self, frames):
        return self.per_frame


def test_a_detector_that_gives_the_wrong_boxes_is_named():
    frames = torch.zeros(2, 3, H, W, dtype=torch.uint8)
    with pytest.raises(ValueError, match=r"detector broken.onnx: expected boxes for each of the 2 frames, got 1"):
        frame_detections(Broken([torch.zeros(0, 5)]), frames)
    with pytest.raises(ValueError, match=r"detector broken.onnx: detections\[1\]: expected .*\(N, 5\).*got \(3, 4\)"):
        frame_detections(Broken([torch.zeros(0, 5), torch.zeros(3, 4)]), frames)
    with pytest.raises(ValueError, match=r"detector broken.onnx: detections\[0\]: expected \(N, 5\) boxes.*got list"):
        frame_detections(Broken([[[1.0, 2.0, 3.0, 4.0, 0.5], [1.0, 2.0]], []]), frames)  # ragged


def test_a_model_path_still_builds_yolox(tmp_path):
    missing = tmp_path / "nowhere.onnx"
    with pytest.raises(FileNotFoundError, match="nowhere.onnx"):
        as_detector(missing)


@needs_mediapipe
def test_estimate_poses_takes_a_detector_of_ones_own():
    """Every person, top-down, from another detector's boxes: the run records the detector by its
    class name; black frames give MediaPipe nobody, so no pose and no person."""
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    est = estimate_poses(frames, people="all", detector=Walking())
    assert est.metadata["detector"] == "Walking" and est.metadata["tracks"] == 1
    assert float(est.keypoints_conf.amax()) == 0 and est.metadata["people_without_pose"] == [0]
