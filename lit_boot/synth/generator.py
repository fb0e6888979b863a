"""Synthetic human scenes with exact ground truth: :func:`make_scene`.

A textured ellipsoid body, animated procedurally or by a BVH file, walks in front of a
textured floor and wall, seen by a perspective camera that may pan or dolly. Every pixel of
frame t is a known surface point, so its position in frame t+1 (hence the forward flow) and
whether it is hidden there (the occlusion mask) are exact. The scene carries simulated
METRO-like 3D joints with weak-perspective cameras and DCPose-like COCO-17 keypoints.

With ``people`` = N > 1 the same frames hold N bodies (:mod:`lit_boot.synth.crowd` places the
others so that they cross person 0), composited by depth: every pixel shows the nearest surface
and carries its flow. Person 0's ground truth and estimates are the scene's own; the others'
are ``gt.others`` (:class:`~lit_boot.core.scene.PersonTruth`) and ``Scene.others``, and every
person gets boxes around its visible true keypoints.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import torch

from ..core.cameras import Cameras
from ..core.joints import LSP14, COCO17
from ..core.people import Person
from ..core.scene import GroundTruth, PersonTruth, Scene
from .appearance import Appearance
from .body import Body, PartPoses, concat_poses
from .bvh import bvh_motion
from .camera_rig import CameraRig, frame_person
from .config import EstimateConfig, SynthConfig
from .crowd import Walker, cross, crowd_generator, draw_walkers, keypoint_boxes
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


def _place(motion: Motion, kind: str, heading_deg: float | None) -> Motion:
    """Turn the motion (of ``kind``) about the vertical so it faces (or travels towards)
    ``heading_deg`` and centre its clip on the origin."""
    lm = motion.skeleton.landmarks
    _, pos = motion.global_transforms()
    travel = pos[-1, 0] - pos[0, 0]
    travel[1] = 0
    if kind in _LOCOMOTION and travel.norm() > 100.0:
        direction = travel
    else:  # facing = left x up
        left = pos[0, lm["left_hip"]] - pos[0, lm["right_hip"]]
        direction = torch.stack([-left[2], torch.zeros(()), left[0]])  # left x up
    current = math.atan2(float(direction[0]), float(direction[2]))
    default = 90.0 if kind in _LOCOMOTION else 160.0
    target = math.radians(default if heading_deg is None else heading_deg)
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
    """Renders one scene's frames and ground truth from posed parts and a camera rig.

    poses: every person's parts, one after another; groups: each person's slice of them;
    looks: each person's appearance (person 0's also gives the background and the light).
    """

    def __init__(self, poses: PartPoses, groups: list[slice], rig: CameraRig, planes_w: torch.Tensor,
                 looks: list[Appearance]):  # fmt: skip
        self.poses, self.groups, self.rig, self.planes_w, self.looks = poses, groups, rig, planes_w, looks
        self.look = looks[0]
        self.owner = torch.cat([torch.full((g.stop - g.start,), p) for p, g in enumerate(groups)])  # part -> person

    def hits(self, i: int) -> Hits:
        R, C = self.rig.R[i], self.rig.C[i]
        centres = (self.poses.centres[i] - C) @ R.T
        axes = R @ self.poses.axes[i]
        n_c = self.planes_w[:, :3] @ R.T
        d_c = self.planes_w[:, 3] - self.planes_w[:, :3] @ C
        planes = torch.cat([n_c, d_c[:, None]], -1)
        return cast(self.rig.K, centres, axes, self.poses.radii, planes, groups=self.groups)

    def who(self, hits: Hits) -> torch.Tensor:
        """(H, W) int8: the person each pixel of ``hits`` shows (-1: background)."""
        return torch.where(hits.part >= 0, self.owner[hits.part.clamp_min(0)], -1).to(torch.int8)

    def rest_coords(self, i: int, hits: Hits, on: torch.Tensor | None = None) -> torch.Tensor:
        """Rest-pose coordinates (N, 3) of the body pixels of ``hits`` (those of ``on``) at time ``i``."""
        on = hits.part >= 0 if on is None else on
        p = hits.part[on]
        world = self.rig.to_world(hits.point[on], i)
        rel = world - self.poses.attach_pos[i, p]
        return (self.poses.attach_rot[i, p].transpose(-1, -2) @ rel[..., None])[..., 0] + self.poses.rest_origin[p]

    def colour(self, i: int, hits: Hits) -> torch.Tensor:
        """(H, W, 3) linear RGB in [0, 1] (before clipping) of the surfaces in ``hits``."""
        rgb = torch.zeros_like(hits.point)
        normal_w = hits.normal @ self.rig.R[i]
        who = self.who(hits)
        for person, (look, group) in enumerate(zip(self.looks, self.groups)):
            on = who == person
            if on.any():
                colour = look.body_colour(hits.part[on] - group.start, self.rest_coords(i, hits, on))
                rgb[on] = self.look.shade(colour, normal_w[on])
        bg = hits.plane >= 0
        world = self.rig.to_world(hits.point[bg], i)
        plane = hits.plane[bg]
        coords = torch.where((plane == 0)[:, None], world[:, [0, 2]], world[:, [0, 1]])
        rgb[bg] = self.look.shade(self.look.plane_colour(plane, coords), normal_w[bg])
        rgb[~((hits.part >= 0) | bg)] = 0.6  # sky (never seen with the default framing)
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
class _Actor:
    """One person of the scene: its motion (at every render time), body and posed parts."""

    motion: Motion
    body: Body
    poses: PartPoses

    @classmethod
    def of(cls, motion: Motion, girth: float) -> _Actor:
        """The person doing ``motion``, its limbs' thickness times ``girth``."""
        body = Body(motion.skeleton, girth=girth)
        return cls(motion, body, body.pose(motion).to(torch.float32))


