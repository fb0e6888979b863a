"""RAFT models from torchvision, their input convention, and flow prediction.

torchvision's RAFT takes RGB in [-1, 1] with sides divisible by 8 (its own size check has a
precedence bug, so we pad ourselves) and at least 128 px (its correlation pyramid downsamples
the 1/8 feature maps three more times). :func:`prepare_pair` turns uint8 (0..255) or float
(0..1) RGB of any size into that, replicate-padding to a multiple of 8 and at least 128 px;
:func:`predict_flow` returns the flow cropped back to the input size.
"""

from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F
from torchvision.models.optical_flow import RAFT, raft_large, raft_small
from torchvision.models.optical_flow._utils import make_coords_grid, upsample_flow

from .weights import ARCHS, load_state_dict_file, resolve_weights

__all__ = ["load_raft", "prepare_pair", "predict_flow", "pad_to_multiple", "truncated_raft", "encode_frames",
           "context_state", "run_updates", "to_unit_range"]


def load_raft(arch: str = "raft_small", weights: str | Path | None = "C_T_V1") -> RAFT:
    """A torchvision RAFT (``raft_small`` or ``raft_large``) with ``weights``: a file path
    (torchvision or original princeton-vl format), a torchvision weights name (``C_T_V1``,
    ``C_T_V2``, ``C_T_SKHT_V2`` ...; looked up locally first, see :mod:`lit_boot.flow.weights`),
    or None for random initialisation."""
    if arch not in ARCHS:
        raise ValueError(f"arch: expected one of {ARCHS}, got {arch!r}")
    model = raft_small() if arch == "raft_small" else raft_large()
    if weights is not None:
        path = resolve_weights(arch, weights)
        state = load_state_dict_file(path, arch)
        result = model.load_state_dict(state, strict=False)
        if result.missing_keys or result.unexpected_keys:
            raise ValueError(
                f"{path}: does not fit {arch}: missing {result.missing_keys[:5]}, unexpected {result.unexpected_keys[:5]}"
            )
    return model


#: The smallest side RAFT accepts (feature maps of 16 at 1/8 resolution).
MIN_SIZE = 128


