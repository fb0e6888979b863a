"""The settings of a synthetic scene: :class:`SynthConfig` and its :class:`EstimateConfig`.

Plain dataclasses with no heavy imports, so the command line can list them without loading torch.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

__all__ = ["MOTION_KINDS", "EstimateConfig", "SynthConfig", "ACCURATE_DETECTOR"]

#: The procedural motions (plus "bvh", a motion read from a BVH file).
MOTION_KINDS = ("walk", "run", "wave", "jump", "turn")


@dataclass
class EstimateConfig:
    """Error model of the simulated estimators. Pixel settings are for a person 256 px tall
    and scale with the person's height in the image.

    The 2D keypoint noise is set from MediaPipe Pose on the real clips and Sintel samples in
    ../shared (benchmarks/detector_noise.py, BENCHMARKS.md "How bad is a real detector"): 5 px
    at 256 px tall is the median jitter of the clips where it could be measured (basketball 1.1,
    football 4.5, street 5.1, Sintel alley_1 10.3, market_5 38.6). :data:`ACCURATE_DETECTOR`
    overrides it with the earlier, cleaner setting (2 px).

    Args:
        mpjpe_mm: root-aligned MPJPE of the METRO-like 3D joints, mm (exact).
        bias_share: share of the 3D error variance that is a constant per-joint bias (the
            rest is per-frame jitter).
        gross_error_prob: chance per joint and frame of a gross 3D error (4x the jitter).
        camera_noise_px: 2D noise seen by the weak-perspective camera fit.
        keypoint_noise_px: 2D keypoint noise of visible joints.
        occluded_noise_px: 2D keypoint noise of hidden joints.
        visible_conf: confidence range of visible joints.
        occluded_conf: confidence range of hidden joints.
        miss_prob: chance per joint and frame of a missed detection (confidence 0).
        jump_prob: chance per joint and frame of a jump (one frame, far away, confident).
        jump_px: jump distance range.
        lock_prob: chance per frame that a joint group locks onto a wrong place.
        lock_frames: lock duration range, frames.
        lock_px: distance of the wrong place.
        failure_conf: confidence range of jumps and locks.
    """

    mpjpe_mm: float = 70.0
    bias_share: float = 0.6
    gross_error_prob: float = 0.02
    camera_noise_px: float = 1.5
    keypoint_noise_px: float = 5.0
    occluded_noise_px: float = 10.0
    visible_conf: tuple[float, float] = (0.75, 0.98)
    occluded_conf: tuple[float, float] = (0.1, 0.5)
    miss_prob: float = 0.03
    jump_prob: float = 0.01
    jump_px: tuple[float, float] = (25.0, 60.0)
    lock_prob: float = 0.04
    lock_frames: tuple[int, int] = (2, 5)
    lock_px: tuple[float, float] = (30.0, 80.0)
    failure_conf: tuple[float, float] = (0.7, 0.95)


#: EstimateConfig overrides of an accurate 2D detector (the defaults until the real clips were measured).
ACCURATE_DETECTOR = {"keypoint_noise_px": 2.0, "occluded_noise_px": 6.0}


@dataclass
class SynthConfig:
    """Everything that defines a synthetic scene; the same config gives the same scene bit
    for bit.

    Args:
        motion: walk, run, wave, jump, turn, or bvh (then give --bvh).
        frames: number of frames T.
        height: image height in pixels.
        width: image width in pixels.
        fps: frames per second.
        seed: seed of everything random (motion variations, textures, estimates).
        speed: procedural motion speed factor (cycle rate and travel speed).
        amplitude: procedural motion amplitude factor (joint angle swings).
        heading_deg: the direction the body faces or travels: 0 away from the camera, 90
            towards image left, 180 towards the camera; default: 90 for walk/run/bvh, 160
            otherwise.
        bvh: path of a BVH file (CMU naming, e.g. ../shared/data/mocap/cmu_131/131_01.bvh).
        bvh_start: start time in the BVH file, seconds.
        body_height_mm: body height in millimetres.
        girth: factor on every limb's thickness.
        fov_deg: horizontal field of view of the camera, degrees.
        fill: fraction of the image height the person fills.
        camera_height_mm: camera height above the floor (default: 55% of the person's extent).
        pan_deg_per_s: camera pan rate (yaw), degrees per second.
        dolly_mm_per_s: camera dolly speed along its initial viewing direction, mm per second.
        noise_std: Gaussian image noise, grey levels (0-255).
        motion_blur: samples per frame over the shutter interval (0 or 1: no blur).
        shutter: fraction of the frame interval the shutter is open (motion blur).
        name: scene name (default: synth_<motion>_s<seed>).
        estimates: error model of the simulated METRO-like and DCPose-like estimates.
        people: number of people N. Person 0 is the one the options above describe; the
            others walk across the frame the other way, at other depths, so that people cross
            and hide each other (their bodies, clothes and gaits drawn from the seed).
    """

    motion: str = "walk"
    frames: int = 24
    height: int = 256
    width: int = 256
    fps: float = 30.0
    seed: int = 0
    speed: float = 1.0
    amplitude: float = 1.0
    heading_deg: float | None = None
    bvh: str | None = None
    bvh_start: float = 0.0
    body_height_mm: float = 1700.0
    girth: float = 1.0
    fov_deg: float = 55.0
    fill: float = 0.7
    camera_height_mm: float | None = None
    pan_deg_per_s: float = 0.0
    dolly_mm_per_s: float = 0.0
    noise_std: float = 0.0
    motion_blur: int = 0
    shutter: float = 0.5
    name: str | None = None
    estimates: EstimateConfig = field(default_factory=EstimateConfig)
    people: int = 1

    def __post_init__(self) -> None:
        kinds = (*MOTION_KINDS, "bvh")
        if self.motion not in kinds:
            raise ValueError(f"SynthConfig.motion: expected one of {kinds}, got {self.motion!r}")
        if self.motion == "bvh" and not self.bvh:
            raise ValueError("SynthConfig.bvh: motion 'bvh' needs the path of a BVH file")
        if self.frames < 2:
            raise ValueError(f"SynthConfig.frames: expected at least 2 frames, got {self.frames}")
        for side in ("height", "width"):
            if getattr(self, side) < 16:
                raise ValueError(f"SynthConfig.{side}: expected at least 16 px, got {getattr(self, side)}")
        if self.fps <= 0:
            raise ValueError(f"SynthConfig.fps: expected a positive rate, got {self.fps}")
        if isinstance(self.people, bool) or not isinstance(self.people, int) or self.people < 1:
            raise ValueError(f"SynthConfig.people: expected a whole number of people >= 1, got {self.people!r}")
        _check_estimates(self.estimates)


def _check_estimates(config: EstimateConfig) -> None:
    """ValueError naming the field (``SynthConfig.estimates.<name>``) for a negative amount, a
    probability or share above 1, a confidence above 1, or a range whose low end is above its high."""
    for f in fields(config):
        value, name = getattr(config, f.name), f"SynthConfig.estimates.{f.name}"
        values = value if isinstance(value, tuple) else (value,)
        if any(v < 0 for v in values):
            raise ValueError(f"{name}: expected values >= 0, got {value}")
        if (f.name.endswith(("_prob", "_share", "_conf"))) and any(v > 1 for v in values):
            raise ValueError(f"{name}: expected values <= 1 (a probability or share), got {value}")
        if isinstance(value, tuple) and (len(value) != 2 or value[0] > value[1]):
            raise ValueError(f"{name}: expected a range (low, high) with low <= high, got {value}")