@dataclass
class _Staging:
    """What the frames are rendered from: the people (person 0 first, then ``walkers``' people),
    the camera rig and the renderer, with T frames and S blur sub-frames per frame."""

    actors: list[_Actor]
    walkers: list[Walker]
    rig: CameraRig
    renderer: _Renderer
    T: int
    S: int


def _actors(cfg: SynthConfig, times: torch.Tensor, T: int, walkers: list[Walker]) -> list[_Actor]:
    """Person 0 (the config's motion and body) and one walker per entry of ``walkers``, crossing it."""
    motion = _place(_motion(cfg, times), cfg.motion, cfg.heading_deg)
    actors = [_Actor.of(motion, cfg.girth)]
    for w in walkers:
        skeleton = procedural_skeleton(w.height_mm)
        own = procedural_motion(w.kind, times, skeleton=skeleton, speed=w.speed, amplitude=w.amplitude, seed=w.seed)
        actors.append(_Actor.of(cross(_place(own, w.kind, w.heading_deg), motion, w, T), w.girth))
    return actors


def _extent(poses: PartPoses) -> tuple[torch.Tensor, torch.Tensor]:
    """The world box (lo (3,), hi (3,)) mm of every ellipsoid's bounding sphere over the clip."""
    ext = poses.radii.amax(-1)
    return (poses.centres - ext[:, None]).flatten(0, -2).amin(0), (poses.centres + ext[:, None]).flatten(0, -2).amax(0)


def _look(body: Body, g: torch.Generator, rig: CameraRig, z_mm: float, wall_mm_per_px: float,
          other: bool) -> Appearance:  # fmt: skip
    """A person's appearance, its texels of 1.5 px at its distance (at ``z_mm``); another person
    than person 0 (``other``) wears shirt and trousers of colours drawn from ``g``."""
    mm_per_px = float((rig.C[:, 2] - z_mm).abs().mean()) / rig.K.fx
    clothes = {m: torch.rand(3, generator=g) * 0.7 + 0.15 for m in ("shirt", "pants")} if other else None
    return Appearance(body.material, g, body_texel_mm=1.5 * mm_per_px, background_texel_mm=wall_mm_per_px,
                      base_colours=clothes)  # fmt: skip


