"""Procedural human motions: a proportional skeleton and joint angles as smooth functions of time.

Body frame convention of :mod:`lit_boot.synth.skeleton` (x = left, y = up, z = forward, mm,
identity rest rotations, arms hanging down). Sign facts used throughout: a positive rotation
about x tilts an upward bone forward and a downward bone backward, so hip / shoulder / elbow
flexion (limb forward) is a *negative* x-rotation while knee flexion (shin backward) and a
forward torso lean are *positive*; a positive rotation about z moves a hanging limb to +x
(left arm abduction), and a positive rotation about y turns the body to its left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from lit_boot.synth.bvh import rest_height
from lit_boot.synth.config import MOTION_KINDS
from lit_boot.synth.skeleton import Motion, Skeleton, axis_angle_to_matrix, forward_kinematics

__all__ = ["MOTION_KINDS", "procedural_skeleton", "procedural_motion"]


_SIDES = (("left", 1.0), ("right", -1.0))
_ROTATED = (
    "pelvis", "spine", "chest", "neck", "head",
    "left_hip", "left_knee", "left_ankle", "right_hip", "right_knee", "right_ankle",
    "left_shoulder", "left_elbow", "left_wrist", "right_shoulder", "right_elbow", "right_wrist",
)  # fmt: skip
_ORDER = "yxz"  # local rotation R = Ry @ Rx @ Rz
_FEET = ("left_toe", "right_toe", "left_ankle", "right_ankle")
_CONTACT_MM = 2.0  # soft-min temperature of the ground contact

# (name, parent, offset from the parent as fractions of the height; x is +-mirrored per side)
_BONES = (
    ("pelvis", None, (0.0, 0.54, 0.0)),
    ("spine", "pelvis", (0.0, 0.10, 0.0)),
    ("chest", "spine", (0.0, 0.12, 0.0)),
    ("neck", "chest", (0.0, 0.08, 0.0)),
    ("head", "neck", (0.0, 0.03, 0.0)),
    ("head_top", "head", (0.0, 0.13, 0.0)),
    ("{s}_hip", "pelvis", (0.095, -0.01, 0.0)),
    ("{s}_knee", "{s}_hip", (0.0, -0.245, 0.0)),
    ("{s}_ankle", "{s}_knee", (0.0, -0.246, 0.0)),
    ("{s}_toe", "{s}_ankle", (0.0, -0.039, 0.14)),
    ("{s}_shoulder", "chest", (0.13, 0.058, 0.0)),
    ("{s}_elbow", "{s}_shoulder", (0.0, -0.186, 0.0)),
    ("{s}_wrist", "{s}_elbow", (0.0, -0.146, 0.0)),
    ("{s}_hand", "{s}_wrist", (0.0, -0.10, 0.0)),
)


def procedural_skeleton(height_mm: float = 1700.0) -> Skeleton:
    """A 22-joint human (LANDMARKS + ``spine``) standing with arms down, feet on y = 0.

    Segment lengths are anthropometric fractions of ``height_mm`` (Drillis-Contini style);
    the root is the pelvis at 0.54 H, head_top at H; landmarks map each name to its index.
    """
    names: list[str] = []
    parents: list[int] = []
    offsets: list[tuple[float, float, float]] = []
    for name, parent, (x, y, z) in _BONES:
        sides = _SIDES if "{s}" in name else (("", 1.0),)
        for side, sign in sides:
            names.append(name.format(s=side))
            parents.append(-1 if parent is None else names.index(parent.format(s=side)))
            offsets.append((sign * x * height_mm, y * height_mm, z * height_mm))
    return Skeleton(tuple(names), tuple(parents), torch.tensor(offsets), {n: i for i, n in enumerate(names)})


class _Rig:
    """Per-joint angles (radians) accumulated per axis, plus the seed's deterministic jitter.

    ``phase(joint, phi)`` adds the joint's phase offset (+-0.15 rad); ``amp(joint)`` is its
    amplitude factor (amplitude x [0.9, 1.1]). ``phi0`` is a global cycle phase in [0, 2 pi).
    """

    def __init__(self, times: torch.Tensor, amplitude: float, seed: int) -> None:
        gen = torch.Generator().manual_seed(seed)
        jitter = torch.rand(2, len(_ROTATED), generator=gen, dtype=torch.float64) * 2 - 1
        self.phi0 = float(torch.rand(1, generator=gen, dtype=torch.float64)) * 2 * math.pi
        self._phase = dict(zip(_ROTATED, (0.15 * jitter[0]).tolist()))
        self._amp = dict(zip(_ROTATED, (amplitude * (1 + 0.1 * jitter[1])).tolist()))
        self.t = times
        self.angles: dict[str, dict[str, torch.Tensor]] = {}

    def phase(self, joint: str, phi: torch.Tensor) -> torch.Tensor:
        return phi + self._phase[joint]

    def amp(self, joint: str) -> float:
        return self._amp[joint]

    def add(self, joint: str, axis: str, degrees: torch.Tensor | float) -> None:
        """Add ``degrees`` (T,) or a constant to ``joint``'s rotation about ``axis``."""
        axes = self.angles.setdefault(joint, {})
        axes[axis] = axes.get(axis, torch.zeros_like(self.t)) + torch.as_tensor(degrees).to(self.t) * (math.pi / 180)


