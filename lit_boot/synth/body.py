"""The synthetic body: ellipsoid parts attached rigidly to a skeleton's joints.

Each part spans two landmarks of the rest pose (its long axis), has a cross-section radius
(and a depth ratio for the torso), and rides on one joint's frame. Because rest rotations are
the identity, a point of a part in rest-pose coordinates ``q`` sits at
``R_j(t) @ (q - x_j_rest) + x_j(t)`` at time t: every surface point has exact motion, which is
what makes the ground-truth flow exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from .skeleton import Motion, Skeleton

__all__ = ["PartSpec", "BODY_PARTS", "MATERIALS", "Body", "PartPoses", "concat_poses"]


@dataclass(frozen=True)
class PartSpec:
    """One ellipsoid: from landmark ``start`` to ``end``, attached to ``attach``.

    ``radius`` and ``depth`` are fractions of the body height (left-right and front-back
    semi-axes); ``pad`` lengthens the long semi-axis beyond half the segment.
    """

    name: str
    start: str
    end: str
    attach: str
    radius: float
    depth: float
    material: str
    pad: float = 0.12


def _limbs(side: str) -> list[PartSpec]:
    s = side
    return [
        PartSpec(f"{s}_upper_arm", f"{s}_shoulder", f"{s}_elbow", f"{s}_shoulder", 0.028, 0.028, "shirt"),
        PartSpec(f"{s}_forearm", f"{s}_elbow", f"{s}_wrist", f"{s}_elbow", 0.022, 0.022, "skin"),
        PartSpec(f"{s}_hand", f"{s}_wrist", f"{s}_hand", f"{s}_wrist", 0.02, 0.012, "skin", 0.05),
        PartSpec(f"{s}_thigh", f"{s}_hip", f"{s}_knee", f"{s}_hip", 0.045, 0.045, "pants", 0.08),
        PartSpec(f"{s}_shin", f"{s}_knee", f"{s}_ankle", f"{s}_knee", 0.032, 0.032, "pants", 0.06),
        PartSpec(f"{s}_foot", f"{s}_ankle", f"{s}_toe", f"{s}_ankle", 0.022, 0.018, "shoes", 0.1),
    ]


#: The default body: torso in two pieces, neck, head, and six parts per side.
BODY_PARTS: tuple[PartSpec, ...] = (
    PartSpec("abdomen", "pelvis", "chest", "pelvis", 0.09, 0.062, "shirt", 0.1),
    PartSpec("chest", "chest", "neck", "chest", 0.105, 0.068, "shirt", 0.35),
    PartSpec("neck", "neck", "head", "neck", 0.03, 0.03, "skin", 0.2),
    PartSpec("head", "head", "head_top", "head", 0.055, 0.065, "skin", 0.1),
    *_limbs("left"),
    *_limbs("right"),
)

#: Material name -> (base RGB in [0,1], texture contrast).
MATERIALS: dict[str, tuple[tuple[float, float, float], float]] = {
    "shirt": ((0.75, 0.25, 0.2), 0.45),
    "pants": ((0.2, 0.3, 0.6), 0.45),
    "skin": ((0.85, 0.65, 0.5), 0.2),
    "shoes": ((0.15, 0.12, 0.1), 0.5),
}


@dataclass
class PartPoses:
    """Ellipsoids at some times. centres (T, P, 3) mm; axes (T, P, 3, 3) with the unit
    semi-axis directions as columns; radii (P, 3) mm; attach_rot (T, P, 3, 3) and attach_pos
    (T, P, 3): the carrying joint's global frame; rest_origin (P, 3): that joint's rest position."""

    centres: torch.Tensor
    axes: torch.Tensor
    radii: torch.Tensor
    attach_rot: torch.Tensor
    attach_pos: torch.Tensor
    rest_origin: torch.Tensor

    def to(self, dtype: torch.dtype) -> PartPoses:
        """The same poses in another dtype."""
        return PartPoses(*(getattr(self, k).to(dtype) for k in self.__dataclass_fields__))

    def lowest_point(self) -> torch.Tensor:
        """(T,) the smallest y over all ellipsoid surfaces (body frame: y up)."""
        extent = ((self.axes[..., 1, :] * self.radii) ** 2).sum(-1).sqrt()  # (T, P)
        return (self.centres[..., 1] - extent).amin(-1)


def concat_poses(poses: list[PartPoses]) -> PartPoses:
    """Several bodies' poses as one (their parts one after another, at the same times); a
    single body's poses are returned as they are."""
    if len(poses) == 1:
        return poses[0]
    per_time = ("centres", "axes", "attach_rot", "attach_pos")
    return PartPoses(*(torch.cat([getattr(p, k) for p in poses], 1 if k in per_time else 0)
                       for k in PartPoses.__dataclass_fields__))  # fmt: skip


