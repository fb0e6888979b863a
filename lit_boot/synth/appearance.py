"""Colours of the synthetic world: textured background planes and textured clothes.

Body colour is a function of the rest-pose coordinate of the surface point (a solid texture),
so it is glued to the limbs; background colour is a function of the world coordinate on each
plane. Light is a fixed direction in the world with a large ambient share (soft shading:
enough for depth cues, small enough that brightness stays nearly constant as limbs turn).
"""

from __future__ import annotations

import torch

from .body import MATERIALS
from .texture import periodic_noise, sample_tiled

__all__ = ["Appearance"]


class Appearance:
    """Seeded textures and palettes for one scene.

    materials: one material name per body part (keys of :data:`MATERIALS`); base_colours:
    RGB in [0, 1] replacing some materials' base colours (other clothes for another person).
    """

    def __init__(
        self,
        materials: list[str],
        generator: torch.Generator,
        body_texel_mm: float = 8.0,
        background_texel_mm: float = 12.0,
        ambient: float = 0.7,
        base_colours: dict[str, torch.Tensor] | None = None,
    ):
        g = generator
        self.ambient = ambient
        # Texel sizes are chosen by the caller from the image scale (the finest noise period
        # is two texels), so textures do not alias.
        self.body_texel, self.bg_texel = body_texel_mm, background_texel_mm
        self.body_noise = periodic_noise((32, 32, 32), 3, g, beta=1.2)
        self.body_patch = periodic_noise((32, 32, 32), 1, g, beta=2.5)
        self.bg_noise = periodic_noise((256, 256), 3, g, beta=1.6)
        self.bg_patch = periodic_noise((128, 128), 2, g, beta=2.5)
        jitter = lambda: (torch.rand(3, generator=g) - 0.5) * 0.25  # noqa: E731
        bases = {name: torch.tensor(rgb) for name, (rgb, _) in MATERIALS.items()} | (base_colours or {})
        palette = {name: (rgb + jitter()).clamp(0.05, 0.95) for name, rgb in bases.items()}
        self.part_base = torch.stack([palette[m] for m in materials])  # (P, 3)
        self.part_contrast = torch.tensor([MATERIALS[m][1] for m in materials])  # (P,)
        self.plane_base = torch.stack([torch.rand(3, generator=g) * 0.5 + 0.25 for _ in range(2)])
        self.plane_patch = torch.stack([torch.rand(3, generator=g) for _ in range(2)])
        light = torch.tensor([0.4, 0.8, -0.45]) + (torch.rand(3, generator=g) - 0.5) * 0.3
        self.light_world = light / light.norm()

    def body_colour(self, part: torch.Tensor, rest_points: torch.Tensor) -> torch.Tensor:
        """RGB (N, 3) in [0, 1] of body points: part (N,), rest-pose coordinates (N, 3) mm."""
        detail = sample_tiled(self.body_noise, rest_points, self.body_texel)  # (N, 3)
        patch = torch.tanh(4.0 * sample_tiled(self.body_patch, rest_points, 2.0 * self.body_texel))  # (N, 1)
        contrast = self.part_contrast[part][:, None]
        base = self.part_base[part]
        return base * (1.0 + contrast * (0.35 * detail.mean(-1, keepdim=True) + 0.2 * detail + 0.5 * patch))

    def plane_colour(self, plane: torch.Tensor, coords: torch.Tensor) -> torch.Tensor:
        """RGB (N, 3) of background points: plane index (N,), in-plane world coordinates (N, 2) mm."""
        detail = sample_tiled(self.bg_noise, coords, self.bg_texel)
        patch = torch.tanh(5.0 * sample_tiled(self.bg_patch, coords, 4.0 * self.bg_texel))  # (N, 2)
        sel = patch.gather(1, plane[:, None].clamp(0, 1))  # one patch field per plane
        base = self.plane_base[plane.clamp(0, 1)]
        tint = self.plane_patch[plane.clamp(0, 1)]
        mixed = torch.lerp(base, tint, (sel + 1.0) * 0.35)
        luminance = detail.mean(-1, keepdim=True)
        return mixed * (1.0 + 0.3 * luminance + 0.08 * detail)

    def shade(self, colour: torch.Tensor, normal_world: torch.Tensor) -> torch.Tensor:
        """Soft Lambertian shading of (N, 3) colours by world normals (N, 3)."""
        lambert = (normal_world @ self.light_world).clamp_min(0)[:, None]
        return colour * (self.ambient + (1.0 - self.ambient) * 1.25 * lambert)
