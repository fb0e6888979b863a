"""Simulated off-the-shelf estimates, with the errors real estimators make.

- METRO-like 3D joints (LSP-14, root-relative mm in camera orientation): a seeded per-joint
  bias, temporal jitter and occasional gross errors, scaled so the root-aligned MPJPE equals
  ``mpjpe_mm`` exactly; weak-perspective cameras (METRO/HMR, on a 224 px crop around the
  person) fitted to them by least squares against the true 2D joints.
- DCPose-like 2D keypoints (COCO-17) with confidences: pixel noise, low confidence and more
  noise where a joint is hidden, missed detections (confidence 0), *jumps* (a joint leaps far
  away for one frame with high confidence) and *locks* (for several frames a group of joints
  sits on a wrong place, frozen, with high confidence: the detector follows the wrong body).
"""

from __future__ import annotations

import torch

from ..core.cameras import Cameras, fit_weak_perspective
from ..core.joints import LSP14
from .config import EstimateConfig

__all__ = ["EstimateConfig", "simulate_metro", "simulate_keypoints"]

#: COCO-17 joint groups that lock together (a wrong body part, a wrong limb).
_LOCK_GROUPS = (
    tuple(range(17)),  # the whole body jumps to another person
    (5, 7, 9), (6, 8, 10), (11, 13, 15), (12, 14, 16), (0, 1, 2, 3, 4),
)  # fmt: skip


def _uniform(lo_hi: tuple[float, float], shape: tuple[int, ...], g: torch.Generator) -> torch.Tensor:
    lo, hi = lo_hi
    return lo + (hi - lo) * torch.rand(shape, generator=g)


def simulate_metro(
    joints3d: torch.Tensor, joints2d: torch.Tensor, config: EstimateConfig, g: torch.Generator
) -> tuple[torch.Tensor, Cameras]:
    """METRO-like estimates from true LSP-14 joints3d (T, 14, 3) mm and joints2d (T, 14, 2) px.

    Returns root-relative joints (T, 14, 3) with root-aligned MPJPE = ``config.mpjpe_mm`` and
    weak-perspective :class:`Cameras` whose projection of them approximates the image.
    """
    T, J, _ = joints3d.shape
    root = list(LSP14.root)
    bias = torch.randn(1, J, 3, generator=g) * config.bias_share**0.5
    jitter = torch.randn(T, J, 3, generator=g) * (1 - config.bias_share) ** 0.5
    gross = (torch.rand(T, J, 1, generator=g) < config.gross_error_prob) * torch.randn(T, J, 3, generator=g) * 4.0
    noise = bias + jitter + gross
    noise = noise - noise[:, root].mean(1, keepdim=True)
    unit_mpjpe = noise.norm(dim=-1).mean().clamp_min(1e-9)
    noise = noise * (config.mpjpe_mm / unit_mpjpe)
    centred = joints3d - joints3d[:, root].mean(1, keepdim=True)
    estimate = centred + noise
    # The crop METRO would see: a square 1.2x the joints' extent around their centre.
    lo, hi = joints2d.amin(1), joints2d.amax(1)
    side = (hi - lo).amax(-1) * 1.2 + 1.0
    scale = 224.0 / side
    crops = torch.stack([scale, (lo[:, 0] + hi[:, 0]) / 2 * scale, (lo[:, 1] + hi[:, 1]) / 2 * scale], -1)
    seen = joints2d + torch.randn(joints2d.shape, generator=g) * config.camera_noise_px * _pixel_unit(joints2d)
    params = fit_weak_perspective(estimate, seen, crops)
    return estimate.float(), Cameras("weak_perspective", params.float(), crops.float())


def _pixel_unit(points: torch.Tensor) -> torch.Tensor:
    """(T, 1, 1) scale: the person's image height / 256 px (at least 0.25)."""
    height = (points[..., 1].amax(-1) - points[..., 1].amin(-1)).clamp_min(1.0)
    return (height / 256.0).clamp_min(0.25)[:, None, None]


def simulate_keypoints(
    keypoints: torch.Tensor, visible: torch.Tensor, config: EstimateConfig, g: torch.Generator
) -> tuple[torch.Tensor, torch.Tensor, list[dict]]:
    """DCPose-like detections from true COCO-17 keypoints (T, 17, 2) px and their visibility
    (T, 17) bool. Returns (keypoints (T, 17, 2), confidences (T, 17), failure events)."""
    T, K, _ = keypoints.shape
    unit = _pixel_unit(keypoints)
    vis = visible[..., None]
    sigma = torch.where(vis, config.keypoint_noise_px, config.occluded_noise_px) * unit
    out = keypoints + torch.randn(keypoints.shape, generator=g) * sigma
    conf = torch.where(visible, _uniform(config.visible_conf, (T, K), g), _uniform(config.occluded_conf, (T, K), g))
    events: list[dict] = []
    # Jumps: one joint, one frame, far away, confident.
    jump = torch.rand(T, K, generator=g) < config.jump_prob
    for t, k in jump.nonzero().tolist():
        angle = torch.rand((), generator=g) * 6.2832
        dist = _uniform(config.jump_px, (), g) * unit[t, 0, 0]
        out[t, k] += torch.stack([angle.cos(), angle.sin()]) * dist
        conf[t, k] = _uniform(config.failure_conf, (), g)
        events.append({"kind": "jump", "frame": t, "joints": [k], "pixels": round(float(dist), 1)})
    # Locks: a group of joints freezes on a wrong place for a few frames, confidently.
    t = 0
    while t < T:
        if torch.rand((), generator=g) < config.lock_prob:
            group = list(_LOCK_GROUPS[int(torch.randint(len(_LOCK_GROUPS), (), generator=g))])
            length = int(torch.randint(config.lock_frames[0], config.lock_frames[1] + 1, (), generator=g))
            angle = torch.rand((), generator=g) * 6.2832
            dist = _uniform(config.lock_px, (), g) * unit[t, 0, 0]
            anchor = keypoints[t, group] + torch.stack([angle.cos(), angle.sin()]) * dist
            frames = list(range(t, min(T, t + length)))
            for f in frames:
                out[f, group] = anchor + torch.randn(anchor.shape, generator=g) * config.keypoint_noise_px * unit[f, 0, 0]
                conf[f, group] = _uniform(config.failure_conf, (len(group),), g)
            events.append({"kind": "lock", "frames": frames, "joints": group, "pixels": round(float(dist), 1)})
            t += length
        else:
            t += 1
    # Missed detections: confidence 0 (the position is whatever the detector left there).
    conf = torch.where(torch.rand(T, K, generator=g) < config.miss_prob, torch.zeros_like(conf), conf)
    return out.float(), conf.float(), events