def pad_to_multiple(
    images: torch.Tensor, multiple: int = 8, min_size: int = MIN_SIZE
) -> tuple[torch.Tensor, tuple[int, int, int, int]]:
    """Replicate-pad (B, C, H, W) so H and W are multiples of ``multiple`` and at least
    ``min_size``, split evenly (the extra pixel at the bottom/right). Returns the padded tensor
    and (left, right, top, bottom)."""
    H, W = images.shape[-2:]
    ph = max((-H) % multiple, min_size - H)
    pw = max((-W) % multiple, min_size - W)
    pad = (pw // 2, pw - pw // 2, ph // 2, ph - ph // 2)
    if ph == 0 and pw == 0:
        return images, pad
    return F.pad(images, pad, mode="replicate"), pad


def to_unit_range(images: torch.Tensor, name: str) -> torch.Tensor:
    """RGB (3, H, W) or (B, 3, H, W), uint8 0..255 or float 0..1, as RAFT takes it: (B, 3, H, W)
    in [-1, 1]. ``name`` names the argument in errors."""
    if images.ndim == 3:
        images = images[None]
    if images.ndim != 4 or images.shape[1] != 3:
        raise ValueError(f"{name}: expected RGB images (3, H, W) or (B, 3, H, W), got shape {tuple(images.shape)}")
    if images.dtype == torch.uint8:
        return images.float() / 127.5 - 1.0
    if not images.is_floating_point():
        raise ValueError(f"{name}: expected uint8 (0..255) or float (0..1) images, got {images.dtype}")
    return images * 2.0 - 1.0


def prepare_pair(
    image1: torch.Tensor, image2: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, tuple[int, int, int, int]]:
    """RAFT inputs from two batches of RGB images: uint8 0..255 or float 0..1, (B, 3, H, W) or
    (3, H, W) -> [-1, 1], padded to multiples of 8; returns them and the padding."""
    a, b = to_unit_range(image1, "image1"), to_unit_range(image2, "image2")
    if a.shape != b.shape:
        raise ValueError(f"image1 and image2: shapes differ, {tuple(a.shape)} vs {tuple(b.shape)}")
    a, pad = pad_to_multiple(a)
    b, _ = pad_to_multiple(b)
    return a, b, pad


def unpad(flow: torch.Tensor, pad: tuple[int, int, int, int]) -> torch.Tensor:
    """Crop a padded (..., H, W) tensor back to the input size."""
    left, right, top, bottom = pad
    H, W = flow.shape[-2:]
    return flow[..., top : H - bottom, left : W - right]


def encode_frames(model: RAFT, images: torch.Tensor) -> torch.Tensor:
    """RAFT's feature maps (B, C, h, w) at 1/8 resolution of prepared images (B, 3, 8h, 8w).
    The encoder normalises each image on its own, so a frame's map is the same in every pair."""
    return model.feature_encoder(images)


def context_state(model: RAFT, image1: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """RAFT's initial hidden state and context features (B, C, h, w) of prepared first frames."""
    out = model.context_encoder(image1)
    size = model.update_block.hidden_state_size
    hidden, context = torch.split(out, [size, out.shape[1] - size], dim=1)
    return torch.tanh(hidden), F.relu(context)


def run_updates(
    model: RAFT,
    fmap1: torch.Tensor,
    fmap2: torch.Tensor,
    hidden: torch.Tensor,
    context: torch.Tensor,
    flow8: torch.Tensor | None,
    updates: int,
    grad_updates: int | None = None,
) -> tuple[list[torch.Tensor], torch.Tensor]:
    """RAFT's update iterations (torchvision's modules) over encoded inputs (B, C, h, w), from the
    1/8-resolution flow ``flow8`` (B, 2, h, w) in 1/8 px (None: zero, RAFT's own start; a flow:
    a warm start). Gradients (when enabled) go through the last ``grad_updates`` iterations only
    (None: all, as torchvision). Returns the flows (B, 2, 8h, 8w) px of those iterations,
    upsampled, and the last iteration's 1/8-resolution flow (detached)."""
    B, _, h, w = fmap1.shape
    model.corr_block.build_pyramid(fmap1, fmap2)
    coords0 = make_coords_grid(B, h, w).to(fmap1.device)
    coords1 = coords0.clone() if flow8 is None else coords0 + flow8.to(coords0)
    flows, first = [], 0 if grad_updates is None else updates - grad_updates
    for i in range(updates):
        with torch.set_grad_enabled(torch.is_grad_enabled() and i >= first):
            coords1 = coords1.detach()  # as RAFT: no gradient through the coordinates' chain
            corr = model.corr_block.index_pyramid(centroids_coords=coords1)
            hidden, delta = model.update_block(hidden, context, corr, coords1 - coords0)
            coords1 = coords1 + delta
            if i >= first:
                mask = None if model.mask_predictor is None else model.mask_predictor(hidden)
                flows.append(upsample_flow(flow=coords1 - coords0, up_mask=mask))
    return flows, (coords1 - coords0).detach()


def truncated_raft(model: RAFT, image1: torch.Tensor, image2: torch.Tensor, updates: int,
                   grad_updates: int) -> list[torch.Tensor]:  # fmt: skip
    """RAFT's forward (torchvision's modules, the same iterations) with truncated backpropagation:
    the first ``updates - grad_updates`` iterations run without gradient, and only the last
    ``grad_updates`` iterations' flows are upsampled and returned, (B, 2, H, W) px each. Inputs
    as torchvision's RAFT takes them (see :func:`prepare_pair`). The values equal the forward's."""
    return _iterate(model, image1, image2, updates, grad_updates, None)


def _iterate(model: RAFT, image1: torch.Tensor, image2: torch.Tensor, updates: int, grad_updates: int | None,
             flow8: torch.Tensor | None) -> list[torch.Tensor]:  # fmt: skip
    """RAFT's encoders and ``updates`` iterations on prepared inputs, from ``flow8`` (see
    :func:`run_updates`): the upsampled flows of the iterations with gradient."""
    if grad_updates is not None and not 1 <= grad_updates <= updates:
        raise ValueError(f"grad_updates: expected 1..{updates} (the training updates), got {grad_updates}")
    fmap1, fmap2 = torch.chunk(encode_frames(model, torch.cat([image1, image2], dim=0)), chunks=2, dim=0)
    hidden, context = context_state(model, image1)
    return run_updates(model, fmap1, fmap2, hidden, context, flow8, updates, grad_updates)[0]


def predict_flow(
    model: RAFT,
    image1: torch.Tensor,
    image2: torch.Tensor,
    num_flow_updates: int = 32,
    all_updates: bool = False,
    grad_updates: int | None = None,
    start: torch.Tensor | None = None,
) -> torch.Tensor | list[torch.Tensor]:
    """Forward flow image1 -> image2 with ``num_flow_updates`` RAFT iterations: (B, 2, H, W) in
    pixels at the input size (or the list of every update's flow with ``all_updates``).
    Runs on the model's device; gradients flow when enabled (used for fine-tuning), through the
    last ``grad_updates`` iterations only when given (:func:`truncated_raft`; ``all_updates``
    then lists those iterations' flows). ``start`` (B, 2, H, W) px: a warm start, the iterations
    begin from it (replicate-padded like the images, averaged onto RAFT's 1/8 grid) instead of
    zero."""
    device = next(model.parameters()).device
    a, b, pad = prepare_pair(image1.to(device), image2.to(device))
    if start is not None:
        left, right, top, bottom = pad
        padded = F.pad(start.to(device).float(), (left, right, top, bottom), mode="replicate")
        flows = _iterate(model, a, b, num_flow_updates, grad_updates, F.avg_pool2d(padded, 8) / 8)
    elif grad_updates is None:
        flows = model(a, b, num_flow_updates=num_flow_updates)
    else:
        flows = truncated_raft(model, a, b, num_flow_updates, grad_updates)
    if all_updates:
        return [unpad(f, pad) for f in flows]
    return unpad(flows[-1], pad)
