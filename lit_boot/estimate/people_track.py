"""Every person followed over a video's detections: tracks whose ids hold through crossings.

:func:`track_people` gives each frame's detections to the tracks by the cost of
:mod:`.track_cost`: how far a detection is from each track's *predicted* box (its last box moved
on by its velocity, so that two people who cross keep their ids) and, where the detections come
with keypoints, from its predicted pose and the pose's shape (where one person's box lies inside
another's during a crossing, the joints still say who is who). The assignment is a beam search
over each frame's best assignments (:mod:`.track_search`): a frame's choice is judged by the
frames after it, so a track that took the wrong person where two overlap is given back its own
when the next frames show it. A track not seen for more than ``max_gap`` frames ends; an
unmatched detection starts a new track. Then a track that starts just after another ends
continues it where their motions meet within ``max_jump`` per frame (``stitch``: an occluded
person's box shrinks or jumps, and the link refuses it); with the detections' looks (the colours
near each pose's joints, :mod:`.looks`), a tracklet that starts any number of frames later
continues one whose look it shares (a person hidden for longer than ``max_gap``, found again).
Tracks seen in fewer than
``min_frames`` frames (capped at T) are dropped (a stray detection), gaps of at most ``max_gap``
frames are bridged by linear interpolation of the box and score, and the tracks are ordered by
prominence (the sum over frames of box area x score): person 0 is the most prominent. Boxes are
x0, y0, x1, y1 px with pixel centres at integer coordinates (:mod:`.detector`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import torch

from .looks import look_distance
from .person_track import check_detections
from .track_cost import KEYPOINT_WEIGHT, SMOOTHING, TrackState, box_centre, box_side
from .track_search import assign, link

__all__ = ["track_people", "select_people", "people_count", "PEOPLE_CHOICES", "parse_people", "BEAM"]

log = logging.getLogger(__name__)

#: The named choices of ``people`` (or a number N >= 1: the N most prominent).
PEOPLE_CHOICES = ("all", "largest")
#: The hypotheses the link keeps per frame (BENCHMARKS.md, "Tracking with hindsight").
BEAM = 16
#: The largest Hellinger distance between two tracklets' looks that joins them after a long gap
#: (BENCHMARKS.md, "Found again after a long gap").
MAX_LOOK = 0.4


@dataclass
class _Tracklet:
    """A linked track while stitching: its boxes (frame -> (5,) box and score), last frame, velocity,
    and its detections' looks (frame -> (D,), the frames whose detection has one)."""

    boxes: dict[int, torch.Tensor]
    last: int
    velocity: torch.Tensor
    looks: dict[int, torch.Tensor] = field(default_factory=dict)
    mean_look: torch.Tensor | None = field(default=None, repr=False)  # look()'s, until the tracklet is joined

    @classmethod
    def of(cls, state: TrackState, detections: list[torch.Tensor],
           looks: Sequence[torch.Tensor] | None) -> _Tracklet:  # fmt: skip
        boxes = state.boxes()
        return cls(boxes, state.last, state.velocity, {} if looks is None else _looks_of(boxes, detections, looks))

    def look(self) -> torch.Tensor | None:
        """The mean of its looks, None without any."""
        if self.mean_look is None and self.looks:
            self.mean_look = torch.stack(list(self.looks.values())).mean(0)
        return self.mean_look


def _looks_of(boxes: dict[int, torch.Tensor], detections: list[torch.Tensor],
              looks: Sequence[torch.Tensor]) -> dict[int, torch.Tensor]:  # fmt: skip
    """Frame -> the look of the detection each box is (the link keeps the detection's own row), where it has one."""
    out = {}
    for t, box in boxes.items():
        same = (detections[t] == box).all(-1).nonzero()
        if len(same) and float(looks[t][int(same[0])].sum()) > 0:
            out[t] = looks[t][int(same[0])]
    return out


def _median_side(track: _Tracklet) -> float:
    return float(box_side(torch.stack([b[:4] for b in track.boxes.values()])).median())


