"""Every person of an external multi-person keypoint file (COCO results from RTMPose, ViTPose,
OpenPose; DCPose), linked into tracks by the person tracker when the file has no track ids.

:func:`link_keypoint_people` boxes each detection's keypoints (those with confidence > 0) and runs
:func:`~.people_track.track_people` on the boxes and the keypoints (an optimal assignment on
velocity-predicted boxes and joints: ids kept through crossings); :func:`read_tracked_estimates` reads a file with every
person this way (``lit_boot.data.readers.read_estimates(person="all", link=...)``).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from ..data.readers import PoseEstimates, read_estimates
from ..data.readers.estimates import detect_kind
from ..data.readers.frame_people import keypoint_box
from .people_track import people_count, track_people

__all__ = ["link_keypoint_people", "read_tracked_estimates"]


def link_keypoint_people(people: Sequence[Sequence[np.ndarray]], scores: Sequence[Sequence[float]] | None = None,
                         **tracker: Any) -> list[list[int]]:  # fmt: skip
    """The track of each detection: ``people[t][i]`` (K, 3) (x, y, confidence) -> ``labels[t][i]``,
    the index of its track (most prominent first) or -1 (no keypoint found, or a stray detection the
    tracker dropped). ``scores``: detection scores (default: the mean keypoint confidence);
    ``tracker``: :func:`~.people_track.track_people` options."""
    detections, keypoints, index = [], [], []
    for t, frame in enumerate(people):
        rows, poses, kept = [], [], []
        for i, p in enumerate(frame):
            box = keypoint_box(np.asarray(p, dtype=np.float64))
            if box is None:
                continue
            score = scores[t][i] if scores is not None else float(np.clip(p[p[:, 2] > 0, 2], 0, 1).mean())
            rows.append([*box, min(max(float(score), 1e-3), 1.0)])
            poses.append(torch.as_tensor(np.asarray(p, dtype=np.float32)))
            kept.append(i)
        detections.append(torch.tensor(rows, dtype=torch.float32).reshape(-1, 5))
        keypoints.append(torch.stack(poses) if poses else torch.zeros(0, 0, 3))
        index.append(kept)
    tracks = track_people(detections, keypoints=keypoints, **tracker)
    labels = [[-1] * len(frame) for frame in people]
    for p, track in enumerate(tracks):
        for t, box in enumerate(track):
            if box[4] <= 0:
                continue
            same = (detections[t] == box).all(-1).nonzero()  # a detected frame: the detection's own box
            if len(same):
                labels[t][index[t][int(same[0])]] = p
    return labels


def read_tracked_estimates(path: str | os.PathLike, *, kind: str | None = None, people: str | int = "all",
                           **options: Any) -> PoseEstimates:  # fmt: skip
    """Every person of a COCO keypoint or DCPose file (``kind`` None: detected from the file),
    linked by the file's track ids when every detection has one, else by
    :func:`link_keypoint_people` (a lit-boot pose file: its people as saved); ``people``: all,
    largest or the N most prominent. ``options`` go to the reader (``image_ids``, ``image_size``, ...)."""
    kind = kind or detect_kind(path)
    if kind in ("dcpose", "coco"):
        est = read_estimates(path, kind=kind, person="all", link=link_keypoint_people, **options)
    else:  # a lit-boot pose file holds its people already; METRO has one
        est = read_estimates(path, kind=None if kind == "?" else kind, **options)
    return est.with_people(est.people()[: max(people_count(people, est.num_people), 1)])
