"""Every person followed over a video's detections: tracks whose ids hold through crossings.

:func:`track_people` links each frame's detections to the open tracks by an optimal assignment
(scipy's ``linear_sum_assignment``) on a cost from each track's *predicted* box: its last box moved
on by the track's velocity (px per frame, a running mean of its centre's motion, each frame
weighing ``smoothing``), so that two people who cross keep their ids. The cost of a detection for
a track is ``1 - IoU`` with the predicted box when they overlap by at least ``min_iou``, else
``1 + d / reach`` when the centres are ``d`` px apart within ``reach`` = ``max_jump`` x the box's larger
side x the frames since it was last seen; a detection further away, or more than ``max_scale``
times larger or smaller (larger side), is not that track's. Where the detections come with
keypoints (each one's pose), ``keypoint_weight`` x a pose distance is added: the median distance
of the shared confident joints from the track's last keypoints moved on by its velocity, in box
sides per frame since those keypoints were seen, plus :data:`KEYPOINT_SHAPE_WEIGHT` x how much
farther the pose's shape (the shared joints about their mean) is from the track's than from the
best-shaped track's for the same detection, at most 1 in all; and :data:`KEYPOINT_GAP_COST` per
frame the track has gone unseen beyond the last (a track seen a frame ago goes first):
where one person's box lies inside another's during a crossing, the joints still say who is who;
and the track's velocity comes from its joints' median motion where it shares enough of them with
the last frame (an occluder moves a box's centre, not the person).
Leaving a track or a detection unmatched costs :data:`MISS_COST` each, so a good match is never
traded for two poor ones. A track not seen for more than ``max_gap`` frames ends; an unmatched
detection starts a new track. Then a track that starts just after another ends continues it
where their motions meet within ``max_jump`` per frame (``stitch``: an occluded person's box
shrinks or jumps, and the frame-by-frame link refuses it). Tracks seen in fewer than
``min_frames`` frames (capped at T) are dropped (a stray detection), gaps of at most ``max_gap`` frames are bridged by linear interpolation
of the box and score, and the tracks are ordered by prominence (the sum over frames of box area x
score): person 0 is the most prominent. Boxes are x0, y0, x1, y1 px with
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
#: The weight of the keypoint distance (in box sides, at most 1) in a pair's cost, where the
#: detections come with keypoints (BENCHMARKS.md, "The tracker on synthetic crossings").
KEYPOINT_WEIGHT = 4.0
#: The confidence above which a joint counts in the keypoint distance (and the joints' motion),
#: and how many joints a track and a detection must share for it to count.
KEYPOINT_CONF = 0.3
KEYPOINT_MIN_JOINTS = 4
#: A track's velocity from its joints' median motion where they are shared (else the box centre's).
JOINT_VELOCITY = True
#: The keypoint distance per frame since the track's keypoints were seen (a pose unseen for a while
#: predicts loosely; BENCHMARKS.md, "Keypoints in the tracker").
KEYPOINT_PER_FRAME = True
#: Where the detections come with keypoints: the cost per frame a track has gone unseen beyond the
#: last. A track seen a frame ago predicts better than one unseen for longer, whose keypoint
#: distance (per frame since seen) is also cheap (BENCHMARKS.md, "Keypoints in the tracker").
KEYPOINT_GAP_COST = 0.3
#: Where the detections come with keypoints: the weight of a pair's pose-shape distance (box
#: sides) beyond the best-shaped track's for the same detection, added to the keypoint distance
#: (BENCHMARKS.md, "The pose's shape in the tracker").
KEYPOINT_SHAPE_WEIGHT = 1.0


@dataclass
class _Track:
    boxes: dict[int, torch.Tensor] = field(default_factory=dict)  # frame -> (5,) box and score
    velocity: torch.Tensor = field(default_factory=lambda: torch.zeros(2))
    last: int = -1
    keypoints: torch.Tensor | None = None  # (K, 3) x, y px, confidence: the latest frame's that had any
    keypoint_frame: int = -1

    def predicted(self, t: int) -> torch.Tensor:
        box = self.boxes[self.last][:4]
        return box + (self.velocity * (t - self.last)).repeat(2)

    def predicted_keypoints(self, t: int) -> torch.Tensor | None:
        if self.keypoints is None:
            return None
        return self.keypoints + torch.cat([self.velocity * (t - self.keypoint_frame), torch.zeros(1)])

    def _joint_step(self, t: int, keypoints: torch.Tensor | None) -> torch.Tensor | None:
        """The median motion (2,) px per frame of the joints confident in both the track's last
        keypoints and ``keypoints`` (K, 3), None with fewer than KEYPOINT_MIN_JOINTS (a box's
        centre moves where an occluder hides part of the person; the joints do not)."""
        if not JOINT_VELOCITY or keypoints is None or self.keypoints is None or keypoints.shape != self.keypoints.shape:
            return None
        shared = (keypoints[:, 2] > KEYPOINT_CONF) & (self.keypoints[:, 2] > KEYPOINT_CONF)
        if int(shared.sum()) < KEYPOINT_MIN_JOINTS:
            return None
        return (keypoints[shared, :2] - self.keypoints[shared, :2]).median(0).values / (t - self.keypoint_frame)

    def add(self, t: int, det: torch.Tensor, smoothing: float = SMOOTHING,
            keypoints: torch.Tensor | None = None) -> None:  # fmt: skip
        if self.boxes:
            step = self._joint_step(t, keypoints)
            if step is None:
                step = (_centre(det[:4]) - _centre(self.boxes[self.last][:4])) / (t - self.last)
            self.velocity = step if len(self.boxes) == 1 else (1 - smoothing) * self.velocity + smoothing * step
        self.boxes[t], self.last = det.clone(), t
        if keypoints is not None and bool((keypoints[:, 2] > 0).any()):
            self.keypoints, self.keypoint_frame = keypoints.clone(), t


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


def _keypoint_distance(tracks: list[_Track], t: int, keypoints: torch.Tensor,
                       side: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """Two (N_tracks, N_dets) distances between each track's predicted keypoints and each
    detection's ``keypoints`` (N_dets, K, 3), over the joints confident (> :data:`KEYPOINT_CONF`)
    in both, in units of the predicted box's larger side ``side`` (N_tracks,); NaN where fewer than
    :data:`KEYPOINT_MIN_JOINTS` joints are shared (or a track has no keypoints yet):

    - where: the median distance of the joints, per frame since the track's keypoints were seen
      (a pose unseen for a while is a looser prediction);
    - shape: the median distance of the joints once each pose's shared joints are centred on
      their mean (the pose's layout, wherever it is: where two people overlap, their joints'
      places coincide, their layouts do not)."""
    K = keypoints.shape[1]
    pred = torch.stack([p if (p := tr.predicted_keypoints(t)) is not None and p.shape[0] == K
                        else torch.zeros(K, 3) for tr in tracks])  # fmt: skip
    shared = (pred[:, None, :, 2] > KEYPOINT_CONF) & (keypoints[None, :, :, 2] > KEYPOINT_CONF)
    offset = pred[:, None, :, :2] - keypoints[None, :, :, :2]  # (N_tracks, N_dets, K, 2)
    weight = shared[..., None].float()
    centred = offset - (offset * weight).sum(-2, keepdim=True) / weight.sum(-2, keepdim=True).clamp_min(1.0)
    few = shared.sum(-1) < KEYPOINT_MIN_JOINTS
    where, shape = ((d.norm(dim=-1) / side[:, None, None]).masked_fill(~shared, math.nan).nanmedian(dim=-1).values
                    for d in (offset, centred))  # fmt: skip
    if KEYPOINT_PER_FRAME:
        age = torch.tensor([float(t - tr.keypoint_frame) if tr.keypoints is not None else 1.0 for tr in tracks])
        where = where / age[:, None].clamp_min(1.0)
    return where.masked_fill(few, math.nan), shape.masked_fill(few, math.nan)


def _costs(tracks: list[_Track], t: int, dets: torch.Tensor, min_iou: float, max_jump: float,
           max_scale: float, keypoints: torch.Tensor | None = None,
           keypoint_weight: float = KEYPOINT_WEIGHT) -> torch.Tensor:  # fmt: skip
    """(N_tracks, N_dets) assignment costs; inf where a detection cannot be the track's."""
    pred = torch.stack([tr.predicted(t) for tr in tracks])
    gap = torch.tensor([float(t - tr.last) for tr in tracks])
    iou = _iou_matrix(pred, dets[:, :4])
    dist = (_centre(pred)[:, None] - _centre(dets[:, :4])[None]).norm(dim=-1)
    reach = max_jump * _side(pred)[:, None] * gap[:, None]
    cost = torch.where(iou >= min_iou, 1 - iou, 1 + dist / reach)
    ratio = _side(pred)[:, None] / _side(dets[:, :4])[None]
    far = (iou < min_iou) & (dist > reach)
    if keypoints is not None and keypoint_weight > 0:
        where, shape = _keypoint_distance(tracks, t, keypoints, _side(pred))
        # the shape against the best-shaped track's for the same detection: it ranks the tracks,
        # and a pair whose shape cannot be measured is neither favoured nor penalised by it
        best = torch.nan_to_num(shape, nan=math.inf).amin(0, keepdim=True)
        pose = where + KEYPOINT_SHAPE_WEIGHT * (shape - best)
        cost = cost + keypoint_weight * torch.nan_to_num(pose.clamp_max(1.0), nan=0.0)
        cost = cost + KEYPOINT_GAP_COST * (gap[:, None] - 1)
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