def _stage(cfg: SynthConfig, g: torch.Generator) -> _Staging:
    """Place the people's motions, frame them with the camera rig and build the renderer (person
    0's textures drawn from ``g``, the other people and their textures from their own generator)."""
    frame_times, blur_times = _sample_times(cfg)
    T, S = blur_times.shape
    all_times = torch.cat([frame_times, blur_times.flatten()]) if S > 1 else frame_times
    crowd = crowd_generator(cfg.seed)
    walkers = draw_walkers(cfg, crowd)
    actors = _actors(cfg, all_times, T, walkers)
    poses = concat_poses([a.poses for a in actors])
    lo, hi = _extent(poses)
    floor_y = float(poses.lowest_point().min()) - 1.0
    lo[1] = floor_y
    rig = frame_person(
        lo, hi, all_times.float(), cfg.height, cfg.width, cfg.fov_deg, cfg.fill,
        None if cfg.camera_height_mm is None else floor_y + cfg.camera_height_mm,
        cfg.pan_deg_per_s, cfg.dolly_mm_per_s,
    )  # fmt: skip
    # Texels of 1.5 px at each person's (the wall's) distance: the finest texture period is 3 px.
    wall_mm_per_px = 1.5 * (float((rig.C[:, 2] - (lo[2] + hi[2]) / 2).abs().mean()) / rig.K.fx + 2500.0 / rig.K.fx)
    looks = []
    for p, actor in enumerate(actors):
        a_lo, a_hi = _extent(actor.poses) if len(actors) > 1 else (lo, hi)
        looks.append(_look(actor.body, crowd if p else g, rig, (a_lo[2] + a_hi[2]) / 2, wall_mm_per_px, p > 0))
    sizes = [a.poses.radii.shape[0] for a in actors]
    groups = [slice(sum(sizes[:p]), sum(sizes[: p + 1])) for p in range(len(actors))]
    renderer = _Renderer(poses, groups, rig, _world_planes(lo, hi, floor_y), looks)
    return _Staging(actors, walkers, rig, renderer, T, S)


def _render(st: _Staging, cfg: SynthConfig, g: torch.Generator) -> tuple[torch.Tensor, ...]:
    """frames (T, 3, H, W) uint8 (motion blur over S sub-frames, sensor noise from ``g``), GT
    flows (T-1, 2, H, W) px, occluded (T-1, H, W), who (T, H, W) int8 (the person each pixel
    shows, -1 none) and depths (T, H, W) mm."""
    T, S, H, W, renderer = st.T, st.S, cfg.height, cfg.width, st.renderer
    frames = torch.empty(T, 3, H, W, dtype=torch.uint8)
    flows = torch.empty(T - 1, 2, H, W)
    occluded = torch.empty(T - 1, H, W, dtype=torch.bool)
    who = torch.empty(T, H, W, dtype=torch.int8)
    depths: list[torch.Tensor] = []
    hit_list: list[Hits | None] = []
    for i in range(T):
        hits = renderer.hits(i)
        hit_list.append(hits)
        depths.append(hits.depth)
        who[i] = renderer.who(hits)
        if S > 1:
            rgb = sum(renderer.colour(T + i * S + s, renderer.hits(T + i * S + s)) for s in range(S)) / S
        else:
            rgb = renderer.colour(i, hits)
        noise = torch.randn(H, W, 3, generator=g) * (cfg.noise_std / 255.0) if cfg.noise_std > 0 else 0.0
        frames[i] = ((rgb + noise).clamp(0, 1) * 255.0).round().to(torch.uint8).permute(2, 0, 1)
        if i > 0:
            flows[i - 1], occluded[i - 1] = renderer.flow(i - 1, i, hit_list[i - 1], hits.depth, i)
            hit_list[i - 1] = None  # free memory
    return frames, flows, occluded, who, torch.stack(depths)