def _end_velocity(a: _Tracklet, b: _Tracklet) -> torch.Tensor:
    """The velocity of tracklet ``b`` continuing ``a``: b's own, or a's where b has one box (no motion yet)."""
    return b.velocity if len(b.boxes) > 1 else a.velocity


def _stitch_cost(a: _Tracklet, b: _Tracklet, max_scale: float) -> float:
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
    forward = box_centre(a.boxes[a.last][:4]) + a.velocity * gap - box_centre(b.boxes[first][:4])
    backward = box_centre(b.boxes[first][:4]) - _end_velocity(a, b) * gap - box_centre(a.boxes[a.last][:4])
    return float(torch.maximum(forward.norm(), backward.norm())) / max(side_a, side_b)


def _join(tracks: list[_Tracklet], cost_of: Callable[[_Tracklet, _Tracklet], float],
          limit: float) -> list[_Tracklet]:  # fmt: skip
    """Tracklets joined where ``cost_of(a, b)`` (b starting after a ends; inf: never) is below
    ``limit``, the cheapest pairs first (an optimal assignment per pass, passes until none is left)."""
    while True:
        cost = torch.full((len(tracks), len(tracks)), math.inf)
        for i, a in enumerate(tracks):
            for j, b in enumerate(tracks):
                if min(b.boxes) > a.last:
                    cost[i, j] = cost_of(a, b)
        pairs = assign(cost.masked_fill(cost >= limit, math.inf), miss=limit)
        if not pairs:
            return tracks
        for i, j in pairs:  # a and b distinct: b starts after a ends
            a, b = tracks[i], tracks[j]
            a.boxes.update(b.boxes)
            a.looks.update(b.looks)
            a.mean_look = None
            a.last, a.velocity = b.last, _end_velocity(a, b)
            b.boxes = {}
        tracks = [tr for tr in tracks if tr.boxes]


def _stitch(tracks: list[_Tracklet], max_gap: int, max_scale: float, max_jump: float) -> list[_Tracklet]:
    """Tracklets joined where one starts within ``max_gap`` + 1 frames after another ended and
    their motions meet within the link's own reach, ``max_jump`` box sides per frame of the gap
    (:func:`_stitch_cost`), the closest pairs first: the frame-by-frame link refuses such a pair
    where an occluded person's box shrinks to its visible part or jumps, comparing single boxes."""

    def cost_of(a: _Tracklet, b: _Tracklet) -> float:
        gap = min(b.boxes) - a.last
        return _stitch_cost(a, b, max_scale) / gap if gap <= max_gap + 1 else math.inf

    return _join(tracks, cost_of, max_jump)


def _reidentify(tracks: list[_Tracklet], max_scale: float, max_jump: float, max_look: float,
                min_frames: int) -> list[_Tracklet]:  # fmt: skip
    """Tracklets joined after a gap of any length where their looks (each one's mean) are within
    ``max_look`` of each other (:func:`.looks.look_distance`) and their motions meet within
    ``max_jump`` box sides per frame of the gap, the closest looks first: a person hidden for longer
    than the link and the stitch bridge, found again. Each must be seen in ``min_frames`` frames,
    a track of its own (a stray detection, a chair taken for a person, is not someone found again)."""

    def cost_of(a: _Tracklet, b: _Tracklet) -> float:
        look_a, look_b = a.look(), b.look()
        if look_a is None or look_b is None or min(len(a.boxes), len(b.boxes)) < min_frames:
            return math.inf
        if _stitch_cost(a, b, max_scale) / (min(b.boxes) - a.last) > max_jump:
            return math.inf
        return float(look_distance(look_a, look_b))

    return _join(tracks, cost_of, max_look)


