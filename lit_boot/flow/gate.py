"""The evidence gate (issue 13, "do no harm"): keep a sketch pixel only where the images
support it.

A painted pixel is kept when the sketch's displacement explains the frames at least as well as
the base flow there: census error (:func:`~lit_boot.flow.evidence.photometric_error`, 7x7) of
the sketch flow <= that of the base flow + ``gate_margin``, compared only where both flows'
targets are in bounds ("comparable"); per pixel, per bone (the mean difference over the
bone's comparable "core" pixels, those within ``gate_core`` px of its frame-t segment, decides
for all its pixels: the footprint's background pixels would drown the limb's), or both. With
``gate="photometric+fb"`` a pixel is also kept where the base flow fails its own
forward-backward check (occluded or wrong: RAFT has no claim there). Pixels that are neither
comparable nor fb-failed are dropped: unverifiable.
With ``gate_search`` = r > 0, each bone's displacement is first shifted by the integer offset
(|dx|, |dy| <= r px) that minimises its mean census error over its core pixels (no shift on
ties), and the shifted sketch is what is judged and painted.
The comparison is local and relative (sketch vs base at the same pixel), never an absolute
threshold (BENCHMARKS.md, "Image evidence").
"""

from __future__ import annotations

from dataclasses import replace

import torch
from torch import Tensor

from .evidence import forward_backward_check, photometric_error
from .sketch import SketchConfig, SketchResult

__all__ = ["GATE_REPORT_KEYS", "gate_sketch"]

#: What :func:`gate_sketch` reports (FlowTTT prefixes them with "target/").
GATE_REPORT_KEYS = (
    "gate_kept_fraction",  # kept / painted pixels (1 when nothing was painted)
    "gate_rejected_bones",  # bones that painted pixels before the gate and none after
    "gate_fb_failed_fraction",  # painted pixels where the base flow fails its fb check
    "gate_unverifiable_fraction",  # painted pixels where the two flows cannot be compared
    "gate_worse_fraction",  # comparable painted pixels where the sketch's error > base's + margin
    "gate_search_shift_px",  # mean length of the kept bones' search shifts (0 without search)
)


def _line_distance(owner: Tensor, ends: Tensor) -> Tensor:
    """(B, H, W) px: each painted pixel's distance to its bone's segment ``ends`` (B, E, 2, 2)
    (frame t); inf where ``owner`` (B, H, W) is -1."""
    B, H, W = owner.shape
    ys, xs = torch.meshgrid(torch.arange(H, device=owner.device), torch.arange(W, device=owner.device), indexing="ij")
    pix = torch.stack([xs, ys], -1).to(ends.dtype)  # (H, W, 2)
    seg = ends[torch.arange(B, device=owner.device)[:, None, None], owner.clamp_min(0)]  # (B, H, W, 2, 2)
    a, d = seg[..., 0, :], seg[..., 1, :] - seg[..., 0, :]
    s = (((pix - a) * d).sum(-1) / d.square().sum(-1).clamp_min(1e-12)).clamp(0.0, 1.0)
    dist = (pix - a - s[..., None] * d).norm(dim=-1)
    return torch.where(owner >= 0, dist, torch.full_like(dist, torch.inf))


def _bone_mean(values: Tensor, select: Tensor, owner: Tensor, bones: int) -> Tensor:
    """(B, E): mean of ``values`` (B, H, W) over each bone's ``select``-ed pixels; NaN for none."""
    B = values.shape[0]
    sel = select & (owner >= 0)
    key = (torch.arange(B, device=values.device)[:, None, None] * bones + owner.clamp_min(0))[sel]
    sums = values.new_zeros(B * bones).index_add_(0, key, values[sel])
    counts = values.new_zeros(B * bones).index_add_(0, key, torch.ones_like(values[sel]))
    return (sums / counts).view(B, bones)


def _per_pixel(per_bone: Tensor, owner: Tensor) -> Tensor:
    """(B, E, ...) per-bone values spread to the pixels of ``owner`` (B, H, W): (B, H, W, ...)."""
    return per_bone[torch.arange(owner.shape[0], device=owner.device)[:, None, None], owner.clamp_min(0)]


def _search(
    image1: Tensor, image2: Tensor, flow: Tensor, owner: Tensor, core: Tensor, bones: int, radius: int
) -> Tensor:
    """The bone shifts (B, E, 2) px, |dx|, |dy| <= ``radius``, that minimise each bone's mean
    census error over its ``core`` pixels (B, H, W); zero on ties or without core pixels."""
    r = torch.arange(-radius, radius + 1, dtype=flow.dtype, device=flow.device)
    grid = torch.cartesian_prod(r, r)
    grid = grid[grid.norm(dim=-1).argsort(stable=True)]  # (0, 0) first: it wins ties
    best = flow.new_full((owner.shape[0], bones), torch.inf)
    shift = flow.new_zeros(owner.shape[0], bones, 2)
    painted = (owner >= 0)[:, None]
    for offset in grid:
        err, valid = photometric_error(image1, image2, torch.where(painted, flow + offset[:, None, None], flow))
        mean = _bone_mean(err, core & valid, owner, bones)
        better = mean < best  # NaN never is
        best, shift = torch.where(better, mean, best), torch.where(better[..., None], offset, shift)
    return shift


