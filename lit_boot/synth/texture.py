"""Procedural textures: seeded periodic noise sampled at continuous coordinates.

Noise is made by filtering white noise in the Fourier domain (power ~ 1/f^beta), so it tiles
seamlessly in every direction; a tiled 2D texture covers the background planes and a tiled 3D
volume gives the body a *solid* texture in rest-pose coordinates, which therefore moves
rigidly with each limb, like printed clothes. Thresholded noise adds sharp-edged patches, so a
flow network has corners and edges to track, not only smooth blobs.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["periodic_noise", "sample_tiled"]


def periodic_noise(
    shape: tuple[int, ...], channels: int, generator: torch.Generator, beta: float = 1.6, min_period: float = 2.0
) -> torch.Tensor:
    """Zero-mean, unit-std periodic noise of ``shape`` (2 or 3 dims) with ``channels`` channels.

    Returns (channels, *shape) float32. ``beta`` sets the spectral slope; frequencies with a
    period under ``min_period`` texels are cut (no aliasing when sampled at about a texel per
    pixel).
    """
    white = torch.randn((channels, *shape), generator=generator)
    spec = torch.fft.rfftn(white, dim=tuple(range(1, len(shape) + 1)))
    freqs = [torch.fft.fftfreq(n) for n in shape[:-1]] + [torch.fft.rfftfreq(shape[-1])]
    grids = torch.meshgrid(*freqs, indexing="ij")
    radius = torch.sqrt(sum(g * g for g in grids))
    gain = torch.where(radius > 0, radius.clamp_min(1e-6) ** (-beta / 2.0), torch.zeros_like(radius))
    gain = torch.where(radius <= 1.0 / min_period, gain, torch.zeros_like(gain))
    out = torch.fft.irfftn(spec * gain, s=shape, dim=tuple(range(1, len(shape) + 1)))
    out = out - out.mean(dim=tuple(range(1, out.ndim)), keepdim=True)
    return out / out.std(dim=tuple(range(1, out.ndim)), keepdim=True).clamp_min(1e-8)


def sample_tiled(texture: torch.Tensor, coords: torch.Tensor, texel_size: float) -> torch.Tensor:
    """Sample a periodic texture at continuous coordinates, tiling it forever.

    texture (C, *S) with 2 or 3 spatial dims; coords (N, D) in the same units as ``texel_size``
    (e.g. mm), D = number of spatial dims, coordinate i indexes spatial dim i. Returns (N, C),
    trilinear/bilinear, seamless across the tile border.
    """
    dims = texture.ndim - 1
    sizes = torch.tensor(texture.shape[1:], dtype=coords.dtype, device=coords.device)
    # Texel centres at (k + 0.5) * texel_size; pad one texel circularly on each side.
    idx = torch.remainder(coords / texel_size - 0.5, sizes) + 1.0  # in padded index space
    padded = F.pad(texture[None], (1, 1) * dims, mode="circular")
    padded_sizes = sizes + 2.0
    norm = idx / (padded_sizes - 1.0) * 2.0 - 1.0  # align_corners=True normalisation
    grid = norm.flip(-1)  # grid_sample wants (x, y[, z]) = last spatial dim first
    grid = grid.view(1, *([1] * (dims - 1)), -1, dims).to(texture.dtype)
    out = F.grid_sample(padded, grid, mode="bilinear", padding_mode="border", align_corners=True)
    return out.reshape(texture.shape[0], -1).T