def _dense(track: _Tracklet, T: int, max_gap: int) -> torch.Tensor:
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
    beam: int = BEAM,
    looks: Sequence[torch.Tensor] | None = None,
    max_look: float = MAX_LOOK,
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
            share at least :data:`.track_cost.KEYPOINT_MIN_JOINTS` confident joints, the median distance
            between the track's keypoints (moved on by its velocity) and the detection's, in box
            sides per frame since the track's keypoints were seen (at most 1), x
            ``keypoint_weight`` is added to the pair's cost (and :data:`.track_cost.KEYPOINT_GAP_COST` per
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
        beam: the hypotheses kept per frame: each is extended by the frame's few best
            assignments and the cheapest ``beam`` over the frames so far go on, so a frame's
            choice is judged by the frames after it (:mod:`.track_search`); 1: each frame's
            optimal assignment, decided there.
        looks: optional, each detection's look: T tensors (N_t, D), a colour histogram summing
            to 1 or zeros (none), one row per detection of that frame (:func:`.looks.detection_looks`).
            After the stitch, a tracklet that starts any number of frames after another ended
            continues it where their looks (each one's mean) are within ``max_look`` (Hellinger
            distance), their motions meet within ``max_jump`` box sides per frame of the gap and
            each is seen in ``min_frames`` frames, the closest looks first: a person hidden for
            longer than ``max_gap`` found again (BENCHMARKS.md, "Found again after a long gap").
            None: no such join.
        max_look: see ``looks``.

    Returns:
        (P, T, 5) float32: each track's box and score per frame (zeros where the person is
        absent), most prominent first (see the module docstring); P may be 0.
    """
    _check_options(max_gap, max_jump, min_iou, max_scale, min_frames, smoothing, keypoint_weight, beam)
    if not 0 <= max_look <= 1:
        raise ValueError(f"max_look: expected a Hellinger distance in [0, 1], got {max_look!r}")
    detections = check_detections(detections)
    keypoints = None if keypoints is None or keypoint_weight == 0 else _check_keypoints(keypoints, detections)
    T = len(detections)
    looks = None if looks is None else _check_looks(looks, detections)
    linked = [_Tracklet.of(tr, detections, looks)
              for tr in link(detections, keypoints, beam=beam, max_gap=max_gap, smoothing=smoothing, min_iou=min_iou,
                             max_jump=max_jump, max_scale=max_scale, keypoint_weight=keypoint_weight)]  # fmt: skip
    if stitch:
        linked = _stitch(linked, max_gap, max_scale, max_jump)
    if looks is not None:
        linked = _reidentify(linked, max_scale, max_jump, max_look, min(min_frames, T))
    tracks = [tr for tr in linked if len(tr.boxes) >= min(min_frames, T)]
    if not tracks:
        return torch.zeros(0, T, 5)
    boxes = torch.stack([_dense(tr, T, max_gap) for tr in tracks])
    prominence = ((boxes[..., 2:4] - boxes[..., :2]).clamp_min(0).prod(-1) * boxes[..., 4]).sum(1)
    boxes = boxes[prominence.argsort(descending=True, stable=True)]
    log.debug("people: %d tracks over %d frames (%d detections)", len(boxes), T, sum(len(d) for d in detections))
    return boxes


def _check_options(max_gap: int, max_jump: float, min_iou: float, max_scale: float, min_frames: int,
                   smoothing: float, keypoint_weight: float, beam: int) -> None:  # fmt: skip
    """ValueError naming the first of :func:`track_people`'s options out of its range."""
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
    if isinstance(beam, bool) or not isinstance(beam, int) or beam < 1:
        raise ValueError(f"beam: expected a number of hypotheses >= 1, got {beam!r}")


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


def _check_looks(looks: Sequence[torch.Tensor], detections: list[torch.Tensor]) -> list[torch.Tensor]:
    """The per-detection looks as float32 CPU tensors; ValueError naming the frame where they do not
    match the detections (N_t, D), or where D differs between frames."""
    if len(looks) != len(detections):
        raise ValueError(f"looks: expected one tensor per frame ({len(detections)}), got {len(looks)}")
    out, D = [], None
    for t, (look, det) in enumerate(zip(looks, detections)):
        look = torch.as_tensor(look, dtype=torch.float32).cpu()
        if look.ndim != 2 or look.shape[0] != det.shape[0] or (D is not None and look.shape[0] and look.shape[1] != D):
            raise ValueError(f"looks[{t}]: expected ({det.shape[0]}, {D or 'D'}) one look per detection, "
                             f"got {tuple(look.shape)}")  # fmt: skip
        D = look.shape[1] if look.shape[0] else D
        out.append(look)
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