def _link(detections: Sequence[torch.Tensor], keypoints: Sequence[torch.Tensor] | None, max_gap: int,
          min_iou: float, max_jump: float, max_scale: float, smoothing: float,
          keypoint_weight: float) -> list[_Track]:  # fmt: skip
    tracks: list[_Track] = []
    for t, dets in enumerate(detections):
        kps = None if keypoints is None else keypoints[t]
        open_ = [tr for tr in tracks if t - tr.last <= max_gap + 1]
        matched: set[int] = set()
        if open_ and dets.shape[0]:
            cost = _costs(open_, t, dets, min_iou, max_jump, max_scale, kps, keypoint_weight)
            for r, c in _assign(cost):
                open_[r].add(t, dets[c], smoothing, None if kps is None else kps[c])
                matched.add(c)
        for c in range(dets.shape[0]):
            if c not in matched:
                tracks.append(_Track())
                tracks[-1].add(t, dets[c], keypoints=None if kps is None else kps[c])
    return tracks


def _median_side(track: _Track) -> float:
    return float(_side(torch.stack([b[:4] for b in track.boxes.values()])).median())


def _end_velocity(a: _Track, b: _Track) -> torch.Tensor:
    """The velocity of tracklet ``b`` continuing ``a``: b's own, or a's where b has one box (no motion yet)."""
    return b.velocity if len(b.boxes) > 1 else a.velocity


