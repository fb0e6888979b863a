"""Articulated skeletons, their motions, and forward kinematics.

Body frame convention (shared by the procedural rig and CMU BVH files): x = the body's left,
y = up, z = forward (the way the body faces in its rest pose), millimetres. Rest rotations are
the identity, so a point given in rest-pose coordinates relative to joint j moves rigidly with
joint j's global frame: ``p(t) = R_j(t) @ p_rest_rel + x_j(t)``.

Every skeleton names the *landmarks* the body model needs (see :data:`LANDMARKS`), mapped to
its own joint indices; end sites are joints too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

__all__ = ["LANDMARKS", "Skeleton", "Motion", "forward_kinematics", "euler_to_matrix", "axis_angle_to_matrix"]

#: Joints every skeleton must name, in the body frame convention above.
LANDMARKS = (
    "pelvis", "chest", "neck", "head", "head_top",
    "left_hip", "left_knee", "left_ankle", "left_toe",
    "right_hip", "right_knee", "right_ankle", "right_toe",
    "left_shoulder", "left_elbow", "left_wrist", "left_hand",
    "right_shoulder", "right_elbow", "right_wrist", "right_hand",
)  # fmt: skip


@dataclass
class Skeleton:
    """A joint hierarchy in its rest pose.

    names (N,), parents (N,) with -1 for the root and every parent listed before its children,
    offsets (N, 3) mm: rest offset from the parent (the root's is its rest position),
    landmarks: canonical name (:data:`LANDMARKS`) -> joint index.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: torch.Tensor
    landmarks: dict[str, int]

    def __post_init__(self) -> None:
        n = len(self.names)
        if len(self.parents) != n or tuple(self.offsets.shape) != (n, 3):
            raise ValueError(f"Skeleton: {n} names, {len(self.parents)} parents, offsets {tuple(self.offsets.shape)}")
        for i, p in enumerate(self.parents):
            if not (p < i and (p >= 0 or i == 0)):
                raise ValueError(f"Skeleton: joint {self.names[i]!r} has parent {p}: parents must come first")
        missing = [name for name in LANDMARKS if name not in self.landmarks]
        if missing:
            raise ValueError(f"Skeleton: landmarks missing {missing}")

    def rest_positions(self) -> torch.Tensor:
        """(N, 3) joint positions in the rest pose (mm)."""
        pos = torch.zeros_like(self.offsets)
        for i, p in enumerate(self.parents):
            pos[i] = self.offsets[i] if p < 0 else pos[p] + self.offsets[i]
        return pos

    def scaled(self, factor: float) -> Skeleton:
        """The same skeleton with all offsets multiplied by ``factor``."""
        return Skeleton(self.names, self.parents, self.offsets * factor, dict(self.landmarks))


@dataclass
class Motion:
    """A skeleton's pose over time.

    times (T,) seconds; rotations (T, N, 3, 3) local rotations (in the parent's frame);
    root_positions (T, 3) mm in the world (body frame axes).
    """

    skeleton: Skeleton
    times: torch.Tensor
    rotations: torch.Tensor
    root_positions: torch.Tensor

    def __post_init__(self) -> None:
        T, N = self.times.shape[0], len(self.skeleton.names)
        if tuple(self.rotations.shape) != (T, N, 3, 3) or tuple(self.root_positions.shape) != (T, 3):
            raise ValueError(
                f"Motion: expected rotations ({T}, {N}, 3, 3) and root_positions ({T}, 3), "
                f"got {tuple(self.rotations.shape)} and {tuple(self.root_positions.shape)}"
            )

    def global_transforms(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Forward kinematics: (global rotations (T, N, 3, 3), positions (T, N, 3) mm)."""
        return forward_kinematics(self.skeleton, self.rotations, self.root_positions)


def forward_kinematics(
    skeleton: Skeleton, rotations: torch.Tensor, root_positions: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Global rotations (T, N, 3, 3) and positions (T, N, 3) from local rotations.

    ``R_j = R_parent @ r_j``, ``x_j = x_parent + R_parent @ offset_j``; the root sits at
    ``root_positions`` with rotation ``r_root``.
    """
    glob: list[torch.Tensor] = []
    pos: list[torch.Tensor] = []
    offsets = skeleton.offsets.to(rotations)
    for j, p in enumerate(skeleton.parents):
        if p < 0:
            glob.append(rotations[:, j])
            pos.append(root_positions.to(rotations))
        else:
            glob.append(glob[p] @ rotations[:, j])
            pos.append(pos[p] + glob[p] @ offsets[j])
    return torch.stack(glob, 1), torch.stack(pos, 1)


def axis_angle_to_matrix(axis: str, angle: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) about a body axis 'x', 'y' or 'z' by ``angle`` radians."""
    c, s = torch.cos(angle), torch.sin(angle)
    o, z = torch.ones_like(angle), torch.zeros_like(angle)
    rows = {
        "x": ((o, z, z), (z, c, -s), (z, s, c)),
        "y": ((c, z, s), (z, o, z), (-s, z, c)),
        "z": ((c, -s, z), (s, c, z), (z, z, o)),
    }[axis]
    return torch.stack([torch.stack(r, -1) for r in rows], -2)


def euler_to_matrix(angles_deg: torch.Tensor, order: str) -> torch.Tensor:
    """BVH Euler angles (..., 3) in degrees, applied in channel ``order`` (e.g. 'ZYX'):
    ``R = R_order[0] @ R_order[1] @ R_order[2]``."""
    mats = [axis_angle_to_matrix(a.lower(), angles_deg[..., i] * (math.pi / 180.0)) for i, a in enumerate(order)]
    return mats[0] @ mats[1] @ mats[2]
