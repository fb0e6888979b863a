"""Every person followed over a video's detections: tracks whose ids hold through crossings.

:func:`track_people` links each frame's detections to the open tracks by an optimal assignment
(scipy's ``linear_sum_assignment``) on a cost from each track's *predicted* box: its last box
moved on by the track's velocity (px per frame, a running mean of its centre's motion, each
frame weighing ``smoothing``), so that
two people who cross keep their ids. The cost of a detection for a track is ``1 - IoU`` with the
predicted box when they overlap by at least ``min_iou``, else ``1 + d / reach`` when the centres
are ``d`` px apart within ``reach`` = ``max_jump`` x the box's larger side x the frames since it
was last seen; a detection further away, or more than ``max_scale`` times larger or smaller
(larger side), is not that track's. Leaving a track or a detection unmatched costs
:data:`MISS_COST` each, so a good match is never traded for two poor ones. A track not seen for more than ``max_gap`` frames ends; an
unmatched detection starts a new track. Tracks seen in fewer than ``min_frames`` frames (capped
at T) are dropped (a stray detection), gaps of at most ``max_gap`` frames are bridged by linear
interpolation of the box and score, and the tracks are ordered by prominence (the sum over
frames of box area x score): person 0 is the most prominent. Boxes are x0, y0, x1, y1 px with
pixel centres at integer coordinates (:mod:`.detector`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from .person_track import check_detections

__all__ = ["track_people", "select_people", "people_count", "PEOPLE_CHOICES", "parse_people"]

log = logging.getLogger(__name__)

#: The cost of leaving a track or a detection unmatched in a frame (pair costs lie in [0, 2]).
MISS_COST = 1.0
#: The weight of a frame's own motion in a track's velocity (BENCHMARKS.md, "The tracker on
#: synthetic crossings").
SMOOTHING = 0.1
#: The named choices of ``people`` (or a number N >= 1: the N most prominent).
PEOPLE_CHOICES = ("all", "largest")


@dataclass
class _Track:
    boxes: dict[int, torch.Tensor] = field(default_factory=dict)  # frame -> (5,) box and score
    velocity: torch.Tensor = field(default_factory=lambda: torch.zeros(2))
    last: int = -1

    def predicted(self, t: int) -> torch.Tensor:
        box = self.boxes[self.last][:4]
        return box + (self.velocity * (t - self.last)).repeat(2)

    def add(self, t: int, det: torch.Tensor, smoothing: float = SMOOTHING) -> None:
        if self.boxes:
            step = (_centre(det[:4]) - _centre(self.boxes[self.last][:4])) / (t - self.last)
            self.velocity = step if len(self.boxes) == 1 else (1 - smoothing) * self.velocity + smoothing * step
        self.boxes[t], self.last = det.clone(), t


def _centre(box: torch.Tensor) -> torch.Tensor:
    return (box[..., :2] + box[..., 2:4]) / 2


def _side(box: torch.Tensor) -> torch.Tensor:
    return (box[..., 2:4] - box[..., :2]).amax(-1).clamp_min(1.0)


def _iou_matrix(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """IoU (N, M) of boxes a (N, 4) and b (M, 4)."""
    lo = torch.maximum(a[:, None, :2], b[None, :, :2])
    hi = torch.minimum(a[:, None, 2:4], b[None, :, 2:4])
    inter = (hi - lo).clamp_min(0).prod(-1)
    area = lambda x: (x[:, 2:4] - x[:, :2]).clamp_min(0).prod(-1)  # noqa: E731
    return inter / (area(a)[:, None] + area(b)[None, :] - inter).clamp_min(1e-9)


def _costs(tracks: list[_Track], t: int, dets: torch.Tensor, min_iou: float, max_jump: float,
           max_scale: float) -> torch.Tensor:  # fmt: skip
    """(N_tracks, N_dets) assignment costs; inf where a detection cannot be the track's."""
    pred = torch.stack([tr.predicted(t) for tr in tracks])
    gap = torch.tensor([float(t - tr.last) for tr in tracks])
    iou = _iou_matrix(pred, dets[:, :4])
    dist = (_centre(pred)[:, None] - _centre(dets[:, :4])[None]).norm(dim=-1)
    reach = max_jump * _side(pred)[:, None] * gap[:, None]
    cost = torch.where(iou >= min_iou, 1 - iou, 1 + dist / reach)
    ratio = _side(pred)[:, None] / _side(dets[:, :4])[None]
    far = (iou < min_iou) & (dist > reach)
    return cost.masked_fill(far | (ratio > max_scale) | (ratio < 1 / max_scale), math.inf)


def _assign(cost: torch.Tensor, miss: float = MISS_COST) -> list[tuple[int, int]]:
    """The optimal (track, detection) pairs of finite cost, where leaving a track or a detection
    unmatched costs ``miss`` each (so a pair is matched only where that is cheaper than leaving
    both alone, and a good match is not traded for two poor ones)."""
    from scipy.optimize import linear_sum_assignment

    N, M = cost.shape
    if N == 0 or M == 0:
        return []
    never = 1e6
    full = torch.full((N + M, M + N), never, dtype=torch.float64)
    full[:N, :M] = torch.where(torch.isfinite(cost), cost.double(), torch.full_like(cost.double(), never))
    full[:N, M:] = torch.where(torch.eye(N, dtype=torch.bool), miss, never)  # a track left unmatched
    full[N:, :M] = torch.where(torch.eye(M, dtype=torch.bool), miss, never)  # a detection left unmatched
    full[N:, M:] = 0.0
    rows, cols = linear_sum_assignment(full.numpy())
    return [(int(r), int(c)) for r, c in zip(rows, cols) if r < N and c < M and full[r, c] < never]


