"""Each frame's detections given to the tracks: the optimal assignment, and a beam search over
each frame's few best assignments that judges a frame's choice by the frames after it.

Linking frame by frame takes each frame's optimal assignment (:func:`assign`: scipy's
``linear_sum_assignment`` on the pair costs of :mod:`.track_cost`, leaving a track or a detection
unmatched at ``miss`` each), and a wrong choice where two people overlap stays: the next frames
pay for it (a track that took the wrong person is far from its own when that one comes back) but
cannot undo it. :func:`link` keeps ``beam`` hypotheses instead: each is extended by the frame's
:data:`BRANCHES` best assignments for its tracks (Murty's ranking, :func:`best_assignments`), and
the ``beam`` with the lowest cost summed over the frames so far go on; the cheapest at the last
frame is the answer. ``beam`` 1 is the frame-by-frame link (BENCHMARKS.md, "Tracking with
hindsight").
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch

from .track_cost import MISS_COST, TrackState, pair_costs

__all__ = ["assign", "best_assignments", "link", "BRANCHES"]

#: How many of a frame's best assignments each hypothesis is extended by (BENCHMARKS.md,
#: "Tracking with hindsight").
BRANCHES = 6
#: In the cost summed over the frames, what a track left unmatched costs per frame (within a
#: frame's assignment it costs MISS_COST, as does a detection left alone): a hypothesis is not
#: charged much for keeping an open track nobody takes, so it need not give that track another
#: person's detection to be cheaper (BENCHMARKS.md, "Tracking with hindsight").
UNSEEN_COST = 0.25
#: A cost that stands for "not allowed" in the padded assignment problem.
_NEVER = 1e6


def _padded(cost: torch.Tensor, miss: float) -> np.ndarray:
    """The (N + M, M + N) assignment problem of N tracks and M detections: the pair costs (inf:
    not allowed), each track's own miss column and each detection's own miss row at ``miss``,
    zeros where two misses meet."""
    N, M = cost.shape
    full = np.full((N + M, M + N), _NEVER)
    pairs = cost.double().numpy()
    full[:N, :M] = np.where(np.isfinite(pairs), pairs, _NEVER)
    full[np.arange(N), M + np.arange(N)] = miss
    full[N + np.arange(M), np.arange(M)] = miss
    full[N:, M:] = 0.0
    return full


def _solve(problem: np.ndarray) -> tuple[float, np.ndarray] | None:
    """The optimal total and each row's column, None where only a disallowed entry fits."""
    from scipy.optimize import linear_sum_assignment

    rows, cols = linear_sum_assignment(problem)
    total = float(problem[rows, cols].sum())
    return None if total >= _NEVER else (total, cols)


def _pairs(cols: np.ndarray, N: int, M: int) -> list[tuple[int, int]]:
    return [(r, int(cols[r])) for r in range(N) if cols[r] < M]


def assign(cost: torch.Tensor, miss: float = MISS_COST) -> list[tuple[int, int]]:
    """The optimal (track, detection) pairs of finite ``cost`` (N, M), where leaving a track or a
    detection unmatched costs ``miss`` each (a pair is matched only where that is cheaper than
    leaving both alone, and a good match is not traded for two poor ones)."""
    N, M = cost.shape
    if N == 0 or M == 0:
        return []
    return _pairs(_solve(_padded(cost, miss))[1], N, M)


def best_assignments(cost: torch.Tensor, k: int, miss: float = MISS_COST) -> list[tuple[float, list[tuple[int, int]]]]:
    """Up to ``k`` assignments of ``cost`` (N, M) as (total cost, pairs), cheapest first, each a
    different set of pairs (Murty's ranking: each answer's problem split into sub-problems that
    keep its first tracks' choices and forbid the next one's)."""
    N, M = cost.shape
    problem = _padded(cost, miss)
    first = _solve(problem)
    queue = [(first[0], 0, problem, first[1], 0)]
    out, count = [], 1
    while queue and len(out) < k:
        total, _, problem, cols, kept = heapq.heappop(queue)
        out.append((total, _pairs(cols, N, M)))
        sub = problem.copy()
        for r in range(kept, N):  # only the track rows choose: the rest follows from them
            forbidden = sub.copy()
            forbidden[r, cols[r]] = _NEVER
            if (solved := _solve(forbidden)) is not None:
                heapq.heappush(queue, (solved[0], count, forbidden, solved[1], r))
                count += 1
            keep = sub[r, cols[r]]
            sub[r, :], sub[:, cols[r]] = _NEVER, _NEVER
            sub[r, cols[r]] = keep
    return out


