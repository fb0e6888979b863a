"""Every person of a multi-person keypoint file (COCO results, DCPose): each frame's people, linked
into tracks, as one :class:`~.pose_estimates.PoseEstimates` with ``others``.

A file's people are linked by its own track ids (``"track_id"`` in a COCO result or DCPose entry,
as PoseTrack-style trackers write them) or, where it has none, by a ``link`` function given by
the caller (:func:`lit_boot.estimate.link_keypoint_people`: the person tracker on the keypoints'
boxes). Each track becomes a person (zero rows with confidence 0 where it is absent), the most
prominent (the sum over frames of keypoint-box area x mean confidence) first.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch

from ...core.people import Person
from .pose_estimates import PoseEstimates

__all__ = ["Link", "keypoint_box", "track_labels", "every_person", "clean_keypoints"]

#: people[t][i] (K, 3) [x, y, confidence], scores[t][i] or None -> labels[t][i]: the person (track)
#: of each detection, -1 for none.
Link = Callable[[list[list[np.ndarray]], list[list[float]] | None], list[list[int]]]


def keypoint_box(p: np.ndarray) -> np.ndarray | None:
    """(4,) x0, y0, x1, y1 px around a (K, 3) person's keypoints with confidence > 0 (None: none)."""
    pts = p[(p[:, 2] > 0) & np.isfinite(p[:, :2]).all(-1), :2]
    return None if len(pts) == 0 else np.concatenate([pts.min(0), pts.max(0)])


def track_labels(raw: list[list[Any]]) -> list[list[int]] | None:
    """The file's track ids per detection as ints >= 0 (kept when they are such ints already,
    else numbered in order of first appearance); None when a detection has none."""
    if not raw or any(v is None for frame in raw for v in frame):
        return None
    values = [v for frame in raw for v in frame]
    if all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in values):
        return [list(frame) for frame in raw]
    number = {v: i for i, v in enumerate(dict.fromkeys(str(v) for v in values))}
    return [[number[str(v)] for v in frame] for frame in raw]


def clean_keypoints(out: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """(T, K, 3) [x, y, confidence] -> keypoints (T, K, 2) and confidence (T, K) float32 tensors:
    confidence clipped to [0, 1], a non-finite point becomes (0, 0) with confidence 0."""
    conf = np.clip(np.nan_to_num(out[..., 2]), 0.0, 1.0)
    bad = ~np.isfinite(out[..., :2]).all(-1)
    conf[bad] = 0.0
    xy = np.where(bad[..., None], 0.0, out[..., :2])
    return torch.from_numpy(xy.astype(np.float32)), torch.from_numpy(conf.astype(np.float32))


def _prominence(track: np.ndarray) -> float:
    total = 0.0
    for p in track:
        box = keypoint_box(p)
        if box is not None:
            total += float(np.prod(box[2:] - box[:2])) * float(np.clip(p[p[:, 2] > 0, 2], 0, 1).mean())
    return total


def every_person(people: Sequence[Sequence[np.ndarray]], labels: Sequence[Sequence[int]], *, source: str,
                 image_size: tuple[int, int] | None, metadata: dict[str, Any]) -> PoseEstimates:  # fmt: skip
    """Every labelled person (a track) of ``people`` (per frame, (K, 3) arrays) as PoseEstimates
    with ``others``, the most prominent first; a frame's second detection of one track is dropped.
    Without any labelled detection: one person found nowhere."""
    T = len(people)
    K = next((len(p) for frame in people for p in frame), 17)
    tracks: dict[int, np.ndarray] = {}
    for t, (frame, labs) in enumerate(zip(people, labels)):
        for p, label in zip(frame, labs):
            track = tracks.setdefault(int(label), np.zeros((T, K, 3), np.float32)) if label >= 0 else None
            if track is not None and not track[t, :, 2].any():
                track[t] = p
    if not tracks:
        tracks = {0: np.zeros((T, K, 3), np.float32)}
    order = sorted(tracks, key=lambda i: -_prominence(tracks[i]))
    persons = []
    for i in order:
        keypoints, conf = clean_keypoints(tracks[i])
        persons.append(Person(i, keypoints2d=keypoints, keypoints_conf=conf))
    main, *others = persons
    meta = {**metadata, "person_rule": "all", "tracks": order}
    return PoseEstimates(keypoints2d=main.keypoints2d, keypoints_conf=main.keypoints_conf, keypoints_layout="coco17",
                         track_id=main.track_id, others=tuple(others), image_size=image_size, source=source,
                         metadata=meta)  # fmt: skip
