"""The id sheet: the frames to check, each person drawn and named, to see whose id switched.

:func:`id_sheet` draws the frames where a person's id may have switched (:func:`~.id_checks.frames_to_check`,
or any frames asked for) as tiles of one picture: in each, every person's box and pose in its colour
(the main person lime, the others in :data:`~lit_boot.data.visualize.OTHER_COLOURS`, as in the
overlay video) with "person N" (its track id) at the box's top left, and the tile's video frame
number. What it shows is what a fix says (:mod:`.id_fixes`): "person 1 is on the woman in red until
frame 6 and on the man from frame 7" is ``swap 1 2 at 7-`` when person 2 went the other way.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np
import torch

from ..core.people import Person
from ..data.visualize import OTHER_RGB, draw_skeleton
from .id_checks import frames_to_check

__all__ = ["id_sheet", "sheet_rows", "MAIN_RGB"]

MAIN_RGB = (0, 255, 0)  #: the main person's colour (lime, the overlay's pose after the run)


def person_colour(p: int) -> tuple[int, int, int]:
    """The colour of the ``p``-th person (0: the main one) in the scene's order."""
    return MAIN_RGB if p == 0 else OTHER_RGB[(p - 1) % len(OTHER_RGB)]


def sheet_rows(people: Sequence[Person]) -> list[int]:
    """The frame rows (0-based, increasing) where any of ``people`` has a frame to check."""
    marks = frames_to_check(people)
    if not marks:
        return []
    return torch.stack(marks).any(0).nonzero().flatten().tolist()


def _text(image: np.ndarray, text: str, org: tuple[int, int], colour: tuple[int, int, int], scale: float,
          taken: list[tuple[int, int, int, int]] | None = None, lowest: int | None = None) -> None:  # fmt: skip
    """``text`` in ``colour`` on a black box, its baseline's left end at ``org`` (kept inside the
    image, and moved down past the boxes of ``taken`` (x0, y0, x1, y1), to which it is added, but
    not below ``lowest``), in place."""
    (w, h), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    x = int(min(max(org[0], 0), max(image.shape[1] - w - 2, 0)))
    y = int(max(org[1], h + 2))
    for _ in range(len(taken or [])):
        hit = [r for r in taken if x < r[2] and r[0] < x + w + 2 and y - h - 2 < r[3] and r[1] < y + base]
        if not hit or (lowest is not None and max(r[3] for r in hit) + h + 3 > lowest):
            break
        y = max(r[3] for r in hit) + h + 3
    y = int(min(y, image.shape[0] - base - 1))
    if taken is not None:
        taken.append((x, y - h - 2, x + w + 2, y + base))
    cv2.rectangle(image, (x, y - h - 2), (x + w + 2, y + base), (0, 0, 0), cv2.FILLED)
    cv2.putText(image, text, (x + 1, y), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv2.LINE_AA)


def _tile(frame: torch.Tensor, people: Sequence[Person], t: int, number: int, layout: str, width: int) -> np.ndarray:
    """Frame ``t`` (3, H, W) uint8 resized to ``width`` px wide, every person drawn and named."""
    H, W = frame.shape[1:]
    s = width / W
    height = max(1, round(H * s))
    image = torch.from_numpy(cv2.resize(frame.permute(1, 2, 0).numpy(), (width, height),
                                        interpolation=cv2.INTER_AREA)).permute(2, 0, 1)  # fmt: skip
    labels = []  # (track id, colour, box in the tile's px, has a pose)
    for p, person in enumerate(people):
        colour = person_colour(p)
        box = None if person.person_boxes is None or person.person_boxes[t, 4] <= 0 else person.person_boxes[t, :4]
        conf = None if person.keypoints_conf is None else person.keypoints_conf[t]
        posed = conf is not None and bool((conf > 0).any())
        if posed:
            image = draw_skeleton(image, (person.keypoints2d[t].float() + 0.5) * s - 0.5, layout, conf,
                                  color=colour, radius=1, width=1)  # fmt: skip
        if box is not None:
            labels.append((person.track_id, colour, box * s, posed))
        elif posed:
            points = person.keypoints2d[t][conf > 0].float() * s
            labels.append((person.track_id, colour, torch.cat([points.amin(0), points.amax(0)]), posed))
    out = np.ascontiguousarray(image.permute(1, 2, 0).numpy())
    scale, taken = max(0.35, width / 800), []
    for track_id, colour, (x0, y0, x1, y1), posed in labels:
        cv2.rectangle(out, (round(float(x0)), round(float(y0))), (round(float(x1)), round(float(y1))), colour, 1)
        _text(out, f"person {track_id}", (round(float(x0)), round(float(y0)) - 2), colour, scale, taken,
              lowest=round(float(y1)))  # fmt: skip
    _text(out, f"frame {number}", (2, out.shape[0] - 4), (255, 255, 255), scale)
    return out


def id_sheet(frames: torch.Tensor, people: Sequence[Person], layout: str, rows: Sequence[int] | None = None,
             numbers: Sequence[int] | None = None, *, tile_width: int = 480, columns: int = 4,
             most: int = 48) -> torch.Tensor:  # fmt: skip
    """The id sheet (module docstring), uint8 (3, H', W'): frames (T, 3, H, W) uint8 RGB, the
    scene's ``people`` (keypoints in ``layout``, boxes x0, y0, x1, y1 px), the frame ``rows`` to
    draw (default :func:`sheet_rows`; at most ``most``, the first ones), the frames' video frame
    ``numbers`` (default 0..T-1), ``columns`` tiles of ``tile_width`` px per line. Raises
    ValueError when there is no frame to draw."""
    T = frames.shape[0]
    rows = sheet_rows(people) if rows is None else [int(r) for r in rows]
    numbers = list(range(T)) if numbers is None else [int(n) for n in numbers]
    if not rows:
        raise ValueError("id_sheet: no frame to draw (no person has a frame to check)")
    if any(not 0 <= r < T for r in rows):
        raise ValueError(f"id_sheet: frame rows must lie in 0..{T - 1}, got {rows}")
    tiles = [_tile(frames[r], people, r, numbers[r], layout, tile_width) for r in rows[:most]]
    columns = max(1, min(columns, len(tiles)))
    h, w = tiles[0].shape[:2]
    sheet = np.zeros((h * math.ceil(len(tiles) / columns), w * columns, 3), dtype=np.uint8)
    for k, tile in enumerate(tiles):
        y, x = divmod(k, columns)
        sheet[y * h:(y + 1) * h, x * w:(x + 1) * w] = tile
    return torch.from_numpy(sheet).permute(2, 0, 1).contiguous()
