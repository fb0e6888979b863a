"""Fixing people's ids by hand: what a user writes after looking at the frames to check.

The tracker keeps most ids (:mod:`.people_track`), not all: where people overlap for long a pose
may pass from one person to another, and a person found again may get a new id. The frames where
that may have happened are listed to check (:mod:`.id_checks`); after looking at them, a user
writes what is wrong as fixes, one short sentence each, with the track ids and the video frame
numbers that the "ids to check" line and the id sheet show:

- ``swap A B`` or ``swap A B at FRAMES``: persons A and B trade everything (poses, boxes, 3D
  joints, cameras) in those frames (all of them without ``at``);
- ``join B into A``: person B is person A: B's frames become A's (B has none left and goes);
  where both have a pose or a box in a frame, the fix is refused (``drop`` one there first);
- ``split A at FRAMES``: A's frames there are someone else's, a new person (the next free id);
- ``drop A at FRAMES``: A's poses and boxes there are nobody's (a blend of two people, a pose on
  the background); ``drop A``: person A is nobody and goes.

FRAMES: video frame numbers, ``7`` or ``7-9`` or ``7-`` (to the last frame), several joined by
commas (``3-5, 9``, as the "ids to check" line writes them). A person left without a pose or a box
in any frame goes. In frames where a fix left a person with no pose, its 3D joints and camera are
taken from its nearest frame with a pose, as the estimators fill the frames they miss
(:func:`~.world_to_lsp.nearest_found`), and its keypoints are 0.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence

import torch

from ..core.cameras import Cameras
from ..core.people import Person
from ..core.scene import Scene
from ..data.readers.pose_estimates import PoseEstimates
from .id_checks import frame_numbers, frame_ranges, frames_to_check
from .world_to_lsp import nearest_found

__all__ = ["IdFix", "parse_fix", "fix_ids", "fix_scene", "fix_estimates", "frame_rows", "FIX_GRAMMAR"]

#: One line on what a fix may say (errors end with it).
FIX_GRAMMAR = ("a fix is one of: 'swap A B [at FRAMES]', 'join B into A', 'split A at FRAMES', 'drop A [at FRAMES]' "
               "(A, B: track ids; FRAMES: video frame numbers like '7', '7-9', '7-' or '3-5, 9')")

_PATTERNS = {
    "swap": re.compile(r"swap\s+(\d+)\s+(\d+)(?:\s+at\s+(.+))?"),
    "join": re.compile(r"join\s+(\d+)\s+into\s+(\d+)()"),
    "split": re.compile(r"split\s+(\d+)()\s+at\s+(.+)"),
    "drop": re.compile(r"drop\s+(\d+)()(?:\s+at\s+(.+))?"),
}
_SPAN = re.compile(r"(\d+)(?:\s*(-)\s*(\d+)?)?")


@dataclasses.dataclass(frozen=True)
class IdFix:
    """One fix (module docstring): ``verb`` swap/join/split/drop, the track ids ``first`` (A: the
    person fixed; of a join, the one who stays) and ``second`` (B: the other of a swap, the one who
    goes into A in a join; None for split and drop), and ``spans`` ((first, last) video frame
    numbers, last None: to the end) or None: every frame. ``text``: as written, spaces squeezed."""

    verb: str
    first: int
    second: int | None
    spans: tuple[tuple[int, int | None], ...] | None
    text: str

    def rows(self, numbers: Sequence[int]) -> torch.Tensor:
        """(T,) bool: the rows whose video frame ``numbers`` (T,) lie in the fix's frames. Raises
        ValueError where a span holds no frame of the clip."""
        return _span_rows(self.spans, numbers, f"fix {self.text!r}")


def _span_rows(spans: tuple[tuple[int, int | None], ...] | None, numbers: Sequence[int], who: str) -> torch.Tensor:
    """(T,) bool: the rows whose video frame ``numbers`` lie in ``spans`` (None: all); a ValueError
    starting with ``who`` where a span holds none of them."""
    numbers_t = torch.as_tensor(list(numbers), dtype=torch.int64)
    if spans is None:
        return torch.ones(len(numbers_t), dtype=torch.bool)
    rows = torch.zeros(len(numbers_t), dtype=torch.bool)
    last = int(numbers_t.max()) if len(numbers_t) else 0
    for start, stop in spans:
        here = (numbers_t >= start) & (numbers_t <= (last if stop is None else stop))
        if not bool(here.any()):
            shown = str(start) if stop == start else f"{start}-{'' if stop is None else stop}"
            raise ValueError(f"{who}: frames {shown} are none of the clip's video frames "
                             f"({int(numbers_t.min()) if len(numbers_t) else 0}-{last})")  # fmt: skip
        rows |= here
    return rows


def _spans(text: str, who: str) -> tuple[tuple[int, int | None], ...]:
    """Frame spans "7", "7-9", "7-", comma-separated, as (first, last or None); errors start with ``who``."""
    out = []
    for part in text.split(","):
        match = _SPAN.fullmatch(part.strip())
        if match is None:
            raise ValueError(f"{who}: {part.strip()!r} is not a frame span; {FIX_GRAMMAR}")
        start, dash, stop = match.groups()
        last = None if dash and stop is None else int(stop) if stop is not None else int(start)
        if last is not None and last < int(start):
            raise ValueError(f"{who}: frame span {part.strip()!r} ends before it starts")
        out.append((int(start), last))
    return tuple(out)


def frame_rows(text: str, numbers: Sequence[int], who: str = "frames") -> torch.Tensor:
    """(T,) bool: the rows whose video frame ``numbers`` (T,) are named by ``text``: "all", or spans
    as a fix writes them ("7", "7-9", "7-", "3-5, 9"). Raises ValueError starting with ``who``."""
    if " ".join(text.split()).lower() == "all":
        return _span_rows(None, numbers, who)
    return _span_rows(_spans(text, who), numbers, who)


def parse_fix(text: str) -> IdFix:
    """An :class:`IdFix` from its sentence (module docstring). Raises ValueError naming the text."""
    said = " ".join(str(text).split())
    for verb, pattern in _PATTERNS.items():
        match = pattern.fullmatch(said.lower())
        if match is None:
            continue
        first, second, frames = match.groups()
        if verb == "join":  # "join B into A": B's frames go to A
            first, second = second, first
        if second and int(first) == int(second):
            raise ValueError(f"fix {said!r}: names person {first} twice")
        spans = _spans(frames, f"fix {said!r}") if frames else None
        return IdFix(verb, int(first), int(second) if second else None, spans, said)
    raise ValueError(f"fix {said!r}: not understood; {FIX_GRAMMAR}")


class _Rows:
    """One person's per-frame tensors by name (cameras as ``cameras_params`` / ``cameras_crops``),
    cloned so that fixes change them in place, and the frames a fix touched (T,) bool."""

    def __init__(self, person: Person):
        self.track_id, self.cameras = person.track_id, person.cameras
        self.arrays = {key: getattr(person, key).clone() for key in ("keypoints2d", "keypoints_conf", "joints3d",
                                                                    "person_boxes") if getattr(person, key) is not None}
        if person.cameras is not None:
            self.arrays["cameras_params"] = person.cameras.params.clone()
            if person.cameras.crops is not None:
                self.arrays["cameras_crops"] = person.cameras.crops.clone()
        self.touched = torch.zeros(next(iter(self.arrays.values())).shape[0], dtype=torch.bool)

    def copy(self, track_id: int | None = None, empty: bool = False) -> _Rows:
        """A copy (of ``track_id`` if given); ``empty``: absent in every frame, every frame touched."""
        out = _Rows.__new__(_Rows)
        out.track_id, out.cameras = self.track_id if track_id is None else track_id, self.cameras
        out.arrays = {key: torch.zeros_like(v) if empty else v.clone() for key, v in self.arrays.items()}
        out.touched = torch.ones_like(self.touched) if empty else self.touched.clone()
        return out

    def posed(self) -> torch.Tensor:
        """(T,) bool: frames with a keypoint of confidence > 0."""
        conf = self.arrays.get("keypoints_conf")
        return torch.zeros_like(self.touched) if conf is None else (conf > 0).any(-1)

    def present(self) -> torch.Tensor:
        """(T,) bool: frames with a pose or a box."""
        boxes = self.arrays.get("person_boxes")
        return self.posed() | (torch.zeros_like(self.touched) if boxes is None else boxes[:, 4] > 0)

    def take(self, other: _Rows, rows: torch.Tensor) -> None:
        """Copy ``other``'s frames ``rows`` (T,) bool into this person's."""
        for key, value in self.arrays.items():
            value[rows] = other.arrays[key][rows]
        self.touched |= rows

    def clear(self, rows: torch.Tensor) -> None:
        """No pose and no box in frames ``rows`` (T,) bool."""
        for key in ("keypoints_conf", "person_boxes", "keypoints2d"):
            if key in self.arrays:
                self.arrays[key][rows] = 0
        self.touched |= rows

    def person(self) -> Person:
        """The Person, its touched frames without a pose given its nearest posed frame's 3D joints
        and camera and keypoints 0."""
        arrays, posed = dict(self.arrays), self.posed()
        fill = self.touched & ~posed
        if bool(fill.any()) and bool(posed.any()):
            near = nearest_found(posed)
            for key in ("joints3d", "cameras_params", "cameras_crops"):
                if key in arrays:
                    arrays[key][fill] = arrays[key][near[fill]]
        if "keypoints2d" in arrays:
            arrays["keypoints2d"][fill] = 0
        cameras = None if self.cameras is None else Cameras(
            self.cameras.model, arrays.pop("cameras_params"), arrays.pop("cameras_crops", None), self.cameras.crop_size)
        return Person(track_id=self.track_id, cameras=cameras, **arrays)


def _spans_text(rows: torch.Tensor, numbers: Sequence[int]) -> str:
    return frame_ranges([int(numbers[t]) for t in rows.nonzero().flatten().tolist()])


def _apply(table: dict[int, _Rows], fix: IdFix, numbers: Sequence[int], next_id: int) -> str:
    """Apply ``fix`` to ``table`` (track id -> rows, changed in place); returns what it did."""
    for track_id in (fix.first, fix.second):
        if track_id is not None and track_id not in table:
            raise ValueError(f"fix {fix.text!r}: no person {track_id} (people: {', '.join(map(str, table))})")
    rows, a = fix.rows(numbers), table[fix.first]
    if fix.verb == "swap":
        b = table[fix.second]
        saved = a.copy()
        a.take(b, rows)
        b.take(saved, rows)
        return f"{fix.text}: persons {fix.first} and {fix.second} traded frames {_spans_text(rows, numbers)}"
    if fix.verb == "join":
        b = table[fix.second]
        both = a.present() & b.present()
        if bool(both.any()):
            raise ValueError(f"fix {fix.text!r}: persons {fix.first} and {fix.second} are both in frames "
                             f"{_spans_text(both, numbers)}; drop one of them there first")  # fmt: skip
        moved = b.present()
        a.take(b, moved)
        del table[fix.second]
        return f"{fix.text}: person {fix.second}'s frames {_spans_text(moved, numbers)} are person {fix.first}'s"
    mine = rows & a.present()
    if fix.verb == "drop" and fix.spans is None:
        del table[fix.first]
        return f"{fix.text}: person {fix.first} removed"
    if not bool(mine.any()):
        raise ValueError(f"fix {fix.text!r}: person {fix.first} has no pose or box in those frames")
    if fix.verb == "split":
        table[next_id] = a.copy(next_id, empty=True)
        table[next_id].take(a, mine)
        a.clear(mine)
        return f"{fix.text}: frames {_spans_text(mine, numbers)} are a new person {next_id}'s"
    a.clear(mine)
    return f"{fix.text}: person {fix.first} has nobody's pose in frames {_spans_text(mine, numbers)}"


def fix_ids(people: Sequence[Person], fixes: Sequence[str | IdFix],
            numbers: Sequence[int] | None = None) -> tuple[list[Person], list[str]]:  # fmt: skip
    """``people`` (each with keypoints_conf or person_boxes over the same T frames) after
    ``fixes`` (sentences or :class:`IdFix`, module docstring), applied in turn; ``numbers`` (T,):
    the frames' video frame numbers (default 0..T-1). Returns the people (in their order, new ones
    last; those left with no frame go) and one line per fix saying what it did (and one per person
    left with nothing). Raises ValueError naming the fix that cannot be applied."""
    if not people:
        raise ValueError("fix_ids: no people to fix")
    if any(p.keypoints_conf is None and p.person_boxes is None for p in people):
        raise ValueError("fix_ids: the people need keypoint confidences or boxes (nothing else says where "
                         "a person is)")  # fmt: skip
    table = {p.track_id: _Rows(p) for p in people}
    T = next(iter(table.values())).touched.shape[0]
    numbers = list(range(T)) if numbers is None else [int(n) for n in numbers]
    if len(numbers) != T:
        raise ValueError(f"fix_ids: expected {T} frame numbers (one per frame), got {len(numbers)}")
    next_id, notes = max(table) + 1, []
    for fix in fixes:
        fix = fix if isinstance(fix, IdFix) else parse_fix(fix)
        notes.append(_apply(table, fix, numbers, next_id))
        next_id = max(next_id, max(table, default=-1) + 1)
    for track_id in [i for i, rows in table.items() if not bool(rows.present().any())]:
        del table[track_id]
        notes.append(f"person {track_id} has no frame left and goes")
    if not table:
        raise ValueError("fix_ids: the fixes leave nobody")
    return [rows.person() for rows in table.values()], notes


def _history(metadata: dict, fixes: Sequence[str | IdFix], notes: list[str]) -> list[dict]:
    said = [fix.text if isinstance(fix, IdFix) else " ".join(str(fix).split()) for fix in fixes]
    return [*metadata.get("id_fixes", []), {"fixes": said, "done": notes}]


def fix_scene(scene: Scene, fixes: Sequence[str | IdFix]) -> tuple[Scene, list[str]]:
    """``scene`` with its people's ids fixed (:func:`fix_ids`, frame numbers from
    ``scene.metadata["frame_indices"]`` where recorded), the fixes and what they did appended to
    ``metadata["id_fixes"]``; and those lines. The ground truth stays each track's (where the main
    person goes, the next one's truth becomes the main one, :meth:`~lit_boot.core.scene.GroundTruth.with_main`)."""
    people, notes = fix_ids(scene.people(), fixes, frame_numbers(scene))
    meta = {**scene.metadata, "id_fixes": _history(scene.metadata, fixes, notes)}
    gt = scene.gt
    if gt is not None and people[0].track_id != scene.track_id:  # the main person went: the next one leads
        gt = gt.with_main(people[0].track_id, scene.track_id)
    return dataclasses.replace(scene.with_people(people), metadata=meta, gt=gt), notes


def fix_estimates(estimates: PoseEstimates, fixes: Sequence[str | IdFix]) -> tuple[PoseEstimates, list[str]]:
    """``estimates`` (a pose file's) with their people's ids fixed (:func:`fix_ids`, frame numbers
    ``frame_indices``), ``metadata["id_fixes"]`` appended and each ``metadata["people"]`` record's
    ``check_ids`` made again for the people after the fixes (records of people gone are left out);
    and what the fixes did."""
    people, notes = fix_ids(estimates.people(), fixes, estimates.frame_indices.tolist())
    records = {r.get("track_id"): r for r in estimates.metadata.get("people", []) if isinstance(r, dict)}
    checks = frames_to_check(people) if len(people) > 1 else [torch.zeros(estimates.num_frames, dtype=torch.bool)]
    fresh = [{**records.get(p.track_id, {"track_id": p.track_id}),
              "check_ids": estimates.frame_indices[check].tolist()} for p, check in zip(people, checks)]  # fmt: skip
    meta = {**estimates.metadata, "id_fixes": _history(estimates.metadata, fixes, notes)}
    if "people" in estimates.metadata:
        meta["people"] = fresh
    return estimates.with_people(people, metadata=meta), notes