class Body:
    """Ellipsoid parts on a skeleton. ``girth`` scales every cross-section radius."""

    def __init__(self, skeleton: Skeleton, parts: tuple[PartSpec, ...] = BODY_PARTS, girth: float = 1.0):
        self.skeleton = skeleton
        self.parts = parts
        rest = skeleton.rest_positions()
        lm = skeleton.landmarks
        height = float(rest[lm["head_top"], 1] - torch.minimum(rest[lm["left_toe"], 1], rest[lm["left_ankle"], 1]))
        self.height_mm = height
        self.attach_index = torch.tensor([lm[p.attach] for p in parts])
        self.rest_origin = rest[self.attach_index]
        self.material = [p.material for p in parts]
        centres, axes, radii = [], [], []
        for p in parts:
            a, b = rest[lm[p.start]], rest[lm[p.end]]
            seg = b - a
            length = float(seg.norm())
            long_axis = seg / max(length, 1e-6)
            side = torch.tensor([1.0, 0.0, 0.0]) - long_axis * long_axis[0]  # body-left, made orthogonal
            if side.norm() < 1e-3:
                side = torch.tensor([0.0, 0.0, 1.0]) - long_axis * long_axis[2]
            side = side / side.norm()
            front = torch.linalg.cross(long_axis, side)
            centres.append((a + b) / 2)
            axes.append(torch.stack([long_axis, side, front], dim=1))
            half = max(length / 2 * (1 + p.pad), p.radius * height)
            radii.append(torch.tensor([half, p.radius * girth * height, p.depth * girth * height]))
        self.rest_centres = torch.stack(centres)  # (P, 3)
        self.rest_axes = torch.stack(axes)  # (P, 3, 3)
        self.radii = torch.stack(radii)  # (P, 3)

    def pose(self, motion: Motion) -> PartPoses:
        """Ellipsoids in the world (body-frame axes) at each of the motion's times."""
        rot, pos = motion.global_transforms()
        R = rot[:, self.attach_index]  # (T, P, 3, 3)
        x = pos[:, self.attach_index]  # (T, P, 3)
        rest_centres, rest_origin = self.rest_centres.to(R), self.rest_origin.to(R)
        centres = (R @ (rest_centres - rest_origin)[..., None])[..., 0] + x
        return PartPoses(centres, R @ self.rest_axes.to(R), self.radii.to(R), R, x, rest_origin)

    def landmark_positions(self, motion: Motion, names: tuple[str, ...]) -> torch.Tensor:
        """World positions (T, len(names), 3) of named landmarks."""
        _, pos = motion.global_transforms()
        return pos[:, [self.skeleton.landmarks[n] for n in names]]

    def face_points(self, motion: Motion) -> torch.Tensor:
        """World positions (T, 5, 3) of nose, left eye, right eye, left ear, right ear (COCO
        order), fixed in the head's frame."""
        rest = self.skeleton.rest_positions()
        lm = self.skeleton.landmarks
        head = next(i for i, p in enumerate(self.parts) if p.name == "head")
        centre, r = self.rest_centres[head], self.radii[head]
        rx, rz = r[1], r[2]
        offsets = torch.stack([
            torch.stack([0 * rx, -0.15 * r[0], 1.0 * rz]),
            torch.stack([0.35 * rx, 0.1 * r[0], 0.85 * rz]),
            torch.stack([-0.35 * rx, 0.1 * r[0], 0.85 * rz]),
            torch.stack([rx, 0 * rx, 0 * rx]),
            torch.stack([-rx, 0 * rx, 0 * rx]),
        ])  # fmt: skip
        local = centre + offsets - rest[lm["head"]]  # rest coords relative to the head joint
        rot, pos = motion.global_transforms()
        local = local.to(rot)
        R, x = rot[:, lm["head"]], pos[:, lm["head"]]
        return (R[:, None] @ local[None, :, :, None])[..., 0] + x[:, None]
