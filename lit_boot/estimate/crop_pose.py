"""MediaPipe Pose on the person detector's crops, for the frames where it missed the person.

MediaPipe's own person detector misses small and stylised people that a YOLOX box finds
(BENCHMARKS.md, "Person detector"). For each frame where the whole-frame pass found nobody but
the detector has a box, :func:`crop_landmarks` runs MediaPipe again, in static-image mode, on
square crops about the box's centre: the box's larger side enlarged by a margin of it on every
side, resized to a side of so many px (small people are upsampled). MediaPipe's answer depends
on the framing, so several framings are tried in turn (:data:`CROP_ATTEMPTS`), the first that
finds somebody kept (BENCHMARKS.md, "MediaPipe on the detector's crops"). The landmarks
are mapped back to frame pixels (pixel centres at integer coordinates, the convention of
:mod:`.mediapipe_pose`); the world landmarks (metres, hip-centred) need no mapping.
"""

from __future__ import annotations

import time
import warnings

import cv2
import numpy as np
import torch

from ..core.frame_runs import frame_runs

__all__ = ["crop_window", "crop_landmarks", "follow_landmarks", "CROP_ATTEMPTS"]

#: The framings tried in turn: (margin around the box on every side, as a fraction of its larger
#: side; the side in px the square crop is resized to before MediaPipe sees it).
CROP_ATTEMPTS = ((0.25, 384), (0.1, 384), (0.1, 256), (0.5, 256), (0.25, 256))


def crop_window(box: torch.Tensor, margin: float) -> tuple[float, float, float]:
    """The square crop around a box (4,) x0, y0, x1, y1 px: (cx, cy, side) px, its centre and
    side (the box's larger side plus ``margin`` of it on both sides). It may reach outside the
    frame: :func:`crop_landmarks` pads with black there."""
    x0, y0, x1, y1 = (float(v) for v in box[:4])
    side = max(x1 - x0, y1 - y0, 1.0) * (1 + 2 * margin)
    return (x0 + x1) / 2, (y0 + y1) / 2, side


def _square_crop(image: np.ndarray, cx: float, cy: float, side: float, out_px: int) -> np.ndarray:
    """The square of ``side`` px centred on (cx, cy) of an HWC image, resized to out_px x out_px
    (an affine warp: bilinear, black outside the frame)."""
    scale = out_px / side
    # frame pixel centre (x, y) -> crop pixel centre: (x - (cx - side / 2) + 0.5) * scale - 0.5
    matrix = np.array([[scale, 0.0, (side / 2 - cx + 0.5) * scale - 0.5],
                       [0.0, scale, (side / 2 - cy + 0.5) * scale - 0.5]])  # fmt: skip
    return cv2.warpAffine(image, matrix, (out_px, out_px), flags=cv2.INTER_LINEAR, borderValue=(0, 0, 0))


def _process(pose, image: np.ndarray):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # protobuf deprecation noise
        result = pose.process(image)
    return None if result.pose_landmarks is None or result.pose_world_landmarks is None else result


def crop_landmarks(pose, frames: torch.Tensor, boxes: torch.Tensor, todo: torch.Tensor, *,
                   attempts=CROP_ATTEMPTS) -> dict[str, torch.Tensor]:  # fmt: skip
    """MediaPipe ``pose`` (a static-image-mode ``mp.solutions.pose.Pose``) on the crops of the
    frames (T, 3, H, W) uint8 RGB where ``todo`` (T,) bool, around ``boxes`` (T, 5) px, each
    framing of ``attempts`` ((margin, side px), ...) in turn until one finds somebody.

    Returns the arrays of :func:`~.mediapipe_pose.run_mediapipe` (landmarks (T, 33, 2) frame px,
    visibility, presence, world (T, 33, 3) m, found (T,), seconds (T,)), filled only where a
    crop found somebody, and ``attempt`` (T,) int64: the framing's index (-1: none found)."""
    T = frames.shape[0]
    out = _empty(T)
    for t in torch.nonzero(todo & (boxes[:, 4] > 0)).flatten().tolist():
        frame = np.ascontiguousarray(frames[t].permute(1, 2, 0).numpy())
        start = time.perf_counter()
        for k, (margin, side_px) in enumerate(attempts):
            cx, cy, side = crop_window(boxes[t], margin)
            result = _process(pose, _square_crop(frame, cx, cy, side, side_px))
            if result is not None:
                break
        out["seconds"][t] = time.perf_counter() - start
        if result is None:
            continue
        _store(out, t, result, cx, cy, side, side_px)
        out["attempt"][t] = k
    return out


