"""The synthetic scene's perspective camera: framing, pan and dolly over time.

World axes are the body-frame axes (x left, y up, z forward); at yaw 0 the camera looks along
+z. ``R`` (T, 3, 3) maps world to camera (x right, y down, z forward); a world point X is at
``R @ (X - C)`` in the camera frame, C (T, 3) the camera centre in mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from .render import Intrinsics

__all__ = ["CameraRig", "frame_person"]


@dataclass
class CameraRig:
    """Intrinsics plus world->camera rotations R (T, 3, 3) and centres C (T, 3) mm."""

    K: Intrinsics
    R: torch.Tensor
    C: torch.Tensor

    @property
    def translation(self) -> torch.Tensor:
        """(T, 3) t such that a world point X sits at R @ X + t in the camera frame."""
        return -(self.R @ self.C[..., None])[..., 0]

    def to_camera(self, points: torch.Tensor, index: int | slice) -> torch.Tensor:
        """World points (..., 3) at time ``index`` -> camera frame (..., 3)."""
        return (points - self.C[index]) @ self.R[index].T

    def to_world(self, points: torch.Tensor, index: int) -> torch.Tensor:
        """Camera-frame points (..., 3) at time ``index`` -> world (..., 3)."""
        return points @ self.R[index] + self.C[index]


def _rotation(yaw: torch.Tensor, pitch: float) -> torch.Tensor:
    """World->camera rotations (T, 3, 3) for yaw about +y and a downward pitch (radians)."""
    cp, sp = math.cos(pitch), math.sin(pitch)
    forward = torch.stack([yaw.sin() * cp, torch.full_like(yaw, -sp), yaw.cos() * cp], -1)
    right = torch.stack([-yaw.cos(), torch.zeros_like(yaw), yaw.sin()], -1)
    down = torch.linalg.cross(forward, right)
    return torch.stack([right, down, forward], dim=-2)


def frame_person(
    lo: torch.Tensor,
    hi: torch.Tensor,
    times: torch.Tensor,
    height: int,
    width: int,
    fov_deg: float = 55.0,
    fill: float = 0.7,
    camera_height_mm: float | None = None,
    pan_deg_per_s: float = 0.0,
    dolly_mm_per_s: float = 0.0,
) -> CameraRig:
    """A camera that sees the person's whole clip.

    lo, hi (3,): world bounding box of the person over the clip (mm). The person's height
    fills ``fill`` of the image height (or the clip's width fits in 90% of the image width);
    ``fov_deg`` is the horizontal field of view. Pan (deg/s) and dolly (mm/s, along the
    initial viewing direction) are centred on the middle of the clip.
    """
    f = (width / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
    K = Intrinsics(fx=f, fy=f, cx=(width - 1) / 2.0, cy=(height - 1) / 2.0, height=height, width=width)
    extent = hi - lo
    centre = (hi + lo) / 2
    dist = max(f * float(extent[1]) / (fill * height), f * float(extent[0]) / (0.9 * width)) + float(extent[2]) / 2
    cam_y = float(lo[1] + 0.55 * extent[1]) if camera_height_mm is None else camera_height_mm
    pitch = math.atan2(cam_y - float(centre[1]), dist)
    t = times - (times[0] + times[-1]) / 2
    yaw = torch.deg2rad(pan_deg_per_s * t)
    R = _rotation(yaw, pitch)
    start = torch.tensor([float(centre[0]), cam_y, float(centre[2]) - dist])
    forward0 = torch.tensor([0.0, 0.0, 1.0])
    C = start + forward0 * (dolly_mm_per_s * t)[:, None]
    return CameraRig(K, R, C)
