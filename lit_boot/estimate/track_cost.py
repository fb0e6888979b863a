"""The tracker's cost of giving a detection to a track, and a track's running state.

A track (:class:`TrackState`) predicts its next box from its last one moved on by its velocity (px
per frame, a running mean of its centre's motion, each frame weighing ``smoothing``, or the plain
mean of the first steps while each weighs more than that; its joints' median motion where it
shares enough of them with the last frame: an occluder moves a box's centre, not the person).
:func:`pair_costs` gives each (track, detection) pair a box cost in [0, 2] plus the size and pose
terms: ``1 - IoU`` with the predicted box when they overlap by at least
``min_iou``, else ``1 + d / reach`` when the centres are ``d`` px apart within ``reach`` =
``max_jump`` x the box's larger side x the frames since it was last seen; a detection further
away, or more than ``max_scale`` times larger or smaller (larger side), is not that track's (inf);
:data:`SCALE_WEIGHT` x ``|log|`` of the ratio of the larger sides is added.
Where the detections come with keypoints, ``keypoint_weight`` x a pose distance is added: the
median distance of the shared confident joints from the track's last keypoints moved on by its
velocity, in box sides per frame since those keypoints were seen, plus
:data:`KEYPOINT_SHAPE_WEIGHT` x how much farther the pose's shape (the shared joints about their
mean) is from the track's than from the best-shaped track's for the same detection, at most 1 in
all; and :data:`KEYPOINT_GAP_COST` per frame the track has gone unseen beyond the last. Leaving a
track or a detection unmatched costs :data:`MISS_COST` each. Boxes are x0, y0, x1, y1 px with
pixel centres at integer coordinates (:mod:`.detector`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

__all__ = ["TrackState", "pair_costs", "box_centre", "box_side", "iou_matrix", "box_areas", "box_intersections",
           "box_overlaps", "MISS_COST", "SMOOTHING", "KEYPOINT_WEIGHT"]

#: The cost of leaving a track or a detection unmatched in a frame (the box terms of a pair lie in [0, 2]).
MISS_COST = 1.0
#: The weight of a frame's own motion in a track's velocity (BENCHMARKS.md, "The tracker on
#: synthetic crossings").
SMOOTHING = 0.1
#: The weight of the keypoint distance (in box sides, at most 1) in a pair's cost, where the
#: detections come with keypoints (BENCHMARKS.md, "The tracker on synthetic crossings").
KEYPOINT_WEIGHT = 4.0
#: The confidence above which a joint counts in the keypoint distance (and the joints' motion),
#: and how many joints a track and a detection must share for it to count.
KEYPOINT_CONF = 0.3
KEYPOINT_MIN_JOINTS = 4
#: A track's velocity from its joints' median motion where they are shared (else the box centre's).
JOINT_VELOCITY = True
#: A track's velocity starts as the plain mean of its first steps (each of the first n weighing
#: 1 / n) until that weight falls to ``smoothing``; False: its first step as it is, then the running
#: mean (a new track's first step, often a box that changed shape, then steered it for many
#: frames; BENCHMARKS.md, "Tracking with hindsight").
MEAN_START = True
#: The keypoint distance per frame since the track's keypoints were seen (a pose unseen for a while
#: predicts loosely; BENCHMARKS.md, "Keypoints in the tracker").
KEYPOINT_PER_FRAME = True
#: Where the detections come with keypoints: the cost per frame a track has gone unseen beyond the
#: last. A track seen a frame ago predicts better than one unseen for longer, whose keypoint
#: distance (per frame since seen) is also cheap (BENCHMARKS.md, "Keypoints in the tracker").
KEYPOINT_GAP_COST = 0.3
#: The weight of a pair's change of size, ``|log(side / predicted side)|`` of the boxes' larger
#: sides, in its cost (BENCHMARKS.md, "Tracking with hindsight": a person's size changes little from
#: frame to frame; a neighbour's box near the predicted one is often larger or smaller).
SCALE_WEIGHT = 0.5
#: Where the detections come with keypoints: the weight of a pair's pose-shape distance (box
#: sides) beyond the best-shaped track's for the same detection, added to the keypoint distance
#: (BENCHMARKS.md, "The pose's shape in the tracker").
KEYPOINT_SHAPE_WEIGHT = 1.0


@dataclass
class TrackState:
    """One track while linking: its last box and motion, and every box so far as a chain shared
    with the states it was copied from (copying a state is cheap: the beam search keeps many)."""

    box: torch.Tensor | None = None  # (5,) the last box and score
    last: int = -1
    seen: int = 0  # frames with a box
    velocity: torch.Tensor = field(default_factory=lambda: torch.zeros(2))
    keypoints: torch.Tensor | None = None  # (K, 3) x, y px, confidence: the latest frame's that had any
    keypoint_frame: int = -1
    history: tuple | None = None  # (frame, box, earlier history)
    order: tuple[int, int] = (0, 0)  # (frame, detection) where the track started

    def boxes(self) -> dict[int, torch.Tensor]:
        """Frame -> (5,) box and score, every frame the track was seen."""
        out, node = {}, self.history
        while node is not None:
            out[node[0]], node = node[1], node[2]
        return dict(sorted(out.items()))

    def predicted(self, t: int) -> torch.Tensor:
        return self.box[:4] + (self.velocity * (t - self.last)).repeat(2)

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
        """The detection ``det`` (5,) with its ``keypoints`` (K, 3) or None, in frame ``t``."""
        if self.seen:
            step = self._joint_step(t, keypoints)
            if step is None:
                step = (box_centre(det[:4]) - box_centre(self.box[:4])) / (t - self.last)
            weight = max(smoothing, 1.0 / self.seen) if MEAN_START else (1.0 if self.seen == 1 else smoothing)
            self.velocity = (1 - weight) * self.velocity + weight * step
        self.box, self.last, self.seen = det.clone(), t, self.seen + 1
        self.history = (t, self.box, self.history)
        if keypoints is not None and bool((keypoints[:, 2] > 0).any()):
            self.keypoints, self.keypoint_frame = keypoints.clone(), t


def box_centre(box: torch.Tensor) -> torch.Tensor:
    """The centres (..., 2) px of boxes (..., 4 or more) x0, y0, x1, y1."""
    return (box[..., :2] + box[..., 2:4]) / 2


def box_side(box: torch.Tensor) -> torch.Tensor:
    """The larger sides (...) px of boxes (..., 4 or more), at least 1."""
    return (box[..., 2:4] - box[..., :2]).amax(-1).clamp_min(1.0)


def box_areas(boxes: torch.Tensor) -> torch.Tensor:
    """Areas (N,) px^2 of boxes (N, 4 or more), 0 where a side is negative."""
    return (boxes[:, 2:4] - boxes[:, :2]).clamp_min(0).prod(-1)


def box_intersections(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Areas (N, M) px^2 of the intersections of boxes a (N, 4) and b (M, 4)."""
    lo = torch.maximum(a[:, None, :2], b[None, :, :2])
    hi = torch.minimum(a[:, None, 2:4], b[None, :, 2:4])
    return (hi - lo).clamp_min(0).prod(-1)


