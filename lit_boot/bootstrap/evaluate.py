"""What the orchestrator measures after every stage.

- Flow against the scene's GT flow (when it has one): EPE over all valid, non-occluded pixels,
  on the person, on the background, and at the GT joints (the authors' convention: GT joint
  displacement vs the flow at the rounded pixel).
- Poses against the GT poses (when it has them): MPJPE / PA-MPJPE (mm) and acceleration
  error (mm/frame^2) in 3D mode, 2D keypoint error (px) in 2D-only mode.
- Flow-pose agreement, which needs no ground truth: the L_opt residual of the current poses
  under the current flow, i.e. the mean distance (px) between the flow sampled bilinearly at
  each pose joint in frame t and that joint's displacement to frame t+1, over confident joints
  inside the image.
- Drift: the mean distance (px) between a stage's flow and the initial flow outside the
  person (the sketch dilated), which needs no ground truth either.
- Image evidence, no ground truth (what the drift guard compares): ``photo_error``, the mean
  soft census error (7x7, 0..48) of frame t against frame t+1 warped by the flow, over the pixels
  whose target lies in the image; ``track_error``, the mean soft census distance between each
  confident pose joint's neighbourhood in frame t and its neighbourhood at the joint's position
  in frame t+1 (:func:`~lit_boot.flow.evidence.track_error`). Lower is better for both.

EPE-like means pool every selected pixel (or joint) of every pair, not per pair first.
"""

from __future__ import annotations

import torch

from ..core import Scene, get_layout, inside_image
from ..flow.evidence import photometric_error, track_error
from ..metrics import acceleration_error, epe_at_points, flow_errors, mpjpe, pa_mpjpe

__all__ = ["pose_points", "flow_metrics", "pose_metrics", "agreement", "drift", "photo_error", "pose_track_error"]


def pose_points(scene: Scene, mode: str, threshold: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
    """The pose as image points: (T, K, 2) px and a (T, K) bool of joints that count.

    3D mode: the joints projected by the cameras (every joint counts); 2D mode: the keypoints,
    counting those with confidence above ``threshold``.
    """
    if mode == "3d":
        points = scene.cameras.project(scene.joints3d.float())
        return points, torch.ones(points.shape[:2], dtype=torch.bool)
    points = scene.keypoints2d.float()
    conf = scene.keypoints_conf
    keep = conf > threshold if conf is not None else torch.ones(points.shape[:2], dtype=torch.bool)
    return points, keep


@torch.no_grad()
def agreement(flows: torch.Tensor, points: torch.Tensor, keep: torch.Tensor) -> float:
    """Mean |flow(p_t) - (p_t+1 - p_t)| px over pairs and kept joints inside the image.

    flows: (T-1, 2, H, W) px; points: (T, K, 2) px; keep: (T, K) bool (a joint counts in a pair
    when kept in both frames). NaN when no joint counts.
    """
    H, W = flows.shape[-2:]
    p0, p1 = points[:-1].float(), points[1:].float()
    visible = keep[:-1] & keep[1:] & inside_image(p0, H, W)
    err = epe_at_points(flows.float(), p0, p1 - p0, visible, mode="bilinear")
    n = visible.sum()
    return float(err.sum() / n) if n else float("nan")


@torch.no_grad()
def flow_metrics(scene: Scene, flows: torch.Tensor) -> dict[str, float]:
    """EPE all / person / background / at GT joints (px) of ``flows`` (T-1, 2, H, W) against
    the scene's GT flow; {} without one."""
    gt = scene.gt
    if gt is None or gt.flow is None:
        return {}
    flows = flows.float()
    valid = gt.flow_mask()
    out = {"epe": float(flow_errors(flows, gt.flow.float(), valid)["epe"])}
    if gt.person_mask is not None:
        person = gt.person_mask[:-1]
        out["epe_person"] = float(flow_errors(flows, gt.flow.float(), valid & person)["epe"])
        out["epe_background"] = float(flow_errors(flows, gt.flow.float(), valid & ~person)["epe"])
    if gt.joints2d is not None:
        j = gt.joints2d.float()
        H, W = flows.shape[-2:]
        visible = inside_image(j[:-1], H, W)
        err = epe_at_points(flows, j[:-1], j[1:] - j[:-1], visible, mode="nearest")
        out["epe_joints"] = float(err.sum() / visible.sum()) if visible.any() else float("nan")
    return out


@torch.no_grad()
def pose_metrics(scene: Scene, mode: str) -> dict[str, float]:
    """The scene's current estimates against its GT: mpjpe_mm, pa_mpjpe_mm,
    accel_mm_per_frame2 (3D mode, GT joints in the same layout) or kp2d_px (2D mode); {}
    without ground truth."""
    gt = scene.gt
    if gt is None:
        return {}
    if mode == "3d":
        if gt.joints3d is None or scene.joints3d is None or get_layout(gt.joints_layout) != get_layout(scene.joints3d_layout):
            return {}
        layout = get_layout(scene.joints3d_layout)
        root = layout.root or (0,)
        pred, target = scene.joints3d.float(), gt.joints3d.float()
        out = {
            "mpjpe_mm": float(mpjpe(pred, target, root=root).mean()),
            "pa_mpjpe_mm": float(pa_mpjpe(pred, target)),
        }
        if pred.shape[0] >= 3:
            out["accel_mm_per_frame2"] = float(acceleration_error(pred, target, root=root).mean())
        return out
    if gt.keypoints2d is None or scene.keypoints2d is None:
        return {}
    return {"kp2d_px": float((scene.keypoints2d.float() - gt.keypoints2d.float()).norm(dim=-1).mean())}


@torch.no_grad()
def drift(flows: torch.Tensor, initial: torch.Tensor, person: torch.Tensor) -> float:
    """Mean |flows - initial| px over the pixels outside ``person`` (T-1, H, W) bool."""
    outside = ~person
    n = outside.sum()
    if not n:
        return float("nan")
    return float((flows.float() - initial.float()).norm(dim=1)[outside].sum() / n)


@torch.no_grad()
def photo_error(frames: torch.Tensor, flows: torch.Tensor) -> float:
    """Mean census error (0..48) of ``flows`` (T-1, 2, H, W) px on ``frames`` (T, 3, H, W)
    uint8, pooled over the pixels of every pair whose target is in the image; NaN if none."""
    total, count = 0.0, 0
    for t in range(flows.shape[0]):  # one pair at a time: census maps are 49 channels deep
        error, valid = photometric_error(frames[t : t + 1], frames[t + 1 : t + 2], flows[t : t + 1].float())
        total, count = total + float(error[valid].sum()), count + int(valid.sum())
    return total / count if count else float("nan")


@torch.no_grad()
def pose_track_error(frames: torch.Tensor, points: torch.Tensor, keep: torch.Tensor) -> float:
    """Mean census distance (0..48) along the pose's joint tracks: ``points`` (T, K, 2) px,
    ``keep`` (T, K) bool (a joint counts in a pair when kept in both frames and inside both
    images); NaN when no joint counts."""
    total, count = 0.0, 0
    for t in range(frames.shape[0] - 1):
        error, valid = track_error(frames[t : t + 1], frames[t + 1 : t + 2], points[t : t + 1].float(),
                                   points[t + 1 : t + 2].float())  # fmt: skip
        valid = valid[0] & keep[t] & keep[t + 1]
        total, count = total + float(error[0][valid].sum()), count + int(valid.sum())
    return total / count if count else float("nan")
