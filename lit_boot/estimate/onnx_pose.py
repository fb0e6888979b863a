"""A top-down 2D pose model exported to ONNX with a SimCC head (RTMPose's), on each person's box.

MediaPipe's pose in the crop of a box around two people is often the one in front or a blend of
both; a model made for crowded crops, given the box, estimates the person the box is centred on.
With a perfect such model in MediaPipe's place, two thirds of the identity switches left on the
synthetic crossings go (BENCHMARKS.md, "The switches left, by cause"). Its weights are not shipped:
pass the local path of an export (e.g. RTMPose-m's 256x192 COCO model from rtmlib or mmdeploy).

The model (:class:`SimccPoseModel`): one input (1, 3, h, w) float32 RGB, each channel as
(value - mean) / std in 0-255 units (ImageNet's by default, as RTMPose is trained); two outputs,
``simcc_x`` (1, K, w * r) and ``simcc_y`` (1, K, h * r) (by these names, else the first two in
this order): per keypoint a score for each 1/r px of the input's width and height. A keypoint lies
at its best bin / r input px, its confidence the lower of its two best scores (clamped to [0, 1]);
K = 17, COCO's keypoints.
The crop: the box's centre, its width and height x ``padding`` (1.25), the shorter one widened to
the input's aspect ratio, resized bilinearly (``cv2.warpAffine``) onto the input. Pixels: frames and
input with pixel centres at integer coordinates; boxes x0, y0, x1, y1 px (:mod:`.detector`).

:class:`OnnxPoseCrops` is the :class:`~.people_pose.PersonPoseEstimator` of such a model: 2D
keypoints only (no 3D joints nor cameras: the method's 2D mode), one model run per box.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from ..core.joints import COCO17
from ..data.readers import PoseEstimates
from .detector import open_session
from .people_pose import mask_frames

__all__ = ["SimccPoseModel", "OnnxPoseCrops", "crop_transform", "decode_simcc", "estimate_onnx_people"]

#: ImageNet's mean and std of the RGB channels in 0-255 units (RTMPose's normalisation).
IMAGENET_MEAN = (123.675, 116.28, 103.53)
IMAGENET_STD = (58.395, 57.12, 57.375)


def crop_transform(box: Sequence[float], input_size: tuple[int, int], padding: float) -> np.ndarray:
    """(2, 3) the affine map from frame px to input px (u, v) = A @ (x, y, 1) of the crop around
    ``box`` (x0, y0, x1, y1 px) for an input of ``input_size`` (h, w): the box's centre, its sides
    x ``padding``, the shorter widened to the input's aspect ratio (module docstring)."""
    h, w = input_size
    x0, y0, x1, y1 = (float(v) for v in box[:4])
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    side_w, side_h = max(x1 - x0, 1.0) * padding, max(y1 - y0, 1.0) * padding
    side_w, side_h = max(side_w, side_h * w / h), max(side_h, side_w * h / w)
    sx, sy = w / side_w, h / side_h
    # the crop's left edge (cx - side_w / 2) maps to the input's left edge, -0.5
    return np.array([[sx, 0.0, -(cx - side_w / 2) * sx - 0.5], [0.0, sy, -(cy - side_h / 2) * sy - 0.5]])


