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

from ..core.people import Person
from .id_fixes import IdFix, fix_ids
from .pose_duplicates import CONF, MIN_JOINTS, pose_apart

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


def _step(a: Person, b: Person, last: int, first: int) -> float | None:
    """How far B's pose in row ``first`` lies from A's in row ``last``, in A's pose sizes per frame
    between them; None where it does not continue it (module docstring)."""
    if not 0 < first - last <= MAX_GAP:
        return None
    apart = pose_apart(a.keypoints2d[last], a.keypoints_conf[last] > CONF,
                       b.keypoints2d[first], b.keypoints_conf[first] > CONF)  # fmt: skip
    step = None if apart is None else apart / (first - last)
    return step if step is not None and step < MAX_STEP else None


def handovers(people: Sequence[Person]) -> list[tuple[float, int, int, int]]:
    """Every pair of ``people`` (each with keypoints2d (T, K, 2) px and keypoints_conf (T, K)) where
    the second's poses continue the first's (module docstring), as (step, index of A, index of B,
    A's last posed row): the earliest hand-over first (A's last pose, then B's first), then the
    closest (a pose handed on twice is followed in time)."""
    rows = [_posed_rows(p) for p in people]
    found = []
    for i, a in enumerate(people):
        for j, b in enumerate(people):
            if i == j or not rows[i] or not rows[j]:
                continue
            last, first = rows[i][-1], rows[j][0]
            if (step := _step(a, b, last, first)) is not None:
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