def _stitch_cost(a: _Track, b: _Track, max_scale: float) -> float:
    """How far tracklet ``b`` (starting after ``a`` ends) is from continuing ``a``: the distance
    between a's box centre moved on by its velocity to b's first frame and b's first centre, and
    between b's first centre moved back by b's velocity to a's last frame and a's last centre, the
    larger, in median box sides (the larger of the two tracklets'); inf where their median sizes
    differ by more than ``max_scale`` (an occluded person's box shrinks for a frame or two, so the
    sizes of whole tracklets are compared, not of single boxes)."""
    first = min(b.boxes)
    side_a, side_b = _median_side(a), _median_side(b)
    if max(side_a, side_b) / min(side_a, side_b) > max_scale:
        return math.inf
    gap = first - a.last
    forward = _centre(a.boxes[a.last][:4]) + a.velocity * gap - _centre(b.boxes[first][:4])
    backward = _centre(b.boxes[first][:4]) - _end_velocity(a, b) * gap - _centre(a.boxes[a.last][:4])
    return float(torch.maximum(forward.norm(), backward.norm())) / max(side_a, side_b)


def _stitch(tracks: list[_Track], max_gap: int, max_scale: float, max_jump: float) -> list[_Track]:
    """Tracklets joined where one starts within ``max_gap`` + 1 frames after another ended and
    their motions meet within the link's own reach, ``max_jump`` box sides per frame of the gap
    (:func:`_stitch_cost`), the closest pairs first (an optimal assignment per pass): the
    frame-by-frame link refuses such a pair where an occluded person's box shrinks to its
    visible part or jumps, comparing single boxes."""
    while True:
        cost = torch.full((len(tracks), len(tracks)), math.inf)
        for i, a in enumerate(tracks):
            for j, b in enumerate(tracks):
                if 0 < (gap := min(b.boxes) - a.last) <= max_gap + 1:
                    cost[i, j] = _stitch_cost(a, b, max_scale) / gap
        pairs = _assign(cost.masked_fill(cost >= max_jump, math.inf), miss=max_jump)
        if not pairs:
            return tracks
        for i, j in pairs:  # a and b distinct: b starts after a ends
            a, b = tracks[i], tracks[j]
            a.boxes.update(b.boxes)
            a.last, a.velocity = b.last, _end_velocity(a, b)
            if b.keypoints is not None:
                a.keypoints, a.keypoint_frame = b.keypoints, b.keypoint_frame
            b.boxes = {}
        tracks = [tr for tr in tracks if tr.boxes]


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
    keypoints: Sequence[torch.Tensor] | None = None,
    keypoint_weight: float = KEYPOINT_WEIGHT,
    stitch: bool = True,
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
        keypoints: optional, each detection's pose: T tensors (N_t, K, 3) x, y px, confidence
            (0: not found), one row per detection of that frame. Where a track and a detection
            share at least :data:`KEYPOINT_MIN_JOINTS` confident joints, the median distance
            between the track's keypoints (moved on by its velocity) and the detection's, in box
            sides per frame since the track's keypoints were seen (at most 1), x
            ``keypoint_weight`` is added to the pair's cost (and :data:`KEYPOINT_GAP_COST` per
            frame the track has gone unseen beyond the last), with the pose's shape (the shared
            joints about their mean) beyond the best-shaped track's for the detection in the
            same term: who is who where two boxes overlap, and where two people's joints
            coincide, which layout is whose; the track's velocity is its shared joints' median
            motion.
        keypoint_weight: see ``keypoints``; 0 ignores them.
        stitch: after linking, a tracklet that starts within ``max_gap`` + 1 frames after another
            ended continues it where the first one's box centre moved on by its velocity and the
            second one's moved back by its own each come within ``max_jump`` box sides per frame
            of the gap of the other's (each tracklet's median larger side, the larger of the two;
            their median sizes within ``max_scale``), the closest pairs first: the frame-by-frame
            link refuses such a pair where an occluded person's box shrinks to its visible part
            or jumps (BENCHMARKS.md, "Stitching tracklets").

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
    if not keypoint_weight >= 0:
        raise ValueError(f"keypoint_weight: expected a number >= 0, got {keypoint_weight!r}")
    detections = check_detections(detections)
    keypoints = None if keypoints is None or keypoint_weight == 0 else _check_keypoints(keypoints, detections)
    T = len(detections)
    linked = _link(detections, keypoints, max_gap, min_iou, max_jump, max_scale, smoothing, keypoint_weight)
    if stitch:
        linked = _stitch(linked, max_gap, max_scale, max_jump)
    tracks = [tr for tr in linked if len(tr.boxes) >= min(min_frames, T)]
    if not tracks:
        return torch.zeros(0, T, 5)
    boxes = torch.stack([_dense(tr, T, max_gap) for tr in tracks])
    prominence = ((boxes[..., 2:4] - boxes[..., :2]).clamp_min(0).prod(-1) * boxes[..., 4]).sum(1)
    boxes = boxes[prominence.argsort(descending=True, stable=True)]
    log.debug("people: %d tracks over %d frames (%d detections)", len(boxes), T, sum(len(d) for d in detections))
    return boxes


def _check_keypoints(keypoints: Sequence[torch.Tensor], detections: list[torch.Tensor]) -> list[torch.Tensor]:
    """The per-detection keypoints as float32 CPU tensors; ValueError naming the frame where they
    do not match the detections (N_t, K, 3), or where K differs between frames."""
    if len(keypoints) != len(detections):
        raise ValueError(f"keypoints: expected one tensor per frame ({len(detections)}), got {len(keypoints)}")
    out, K = [], None
    for t, (kp, det) in enumerate(zip(keypoints, detections)):
        kp = torch.as_tensor(kp, dtype=torch.float32).cpu()
        other_k = K is not None and kp.ndim == 3 and kp.shape[0] > 0 and kp.shape[1] != K
        if kp.ndim != 3 or kp.shape[0] != det.shape[0] or kp.shape[2] != 3 or other_k:
            raise ValueError(f"keypoints[{t}]: expected ({det.shape[0]}, {K or 'K'}, 3) x, y, confidence per "
                             f"detection, got {tuple(kp.shape)}")  # fmt: skip
        K = kp.shape[1] if kp.shape[0] else K
        out.append(kp)
    return out


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