def decode_simcc(simcc_x: np.ndarray, simcc_y: np.ndarray, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints (K, 2) input px and confidences (K,) in [0, 1] from one crop's ``simcc_x`` (K, Bx)
    and ``simcc_y`` (K, By) scores, ``ratio`` bins per px (module docstring)."""
    points = np.stack([simcc_x.argmax(-1), simcc_y.argmax(-1)], -1).astype(np.float64) / ratio
    confidence = np.minimum(simcc_x.max(-1), simcc_y.max(-1)).clip(0.0, 1.0)
    return points, confidence


class SimccPoseModel:
    """A top-down SimCC pose model through onnxruntime (module docstring).

    Args:
        model: the ONNX file's path.
        padding: the crop's sides in box sides.
        mean: the input's mean per RGB channel, 0-255 units, subtracted.
        std: the input's standard deviation per RGB channel, 0-255 units, divided by.
        threads: onnxruntime's intra-op threads (as :class:`~.detector.PersonDetector`'s).
        providers: onnxruntime's execution providers (as :class:`~.detector.PersonDetector`'s).

    A missing or unreadable file, or one whose input or outputs are not a SimCC model's for COCO's
    17 keypoints, raises an error naming the file and what was expected."""

    def __init__(self, model: str | os.PathLike, *, padding: float = 1.25, mean: Sequence[float] = IMAGENET_MEAN,
                 std: Sequence[float] = IMAGENET_STD, threads: int | None = None,
                 providers: Sequence[str] = ("CPUExecutionProvider",)) -> None:  # fmt: skip
        self.path = Path(model)
        if not self.path.is_file():
            raise FileNotFoundError(f"pose model file {self.path} does not exist (a SimCC pose model exported to ONNX)")
        if not padding >= 1.0:
            raise ValueError(f"padding: expected 1 or more (the crop's sides in box sides), got {padding!r}")
        self.padding = float(padding)
        self.mean, self.std = np.asarray(mean, np.float32), np.asarray(std, np.float32)
        if self.mean.shape != (3,) or self.std.shape != (3,) or not (self.std > 0).all():
            raise ValueError(f"mean, std: expected three values each, std above 0, got {mean!r}, {std!r}")
        self.session = open_session(self.path, threads, providers)
        self.input_name, self.input_size, self.ratio, self.outputs = self._check()

    def __repr__(self) -> str:
        return f"SimccPoseModel({str(self.path)!r}, input {self.input_size[0]}x{self.input_size[1]})"

    def _check(self) -> tuple[str, tuple[int, int], float, list[str]]:
        """The input's name, its (h, w), the bins per px, and simcc_x's and simcc_y's names (by name
        where the model has both, else the first two); ValueError naming the file otherwise."""
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        named = {o.name: o for o in outputs}
        if "simcc_x" in named and "simcc_y" in named:
            outputs = [named["simcc_x"], named["simcc_y"]]
        shape = list(inputs[0].shape) if len(inputs) == 1 else []
        if len(shape) != 4 or not all(isinstance(d, int) for d in shape[1:]) or shape[1] != 3:
            raise ValueError(f"{self.path}: expected one input of fixed shape [1, 3, h, w], got "
                             + ", ".join(f"{i.name} {i.shape}" for i in inputs))  # fmt: skip
        h, w = shape[2], shape[3]
        shapes = [list(o.shape) for o in outputs[:2]]
        K = len(COCO17.names)
        fits = len(outputs) >= 2 and all(len(s) == 3 and s[1] == K and isinstance(s[2], int) for s in shapes)
        if not fits or shapes[0][2] * h != shapes[1][2] * w or shapes[0][2] % w:
            raise ValueError(f"{self.path}: expected outputs simcc_x [1, {K}, {w} x r] and simcc_y [1, {K}, {h} x r] "
                             "(a SimCC head for COCO's 17 keypoints), got "
                             + ", ".join(f"{o.name} {o.shape}" for o in outputs))  # fmt: skip
        return inputs[0].name, (h, w), shapes[0][2] / w, [o.name for o in outputs[:2]]

    def keypoints(self, frame: torch.Tensor, box: torch.Tensor) -> torch.Tensor:
        """(17, 3) x, y frame px and confidence of the person in ``box`` (x0, y0, x1, y1 px) of
        ``frame`` (3, H, W) uint8 RGB."""
        h, w = self.input_size
        to_input = crop_transform(box.tolist(), (h, w), self.padding)
        image = np.ascontiguousarray(frame.permute(1, 2, 0).numpy())
        crop = cv2.warpAffine(image, to_input, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        blob = ((crop.astype(np.float32) - self.mean) / self.std).transpose(2, 0, 1)[None]
        simcc_x, simcc_y = self.session.run(self.outputs, {self.input_name: np.ascontiguousarray(blob)})
        points, confidence = decode_simcc(simcc_x[0], simcc_y[0], self.ratio)
        back = cv2.invertAffineTransform(to_input)
        frame_points = points @ back[:, :2].T + back[:, 2]
        return torch.as_tensor(np.concatenate([frame_points, confidence[:, None]], -1), dtype=torch.float32)


class OnnxPoseCrops:
    """The :class:`~.people_pose.PersonPoseEstimator` of a :class:`SimccPoseModel` (or its path):
    each box's crop gives COCO-17 keypoints (2D only), ``source`` "onnx-pose:<file name>"."""

    def __init__(self, model: SimccPoseModel | str | os.PathLike, frame_indices: torch.Tensor | None = None,
                 **options: Any) -> None:  # fmt: skip
        self.model = model if isinstance(model, SimccPoseModel) else SimccPoseModel(model, **options)
        self.frame_indices = frame_indices

    def estimate_person(self, frames: torch.Tensor, boxes: torch.Tensor) -> PoseEstimates:
        """The person in ``boxes`` (T, 5; score 0: none) of frames (T, 3, H, W) uint8 RGB."""
        T, K = frames.shape[0], len(COCO17.names)
        out = torch.zeros(T, K, 3)
        for t in torch.nonzero(boxes[:, 4] > 0).flatten().tolist():
            out[t] = self.model.keypoints(frames[t], boxes[t, :4])
        return PoseEstimates(keypoints2d=out[..., :2].contiguous(), keypoints_conf=out[..., 2].contiguous(),
                             keypoints_layout="coco17", frame_indices=self.frame_indices,
                             image_size=tuple(frames.shape[2:]), source=f"onnx-pose:{self.model.path.name}",
                             metadata={"pose_model": str(self.model.path)})  # fmt: skip

    def keep_frames(self, estimates: PoseEstimates, keep: torch.Tensor) -> PoseEstimates:
        return mask_frames(estimates, keep)


def estimate_onnx_people(frames: torch.Tensor, model: SimccPoseModel | str | os.PathLike, *,
                         people: str | int = "largest", detector: Any = None,
                         frame_indices: torch.Tensor | None = None) -> PoseEstimates:  # fmt: skip
    """Every tracked person's 2D pose in frames (T, 3, H, W) uint8 RGB, top-down with the SimCC
    ``model`` on the ``detector``'s boxes (None: ``"yolox_nano"``), as
    :func:`~.people_pose.estimate_people` (``people``: all, largest or N; the main person first)."""
    from .detector import as_detector, detector_name
    from .people_pose import estimate_people
    from .people_track import parse_people

    people, detector = parse_people(people), as_detector(detector)
    estimator = OnnxPoseCrops(model, frame_indices)
    meta = {"detector": detector_name(detector), "mode": "top-down: the pose model on each detection's crop"}
    return estimate_people(estimator, frames, detector, people, meta)