def iou_matrix(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """IoU (N, M) of boxes a (N, 4) and b (M, 4)."""
    inter = box_intersections(a, b)
    return inter / (box_areas(a)[:, None] + box_areas(b)[None, :] - inter).clamp_min(1e-9)


def box_overlaps(boxes: torch.Tensor, min_iou: float) -> torch.Tensor:
    """(T, P, P) bool: in each frame, the pairs of distinct people whose boxes (P, T, 5) (score 0:
    absent) are both there and overlap by IoU ``min_iou`` or more."""
    by_frame = boxes.transpose(0, 1)  # (T, P, 5)
    out = torch.stack([iou_matrix(b[:, :4], b[:, :4]) >= min_iou for b in by_frame])
    present = by_frame[..., 4] > 0
    return out & present[:, :, None] & present[:, None, :] & ~torch.eye(boxes.shape[0], dtype=torch.bool)


def _keypoint_distance(tracks: list[TrackState], t: int, keypoints: torch.Tensor,
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


def pair_costs(tracks: list[TrackState], t: int, dets: torch.Tensor, min_iou: float, max_jump: float,
           max_scale: float, keypoints: torch.Tensor | None = None,
           keypoint_weight: float = KEYPOINT_WEIGHT) -> torch.Tensor:  # fmt: skip
    """(N_tracks, N_dets) costs of giving each detection ``dets`` (N_dets, 5) of frame ``t`` to
    each track (the module docstring); inf where a detection cannot be the track's."""
    pred = torch.stack([tr.predicted(t) for tr in tracks])
    gap = torch.tensor([float(t - tr.last) for tr in tracks])
    iou = iou_matrix(pred, dets[:, :4])
    dist = (box_centre(pred)[:, None] - box_centre(dets[:, :4])[None]).norm(dim=-1)
    reach = max_jump * box_side(pred)[:, None] * gap[:, None]
    cost = torch.where(iou >= min_iou, 1 - iou, 1 + dist / reach)
    ratio = box_side(pred)[:, None] / box_side(dets[:, :4])[None]
    far = (iou < min_iou) & (dist > reach)
    if keypoints is not None and keypoint_weight > 0:
        where, shape = _keypoint_distance(tracks, t, keypoints, box_side(pred))
        # the shape against the best-shaped track's for the same detection: it ranks the tracks,
        # and a pair whose shape cannot be measured is neither favoured nor penalised by it
        best = torch.nan_to_num(shape, nan=math.inf).amin(0, keepdim=True)
        pose = where + KEYPOINT_SHAPE_WEIGHT * (shape - best)
        cost = cost + keypoint_weight * torch.nan_to_num(pose.clamp_max(1.0), nan=0.0)
        cost = cost + KEYPOINT_GAP_COST * (gap[:, None] - 1)
    cost = cost + SCALE_WEIGHT * ratio.log().abs()
    return cost.masked_fill(far | (ratio > max_scale) | (ratio < 1 / max_scale), math.inf)