@dataclass(frozen=True)
class _Gait:
    """A cyclic gait: degrees, frequencies in cycles/s and lengths as fractions of the height."""

    freq: float
    stride: float  # travel per cycle
    hip: float  # hip flexion amplitude
    knee: float  # peak knee flexion
    ankle: float
    arm: float  # shoulder swing amplitude
    elbow: float  # static elbow flexion
    lift: float  # extra airborne pelvis lift (peak), on top of the ground contact
    twist: float  # pelvis yaw amplitude
    lean: float  # static forward torso lean
    yaw_rate: float = 0.0  # deg/s of root yaw


_GAITS = {
    "walk": _Gait(freq=1.0, stride=0.765, hip=25, knee=60, ankle=10, arm=20, elbow=15, lift=0.0, twist=5, lean=3),
    "run": _Gait(freq=1.4, stride=1.26, hip=40, knee=100, ankle=15, arm=35, elbow=85, lift=0.025, twist=8, lean=10),
    "turn": _Gait(
        freq=1.0, stride=0.0, hip=10, knee=30, ankle=5, arm=5, elbow=10, lift=0.0, twist=0, lean=0, yaw_rate=90
    ),
}


def _gait(rig: _Rig, g: _Gait, speed: float, height: float) -> torch.Tensor:
    """Fill ``rig`` with a gait; returns the root displacement (T, 3) mm (before ground contact).

    Left hip flexion follows sin(phi) (swing for phi in [-pi/2, pi/2]); knee flexion is a
    non-negative raised cosine peaking early in the swing; the ankle half-compensates the leg's
    pitch; arms swing opposite to the legs. The vertical bob comes from the ground contact.
    """
    phi = 2 * math.pi * g.freq * speed * rig.t + rig.phi0
    for side, sign in _SIDES:
        leg = phi if sign > 0 else phi + math.pi
        hip, knee, ankle, shoulder, elbow = (f"{side}_{j}" for j in ("hip", "knee", "ankle", "shoulder", "elbow"))
        flex = -g.hip * rig.amp(hip) * torch.sin(rig.phase(hip, leg))
        bend = g.knee * rig.amp(knee) * ((1 + torch.cos(rig.phase(knee, leg) + 0.4)) / 2) ** 2
        rig.add(hip, "x", flex)
        rig.add(knee, "x", bend)
        rig.add(ankle, "x", g.ankle * rig.amp(ankle) * torch.sin(rig.phase(ankle, leg) - 0.5) - 0.5 * (flex + bend))
        arm = torch.sin(rig.phase(shoulder, leg + math.pi))
        rig.add(shoulder, "x", -g.arm * rig.amp(shoulder) * arm)
        rig.add(shoulder, "z", sign * 6.0)
        rig.add(elbow, "x", -g.elbow - 0.5 * g.arm * rig.amp(elbow) * (1 + arm) / 2)
    twist = g.twist * rig.amp("pelvis") * torch.sin(rig.phase("pelvis", phi))
    rig.add("pelvis", "y", -twist + g.yaw_rate * speed * rig.t)
    rig.add("spine", "y", 0.6 * twist)
    rig.add("spine", "x", g.lean)
    disp = torch.zeros(rig.t.shape[0], 3, dtype=rig.t.dtype)
    disp[:, 1] = g.lift * height * rig.amp("pelvis") * (1 - torch.cos(2 * phi)) / 2
    disp[:, 2] = g.stride * height * g.freq * speed * rig.t
    return disp


