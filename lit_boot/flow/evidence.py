"""Image evidence for a flow, without ground truth: warping, photometric error, and the
forward-backward occlusion test.

Conventions: flows are (B, 2, H, W) float in pixels, channel 0 = u; the flow (u, v) at pixel
(x, y) of frame t moves it to (x + u, y + v) in frame t+1; pixel centres lie at integer
coordinates. Images are RGB (B, 3, H, W), uint8 (0..255) or float (0..1); uint8 is divided by
255, so ``x`` and ``x.float() / 255`` give the same results. Everything is batched over pairs,
runs on the inputs' device and is differentiable w.r.t. float inputs and flows.

- :func:`warp` backward-warps frame t+1 to frame t with the flow t -> t+1.
- :func:`census_error` (soft census, UnFlow / ARFlow / SMURF style) and :func:`ssim_error`
  compare frame t with the warped frame t+1, per pixel; :func:`photometric_error` does both
  steps for any candidate flow.
- :func:`forward_backward_check` flags pixels whose forward and backward flows disagree
  (Sundaram et al. 2010; UnFlow's defaults): occluded or wrong.
- :func:`track_error` scores point tracks (e.g. pose joints from frame t to t+1) the same way.
- :func:`region_mean` and :func:`tile_mean` average a per-pixel map over masks or tiles.
- :func:`pair_evidence` bundles them into an :class:`Evidence`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import kornia
import torch
import torch.nn.functional as F
from torch import Tensor

from ..core import inside_image

__all__ = [
    "Evidence",
    "census_error",
    "census_transform",
    "forward_backward_check",
    "pair_evidence",
    "photometric_error",
    "region_mean",
    "ssim_error",
    "tile_mean",
    "track_error",
    "to_unit_float",
    "warp",
]

Measure = Literal["census", "ssim"]
MEASURES = ("census", "ssim")


def _check(name: str, tensor: Tensor, channels: int | None = None) -> None:
    """Raise ValueError unless ``tensor`` is (B, C, H, W) (with C == ``channels`` if given)."""
    if not isinstance(tensor, Tensor) or tensor.ndim != 4 or (channels is not None and tensor.shape[1] != channels):
        shape = tuple(tensor.shape) if isinstance(tensor, Tensor) else type(tensor).__name__
        raise ValueError(f"`{name}` must have shape (B, {channels or 'C'}, H, W), got {shape}")


def _check_flow(name: str, flow: Tensor, like: Tensor) -> None:
    _check(name, flow, 2)
    if not flow.is_floating_point():
        raise ValueError(f"`{name}` must be a floating-point flow in pixels, got {flow.dtype}")
    if flow.shape[0] != like.shape[0] or flow.shape[-2:] != like.shape[-2:]:
        expected = (like.shape[0], 2, *like.shape[-2:])
        raise ValueError(f"`{name}` must have shape {expected}, got {tuple(flow.shape)}")


def to_unit_float(image: Tensor) -> Tensor:
    """uint8 0..255 -> float32 0..1; floating tensors are returned as they are."""
    if image.dtype == torch.uint8:
        return image.float() / 255.0
    if not image.is_floating_point():
        raise ValueError(f"expected uint8 (0..255) or float (0..1) images, got {image.dtype}")
    return image


def warp(image: Tensor, flow: Tensor, padding_mode: str = "border") -> tuple[Tensor, Tensor]:
    """Backward-warp ``image`` (frame t+1) to frame t with the flow t -> t+1.

    image: (B, C, H, W), uint8 (read as 0..1) or float; flow: (B, 2, H, W) px. The output at
    pixel (x, y) is ``image`` sampled bilinearly at (x + u, y + v) (``grid_sample``,
    ``align_corners=True``: pixel centres at integers). Samples beyond the outer pixel centres
    repeat the edge (``padding_mode="border"``; or "zeros", "reflection").

    Returns the warped image (B, C, H, W) in the flow's dtype and ``in_bounds`` bool (B, H, W):
    the target lies inside the image area, -0.5 <= x + u < W - 0.5 and -0.5 <= y + v < H - 0.5
    (the pixel that a rounded target would hit exists), and the flow is finite there.
    """
    _check("image", image)
    _check_flow("flow", flow, image)
    image = to_unit_float(image)
    height, width = flow.shape[-2:]
    finite = torch.isfinite(flow).all(1)
    flow = torch.where(finite[:, None], flow, torch.zeros_like(flow))
    ys, xs = torch.meshgrid(
        torch.arange(height, device=flow.device, dtype=flow.dtype),
        torch.arange(width, device=flow.device, dtype=flow.dtype),
        indexing="ij",
    )
    x, y = xs + flow[:, 0], ys + flow[:, 1]
    in_bounds = finite & (x >= -0.5) & (x < width - 0.5) & (y >= -0.5) & (y < height - 0.5)
    grid = torch.stack([2.0 * x / max(width - 1, 1) - 1.0, 2.0 * y / max(height - 1, 1) - 1.0], -1)
    warped = F.grid_sample(image.to(flow.dtype), grid, mode="bilinear", padding_mode=padding_mode, align_corners=True)
    return warped, in_bounds


def census_transform(image: Tensor, radius: int = 3, eps: float = 0.81) -> Tensor:
    """Soft census signature of RGB images: (B, (2r+1)^2, H, W).

    image: (B, 3, H, W) uint8 or float 0..1, converted to grey levels 0..255 (ITU-R 601
    weights, ``kornia.color.rgb_to_grayscale``). For each neighbour n of pixel p in the
    (2r+1)^2 window, the signature is ``d / sqrt(eps + d^2)`` with ``d = I(n) - I(p)``: a soft
    sign in (-1, 1), so a global gain or offset in brightness barely changes it. The image is
    replicate-padded at its border (the centre channel is always 0).
    """
    _check("image", image, 3)
    grey = kornia.color.rgb_to_grayscale(to_unit_float(image)) * 255.0
    size = 2 * radius + 1
    patches = F.unfold(F.pad(grey, (radius,) * 4, mode="replicate"), size)
    diff = patches.view(grey.shape[0], size * size, *grey.shape[-2:]) - grey
    return diff / torch.sqrt(eps + diff.square())


def census_error(image1: Tensor, image2: Tensor, radius: int = 3) -> Tensor:
    """Per-pixel soft Hamming distance of the census signatures of two aligned images.

    image1, image2: (B, 3, H, W) uint8 or float 0..1. For each neighbour, the signatures'
    squared difference d^2 counts as ``d^2 / (0.1 + d^2)`` (0 when they agree, ~1 when their
    signs differ); the sum over the window is the error, (B, H, W) in [0, (2r+1)^2 - 1)
    (48 for the default 7x7 window; a pixel with its census bits all flipped scores ~47).
    """
    t1, t2 = census_transform(image1, radius), census_transform(image2, radius)
    d2 = (t1 - t2).square()
    return (d2 / (0.1 + d2)).sum(1)


def ssim_error(image1: Tensor, image2: Tensor, window: int = 11) -> Tensor:
    """Per-pixel structural dissimilarity ``(1 - SSIM) / 2`` averaged over RGB, in [0, 1].

    image1, image2: (B, 3, H, W) uint8 or float 0..1; SSIM by ``kornia.metrics.ssim`` (Gaussian
    ``window``, sigma 1.5, 'same' zero padding, so the outer window/2 pixels read low).
    Returns (B, H, W).
    """
    _check("image1", image1, 3)
    _check("image2", image2, 3)
    ssim = kornia.metrics.ssim(to_unit_float(image1), to_unit_float(image2), window, max_val=1.0)
    return ((1.0 - ssim) / 2.0).clamp(0.0, 1.0).mean(1)


def photometric_error(
    image1: Tensor,
    image2: Tensor,
    flow: Tensor,
    measure: Measure = "census",
    radius: int = 3,
    ssim_window: int = 11,
    box: tuple[int, int, int, int] | None = None,
) -> tuple[Tensor, Tensor]:
    """How badly ``flow`` (t -> t+1) explains frame t from frame t+1: the per-pixel error
    between ``image1`` and ``image2`` warped by ``flow`` (:func:`warp`).

    image1, image2: (B, 3, H, W) uint8 or float 0..1; flow: (B, 2, H, W) px. ``measure``:
    "census" (:func:`census_error`, window 2 ``radius`` + 1) or "ssim" (:func:`ssim_error`).
    Returns (error (B, H, W) float, valid (B, H, W) bool = the target is in bounds). Lower is
    better; the error means nothing where the pixel is occluded in frame t+1. With ``box`` =
    (y0, y1, x0, x1) px, only that part is measured (the same values as the whole frame's
    there: the window's context around the box is read) and returned, (B, y1 - y0, x1 - x0).
    """
    if measure not in MEASURES:
        raise ValueError(f"`measure` must be one of {MEASURES}, got {measure!r}")
    _check("image1", image1, 3)
    _check("image2", image2, 3)
    if image1.shape != image2.shape:
        raise ValueError(f"`image1` and `image2` shapes differ: {tuple(image1.shape)} vs {tuple(image2.shape)}")
    warped, valid = warp(image2, flow)
    image1 = to_unit_float(image1).to(warped.dtype)
    census = measure == "census"
    error, size, reach = (census_error, radius, radius) if census else (ssim_error, ssim_window, ssim_window // 2)
    if box is None:
        return error(image1, warped, size), valid
    (y0, y1, x0, x1), (H, W) = box, image1.shape[-2:]
    cy0, cy1, cx0, cx1 = max(0, y0 - reach), min(H, y1 + reach), max(0, x0 - reach), min(W, x1 + reach)
    part = error(image1[..., cy0:cy1, cx0:cx1], warped[..., cy0:cy1, cx0:cx1], size)
    return part[..., y0 - cy0 : y1 - cy0, x0 - cx0 : x1 - cx0], valid[..., y0:y1, x0:x1]


def track_error(image1: Tensor, image2: Tensor, points1: Tensor, points2: Tensor, radius: int = 3) -> tuple[Tensor, Tensor]:
    """How badly point tracks explain two frames: the soft census distance (as
    :func:`census_error`) between the signature at ``points1`` in ``image1`` and at ``points2``
    in ``image2``, both sampled bilinearly.

    image1, image2: (B, 3, H, W) uint8 or float 0..1; points1, points2: (B, K, 2) px (x, y),
    pixel centres at integer coordinates. Returns (error (B, K) in [0, (2r+1)^2 - 1), valid
    (B, K) bool = both points inside their images and finite). Lower is better.
    """
    _check("image1", image1, 3)
    _check("image2", image2, 3)
    height, width = image1.shape[-2:]

    def sample(image: Tensor, points: Tensor) -> tuple[Tensor, Tensor]:
        grid = torch.nan_to_num(points.float(), 0.0) * 2 / points.new_tensor([max(width - 1, 1), max(height - 1, 1)]) - 1
        signature = F.grid_sample(census_transform(image, radius), grid[:, :, None].float(), align_corners=True)
        return signature[..., 0], inside_image(points, height, width)

    s1, in1 = sample(image1, points1)
    s2, in2 = sample(image2, points2)
    d2 = (s1 - s2).square()
    return (d2 / (0.1 + d2)).sum(1), in1 & in2


def forward_backward_check(
    flow_fw: Tensor,
    flow_bw: Tensor,
    alpha1: float = 0.01,
    alpha2: float = 0.5,
    outside_occluded: bool = True,
) -> tuple[Tensor, Tensor]:
    """Forward-backward consistency of a flow pair and the occlusion estimate it gives.

    flow_fw: (B, 2, H, W) px, t -> t+1; flow_bw: (B, 2, H, W) px, t+1 -> t. With
    ``b = flow_bw`` sampled at x + f(x) (:func:`warp`), a pixel of frame t is flagged when
    ``|f + b|^2 >= alpha1 (|f|^2 + |b|^2) + alpha2`` (Sundaram et al. 2010; UnFlow's
    alpha1 = 0.01, alpha2 = 0.5 px^2), and, with ``outside_occluded``, when its target leaves
    the image. Returns (fb_error ``|f + b|`` (B, H, W) px, occluded bool (B, H, W)).
    """
    _check("flow_fw", flow_fw, 2)
    _check_flow("flow_bw", flow_bw, flow_fw)
    bw, inside = warp(flow_bw, flow_fw)
    sq = (flow_fw + bw).square().sum(1)
    bound = alpha1 * (flow_fw.square().sum(1) + bw.square().sum(1)) + alpha2
    occluded = ~(sq < bound)  # NaN flows count as occluded
    if outside_occluded:
        occluded = occluded | ~inside
    return sq.sqrt(), occluded


def _masked(values: Tensor, mask: Tensor | None) -> tuple[Tensor, Tensor]:
    """(values with unselected pixels zeroed, selection as values' dtype), both (B, H, W)."""
    if values.ndim != 3:
        raise ValueError(f"`values` must have shape (B, H, W), got {tuple(values.shape)}")
    if mask is None:
        mask = torch.ones_like(values, dtype=torch.bool)
    elif mask.shape != values.shape or mask.dtype != torch.bool:
        got = f"{mask.dtype} {tuple(mask.shape)}"
        raise ValueError(f"`mask` must be a bool tensor of shape {tuple(values.shape)}, got {got}")
    return torch.where(mask, values, torch.zeros_like(values)), mask.to(values.dtype)


def region_mean(values: Tensor, mask: Tensor | None = None) -> Tensor:
    """Mean of a per-pixel map over a region, per image.

    values: (B, H, W) float (may hold NaN/inf outside ``mask``); mask: bool (B, H, W) (None =
    every pixel). Returns (B,); NaN for an image whose region is empty.
    """
    values, weight = _masked(values, mask)
    return values.sum((1, 2)) / weight.sum((1, 2))


def tile_mean(values: Tensor, mask: Tensor | None = None, tiles: tuple[int, int] = (4, 4)) -> Tensor:
    """Mean of a per-pixel map in a grid of ``tiles`` = (ny, nx) tiles, per image.

    values: (B, H, W) float; mask: bool (B, H, W) of the pixels to count (None = all). Row y
    falls in tile row ``y * ny // H`` (column likewise), so tiles differ by at most one pixel
    in size. Returns (B, ny, nx); NaN in tiles with no selected pixel.
    """
    values, weight = _masked(values, mask)
    batch, height, width = values.shape
    ny, nx = tiles
    if not (1 <= ny <= height and 1 <= nx <= width):
        raise ValueError(f"`tiles` must be (ny, nx) with 1 <= ny <= {height} and 1 <= nx <= {width}, got {tiles}")
    rows = torch.arange(height, device=values.device) * ny // height
    cols = torch.arange(width, device=values.device) * nx // width
    index = (rows[:, None] * nx + cols).flatten().expand(batch, -1)
    sums = values.new_zeros(batch, ny * nx).scatter_add_(1, index, values.flatten(1))
    counts = values.new_zeros(batch, ny * nx).scatter_add_(1, index, weight.flatten(1))
    return (sums / counts).view(batch, ny, nx)


@dataclass
class Evidence:
    """What frames t and t+1 say about a flow t -> t+1 (all (B, H, W)).

    photometric: per-pixel error of the warped frame t+1 (see :func:`photometric_error`);
    valid: bool, the flow's target is in bounds; fb_error: px, forward-backward error, and
    occluded: bool, the forward-backward flags (both None without a backward flow).
    """

    photometric: Tensor
    valid: Tensor
    fb_error: Tensor | None = None
    occluded: Tensor | None = None

    @property
    def reliable(self) -> Tensor:
        """bool (B, H, W): in bounds and not flagged as occluded (``valid`` without flags)."""
        return self.valid if self.occluded is None else self.valid & ~self.occluded


def pair_evidence(
    image1: Tensor,
    image2: Tensor,
    flow_fw: Tensor,
    flow_bw: Tensor | None = None,
    *,
    measure: Measure = "census",
    radius: int = 3,
    ssim_window: int = 11,
    alpha1: float = 0.01,
    alpha2: float = 0.5,
) -> Evidence:
    """The :class:`Evidence` of a batch of pairs: images (B, 3, H, W) uint8 or float 0..1,
    flow_fw (B, 2, H, W) px t -> t+1, flow_bw (B, 2, H, W) px t+1 -> t or None. Keywords as in
    :func:`photometric_error` and :func:`forward_backward_check`."""
    error, valid = photometric_error(image1, image2, flow_fw, measure, radius, ssim_window)
    if flow_bw is None:
        return Evidence(error, valid)
    fb_error, occluded = forward_backward_check(flow_fw, flow_bw, alpha1, alpha2)
    return Evidence(error, valid, fb_error, occluded)
