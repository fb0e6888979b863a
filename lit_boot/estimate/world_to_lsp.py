"""Pure conversions of MediaPipe Pose output (no mediapipe import needed).

Conventions: pixels follow lit-boot (pixel centres at integer coordinates, x right, y down),
so a MediaPipe normalised coordinate ``x`` in [0, 1] (0 = the image's left edge) becomes
``x * W - 0.5``. MediaPipe *world* landmarks are metres, origin at the hips' midpoint, axes
aligned with the camera (x right, y down, z away from the camera); lit-boot 3D joints are the
same axes in millimetres, root-relative (LSP-14's root is the hips' midpoint).
"""

from __future__ import annotations

import torch

from ..core.cameras import Cameras, fit_weak_perspective
from ..core.joints import LSP14, MEDIAPIPE33, map_joints

__all__ = [
    "HEAD_TOP_FACTOR",
    "landmark_confidence",
    "landmarks_to_coco17",
    "world_to_lsp14",
    "square_crops",
    "fit_cameras",
    "nearest_found",
]

#: LSP's head top = ears' midpoint + HEAD_TOP_FACTOR * (ears' midpoint - shoulders' midpoint).
#: MediaPipe has no head top; with its typical 0.19-0.20 m from the shoulders' to the ears'
#: midpoint this puts the head top ~0.13 m above the ears (lit-boot's synthetic skeleton uses
#: 0.13 m from the head centre to the head top).
HEAD_TOP_FACTOR = 0.65


def landmark_confidence(visibility: torch.Tensor, presence: torch.Tensor | None = None) -> torch.Tensor:
    """Per-landmark confidence (...,) in [0, 1]: MediaPipe's ``visibility`` (likelihood that the
    landmark is in view and not occluded), times ``presence`` when the model reports it
    (MediaPipe 0.10.14's legacy Pose solution does not)."""
    conf = visibility if presence is None else visibility * presence
    return conf.clamp(0.0, 1.0)


def landmarks_to_coco17(landmarks: torch.Tensor, confidence: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """MediaPipe-33 landmarks (T, 33, 2) px with confidences (T, 33) -> COCO-17 keypoints
    (T, 17, 2) px and confidences (T, 17) (each COCO joint is one MediaPipe landmark)."""
    points, _, conf = map_joints(landmarks, MEDIAPIPE33, "coco17", confidence)
    return points, conf


def world_to_lsp14(world: torch.Tensor, head_top_factor: float = HEAD_TOP_FACTOR) -> torch.Tensor:
    """MediaPipe-33 world landmarks (T, 33, 3) metres -> LSP-14 joints (T, 14, 3) mm.

    Joints MediaPipe has are copied; the neck is the shoulders' midpoint; the head top (which
    MediaPipe lacks) is extrapolated from the shoulders' midpoint through the ears' midpoint
    (see :data:`HEAD_TOP_FACTOR`). The result is re-centred on the hips' midpoint.
    """
    mm = world * 1000.0
    joints, _, _ = map_joints(mm, MEDIAPIPE33, LSP14)
    neck = joints[..., LSP14.index("neck"), :]
    ears = 0.5 * (mm[..., MEDIAPIPE33.index("left_ear"), :] + mm[..., MEDIAPIPE33.index("right_ear"), :])
    joints[..., LSP14.index("head_top"), :] = ears + head_top_factor * (ears - neck)
    root = joints[..., list(LSP14.root), :].mean(-2, keepdim=True)
    return joints - root


def square_crops(
    keypoints: torch.Tensor, confidence: torch.Tensor, crop_size: float = 224.0, margin: float = 1.2
) -> torch.Tensor:
    """The square crop METRO/HMR would see, per frame: (T, 3) = (scale, start_x, start_y).

    The box is the extent of the keypoints (T, K, 2) px with confidence > 0 (all keypoints in
    a frame where none has), its side ``margin`` x the larger extent + 1 px; the image is
    scaled so the side becomes ``crop_size`` and the crop starts at box centre * scale (the
    convention of :func:`lit_boot.core.cameras.project_weak_perspective`).
    """
    seen = confidence > 0
    seen = torch.where(seen.any(-1, keepdim=True), seen, torch.ones_like(seen))
    big = torch.finfo(keypoints.dtype).max
    lo = torch.where(seen[..., None], keypoints, torch.full_like(keypoints, big)).amin(-2)
    hi = torch.where(seen[..., None], keypoints, torch.full_like(keypoints, -big)).amax(-2)
    side = (hi - lo).amax(-1) * margin + 1.0
    scale = crop_size / side
    centre = (lo + hi) / 2
    return torch.stack([scale, centre[:, 0] * scale, centre[:, 1] * scale], -1)


def fit_cameras(
    joints3d: torch.Tensor,
    keypoints: torch.Tensor,
    confidence: torch.Tensor,
    crop_size: float = 224.0,
    margin: float = 1.2,
) -> Cameras:
    """Weak-perspective cameras fitted per frame so that LSP-14 joints (T, 14, 3) mm project
    onto COCO-17 keypoints (T, 17, 2) px, each joint weighted by its keypoint confidence (T, 17)
    mapped to LSP-14 (the head top, which COCO lacks, weighs 0). Frames whose confidences are
    all 0 get unweighted fits (callers replace those frames; see :func:`nearest_found`)."""
    points, _, weights = map_joints(keypoints, "coco17", LSP14, confidence)
    empty = weights.sum(-1, keepdim=True) <= 0
    weights = torch.where(empty, torch.ones_like(weights), weights)
    weights[..., LSP14.index("head_top")] = 0.0
    crops = square_crops(keypoints, confidence, crop_size, margin)
    params = fit_weak_perspective(joints3d, points, crops, crop_size, weights)
    return Cameras("weak_perspective", params.float(), crops.float(), crop_size)


def nearest_found(found: torch.Tensor) -> torch.Tensor:
    """For each frame, the index (T,) int64 of the nearest frame where ``found`` (T,) bool is
    True (itself when found; the earlier one on a tie). Raises ValueError when none is."""
    idx = torch.nonzero(found).flatten()
    if idx.numel() == 0:
        raise ValueError("nearest_found: no frame has a person")
    t = torch.arange(found.shape[0])
    dist = (t[:, None] - idx[None, :]).abs()
    return idx[dist.argmin(-1)]  # argmin returns the first minimum: the earlier frame