def _link(detections: Sequence[torch.Tensor], max_gap: int, min_iou: float, max_jump: float,
          max_scale: float, smoothing: float) -> list[_Track]:  # fmt: skip
    tracks: list[_Track] = []
    for t, dets in enumerate(detections):
        open_ = [tr for tr in tracks if t - tr.last <= max_gap + 1]
        matched: set[int] = set()
        if open_ and dets.shape[0]:
            for r, c in _assign(_costs(open_, t, dets, min_iou, max_jump, max_scale)):
                open_[r].add(t, dets[c], smoothing)
                matched.add(c)
        for c in range(dets.shape[0]):
            if c not in matched:
                tracks.append(_Track())
                tracks[-1].add(t, dets[c])
    return tracks


def _dense(track: _Track, T: int, max_gap: int) -> torch.Tensor:
    """(T, 5) boxes and scores of a track, gaps of at most ``max_gap`` frames interpolated."""
    out = torch.zeros(T, 5)
    seen = sorted(track.boxes)
    for t in seen:
        out[t] = track.boxes[t]
    for a, b in zip(seen, seen[1:]):
        if 1 < b - a <= max_gap + 1:
            for t in range(a + 1, b):
                w = (t - a) / (b - a)
                out[t] = (1 - w) * out[a] + w * out[b]
    return out


def track_people(
    detections: Sequence[torch.Tensor],
    *,
    max_gap: int = 3,
    max_jump: float = 0.5,
    min_iou: float = 0.1,
    max_scale: float = 2.5,
    min_frames: int = 2,
    smoothing: float = SMOOTHING,
) -> torch.Tensor:
    """Every person's box in each frame, from per-frame detections (T tensors (N_t, 5): x0, y0,
    x1, y1 px, score, as :meth:`PersonDetector.detect_frames` gives them).

    Args:
        detections: the detections of each frame; a frame may have none (0, 5).
        max_gap: the longest run of frames a track may miss and go on (bridged by interpolation).
        max_jump: how far a box centre may move per frame without overlapping the predicted
            box, in units of the box's larger side.
        min_iou: the overlap with the predicted box that counts as overlapping.
        max_scale: the largest ratio of box sizes (larger sides) one track accepts.
        min_frames: tracks detected in fewer frames (capped at T) are dropped.
        smoothing: the weight of a frame's own motion in the track's velocity (a running mean;
            lower: a longer memory, which carries a track through a crossing).

    Returns:
        (P, T, 5) float32: each track's box and score per frame (zeros where the person is
        absent), most prominent first (see the module docstring); P may be 0.
    """
    if isinstance(max_gap, bool) or not isinstance(max_gap, int) or max_gap < 0:
        raise ValueError(f"max_gap: expected a number of frames >= 0, got {max_gap!r}")
    for name, value in (("max_jump", max_jump), ("max_scale", max_scale)):
        if not value > 0:
            raise ValueError(f"{name}: expected a positive number, got {value!r}")
    if not 0 < min_iou <= 1:
        raise ValueError(f"min_iou: expected a number in (0, 1], got {min_iou!r}")
    if not 0 < smoothing <= 1:
        raise ValueError(f"smoothing: expected a number in (0, 1], got {smoothing!r}")
    if isinstance(min_frames, bool) or not isinstance(min_frames, int) or min_frames < 1:
        raise ValueError(f"min_frames: expected a number of frames >= 1, got {min_frames!r}")
    detections = check_detections(detections)
    T = len(detections)
    tracks = [tr for tr in _link(detections, max_gap, min_iou, max_jump, max_scale, smoothing)
              if len(tr.boxes) >= min(min_frames, T)]  # fmt: skip
    if not tracks:
        return torch.zeros(0, T, 5)
    boxes = torch.stack([_dense(tr, T, max_gap) for tr in tracks])
    prominence = ((boxes[..., 2:4] - boxes[..., :2]).clamp_min(0).prod(-1) * boxes[..., 4]).sum(1)
    boxes = boxes[prominence.argsort(descending=True, stable=True)]
    log.debug("people: %d tracks over %d frames (%d detections)", len(boxes), T, sum(len(d) for d in detections))
    return boxes


def parse_people(people: str | int) -> str | int:
    """``people`` checked: "all", "largest", or a number N >= 1 (an int or its digits)."""
    if isinstance(people, str) and people.strip().isdigit():
        people = int(people)
    if isinstance(people, bool) or not (people in PEOPLE_CHOICES or (isinstance(people, int) and people >= 1)):
        raise ValueError(f"people: expected 'all', 'largest' or a number of people >= 1, got {people!r}")
    return people


def people_count(people: str | int, available: int) -> int:
    """How many of ``available`` people, most prominent first, ``people`` asks for: all of them,
    the largest (the most prominent) one, or the N most prominent."""
    people = parse_people(people)
    return available if people == "all" else min(available, 1 if people == "largest" else people)


def select_people(tracks: torch.Tensor, people: str | int) -> torch.Tensor:
    """The tracks (P, T, 5), most prominent first, that ``people`` asks for (:func:`people_count`)."""
    return tracks[: people_count(people, tracks.shape[0])]