@dataclass
class _Hypothesis:
    cost: float  # summed over the frames so far
    open: list[TrackState]
    ended: tuple | None = None  # (track, earlier ended): tracks unseen for more than max_gap frames


def _open_at(h: _Hypothesis, t: int, max_gap: int) -> tuple[list[TrackState], tuple | None]:
    """The hypothesis's tracks that may still take a detection in frame ``t``, and its ended ones."""
    open_, ended = [], h.ended
    for tr in h.open:
        if t - tr.last <= max_gap + 1:
            open_.append(tr)
        else:
            ended = (tr, ended)
    return open_, ended


def _extend(opened: tuple[list[TrackState], tuple | None], t: int, dets: torch.Tensor, kps: torch.Tensor | None,
            pairs: list[tuple[int, int]], total: float, smoothing: float) -> _Hypothesis:  # fmt: skip
    """A hypothesis's open and ended tracks ``opened`` (:func:`_open_at` in frame ``t``) with the
    frame's detections given by ``pairs`` (open track, detection); the others start new tracks.
    Only the tracks that change are copied."""
    tracks, ended = list(opened[0]), opened[1]
    matched = set()
    for r, c in pairs:
        tracks[r] = replace(tracks[r])
        tracks[r].add(t, dets[c], smoothing, None if kps is None else kps[c])
        matched.add(c)
    for c in range(dets.shape[0]):
        if c not in matched:
            tracks.append(TrackState(order=(t, c)))
            tracks[-1].add(t, dets[c], keypoints=None if kps is None else kps[c])
    return _Hypothesis(total, tracks, ended)


def link(detections: Sequence[torch.Tensor], keypoints: Sequence[torch.Tensor] | None, *, beam: int, max_gap: int,
         smoothing: float, **cost_options) -> list[TrackState]:  # fmt: skip
    """Every track of the cheapest hypothesis over the whole video, in the order they started.

    Args:
        detections: T tensors (N_t, 5) x0, y0, x1, y1 px, score.
        keypoints: None, or T tensors (N_t, K, 3), each detection's pose.
        beam: the hypotheses kept per frame (1: each frame's optimal assignment).
        max_gap: a track unseen for more than this many frames ends.
        smoothing: the weight of a frame's own motion in a track's velocity.
        cost_options: :func:`.track_cost.pair_costs`' ``min_iou``, ``max_jump``, ``max_scale``,
            ``keypoint_weight``.
    """
    hypotheses = [_Hypothesis(0.0, [])]
    for t, dets in enumerate(detections):
        kps = None if keypoints is None else keypoints[t]
        options, opened = [], [_open_at(h, t, max_gap) for h in hypotheses]
        for i, h in enumerate(hypotheses):
            open_ = opened[i][0]
            if open_ and dets.shape[0]:
                cost = pair_costs(open_, t, dets, keypoints=kps, **cost_options)
                ranked = best_assignments(cost, BRANCHES if beam > 1 else 1)
            else:
                ranked = [(MISS_COST * (len(open_) + dets.shape[0]), [])]
            rebate = (MISS_COST - UNSEEN_COST) * len(open_)  # the same for each of h's options
            options += [(h.cost + total - rebate, i, pairs) for total, pairs in ranked]
        options.sort(key=lambda o: o[0])
        hypotheses = [_extend(opened[i], t, dets, kps, pairs, total, smoothing)
                      for total, i, pairs in options[:beam]]  # fmt: skip
    best, tracks = hypotheses[0], list(hypotheses[0].open)
    node = best.ended
    while node is not None:
        tracks.append(node[0])
        node = node[1]
    return sorted(tracks, key=lambda tr: tr.order)
