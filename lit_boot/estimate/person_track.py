"""One person followed over a video's detections, for single-person scenes.

:func:`main_person_boxes` starts from the most prominent detection of the whole video (the largest
area x score) and follows it forwards and backwards, frame by frame: in each frame the detection
that overlaps the last box most is taken, else the nearest one whose centre moved at most
``max_jump`` box sizes per frame since (the rule of :mod:`.tracking`); nothing else. Gaps of at
most ``max_gap`` frames between two found frames are bridged by linear interpolation of the box;
longer gaps, and the frames before the first and after the last found frame, have nobody.
Boxes are x0, y0, x1, y1 px with pixel centres at integer coordinates (:mod:`.detector`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import torch

from .track_cost import iou_matrix

__all__ = ["main_person_boxes", "person_boxes", "check_detections"]

log = logging.getLogger(__name__)


def _next_box(last: torch.Tensor, candidates: torch.Tensor, frames: int, max_jump: float) -> int | None:
    """The index of the candidate (N, 4) that continues ``last`` (4,) after ``frames`` frames: the
    most overlapping, else the nearest centre within ``max_jump`` x its larger side x ``frames``."""
    if candidates.shape[0] == 0:
        return None
    overlap = iou_matrix(last[None], candidates)[0]
    if overlap.max() > 0:
        return int(overlap.argmax())
    centre = (last[:2] + last[2:]) / 2
    dist = ((candidates[:, :2] + candidates[:, 2:]) / 2 - centre).norm(dim=1)
    size = (last[2:] - last[:2]).max().clamp_min(1.0)
    best = int(dist.argmin())
    return best if dist[best] <= max_jump * size * frames else None


def _follow(detections: Sequence[torch.Tensor], start: int, box: torch.Tensor, order: range, boxes: torch.Tensor,
            found: torch.Tensor, max_jump: float) -> None:  # fmt: skip
    """Follow ``box`` (found in frame ``start``) through the frames of ``order``, filling ``boxes``
    and ``found`` in place."""
    last, last_t = box, start
    for t in order:
        pick = _next_box(last, detections[t][:, :4], abs(t - last_t), max_jump)
        if pick is not None:
            last, last_t = detections[t][pick, :4], t
            boxes[t], found[t] = last, True


def _bridge(boxes: torch.Tensor, found: torch.Tensor, max_gap: int) -> int:
    """Fill gaps of at most ``max_gap`` frames between found frames by linear interpolation, in
    place; returns how many frames were filled."""
    seen = torch.nonzero(found).flatten().tolist()
    filled = 0
    for a, b in zip(seen, seen[1:]):
        if 1 < b - a <= max_gap + 1:
            for t in range(a + 1, b):
                w = (t - a) / (b - a)
                boxes[t], found[t] = (1 - w) * boxes[a] + w * boxes[b], True
                filled += 1
    return filled


def check_detections(detections: Sequence[torch.Tensor]) -> list[torch.Tensor]:
    """The per-frame detections (T tensors (N_t, 5)) as float32 CPU tensors; ValueError naming
    the frame for one of another shape."""
    for t, d in enumerate(detections):
        if not isinstance(d, torch.Tensor) or d.ndim != 2 or d.shape[1] != 5:
            got = tuple(d.shape) if isinstance(d, torch.Tensor) else type(d).__name__
            raise ValueError(f"detections[{t}]: expected a tensor of shape (N, 5) (x0, y0, x1, y1, score), got {got}")
    return [d.detach().float().cpu() for d in detections]


def frame_detections(detector: Any, frames: torch.Tensor) -> list[torch.Tensor]:
    """``detector.detect_frames(frames)`` (a :class:`~.detector.PersonBoxDetector`) checked: one
    (N_t, 5) float32 CPU tensor per frame (an empty frame's may be any empty array); ValueError
    naming the detector and the frame where that is not what it gave."""
    from .detector import detector_name

    name, found = detector_name(detector), list(detector.detect_frames(frames))
    if len(found) != frames.shape[0]:
        raise ValueError(f"detector {name}: expected boxes for each of the {frames.shape[0]} frames, got {len(found)}")
    boxes = []
    for t, d in enumerate(found):
        try:
            d = torch.as_tensor(d, dtype=torch.float32)
        except (TypeError, ValueError, RuntimeError) as err:
            raise ValueError(f"detector {name}: detections[{t}]: expected (N, 5) boxes (x0, y0, x1, y1, score), "
                             f"got {type(d).__name__}: {err}") from None  # fmt: skip
        boxes.append(d.reshape(0, 5) if d.numel() == 0 else d)
    try:
        return check_detections(boxes)
    except ValueError as err:
        raise ValueError(f"detector {name}: {err}") from None


def main_person_boxes(
    detections: Sequence[torch.Tensor], *, max_gap: int = 3, max_jump: float = 0.5
) -> tuple[torch.Tensor, torch.Tensor]:
    """The box of one person in each frame, from per-frame detections (T tensors (N_t, 5): x0,
    y0, x1, y1 px, score, as :meth:`PersonDetector.detect_frames` gives them).

    Args:
        detections: the detections of each frame; a frame may have none (0, 5).
        max_gap: the longest run of frames without the person that is bridged (interpolated).
        max_jump: how far a box centre may move per frame when it does not overlap the last
            box, in units of the last box's larger side.

    Returns:
        boxes (T, 4) float32 px (zeros where nobody), found (T,) bool (True where the person was
        detected or bridged). See the module docstring for the rule.
    """
    if max_gap < 0:
        raise ValueError(f"max_gap: expected a number of frames >= 0, got {max_gap!r}")
    if max_jump <= 0:
        raise ValueError(f"max_jump: expected a positive number of box sizes, got {max_jump!r}")
    detections = check_detections(detections)
    T = len(detections)
    boxes, found = torch.zeros(T, 4), torch.zeros(T, dtype=torch.bool)
    prominence = [(d[:, 2:4] - d[:, :2]).clamp_min(0).prod(1) * d[:, 4] for d in detections]
    best = [(float(p.max()), t, int(p.argmax())) for t, p in enumerate(prominence) if p.numel()]
    if not best:
        return boxes, found
    _, start, index = max(best)
    boxes[start], found[start] = detections[start][index, :4], True
    _follow(detections, start, boxes[start], range(start + 1, T), boxes, found, max_jump)
    _follow(detections, start, boxes[start], range(start - 1, -1, -1), boxes, found, max_jump)
    bridged = _bridge(boxes, found, max_gap)
    log.debug("main person: found in %d of %d frames (%d bridged), started at frame %d",
              int(found.sum()), T, bridged, start)  # fmt: skip
    return boxes, found


def person_boxes(frames: torch.Tensor, detector: Any) -> torch.Tensor:
    """The main person's box in every frame (T, 3, H, W) uint8 RGB: (T, 5) (x0, y0, x1, y1 px,
    score: 1 where found or bridged, 0 and zeros where nobody). ``detector``: any
    :class:`~.detector.PersonBoxDetector` (:class:`~.detector.PersonDetector`, or another with
    ``detect_frames``), or a YOLOX model (a path or a name such as ``"yolox_nano"``, looked up like
    RAFT's weights) to build one with."""
    from .detector import as_detector

    detector = as_detector(detector)
    boxes, found = main_person_boxes(frame_detections(detector, frames))
    return torch.cat([boxes.float() * found[:, None], found[:, None].float()], dim=1)
