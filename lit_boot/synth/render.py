"""Ray casting of ellipsoids and planes: per pixel, the nearest surface (of one person or several).

One ray per pixel centre (pixel (x, y) at integer coordinates) from the camera origin, in the
camera frame (x right, y down, z forward, mm). Ellipsoids are intersected analytically, only
inside the bounding box of their projections; planes cover the rest. Everything is batched
torch: no Python loop over pixels.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from ..core import project_pinhole

__all__ = ["Intrinsics", "Hits", "pixel_rays", "cast"]

#: Distance given to rays that hit nothing (a point at "infinity"), mm.
FAR_MM = 1e7


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels."""

    fx: float
    fy: float
    cx: float
    cy: float
    height: int
    width: int

    def project(self, points: torch.Tensor) -> torch.Tensor:
        """(..., 3) camera-frame mm -> (..., 2) px (the core's pinhole projection, no translation)."""
        params = points.new_tensor([self.fx, self.fy, self.cx, self.cy, 0.0, 0.0, 0.0])
        return project_pinhole(points.reshape(1, -1, 3), params[None]).reshape(*points.shape[:-1], 2)


@dataclass
class Hits:
    """The nearest surface per pixel (H, W): depth (z, mm), point (H, W, 3) camera frame,
    part index (-1: background), plane index (-1: a body part or nothing), normal (H, W, 3)."""

    depth: torch.Tensor
    point: torch.Tensor
    part: torch.Tensor
    plane: torch.Tensor
    normal: torch.Tensor


