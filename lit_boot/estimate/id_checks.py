"""Where a tracked person's id may have switched: the frames a user should look at.

The tracker (:mod:`.people_track`) keeps ids through crossings, but not always where people
overlap for long or one is hidden and found again (BENCHMARKS.md, "The product's own people on
synthetic scenes, end to end"). :func:`frames_to_check` marks, per person, the frames with a pose
where its id is a choice the frames may not settle:

- its box overlaps another person's box by ``min_iou`` or more (who is who is decided there);
- its pose comes back after frames without one, or first appears after the clip's first frame
  (a person found again, or someone new, may continue another's track or start a new one).

A box is the person's ``person_boxes`` where present (score > 0), else the extent of its confident
keypoints (x0, y0, x1, y1 px, pixel centres at integer coordinates). On synthetic scenes with 2
and 3 people crossing for most of the clip, these frames hold 70 of the 72 identity switches of
the poses the built-in estimator makes, and are 22-24% of the frames with a pose (BENCHMARKS.md,
"Where to check the ids", "Found again after a long gap").
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from ..core.frame_runs import frame_runs
from ..core.people import Person
from .pose_duplicates import keypoint_extent
from .track_cost import box_overlaps

__all__ = ["frames_to_check", "frame_ranges", "frame_numbers", "checks_line", "scene_checks", "beside_line",
           "OVERLAP_IOU"]

#: The box overlap (IoU) with another person from which a frame is one to check.
OVERLAP_IOU = 0.3


def _boxes(person: Person) -> torch.Tensor:
    """(T, 5) the person's box and 1 where it has one (``person_boxes``, else its confident
    keypoints' extent), 0 elsewhere."""
    has_pose = person.keypoints_conf is not None
    T = person.keypoints_conf.shape[0] if has_pose else person.person_boxes.shape[0]
    out = torch.zeros(T, 5)
    if has_pose:
        for t in range(T):
            seen = person.keypoints_conf[t] > 0
            if seen.any():
                out[t] = torch.cat([keypoint_extent(person.keypoints2d[t], seen), torch.ones(1)])
    if person.person_boxes is not None:
        boxed = person.person_boxes[:, 4] > 0
        out[boxed] = torch.cat([person.person_boxes[boxed, :4], torch.ones(int(boxed.sum()), 1)], -1)
    return out


def frames_to_check(people: Sequence[Person], min_iou: float = OVERLAP_IOU) -> list[torch.Tensor]:
    """Per person of ``people`` (each with keypoints2d (T, K, 2) and keypoints_conf (T, K), and/or
    person_boxes (T, 5)), a (T,) bool: the frames with a pose where its id may have switched
    (module docstring). A person without keypoints has none to check."""
    if not people:
        return []
    boxes = torch.stack([_boxes(p) for p in people])  # (P, T, 5)
    overlap = box_overlaps(boxes, min_iou).any(-1).T  # (P, T): a box overlapping another's
    out = []
    for i, person in enumerate(people):
        if person.keypoints_conf is None:
            out.append(torch.zeros(boxes.shape[1], dtype=torch.bool))
            continue
        posed = (person.keypoints_conf > 0).any(-1)
        check = posed & overlap[i]
        rows = posed.nonzero().flatten().tolist()
        if rows and rows[0] > 0:
            check[rows[0]] = True  # first seen after the clip's start
        for before, after in zip(rows, rows[1:]):
            if after > before + 1:
                check[after] = True  # back after frames without a pose
        out.append(check)
    return out


def beside_line(people: Sequence[Person], marks: Sequence[torch.Tensor], numbers: Sequence[int],
                min_iou: float = OVERLAP_IOU) -> str:  # fmt: skip
    """Why each frame to check is one, for the swap a user may write: "person 1 beside 2 at 3-5, new
    or back at 9; person 2 new or back at 1" for ``people`` and their ``marks``
    (:func:`frames_to_check`), frame rows named by the video frame ``numbers``: the other people whose
    boxes overlap the person's there (IoU ``min_iou``), else "new or back" (first seen after the
    clip's start, or a pose again after frames without). "" where nothing is marked."""
    if not people:
        return ""
    overlap = box_overlaps(torch.stack([_boxes(p) for p in people]), min_iou)  # (T, P, P)
    parts = []
    for i, (person, mark) in enumerate(zip(people, marks)):
        rows = mark.nonzero().flatten().tolist()
        if not rows:
            continue
        reasons = [f"beside {people[j].track_id} at {frame_ranges([numbers[t] for t in rows if overlap[t, i, j]])}"
                   for j in range(len(people)) if any(bool(overlap[t, i, j]) for t in rows)]  # fmt: skip
        alone = [numbers[t] for t in rows if not bool(overlap[t, i].any())]
        if alone:
            reasons.append(f"new or back at {frame_ranges(alone)}")
        parts.append(f"person {person.track_id} {', '.join(reasons)}")
    return "; ".join(parts)


def frame_ranges(frames: Sequence[int], most: int = 6) -> str:
    """Increasing frame numbers as ranges, e.g. "3-5, 9"; more than ``most`` ranges end in ", ..."."""
    spans = frame_runs(frames)
    text = [str(a) if a == b else f"{a}-{b}" for a, b in spans[:most]]
    return ", ".join(text) + (", ..." if len(spans) > most else "")


def checks_line(checks: Sequence[tuple[int, Sequence[int]]]) -> str:
    """One line for people: "ids to check (...), video frames: person 1 at 3-5; person 2 at 9" from
    (track id, video frame numbers) pairs; "" where none has a frame to check."""
    where = "; ".join(f"person {i} at {frame_ranges(frames)}" for i, frames in checks if len(frames))
    return f"ids to check (people overlapping, new or found again), video frames: {where}" if where else ""


def frame_numbers(scene) -> list[int]:
    """A Scene's video frame numbers: ``scene.metadata["frame_indices"]`` where its reader recorded
    them, else 0..T-1."""
    return list(scene.metadata.get("frame_indices") or range(scene.num_frames))


def scene_checks(scene) -> list[tuple[int, list[int]]]:
    """(track id, video frame numbers) to check for each person of a Scene with several people
    (:func:`frames_to_check`; frame numbers from ``scene.metadata["frame_indices"]`` where its reader
    recorded them, else 0..T-1); [] for one person."""
    if not scene.others:
        return []
    numbers = frame_numbers(scene)
    marks = frames_to_check(scene.people())
    return [(person.track_id, [int(numbers[t]) for t in mark.nonzero().flatten().tolist()])
            for person, mark in zip(scene.people(), marks)]  # fmt: skip