def _joints(actor: _Actor, rig: CameraRig, T: int, depths: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """A person's true LSP-14 joints (T, 14, 3) mm camera frame and (T, 14, 2) px, true COCO-17
    keypoints (T, 17, 2) px, and which keypoints a detector can see (T, 17) bool: inside the
    image, and their own surface not far behind the rendered one (which may be another person's)."""
    body, motion, H, W = actor.body, actor.motion, rig.K.height, rig.K.width
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


def _estimates(truth: tuple[torch.Tensor, ...], cfg: SynthConfig, g: torch.Generator) -> tuple:
    """A person's simulated estimates from its truth (:func:`_joints`): METRO-like joints (T, 14, 3)
    with cameras, DCPose-like keypoints (T, 17, 2) with confidences (T, 17), failure events."""
    joints3d, joints2d, coco2d, visible = truth
    est3d, cams = simulate_metro(joints3d.double(), joints2d.double(), cfg.estimates, g)
    keypoints, conf, events = simulate_keypoints(coco2d, visible, cfg.estimates, g)
    return est3d, cams, keypoints, conf, events


def _others(st: _Staging, truths: list[tuple], estimates: list[tuple], who: torch.Tensor) -> tuple[tuple, tuple]:
    """The other people's ground truth (PersonTruth, ...) and estimates (Person, ...), track ids 1 .. N-1."""
    gts, people = [], []
    for p, w in enumerate(st.walkers, start=1):
        joints3d, joints2d, coco2d, visible = truths[p]
        est3d, cams, keypoints, conf, _ = estimates[p]
        gts.append(PersonTruth(w.track_id, joints3d=joints3d, joints2d=joints2d.float(), keypoints2d=coco2d.float(),
                               person_mask=who == p))  # fmt: skip
        people.append(Person(w.track_id, joints3d=est3d, cameras=cams, keypoints2d=keypoints, keypoints_conf=conf,
                             person_boxes=keypoint_boxes(coco2d, visible)))  # fmt: skip
    return tuple(gts), tuple(people)


def make_scene(config: SynthConfig | None = None, **overrides) -> Scene:
    """Generate a synthetic scene (see :class:`SynthConfig`; keyword overrides allowed)."""
    cfg = replace(config or SynthConfig(), **overrides)
    if isinstance(cfg.estimates, dict):
        cfg = replace(cfg, estimates=EstimateConfig(**cfg.estimates))
    g = torch.Generator().manual_seed(cfg.seed)
    st = _stage(cfg, g)
    T, H, W, K = st.T, cfg.height, cfg.width, st.rig.K
    frames, flows, occluded, who, depths = _render(st, cfg, g)
    truths = [_joints(actor, st.rig, T, depths) for actor in st.actors]
    estimates = [_estimates(truth, cfg, g) for truth in truths]
    (joints3d, joints2d, coco2d, visible), (est3d, cams, keypoints, conf, events) = truths[0], estimates[0]
    gt_others, others = _others(st, truths, estimates, who)
    gt_cams = Cameras("pinhole", torch.tensor([[K.fx, K.fy, K.cx, K.cy, 0.0, 0.0, 0.0]]).repeat(T, 1))
    name = cfg.name or (f"synth_{cfg.motion}_s{cfg.seed}" if cfg.motion != "bvh" else f"synth_{Path(cfg.bvh).stem}_s{cfg.seed}")
    gt = GroundTruth(
        flow=flows, flow_valid=torch.ones(T - 1, H, W, dtype=torch.bool), flow_occluded=occluded, joints3d=joints3d,
        joints2d=joints2d.float(), joints_layout="lsp14", cameras=gt_cams, person_mask=who >= 0,
        keypoints2d=coco2d.float(), others=gt_others,
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
    if others:  # the other people: how they were drawn, and their keypoint failures
        metadata["people"] = [w.describe() | {"keypoint_failures": e[4]} for w, e in zip(st.walkers, estimates[1:])]
    return Scene(
        frames=frames, fps=cfg.fps, name=name, joints3d=est3d, joints3d_layout="lsp14", cameras=cams,
        keypoints2d=keypoints, keypoints_conf=conf, keypoints_layout="coco17", gt=gt, metadata=metadata,
        person_boxes=keypoint_boxes(coco2d, visible) if others else None, others=others,
    )  # fmt: skip