def _chunk(image1, image2, base, flow, owner, ends, base_bw, config: SketchConfig):  # noqa: ANN001, ANN202
    """One chunk's evidence (B, H, W): census difference sketch - base, comparable, fb-failed,
    core; and the (searched) sketch flow (B, 2, H, W) with the shifts (B, E, 2) or None."""
    core = shift = None
    if owner is not None and ends is not None:
        core = _line_distance(owner, ends.to(flow)) <= config.gate_core
        if config.gate_search > 0:
            shift = _search(image1, image2, flow, owner, core, ends.shape[1], config.gate_search)
            flow = torch.where((owner >= 0)[:, None], flow + _per_pixel(shift, owner).permute(0, 3, 1, 2), flow)
    err_s, valid_s = photometric_error(image1, image2, flow)
    err_b, valid_b = photometric_error(image1, image2, base)
    failed = torch.zeros_like(valid_b) if base_bw is None else forward_backward_check(base, base_bw)[1]
    return err_s - err_b, valid_s & valid_b, failed, core, flow, shift


def gate_sketch(
    image1: Tensor,
    image2: Tensor,
    base_flow: Tensor,
    sketch: SketchResult,
    config: SketchConfig,
    base_flow_bw: Tensor | None = None,
    chunk: int = 8,
) -> tuple[SketchResult, dict[str, float]]:
    """Gate a drawn sketch by the images (see the module docstring).

    image1, image2: (B, 3, H, W) frames t and t+1, uint8 or float 0..1; base_flow: (B, 2, H, W)
    px, the flow the sketch is painted over; sketch: its :class:`SketchResult` (with ``owner``
    and ``bone_ends`` for the bone levels and the search); base_flow_bw: (B, 2, H, W) px, the
    base flow t+1 -> t, needed for ``gate="photometric+fb"``. Pairs go ``chunk`` at a time
    (memory: ~50 floats a pixel). Returns the gated sketch (mask, flow, owner cut to the kept
    pixels, flow searched; ``bone_drawn`` false for bones that lost every pixel) and counts
    (:data:`GATE_REPORT_KEYS`). ``gate="off"`` returns the sketch unchanged.
    """
    if config.gate == "off":
        return sketch, {}
    if config.gate == "photometric+fb" and base_flow_bw is None:
        raise ValueError('gate "photometric+fb" needs base_flow_bw, the base flow t+1 -> t')
    owner, ends, E = sketch.owner, sketch.bone_ends, sketch.bone_drawn.shape[1]
    if (config.gate_level != "pixel" or config.gate_search > 0) and (owner is None or ends is None):
        raise ValueError("the bone levels and the search need sketch.owner and bone_ends (from sketch_flow)")
    bw = base_flow_bw if config.gate == "photometric+fb" else None
    parts = []
    for i in range(0, base_flow.shape[0], chunk):
        s = slice(i, i + chunk)
        parts.append(_chunk(image1[s], image2[s], base_flow[s], sketch.flow[s].to(base_flow),
                            None if owner is None else owner[s], None if ends is None else ends[s],
                            None if bw is None else bw[s], config))  # fmt: skip
    device = sketch.mask.device
    diff, comparable, failed, core, flow, shift = (
        None if t[0] is None else torch.cat(t).to(device) for t in zip(*parts)
    )
    supported = comparable & (diff <= config.gate_margin)
    if config.gate_level != "pixel":
        bone_ok = _bone_mean(diff, comparable & core, owner, E) <= config.gate_margin  # NaN: no evidence
        bone = (owner >= 0) & _per_pixel(bone_ok, owner)
        supported = bone & supported if config.gate_level == "bone+pixel" else bone
    kept = sketch.mask & (supported | failed)
    gated_owner, lost = None, torch.zeros_like(sketch.bone_drawn)
    if owner is not None:
        gated_owner = torch.where(kept, owner, torch.full_like(owner, -1))
        lost = _painting(owner, E) & ~_painting(gated_owner, E)
    report = _report(sketch.mask, kept, comparable, failed, diff > config.gate_margin, lost)
    report["gate_search_shift_px"] = 0.0
    if shift is not None and (still := _painting(gated_owner, E)).any():
        report["gate_search_shift_px"] = float(shift.to(device).norm(dim=-1)[still].mean())
    flow = torch.where(kept[:, None], flow.to(sketch.flow), torch.zeros_like(sketch.flow))
    drawn = sketch.bone_drawn & ~lost
    return replace(sketch, flow=flow, mask=kept, bone_drawn=drawn, owner=gated_owner), report


def _painting(owner: Tensor, bones: int) -> Tensor:
    """(B, E) bool: bones owning at least one pixel of ``owner`` (B, H, W)."""
    B = owner.shape[0]
    key = (torch.arange(B, device=owner.device)[:, None, None] * bones + owner.clamp_min(0))[owner >= 0]
    return torch.zeros(B * bones, dtype=torch.bool, device=owner.device).index_fill_(0, key, True).view(B, bones)


def _report(
    painted: Tensor, kept: Tensor, comparable: Tensor, failed: Tensor, worse: Tensor, lost: Tensor
) -> dict[str, float]:
    """The counts of :data:`GATE_REPORT_KEYS` from (B, H, W) bool maps and ``lost`` (B, E)."""
    n = int(painted.sum())
    frac = lambda m: float((m & painted).sum()) / n if n else 0.0  # noqa: E731
    return {
        "gate_kept_fraction": frac(kept) if n else 1.0,
        "gate_rejected_bones": float(lost.sum()),
        "gate_fb_failed_fraction": frac(failed),
        "gate_unverifiable_fraction": frac(~comparable & ~failed),
        "gate_worse_fraction": frac(comparable & worse),
    }
