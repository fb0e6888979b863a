"""A person's poses handed from one track to the next: where they go on, they are one person's.

The tracker links boxes; where people overlap, or the detector merges and splits their boxes, a
person's box may pass to another track while each track's crops (in video mode) keep finding that
person: the poses end on one track and go on, in the next frame or after a short gap, on another
that had none before, and the track left behind goes on with boxes that hold no pose, or ends.
:func:`handovers` finds such pairs: track A's last pose and track B's first lie at most
:data:`MAX_GAP` frames apart, B has no pose before and A none after, and B's first pose continues
A's last (the median distance of the joints confident in both, at least
:data:`~.pose_duplicates.MIN_JOINTS`, below :data:`MAX_STEP` x the size of A's pose per frame
between them). :func:`continue_poses` joins them one at a time, the earliest first (a pose handed on
twice is followed both times), of two at once the closest: A and B trade their frames from the one after A's last
pose on, as the fix ``swap A B at F-`` does (:mod:`.id_fixes`), so that A keeps the person and B
the boxes A left behind. On synthetic scenes with people crossing and the shared street clip it
removes switches and adds none (BENCHMARKS.md, "A person's poses handed from one track to the
next"). Keypoints px; confidences 0 where not found.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from ..core.people import Person
from .id_fixes import IdFix, fix_ids
from .pose_duplicates import CONF, MIN_JOINTS, keypoint_extent

__all__ = ["handovers", "continue_poses", "MAX_GAP", "MAX_STEP"]

#: The most frames from A's last pose to B's first (the tracker's ``max_gap`` + 1: the frames a
#: stitch bridges).
MAX_GAP = 4
#: B's first pose continues A's last where their shared joints lie within this share of A's pose
#: size per frame between them (the duplicate rule's distance for two poses that are one).
MAX_STEP = 0.1


def _posed_rows(person: Person) -> list[int]:
    """The rows where ``person`` has a pose: at least MIN_JOINTS joints confident above CONF."""
    if person.keypoints_conf is None or person.keypoints2d is None:
        return []
    return ((person.keypoints_conf > CONF).sum(-1) >= MIN_JOINTS).nonzero().flatten().tolist()


def _step(a: Person, b: Person) -> tuple[float, int, int] | None:
    """(step, A's last posed row, B's first) where B's first pose continues A's last (module docstring), else None."""
    rows_a, rows_b = _posed_rows(a), _posed_rows(b)
    if not rows_a or not rows_b or not 0 < rows_b[0] - rows_a[-1] <= MAX_GAP:
        return None
    last, first = rows_a[-1], rows_b[0]
    confident_a = a.keypoints_conf[last] > CONF
    shared = confident_a & (b.keypoints_conf[first] > CONF)
    if int(shared.sum()) < MIN_JOINTS:
        return None
    extent = keypoint_extent(a.keypoints2d[last], confident_a)
    size = float((extent[2:] - extent[:2]).max().clamp_min(1.0))
    apart = float((a.keypoints2d[last, shared] - b.keypoints2d[first, shared]).norm(dim=-1).median())
    step = apart / size / (first - last)
    return (step, last, first) if step < MAX_STEP else None


def handovers(people: Sequence[Person]) -> list[tuple[float, int, int, int]]:
    """Every pair of ``people`` (each with keypoints2d (T, K, 2) px and keypoints_conf (T, K)) where
    the second's poses continue the first's (module docstring), as (step, index of A, index of B,
    A's last posed row): the earliest hand-over first (A's last pose, then B's first), then the
    closest (a pose handed on twice is followed in time)."""
    found = []
    for i, a in enumerate(people):
        for j, b in enumerate(people):
            if i != j and (link := _step(a, b)) is not None:
                step, last, first = link
                found.append((last, first, step, i, j))
    return [(step, i, j, last) for last, _, step, i, j in sorted(found)]


def continue_poses(people: Sequence[Person], numbers: Sequence[int]) -> tuple[list[Person], list[str]]:
    """``people`` with each hand-over joined (:func:`handovers`, the first one each time, found again
    after each), ``numbers`` (T,) the frames' video frame numbers; and what the hand-overs did
    (:func:`~.id_fixes.fix_ids`' lines: each swap, and each person left with no pose and no box,
    who goes)."""
    people, said = list(people), []
    for _ in range(len(people)):
        found = handovers(people)
        if not found:
            break
        _, i, j, last = found[0]
        a, b, frame = people[i].track_id, people[j].track_id, int(numbers[last + 1])
        fix = IdFix("swap", a, b, ((frame, None),), f"swap {a} {b} at {frame}-")
        people, notes = fix_ids(people, [fix], numbers)
        said += notes
    return people, said