def _wave(rig: _Rig, speed: float) -> torch.Tensor:
    """Right arm raised to the side, forearm waving in the frontal plane at 1.5 Hz x speed."""
    phi = 2 * math.pi * 1.5 * speed * rig.t + rig.phi0
    rig.add("right_shoulder", "z", -130.0)
    rig.add("right_elbow", "z", -35.0 - 25.0 * rig.amp("right_elbow") * torch.sin(rig.phase("right_elbow", phi)))
    rig.add("right_wrist", "z", -10.0 * rig.amp("right_wrist") * torch.sin(rig.phase("right_wrist", phi - 0.5)))
    rig.add("left_shoulder", "z", 5.0)
    rig.add("left_elbow", "x", -10.0)
    sway = torch.sin(rig.phase("spine", phi / 3))
    rig.add("spine", "z", 3.0 * rig.amp("spine") * sway)
    rig.add("neck", "z", -2.0 * rig.amp("neck") * sway)
    return torch.zeros(rig.t.shape[0], 3, dtype=rig.t.dtype)


def _bump(u: torch.Tensor, lo: float, hi: float) -> torch.Tensor:
    """sin^2 bump rising from 0 at ``lo`` to 1 mid-way and back to 0 at ``hi`` (0 outside)."""
    s = ((u - lo) / (hi - lo)).clamp(0, 1)
    return torch.sin(math.pi * s) ** 2


def _jump(rig: _Rig, speed: float, height: float) -> torch.Tensor:
    """Crouch (u in [0, 0.4)), ballistic flight (u in [0.4, 0.8)), landing absorption; u = cycle
    fraction at 1/1.2 cycles/s x speed. The ankles keep the feet flat; arms swing back, then up."""
    cycle = 2 * math.pi * (rig.t * speed / 1.2) + rig.phi0

    def crouch(joint: str) -> torch.Tensor:
        u = torch.remainder(rig.phase(joint, cycle), 2 * math.pi) / (2 * math.pi)
        return rig.amp(joint) * (_bump(u, 0.0, 0.4) + 0.6 * _bump(u, 0.8, 1.0))

    u = torch.remainder(cycle, 2 * math.pi) / (2 * math.pi)
    pitch = 20.0 * crouch("pelvis")
    rig.add("pelvis", "x", pitch)
    for side, _ in _SIDES:
        hip, knee = -65.0 * crouch(f"{side}_hip"), 70.0 * crouch(f"{side}_knee")
        rig.add(f"{side}_hip", "x", hip)
        rig.add(f"{side}_knee", "x", knee)
        rig.add(f"{side}_ankle", "x", -(pitch + hip + knee))
        arms = -160.0 * rig.amp(f"{side}_shoulder") * _bump(u, 0.3, 0.9) + 40.0 * crouch(f"{side}_shoulder")
        rig.add(f"{side}_shoulder", "x", arms)
        rig.add(f"{side}_elbow", "x", -15.0)
    disp = torch.zeros(rig.t.shape[0], 3, dtype=rig.t.dtype)
    flight = ((u - 0.4) / 0.4).clamp(0, 1)
    disp[:, 1] = 300.0 * (height / 1700.0) * rig.amp("pelvis") * 4 * flight * (1 - flight)
    return disp