def pixel_rays(K: Intrinsics, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """(H, W, 3) ray directions with z = 1 through every pixel centre."""
    ys, xs = torch.meshgrid(
        torch.arange(K.height, dtype=dtype), torch.arange(K.width, dtype=dtype), indexing="ij"
    )
    return torch.stack([(xs - K.cx) / K.fx, (ys - K.cy) / K.fy, torch.ones_like(xs)], dim=-1)


def _person_box(K: Intrinsics, centres: torch.Tensor, radii: torch.Tensor) -> tuple[int, int, int, int]:
    """Pixel box (y0, y1, x0, x1) covering every part's bounding sphere (whole image if a
    sphere reaches behind the camera)."""
    r = radii.amax(-1)
    z_near = centres[:, 2] - r
    if (z_near <= 1.0).any():
        return 0, K.height, 0, K.width
    corners = []
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            for z in (z_near, centres[:, 2] + r):
                x = (centres[:, 0] + sx * r) / z * K.fx + K.cx
                y = (centres[:, 1] + sy * r) / z * K.fy + K.cy
                corners.append(torch.stack([x, y], -1))
    c = torch.cat(corners)
    x0 = int(max(0, torch.floor(c[:, 0].min()).item() - 1))
    x1 = int(min(K.width, torch.ceil(c[:, 0].max()).item() + 2))
    y0 = int(max(0, torch.floor(c[:, 1].min()).item() - 1))
    y1 = int(min(K.height, torch.ceil(c[:, 1].max()).item() + 2))
    return y0, max(y0, y1), x0, max(x0, x1)


def _ellipsoid_hits(
    rays: torch.Tensor, centres: torch.Tensor, axes: torch.Tensor, radii: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Nearest entry distance along each ray (N,) and the part index (N,) (-1 if none).
    rays (N, 3); centres (P, 3); axes (P, 3, 3) columns; radii (P, 3)."""
    # Into each ellipsoid's unit-sphere coordinates: u = diag(1/r) A^T (x - c).
    A = axes.transpose(-1, -2) / radii[..., None]  # (P, 3, 3)
    o = -(A @ centres[..., None])[..., 0]  # (P, 3)  the camera origin
    d = torch.einsum("pij,nj->pni", A, rays)  # (P, N, 3)
    a = (d * d).sum(-1)
    b = 2.0 * (d * o[:, None]).sum(-1)
    c = (o * o).sum(-1)[:, None] - 1.0
    disc = b * b - 4.0 * a * c
    s = (-b - disc.clamp_min(0).sqrt()) / (2.0 * a)
    s = torch.where((disc > 0) & (s > 0), s, torch.full_like(s, float("inf")))
    best, part = s.min(0)
    part = torch.where(torch.isfinite(best), part, torch.full_like(part, -1))
    return best, part


def _composite(
    K: Intrinsics,
    rays: torch.Tensor,
    centres: torch.Tensor,
    axes: torch.Tensor,
    radii: torch.Tensor,
    first: int,
    depth: torch.Tensor,
    part: torch.Tensor,
    plane: torch.Tensor,
) -> None:
    """Draw one person's ellipsoids (parts ``first``, ``first + 1``, ...) over depth, part and
    plane (H, W), in place, where they are nearer than what is there."""
    y0, y1, x0, x1 = _person_box(K, centres, radii)
    if y1 > y0 and x1 > x0 and centres.shape[0] > 0:
        sub = rays[y0:y1, x0:x1].reshape(-1, 3)
        s_body, p_body = _ellipsoid_hits(sub, centres, axes, radii)
        s_body = s_body.view(y1 - y0, x1 - x0)
        p_body = p_body.view(y1 - y0, x1 - x0)
        closer = (p_body >= 0) & (s_body < depth[y0:y1, x0:x1])
        depth[y0:y1, x0:x1] = torch.where(closer, s_body, depth[y0:y1, x0:x1])
        part[y0:y1, x0:x1] = torch.where(closer, p_body + first, part[y0:y1, x0:x1])
        plane[y0:y1, x0:x1] = torch.where(closer, torch.full_like(p_body, -1), plane[y0:y1, x0:x1])


def cast(
    K: Intrinsics,
    centres: torch.Tensor,
    axes: torch.Tensor,
    radii: torch.Tensor,
    planes: torch.Tensor,
    rays: torch.Tensor | None = None,
    groups: Sequence[slice] | None = None,
) -> Hits:
    """Nearest surface per pixel among ellipsoids (camera frame) and planes.

    planes (Q, 4): (n, d) with the plane n . x = d in the camera frame. Depth along a
    z = 1 ray equals the ray parameter. ``groups``: the ellipsoids of each person (slices of
    the part axis; default: all of them one person); each is intersected only inside its own
    box, so the cost grows with the people's boxes, not with the box around all of them.
    """
    rays = pixel_rays(K, centres.dtype) if rays is None else rays
    H, W = K.height, K.width
    # Planes everywhere.
    nd = rays @ planes[:, :3].T  # (H, W, Q)
    s_plane = planes[:, 3] / torch.where(nd.abs() > 1e-9, nd, torch.full_like(nd, 1e-9))
    s_plane = torch.where(s_plane > 0, s_plane, torch.full_like(s_plane, float("inf")))
    depth, plane = s_plane.min(-1)
    plane = torch.where(torch.isfinite(depth), plane, torch.full_like(plane, -1))
    depth = torch.where(torch.isfinite(depth), depth, torch.full_like(depth, FAR_MM))
    part = torch.full((H, W), -1, dtype=torch.long)
    # Each person's ellipsoids inside that person's box, nearer surfaces winning.
    for group in [slice(0, centres.shape[0])] if groups is None else groups:
        _composite(K, rays, centres[group], axes[group], radii[group], group.start, depth, part, plane)
    point = rays * depth[..., None]
    # Normals: planes' own; ellipsoids' gradient of the implicit function.
    normal = torch.zeros_like(point)
    on_plane = plane >= 0
    normal[on_plane] = -planes[plane[on_plane], :3] * torch.sign(nd.gather(-1, plane.clamp_min(0)[..., None])[..., 0][on_plane])[:, None]
    on_body = part >= 0
    if on_body.any():
        p = part[on_body]
        A = axes[p].transpose(-1, -2) / radii[p][..., None]
        u = (A @ (point[on_body] - centres[p])[..., None])[..., 0]
        n = (A.transpose(-1, -2) @ u[..., None])[..., 0]
        normal[on_body] = n / n.norm(dim=-1, keepdim=True).clamp_min(1e-9)
    return Hits(depth=depth, point=point, part=part, plane=plane, normal=normal)
