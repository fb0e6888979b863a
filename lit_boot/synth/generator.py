"""Synthetic human scenes with exact ground truth: :func:`make_scene`.

A textured ellipsoid body, animated procedurally or by a BVH file, walks in front of a
textured floor and wall, seen by a perspective camera that may pan or dolly. Every pixel of
frame t is a known surface point, so its position in frame t+1 (hence the forward flow) and
whether it is hidden there (the occlusion mask) are exact. The scene carries simulated
METRO-like 3D joints with weak-perspective cameras and DCPose-like COCO-17 keypoints.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import torch

from ..core.cameras import Cameras
from ..core.joints import LSP14, COCO17
from ..core.scene import GroundTruth, Scene
from .appearance import Appearance
from .body import Body, PartPoses
from .bvh import bvh_motion
from .camera_rig import CameraRig, frame_person
from .config import EstimateConfig, SynthConfig
from .estimates import simulate_keypoints, simulate_metro
from .motions import procedural_motion, procedural_skeleton
from .render import Hits, cast
from .skeleton import Motion, axis_angle_to_matrix

__all__ = ["SynthConfig", "make_scene"]

_LOCOMOTION = ("walk", "run", "bvh")


def _motion(cfg: SynthConfig, times: torch.Tensor) -> Motion:
    if cfg.motion == "bvh":
        return bvh_motion(Path(cfg.bvh), times, start=cfg.bvh_start, height_mm=cfg.body_height_mm)
    skeleton = procedural_skeleton(cfg.body_height_mm)
    return procedural_motion(
        cfg.motion, times, skeleton=skeleton, speed=cfg.speed, amplitude=cfg.amplitude, seed=cfg.seed
    )


def _place(motion: Motion, cfg: SynthConfig) -> Motion:
    """Turn the motion about the vertical so it faces (or travels towards) ``heading_deg``
    and centre its clip on the origin."""
    lm = motion.skeleton.landmarks
    _, pos = motion.global_transforms()
    travel = pos[-1, 0] - pos[0, 0]
    travel[1] = 0
    if cfg.motion in _LOCOMOTION and travel.norm() > 100.0:
        direction = travel
    else:  # facing = left x up
        left = pos[0, lm["left_hip"]] - pos[0, lm["right_hip"]]
        direction = torch.stack([-left[2], torch.zeros(()), left[0]])  # left x up
    current = math.atan2(float(direction[0]), float(direction[2]))
    default = 90.0 if cfg.motion in _LOCOMOTION else 160.0
    target = math.radians(default if cfg.heading_deg is None else cfg.heading_deg)
    W = axis_angle_to_matrix("y", torch.tensor(target - current, dtype=motion.rotations.dtype))
    rotations = motion.rotations.clone()
    rotations[:, 0] = W @ rotations[:, 0]
    root = motion.root_positions @ W.T
    centre = (pos[:, 0] @ W.T).mean(0)
    root = root - torch.stack([centre[0], torch.zeros(()), centre[2]])
    return Motion(motion.skeleton, motion.times, rotations, root)


def _sample_times(cfg: SynthConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """Frame times (T,) and blur sample times (T, S) in seconds."""
    dt = 1.0 / cfg.fps
    samples = max(1, cfg.motion_blur)
    half = cfg.shutter * dt / 2 if samples > 1 else 0.0
    frame_times = torch.arange(cfg.frames, dtype=torch.float64) * dt + half
    offsets = torch.linspace(-half, half, samples, dtype=torch.float64) if samples > 1 else torch.zeros(1)
    return frame_times, frame_times[:, None] + offsets[None].to(torch.float64)


def _world_planes(lo: torch.Tensor, hi: torch.Tensor, floor_y: float) -> torch.Tensor:
    """(2, 4) world planes n . x = d: the floor and a wall 2.5 m behind the person."""
    wall_z = float(hi[2]) + 2500.0
    return torch.tensor([[0.0, 1.0, 0.0, floor_y], [0.0, 0.0, 1.0, wall_z]])


class _Renderer:
    """Renders one scene's frames and ground truth from posed parts and a camera rig."""

    def __init__(self, body: Body, poses: PartPoses, rig: CameraRig, planes_w: torch.Tensor, look: Appearance):
        self.body, self.poses, self.rig, self.planes_w, self.look = body, poses, rig, planes_w, look

    def hits(self, i: int) -> Hits:
        R, C = self.rig.R[i], self.rig.C[i]
        centres = (self.poses.centres[i] - C) @ R.T
        axes = R @ self.poses.axes[i]
        n_c = self.planes_w[:, :3] @ R.T
        d_c = self.planes_w[:, 3] - self.planes_w[:, :3] @ C
        return cast(self.rig.K, centres, axes, self.poses.radii, torch.cat([n_c, d_c[:, None]], -1))

    def rest_coords(self, i: int, hits: Hits) -> torch.Tensor:
        """Rest-pose coordinates (N, 3) of the body pixels of ``hits`` at time ``i``."""
        on = hits.part >= 0
        p = hits.part[on]
        world = self.rig.to_world(hits.point[on], i)
        rel = world - self.poses.attach_pos[i, p]
        return (self.poses.attach_rot[i, p].transpose(-1, -2) @ rel[..., None])[..., 0] + self.poses.rest_origin[p]

    def colour(self, i: int, hits: Hits) -> torch.Tensor:
        """(H, W, 3) linear RGB in [0, 1] (before clipping) of the surfaces in ``hits``."""
        rgb = torch.zeros_like(hits.point)
        normal_w = hits.normal @ self.rig.R[i]
        on = hits.part >= 0
        if on.any():
            rgb[on] = self.look.shade(self.look.body_colour(hits.part[on], self.rest_coords(i, hits)), normal_w[on])
        bg = hits.plane >= 0
        world = self.rig.to_world(hits.point[bg], i)
        plane = hits.plane[bg]
        coords = torch.where((plane == 0)[:, None], world[:, [0, 2]], world[:, [0, 1]])
        rgb[bg] = self.look.shade(self.look.plane_colour(plane, coords), normal_w[bg])
        rgb[~(on | bg)] = 0.6  # sky (never seen with the default framing)
        return rgb

    def flow(self, i: int, j: int, hits: Hits, next_depth: torch.Tensor, next_index: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Exact forward flow (2, H, W) from time ``i`` to time ``j`` and the occlusion mask
        (H, W): pixels whose surface point is hidden, or outside the image, at ``j``."""
        world = self.rig.to_world(hits.point, i)
        on = hits.part >= 0
        if on.any():
            p = hits.part[on]
            rest = self.rest_coords(i, hits)
            world[on] = (self.poses.attach_rot[j, p] @ (rest - self.poses.rest_origin[p])[..., None])[..., 0] + self.poses.attach_pos[j, p]
        cam = self.rig.to_camera(world, next_index)
        K = self.rig.K
        target = K.project(cam)
        ys, xs = torch.meshgrid(torch.arange(K.height), torch.arange(K.width), indexing="ij")
        flow = torch.stack([target[..., 0] - xs, target[..., 1] - ys])
        tx, ty = target[..., 0].round().long(), target[..., 1].round().long()
        inside = (tx >= 0) & (tx < K.width) & (ty >= 0) & (ty < K.height) & (cam[..., 2] > 0)
        seen = next_depth[ty.clamp(0, K.height - 1), tx.clamp(0, K.width - 1)]
        occluded = ~inside | (cam[..., 2] > seen * 1.01 + 20.0)
        return flow.float(), occluded


@dataclass
class _Staging:
    """What the frames are rendered from: the motion, the posed body, the camera rig and the
    renderer, with T frames and S blur sub-frames per frame."""

    motion: Motion
    body: Body
    rig: CameraRig
    renderer: _Renderer
    T: int
    S: int


def _stage(cfg: SynthConfig, g: torch.Generator) -> _Staging:
    """Place the motion, frame it with the camera rig and build the renderer (its textures
    drawn from ``g``)."""
    frame_times, blur_times = _sample_times(cfg)
    T, S = blur_times.shape
    all_times = torch.cat([frame_times, blur_times.flatten()]) if S > 1 else frame_times
    motion = _place(_motion(cfg, all_times), cfg)
    body = Body(motion.skeleton, girth=cfg.girth)
    poses = body.pose(motion).to(torch.float32)
    ext = poses.radii.amax(-1)
    lo = (poses.centres - ext[:, None]).flatten(0, -2).amin(0)
    hi = (poses.centres + ext[:, None]).flatten(0, -2).amax(0)
    floor_y = float(poses.lowest_point().min()) - 1.0
    lo[1] = floor_y
    rig = frame_person(
        lo, hi, all_times.float(), cfg.height, cfg.width, cfg.fov_deg, cfg.fill,
        None if cfg.camera_height_mm is None else floor_y + cfg.camera_height_mm,
        cfg.pan_deg_per_s, cfg.dolly_mm_per_s,
    )  # fmt: skip
    # Texels of 1.5 px at the person's (the wall's) distance: the finest texture period is 3 px.
    mm_per_px = float((rig.C[:, 2] - (lo[2] + hi[2]) / 2).abs().mean()) / rig.K.fx
    wall_mm_per_px = mm_per_px + 2500.0 / rig.K.fx
    look = Appearance(body.material, g, body_texel_mm=1.5 * mm_per_px, background_texel_mm=1.5 * wall_mm_per_px)
    renderer = _Renderer(body, poses, rig, _world_planes(lo, hi, floor_y), look)
    return _Staging(motion, body, rig, renderer, T, S)


def _render(st: _Staging, cfg: SynthConfig, g: torch.Generator) -> tuple[torch.Tensor, ...]:
    """frames (T, 3, H, W) uint8 (motion blur over S sub-frames, sensor noise from ``g``), GT
    flows (T-1, 2, H, W) px, occluded (T-1, H, W), person masks (T, H, W) and depths (T, H, W) mm."""
    T, S, H, W, renderer = st.T, st.S, cfg.height, cfg.width, st.renderer
    frames = torch.empty(T, 3, H, W, dtype=torch.uint8)
    flows = torch.empty(T - 1, 2, H, W)
    occluded = torch.empty(T - 1, H, W, dtype=torch.bool)
    person = torch.empty(T, H, W, dtype=torch.bool)
    depths: list[torch.Tensor] = []
    hit_list: list[Hits | None] = []
    for i in range(T):
        hits = renderer.hits(i)
        hit_list.append(hits)
        depths.append(hits.depth)
        person[i] = hits.part >= 0
        if S > 1:
            rgb = sum(renderer.colour(T + i * S + s, renderer.hits(T + i * S + s)) for s in range(S)) / S
        else:
            rgb = renderer.colour(i, hits)
        noise = torch.randn(H, W, 3, generator=g) * (cfg.noise_std / 255.0) if cfg.noise_std > 0 else 0.0
        frames[i] = ((rgb + noise).clamp(0, 1) * 255.0).round().to(torch.uint8).permute(2, 0, 1)
        if i > 0:
            flows[i - 1], occluded[i - 1] = renderer.flow(i - 1, i, hit_list[i - 1], hits.depth, i)
            hit_list[i - 1] = None  # free memory
    return frames, flows, occluded, person, torch.stack(depths)


def _joints(st: _Staging, depths: torch.Tensor, H: int, W: int) -> tuple[torch.Tensor, ...]:
    """The true LSP-14 joints (T, 14, 3) mm camera frame and (T, 14, 2) px, the true COCO-17
    keypoints (T, 17, 2) px, and which keypoints a detector can see (T, 17) bool: inside the
    image, and their own surface not far behind the rendered one."""
    T, rig, body, motion = st.T, st.rig, st.body, st.motion
    lsp_world = body.landmark_positions(motion, LSP14.names)[:T]
    coco_world = torch.cat([body.face_points(motion)[:T], body.landmark_positions(motion, COCO17.names[5:])[:T]], 1)
    to_cam = lambda x: torch.einsum("tij,tkj->tki", rig.R[:T].double(), x.double() - rig.C[:T, None].double())  # noqa: E731
    joints3d, coco3d = to_cam(lsp_world).float(), to_cam(coco_world).float()
    joints2d, coco2d = rig.K.project(joints3d), rig.K.project(coco3d)
    px = coco2d.round().long()
    inside = (px[..., 0] >= 0) & (px[..., 0] < W) & (px[..., 1] >= 0) & (px[..., 1] < H)
    depth_at = torch.stack([depths[t][px[t, :, 1].clamp(0, H - 1), px[t, :, 0].clamp(0, W - 1)] for t in range(T)])
    visible = inside & (coco3d[..., 2] < depth_at + 0.08 * body.height_mm)
    return joints3d, joints2d, coco2d, visible


def make_scene(config: SynthConfig | None = None, **overrides) -> Scene:
    """Generate a synthetic scene (see :class:`SynthConfig`; keyword overrides allowed)."""
    cfg = replace(config or SynthConfig(), **overrides)
    if isinstance(cfg.estimates, dict):
        cfg = replace(cfg, estimates=EstimateConfig(**cfg.estimates))
    g = torch.Generator().manual_seed(cfg.seed)
    st = _stage(cfg, g)
    T, H, W, K = st.T, cfg.height, cfg.width, st.rig.K
    frames, flows, occluded, person, depths = _render(st, cfg, g)
    joints3d, joints2d, coco2d, visible = _joints(st, depths, H, W)
    gt_cams = Cameras("pinhole", torch.tensor([[K.fx, K.fy, K.cx, K.cy, 0.0, 0.0, 0.0]]).repeat(T, 1))
    est3d, cams = simulate_metro(joints3d.double(), joints2d.double(), cfg.estimates, g)
    keypoints, conf, events = simulate_keypoints(coco2d, visible, cfg.estimates, g)
    name = cfg.name or (f"synth_{cfg.motion}_s{cfg.seed}" if cfg.motion != "bvh" else f"synth_{Path(cfg.bvh).stem}_s{cfg.seed}")
    gt = GroundTruth(
        flow=flows, flow_valid=torch.ones(T - 1, H, W, dtype=torch.bool), flow_occluded=occluded, joints3d=joints3d,
        joints2d=joints2d.float(), joints_layout="lsp14", cameras=gt_cams, person_mask=person,
        keypoints2d=coco2d.float(),
    )  # fmt: skip
    metadata = {
        "generator": "lit_boot.synth",
        "config": json.loads(json.dumps(asdict(cfg))),  # tuples -> lists: loads back identical
        "keypoint_failures": events,
        "camera": {  # the true camera: x_cam = R @ (x_world - C); world axes x left, y up, z forward
            "fx_fy_cx_cy": [K.fx, K.fy, K.cx, K.cy],
            "world_to_camera_R": st.rig.R[:T].tolist(),
            "centre_mm": st.rig.C[:T].tolist(),
        },
    }
    return Scene(
        frames=frames, fps=cfg.fps, name=name, joints3d=est3d, joints3d_layout="lsp14", cameras=cams,
        keypoints2d=keypoints, keypoints_conf=conf, keypoints_layout="coco17", gt=gt, metadata=metadata,
    )  # fmt: skip