def _soft_floor(heights: torch.Tensor) -> torch.Tensor:
    """Smooth minimum over the last dim (at most the true minimum), temperature _CONTACT_MM."""
    return -_CONTACT_MM * torch.logsumexp(-heights / _CONTACT_MM, dim=-1)


def _local_rotations(skeleton: Skeleton, rig: _Rig) -> torch.Tensor:
    """(T, N, 3, 3) float64 local rotations ``Ry @ Rx @ Rz`` from the rig's angles."""
    T, N = rig.t.shape[0], len(skeleton.names)
    rotations = torch.eye(3, dtype=torch.float64).expand(T, N, 3, 3).clone()
    index = dict(skeleton.landmarks)
    if "spine" in skeleton.names:
        index["spine"] = skeleton.names.index("spine")
    for joint, axes in rig.angles.items():
        if joint in index:
            for axis in (a for a in _ORDER if a in axes):
                rotations[:, index[joint]] = rotations[:, index[joint]] @ axis_angle_to_matrix(axis, axes[axis])
    return rotations


def _ground_contact(skeleton: Skeleton, rotations: torch.Tensor) -> torch.Tensor:
    """(T,) root height change that keeps the feet's (soft) lowest point at its rest level."""
    feet = [skeleton.landmarks[k] for k in _FEET]
    offsets = skeleton.offsets.to(rotations)
    _, pos = forward_kinematics(skeleton, rotations, offsets[0].expand(rotations.shape[0], 3))
    rest = skeleton.rest_positions().to(rotations)[feet, 1]
    return _soft_floor(rest) - _soft_floor(pos[:, feet, 1])


def procedural_motion(
    kind: str,
    times: torch.Tensor,
    *,
    skeleton: Skeleton | None = None,
    speed: float = 1.0,
    amplitude: float = 1.0,
    seed: int = 0,
) -> Motion:
    """A procedural motion of ``kind`` (see :data:`MOTION_KINDS`) at ``times`` (T,) seconds.

    ``skeleton`` defaults to :func:`procedural_skeleton`; any skeleton whose pelvis is the root
    and whose rest pose follows the body frame convention works (rotations go to its landmark
    joints, and to a joint named ``spine`` if present). ``speed`` scales cycle frequencies and
    travel, ``amplitude`` the oscillation amplitudes (static postures stay), ``seed`` selects
    deterministic variations (global cycle phase, +-0.15 rad per-joint phases, +-10 % per-joint
    amplitudes) from a local generator. Distances scale with the skeleton's rest height. The
    root height keeps the lowest toe/ankle at its rest level (soft-min ground contact), plus
    the airborne lift of jumps and runs.
    """
    if kind not in MOTION_KINDS:
        raise ValueError(f"unknown motion kind {kind!r}; expected one of {MOTION_KINDS}")
    if amplitude < 0:
        raise ValueError(f"procedural_motion: amplitude must be >= 0 (negative hyperextends knees), got {amplitude}")
    skeleton = procedural_skeleton() if skeleton is None else skeleton
    if skeleton.landmarks["pelvis"] != 0:
        raise ValueError("procedural_motion: the skeleton's pelvis must be its root (joint 0)")
    dtype = times.dtype if times.is_floating_point() else torch.get_default_dtype()
    rig = _Rig(times.detach().to(torch.float64), amplitude, seed)
    height = rest_height(skeleton)
    if kind in _GAITS:
        disp = _gait(rig, _GAITS[kind], speed, height)
    elif kind == "wave":
        disp = _wave(rig, speed)
    else:
        disp = _jump(rig, speed, height)
    rotations = _local_rotations(skeleton, rig)
    disp[:, 1] += _ground_contact(skeleton, rotations)
    root = skeleton.offsets[0].to(torch.float64) + disp
    return Motion(skeleton, times, rotations.to(dtype), root.to(dtype))
