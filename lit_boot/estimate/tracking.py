"""Tracking checks across frames for a single-person detector.

MediaPipe Pose follows one person: each frame's search region comes from the previous
frame's landmarks, and the person detector runs again only when tracking is lost. Nothing
guarantees it is the same person after a loss, so large jumps of the detection are flagged.
"""

from __future__ import annotations

import torch

__all__ = ["JUMP_POLICIES", "body_box", "drop_jumps", "find_jumps"]

#: keep: flag the frame in ``metadata["jumps"]`` only; drop: also treat it as a frame with
#: nobody (confidence 0, listed in ``metadata["missing_frames"]``).
JUMP_POLICIES = ("keep", "drop")


def body_box(keypoints: torch.Tensor, confidence: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Centre (2,) px and size (scalar: the larger side of the box, px) of one frame's
    keypoints (K, 2) with confidence (K,) > 0 (all keypoints when none has)."""
    seen = confidence > 0
    pts = keypoints[seen] if seen.any() else keypoints
    lo, hi = pts.amin(0), pts.amax(0)
    return (lo + hi) / 2, (hi - lo).amax().clamp_min(1.0)


def find_jumps(
    keypoints: torch.Tensor, confidence: torch.Tensor, found: torch.Tensor, max_jump: float = 0.5
) -> list[int]:
    """Frames (indices into T) whose detection jumped: the box centre moved more than
    ``max_jump`` x the previous box size x the number of frames since the previous frame with
    a person (``found``). keypoints (T, K, 2) px, confidence (T, K), found (T,) bool."""
    return _scan(keypoints, confidence, found, max_jump, drop=False)[0]


def drop_jumps(
    keypoints: torch.Tensor, confidence: torch.Tensor, found: torch.Tensor, max_jump: float = 0.5
) -> tuple[list[int], torch.Tensor]:
    """Like :func:`find_jumps`, but a jumped frame is dropped (compared frames are only those
    kept), so after a switch to another person every later frame of that person is dropped
    too. Returns (jumps, kept (T,) bool)."""
    return _scan(keypoints, confidence, found, max_jump, drop=True)


def _scan(
    keypoints: torch.Tensor, confidence: torch.Tensor, found: torch.Tensor, max_jump: float, drop: bool
) -> tuple[list[int], torch.Tensor]:
    kept = found.clone()
    jumps: list[int] = []
    last: int | None = None
    for t in range(found.shape[0]):
        if not found[t]:
            continue
        if last is not None:
            c0, size = body_box(keypoints[last], confidence[last])
            c1, _ = body_box(keypoints[t], confidence[t])
            if (c1 - c0).norm() > max_jump * size * (t - last):
                jumps.append(t)
                if drop:
                    kept[t] = False
                    continue
        last = t
    return jumps, kept
