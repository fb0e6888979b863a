"""A detection's look: the colours near its confident joints, to tell people apart after a long gap.

A person's look in a frame is a colour histogram (:data:`LOOK_BINS` per RGB channel, ``LOOK_BINS**3``
bins summing to 1) of the pixels within :data:`LOOK_RADIUS` x the box's larger side of its confident
joints (> :data:`.track_cost.KEYPOINT_CONF`): the person's own clothes, also where the detector's box
holds two people (the pose is one person's), not the box's middle. A detection with fewer than
:data:`.track_cost.KEYPOINT_MIN_JOINTS` confident joints has no look (zeros). Two looks are compared
by their Hellinger distance: 0 the same colours, 1 none shared (BENCHMARKS.md, "Found again after a
long gap").
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from .track_cost import KEYPOINT_CONF, KEYPOINT_MIN_JOINTS, box_side

__all__ = ["LOOK_BINS", "LOOK_RADIUS", "joint_look", "detection_looks", "look_distance", "check_rgb_frames"]

#: Bins per RGB channel of a look's histogram.
LOOK_BINS = 4
#: The radius about each confident joint whose pixels make the look, in box sides (at least 1 px).
LOOK_RADIUS = 0.04


def joint_look(frame: torch.Tensor, keypoints: torch.Tensor, side: float) -> torch.Tensor:
    """The look (LOOK_BINS**3,) of one person in ``frame`` (3, H, W) uint8 RGB from its
    ``keypoints`` (K, 3) x, y px, confidence and its box's larger ``side`` px; zeros where fewer than
    KEYPOINT_MIN_JOINTS joints are confident or none of their pixels lies in the frame."""
    out = torch.zeros(LOOK_BINS**3)
    points = keypoints[keypoints[:, 2] > KEYPOINT_CONF, :2].float()
    if points.shape[0] < KEYPOINT_MIN_JOINTS:
        return out
    H, W = frame.shape[1:]
    r = max(1.0, LOOK_RADIUS * side)
    x0, y0 = (max(0, math.floor(float(points[:, i].min()) - r)) for i in (0, 1))
    x1, y1 = min(W, math.ceil(float(points[:, 0].max()) + r) + 1), min(H, math.ceil(float(points[:, 1].max()) + r) + 1)
    if x0 >= x1 or y0 >= y1:
        return out
    ys, xs = torch.meshgrid(torch.arange(y0, y1), torch.arange(x0, x1), indexing="ij")
    near = ((xs - points[:, 0, None, None]) ** 2 + (ys - points[:, 1, None, None]) ** 2 <= r * r).any(0)
    pixels = frame[:, y0:y1, x0:x1][:, near].long() * LOOK_BINS // 256  # (3, n) bin per channel
    if pixels.shape[1] == 0:
        return out
    counts = torch.bincount((pixels[0] * LOOK_BINS + pixels[1]) * LOOK_BINS + pixels[2], minlength=LOOK_BINS**3)
    return counts.float() / counts.sum()


def check_rgb_frames(frames: torch.Tensor) -> None:
    """Raise ValueError unless frames are (T, 3, H, W) uint8 RGB (colours in [0, 1] would all fall
    in one bin, and every look would match)."""
    if frames.dtype != torch.uint8 or frames.ndim != 4 or frames.shape[1] != 3:
        raise ValueError(f"frames: expected (T, 3, H, W) uint8 RGB, got {tuple(frames.shape)} {frames.dtype}")


def detection_looks(frames: torch.Tensor, detections: Sequence[torch.Tensor],
                    keypoints: Sequence[torch.Tensor]) -> list[torch.Tensor]:  # fmt: skip
    """Each detection's look: per frame (N_t, LOOK_BINS**3), from frames (T, 3, H, W) uint8 RGB,
    the detections (N_t, 5) x0, y0, x1, y1 px, score and their keypoints (N_t, K, 3)."""
    check_rgb_frames(frames)
    return [torch.stack([joint_look(frame, kp, float(box_side(box))) for box, kp in zip(dets, kps)])
            if dets.shape[0] else torch.zeros(0, LOOK_BINS**3)
            for frame, dets, kps in zip(frames, detections, keypoints)]  # fmt: skip


def look_distance(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """The Hellinger distance (...) between looks a and b (..., D), each summing to 1."""
    return (1 - (a.clamp_min(0) * b.clamp_min(0)).sqrt().sum(-1)).clamp_min(0).sqrt()