def _empty(T: int) -> dict[str, torch.Tensor]:
    """The arrays of :func:`crop_landmarks` for T frames, nobody found."""
    return {"landmarks": torch.zeros(T, 33, 2), "visibility": torch.zeros(T, 33), "presence": torch.zeros(T, 33),
            "world": torch.zeros(T, 33, 3), "found": torch.zeros(T, dtype=torch.bool),
            "seconds": torch.zeros(T), "attempt": torch.full((T,), -1, dtype=torch.int64)}  # fmt: skip


def _store(out: dict[str, torch.Tensor], t: int, result, cx: float, cy: float, side: float, side_px: int) -> None:
    """MediaPipe's ``result`` on the crop (cx, cy, side) resized to ``side_px``, into row t of ``out``
    (landmarks mapped back to frame pixels)."""
    lms = result.pose_landmarks.landmark
    crop_px = torch.tensor([[lm.x * side_px - 0.5, lm.y * side_px - 0.5] for lm in lms])
    out["landmarks"][t] = (crop_px + 0.5) * (side / side_px) - 0.5 + torch.tensor([cx - side / 2, cy - side / 2])
    out["visibility"][t] = torch.tensor([lm.visibility for lm in lms])
    out["presence"][t] = torch.tensor([lm.presence if lm.HasField("presence") else 1.0 for lm in lms])
    out["world"][t] = torch.tensor([[lm.x, lm.y, lm.z] for lm in result.pose_world_landmarks.landmark])
    out["found"][t] = True


def follow_landmarks(make_pose, frames: torch.Tensor, boxes: torch.Tensor, *, margin: float = CROP_ATTEMPTS[0][0],
                     side_px: int = CROP_ATTEMPTS[0][1]) -> dict[str, torch.Tensor]:  # fmt: skip
    """One tracked person's landmarks: MediaPipe in video mode (``make_pose()``: a new
    ``mp.solutions.pose.Pose(static_image_mode=False)``, a context manager) on a square crop that
    follows the person's ``boxes`` (T, 5) px over frames (T, 3, H, W) uint8 RGB: centred on each
    frame's box, of one side for the whole track (the boxes' median larger side plus ``margin`` of
    it on both sides), resized to ``side_px``. Video mode follows the person it found from one
    frame to the next, where the crops of a box holding two people give static mode now one's pose,
    now the other's (BENCHMARKS.md, "Each track's poses in video mode"). A new Pose starts after
    frames without a box. Returns the arrays of :func:`crop_landmarks` (``attempt`` 0 where found)."""
    T = frames.shape[0]
    out = _empty(T)
    have = boxes[:, 4] > 0
    if not bool(have.any()):
        return out
    larger = torch.maximum(boxes[have, 2] - boxes[have, 0], boxes[have, 3] - boxes[have, 1])
    side = max(float(larger.median()), 1.0) * (1 + 2 * margin)
    for first, last in frame_runs(torch.nonzero(have).flatten().tolist()):
        with make_pose() as pose:
            for t in range(first, last + 1):
                frame = np.ascontiguousarray(frames[t].permute(1, 2, 0).numpy())
                cx, cy = float(boxes[t, 0] + boxes[t, 2]) / 2, float(boxes[t, 1] + boxes[t, 3]) / 2
                start = time.perf_counter()
                result = _process(pose, _square_crop(frame, cx, cy, side, side_px))
                out["seconds"][t] = time.perf_counter() - start
                if result is not None:
                    _store(out, t, result, cx, cy, side, side_px)
                    out["attempt"][t] = 0
    return out
