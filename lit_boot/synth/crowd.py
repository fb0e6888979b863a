"""The other people of a synthetic scene with several (``SynthConfig.people`` > 1).

Person 0 is the scene's main person, the one SynthConfig's motion, body and heading describe.
Every other person p = 1 .. N-1 walks (runs, when person 0 runs) sideways across the frame the
other way to person 0, at its own depth: alternately behind and in front of person 0 (p = 1
behind, p = 2 in front, p = 3 further behind, ...), 0.55-0.75 body heights apart per step. At
a crossing time drawn in the middle 60% of the clip (in the p-th of N-1 equal slots of it, so
the others do not move as a group) it passes person 0, 0.08-0.16 body heights to one side
(the others alternately to either side): the two overlap in the image and the nearer one hides
part of the other. (In a clip too short for a whole crossing they only overlap.)
Its height, girth, speed, amplitude, gait seed and clothes are drawn from a generator of its
own, seeded by the scene's seed (so person 0 and the background take the same draws from the
scene's generator as in a single-person scene).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch

from .config import SynthConfig
from .skeleton import Motion

__all__ = ["Walker", "crowd_generator", "draw_walkers", "cross", "keypoint_boxes"]

#: Added to the scene's seed for the generator of the other people.
_CROWD_SEED = 7_919


@dataclass(frozen=True)
class Walker:
    """One other person: track_id; kind (walk or run); seed of its gait variations; height_mm;
    girth and speed and amplitude (factors); heading_deg (as SynthConfig's); depth_mm (how far
    behind person 0 it passes, negative: in front); crossing (the fractional frame index at
    which it passes person 0); side_mm (how far to person 0's side in x, world mm)."""

    track_id: int
    kind: str
    seed: int
    height_mm: float
    girth: float
    speed: float
    amplitude: float
    heading_deg: float
    depth_mm: float
    crossing: float
    side_mm: float

    def describe(self) -> dict:
        """The walker as JSON-ready numbers (the scene's metadata)."""
        return {k: round(v, 3) if isinstance(v, float) else v for k, v in asdict(self).items()}


def crowd_generator(seed: int) -> torch.Generator:
    """The generator the other people (their walks and clothes) are drawn from."""
    return torch.Generator().manual_seed(seed + _CROWD_SEED)


def _uniform(lo: float, hi: float, g: torch.Generator) -> float:
    return lo + (hi - lo) * float(torch.rand((), generator=g, dtype=torch.float64))


def draw_walkers(cfg: SynthConfig, g: torch.Generator) -> list[Walker]:
    """The people 1 .. ``cfg.people`` - 1 of a scene, drawn from ``g``."""
    default = 90.0 if cfg.motion in ("walk", "run", "bvh") else 160.0
    main_heading = default if cfg.heading_deg is None else cfg.heading_deg
    heading = 270.0 if math.sin(math.radians(main_heading)) >= 0 else 90.0  # the other way across the image
    side = 1.0 if torch.rand((), generator=g) < 0.5 else -1.0  # the side of person 0 that walker 2 passes
    walkers = []
    for p in range(1, cfg.people):
        step = (p + 1) // 2 * _uniform(0.55, 0.75, g) * cfg.body_height_mm
        walkers.append(Walker(
            track_id=p, kind="run" if cfg.motion == "run" else "walk",
            seed=int(torch.randint(0, 2**31 - 1, (), generator=g)),
            height_mm=cfg.body_height_mm * _uniform(0.9, 1.06, g), girth=cfg.girth * _uniform(0.85, 1.2, g),
            speed=cfg.speed * _uniform(0.8, 1.2, g), amplitude=cfg.amplitude * _uniform(0.85, 1.15, g),
            heading_deg=heading, depth_mm=step if p % 2 else -step,
            crossing=(cfg.frames - 1) * (0.2 + 0.6 * _uniform(p - 1, p, g) / (cfg.people - 1)),
            side_mm=(-1.0) ** p * side * _uniform(0.08, 0.16, g) * cfg.body_height_mm,
        ))  # fmt: skip
    return walkers


def _at(points: torch.Tensor, u: float) -> torch.Tensor:
    """points (T, 3) at fractional frame index ``u``, linearly interpolated."""
    i = min(int(math.floor(u)), points.shape[0] - 2)
    return points[i] * (1 - (u - i)) + points[i + 1] * (u - i)


def cross(motion: Motion, main: Motion, walker: Walker, frames: int) -> Motion:
    """``motion`` (placed and centred) moved so that at ``walker.crossing`` its root (pelvis) is
    ``side_mm`` beside and ``depth_mm`` behind ``main``'s. Both motions' first ``frames`` times
    are the frames (blur sub-frame times follow)."""
    u = min(max(walker.crossing, 0.0), frames - 1.0)
    gap = _at(main.root_positions[:frames], u) - _at(motion.root_positions[:frames], u)
    shift = torch.stack([gap[0] + walker.side_mm, torch.zeros_like(gap[1]), gap[2] + walker.depth_mm])
    root = motion.root_positions + shift.to(motion.root_positions)
    return Motion(motion.skeleton, motion.times, motion.rotations, root)


def keypoint_boxes(keypoints: torch.Tensor, visible: torch.Tensor) -> torch.Tensor:
    """A person's boxes (T, 5) from its true keypoints (T, K, 2) px and their visibility (T, K)
    bool: (x0, y0, x1, y1) the visible keypoints' extent and score 1 where one is visible,
    zeros where none is."""
    boxes = torch.zeros(keypoints.shape[0], 5)
    for t in range(keypoints.shape[0]):
        seen = keypoints[t][visible[t]].float()
        if seen.shape[0]:
            boxes[t] = torch.cat([seen.amin(0), seen.amax(0), torch.ones(1)])
    return boxes
