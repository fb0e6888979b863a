"""A borrowed pose: where two people overlap, the crop of one shows the other's pose.

MediaPipe Pose finds one person per crop, and in the crop of a person partly hidden behind
another it often finds the one in front: that pose, on the hidden person's track, would teach the
front person's motion as the hidden one's and switch identities from frame to frame. The pose's
look tells (:mod:`.looks`: the colours near its joints, so the clothes of whoever it lies on).
:func:`borrowed_frames` takes each person's *own* look from the frames where its box overlaps no
other person's (IoU below :data:`OVERLAP`: the crop shows nobody else), and in a frame where it
does overlap, a pose whose look is nearer an overlapping person's own look than its track's own,
by :data:`MARGIN` in Hellinger distance, is that person's: the track has no pose there. A person
with no clear frame has no own look; its pose is borrowed where it looks like an overlapping
person's within :data:`~.people_track.MAX_LOOK` (as near as a person found again after a gap).
BENCHMARKS.md, "A borrowed pose". Keypoints px; boxes x0, y0, x1, y1 px, score (0: no box).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from .looks import check_rgb_frames, joint_look, look_distance
from .people_track import MAX_LOOK
from .track_cost import box_overlaps, box_side

__all__ = ["borrowed_frames", "MARGIN", "OVERLAP"]

#: Two boxes overlap (their crops may show each other's person) from this IoU on.
OVERLAP = 0.1
#: How much nearer another person's own look a pose's look must be than its track's own look.
MARGIN = 0.1


def _looks(frames: torch.Tensor, keypoints: torch.Tensor, confidence: torch.Tensor,
           boxes: torch.Tensor) -> list[torch.Tensor | None]:  # fmt: skip
    """One person's look per frame (None: no box, or too few confident joints)."""
    out: list[torch.Tensor | None] = []
    for frame, kp, conf, box in zip(frames, keypoints, confidence, boxes):
        look = joint_look(frame, torch.cat([kp, conf[:, None]], -1), float(box_side(box[:4]))) if box[4] > 0 else None
        out.append(look if look is not None and float(look.sum()) > 0 else None)
    return out


def borrowed_frames(frames: torch.Tensor, keypoints: Sequence[torch.Tensor], confidence: Sequence[torch.Tensor],
                    boxes: Sequence[torch.Tensor], max_look: float = MAX_LOOK) -> list[torch.Tensor]:  # fmt: skip
    """For P people in frames (T, 3, H, W) uint8 RGB, each one's keypoints (T, K, 2) px,
    confidences (T, K) (0: no pose) and boxes (T, 5): per person a (T,) bool of the frames whose
    pose is another overlapping person's (module docstring; ``max_look``: the distance within which
    a person without an own look is taken to show another's)."""
    check_rgb_frames(frames)
    P = len(keypoints)
    out = [torch.zeros(frames.shape[0], dtype=torch.bool) for _ in range(P)]
    if P < 2:
        return out
    looks = [_looks(frames, keypoints[p], confidence[p], boxes[p]) for p in range(P)]
    overlaps = box_overlaps(torch.stack(list(boxes)), OVERLAP)  # (T, P, P)
    own = []
    for p in range(P):
        clear = [look for look, over in zip(looks[p], overlaps[:, p]) if look is not None and not bool(over.any())]
        own.append(torch.stack(clear).mean(0) if clear else None)
    for p in range(P):
        for t, look in enumerate(looks[p]):
            others = [q for q in torch.nonzero(overlaps[t, p]).flatten().tolist() if own[q] is not None]
            if look is None or not others:
                continue
            limit = float(look_distance(look, own[p])) - MARGIN if own[p] is not None else max_look
            out[p][t] = any(float(look_distance(look, own[q])) < limit for q in others)
    return out
