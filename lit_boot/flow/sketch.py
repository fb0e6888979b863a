"""The target flow sketch (paper section 3.1): a thick stick-man whose pixels carry the motion
of their corresponding point on the bone, painted over a base flow.

Conventions: pixels (x, y) with centres at integer coordinates, y down; flows (B, 2, H, W) in
px, channel 0 = x displacement, forward from frame t to t+1. Every bone (a, b) is sampled at
p_k = a + s_k (b - a) in frame t and q_k = a' + s_k (b' - a') in frame t+1 (the same s_k: point
k corresponds to point k); sample k paints its footprint, centred at round(p_k) (halves round
up), with d_k = q_k - p_k. Where footprints overlap the nearer sample wins when depths are
given, else the later one (later bones, then later samples of a bone), as in the authors' code.
Pixels outside the image are dropped (the authors' code wraps them around: a bug).

Guards (REFERENCE section 7: a bad target teaches the network nonsense): a bone is drawn only
when both ends are confident in both frames, neither end jumps implausibly far, and its
displacement agrees with the base flow; single samples that disagree badly are dropped too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import torch
from torch import Tensor

from ..core.joints import JointLayout, get_layout
from ..metrics import sample_flow_at_points
from .sketch_config import FOOTPRINTS, GATE_LEVELS, GATES, SketchConfig, SketchResult, check_footprint

__all__ = [
    "FOOTPRINTS",
    "GATES",
    "GATE_LEVELS",
    "SketchConfig",
    "SketchResult",
    "footprint_offsets",
    "sketch_flow",
    "sketch_from_layout",
    "target_flow",
]

@lru_cache(maxsize=32)
def _offsets(footprint: str, size: int, device: torch.device) -> Tensor:
    check_footprint(footprint, size)
    if footprint == "cross":
        r = torch.arange(-size, size + 1)
        zero = torch.zeros_like(r)
        off = torch.cat([torch.stack([r, zero], -1), torch.stack([zero[r != 0], r[r != 0]], -1)])
    else:
        r = torch.arange(-(size // 2), size - size // 2) if footprint == "square" else torch.arange(-size, size + 1)
        dy, dx = torch.meshgrid(r, r, indexing="ij")
        off = torch.stack([dx.flatten(), dy.flatten()], -1)
        if footprint == "disk":
            off = off[(off**2).sum(-1) <= size**2]
    return off.to(device)


def footprint_offsets(footprint: str, size: int, device: torch.device | str | None = None) -> Tensor:
    """(F, 2) long pixel offsets (dx, dy) of a footprint (see :class:`SketchConfig`); cached."""
    return _offsets(footprint, int(size), torch.device(device or "cpu")).clone()


def _clip_segment(a: Tensor, b: Tensor, lo: Tensor, hi: Tensor) -> tuple[Tensor, Tensor]:
    """Liang-Barsky: the range [s0, s1] of s in [0, 1] where a + s (b - a) lies in the box
    [lo, hi] (per axis); empty when s0 > s1. a, b: (..., 2); lo, hi: (2,). Returns (...,)."""
    d = b - a
    flat = d == 0
    safe = torch.where(flat, torch.ones_like(d), d)
    t_lo, t_hi = (lo - a) / safe, (hi - a) / safe
    inside = (a >= lo) & (a <= hi)
    inf = torch.full_like(d, math.inf)
    enter = torch.where(flat, torch.where(inside, -inf, inf), torch.minimum(t_lo, t_hi))
    leave = torch.where(flat, torch.where(inside, inf, -inf), torch.maximum(t_lo, t_hi))
    return enter.amax(-1).clamp_min(0.0), leave.amin(-1).clamp_max(1.0)


def _median(x: Tensor, valid: Tensor) -> Tensor:
    """Lower median of x (..., N) over its ``valid`` entries (NaN when none), as torch.median;
    by sorting, which stays deterministic where torch's median kernels are not (CUDA)."""
    count = valid.sum(-1, keepdim=True)
    ordered = torch.where(valid, x, torch.full_like(x, math.inf)).sort(dim=-1).values
    median = ordered.gather(-1, ((count - 1) // 2).clamp_min(0))[..., 0]
    return torch.where(count[..., 0] > 0, median, torch.full_like(median, math.nan))


def _plausible_joints(jt: Tensor, jt1: Tensor, ok: Tensor, max_jump: float, groups: Tensor | None = None) -> Tensor:
    """(B, K) bool: joints whose motion is at most ``max_jump`` x their person's size, the
    diagonal of the bounding box of the person's ``ok`` joints of frame t (0 when there are
    none, or when they are a single point: then any motion is implausible). ``groups`` (K,)
    long: the person of each joint (None: one person)."""
    if groups is None:
        groups = torch.zeros(jt.shape[1], dtype=torch.long, device=jt.device)
    inf = torch.full_like(jt, math.inf)
    size = torch.zeros(jt.shape[:2], dtype=jt.dtype, device=jt.device)
    for g in torch.unique(groups).tolist():
        mine = ok & (groups == g)
        lo = torch.where(mine[..., None], jt, inf).amin(1)
        hi = torch.where(mine[..., None], jt, -inf).amax(1)
        person = torch.where(mine.any(1), (hi - lo).norm(dim=-1), torch.zeros_like(lo[:, 0]))
        size = torch.where(groups == g, person[:, None], size)
    return (jt1 - jt).norm(dim=-1) <= max_jump * size


def _along(x: Tensor, y: Tensor, s0: Tensor, s1: Tensor, u: Tensor) -> Tensor:
    """Points x + s (y - x) at s = s0 + u (s1 - s0): x, y (B, E, D); s0, s1 (B, E); u (B, E, N).
    Returns (B, E, N, D), interpolated between the clipped ends (precise for far-off joints)."""
    x0, x1 = x + s0[..., None] * (y - x), x + s1[..., None] * (y - x)
    return x0[:, :, None] + u[..., None] * (x1 - x0)[:, :, None]


@dataclass
class _Samples:
    """Bone samples, (B, E, N, ...): frame-t position p, displacement d, depth or None,
    valid (a real sample whose footprint can touch the image)."""

    p: Tensor
    d: Tensor
    depth: Tensor | None
    valid: Tensor


def _sample_bones(
    jt: Tensor, jt1: Tensor, bones: Tensor, keep: Tensor, depths: Tensor | None, height: int, width: int,
    config: SketchConfig, reach: int,
) -> _Samples:  # fmt: skip
    """Sample the ``keep`` bones (B, E): fixed ``points_per_bone`` over the whole bone, or dense
    (<= 0.5 px apart) over the part within ``reach`` px of the image."""
    a, b = jt[:, bones[:, 0]], jt[:, bones[:, 1]]  # (B, E, 2)
    a1, b1 = jt1[:, bones[:, 0]], jt1[:, bones[:, 1]]
    if config.points_per_bone is None:
        lo = jt.new_tensor([-reach - 0.5, -reach - 0.5])
        hi = jt.new_tensor([width - 0.5 + reach, height - 0.5 + reach])
        s0, s1 = _clip_segment(a, b, lo, hi)
        seen = (b - a).norm(dim=-1) * (s1 - s0)
        n = torch.where(keep & (s1 >= s0), torch.ceil(2.0 * seen.clamp_min(0)).long() + 1, 0)
    else:
        s0, s1 = torch.zeros_like(a[..., 0]), torch.ones_like(a[..., 0])
        n = torch.where(keep, config.points_per_bone, 0)
    N = int(n.max()) if n.numel() else 0
    k = torch.arange(N, device=jt.device)
    u = k.to(jt.dtype) / (n - 1).clamp_min(1)[..., None].to(jt.dtype)  # (B, E, N): 0 .. 1 over [s0, s1]
    p, q = _along(a, b, s0, s1, u), _along(a1, b1, s0, s1, u)
    c = torch.floor(p + 0.5)
    size = jt.new_tensor([width, height])
    valid = (k < n[..., None]) & ((c >= -reach) & (c <= size - 1 + reach)).all(-1)
    depth = None
    if depths is not None:
        depth = _along(depths[:, bones[:, 0], None], depths[:, bones[:, 1], None], s0, s1, u)[..., 0]
    return _Samples(p, q - p, depth, valid)


def _paint(samples: _Samples, offsets: Tensor, reach: int, height: int, width: int) -> tuple[Tensor, Tensor, Tensor]:
    """Paint every valid sample's footprint (offsets within ``reach`` px; valid centres lie
    within ``reach`` px of the image); per pixel the highest-priority sample wins. Returns
    (flow (B, 2, H, W), mask (B, H, W), owner (B, H, W): the winner's bone, -1 unpainted).

    Priorities are unique integers per image (drawing order, or depth then drawing order), the
    winner is found with a scatter ``amax``: deterministic on every device.
    """
    p, valid = samples.p.flatten(1, 2), samples.valid.flatten(1)  # (B, S, 2), (B, S)
    B, S = valid.shape
    order = torch.arange(S, device=p.device).expand(B, S)
    if samples.depth is None:
        prio = order
    else:  # nearer wins; ties keep drawing order (stable sort of -depth: later = higher)
        depth = torch.nan_to_num(samples.depth.flatten(1), nan=math.inf)
        depth = torch.where(valid, depth, torch.full_like(depth, math.inf))
        idx = torch.sort(-depth, dim=1, stable=True).indices
        prio = torch.empty_like(idx).scatter_(1, idx, order)
    centre = torch.where(valid[..., None], torch.floor(p + 0.5), torch.zeros_like(p)).long()
    # Samples sharing a centre paint the same pixels: only the top one can win (dense sampling
    # puts ~2 samples per centre), so drop the others before expanding the footprints.
    gh, gw = height + 2 * reach, width + 2 * reach
    key = (torch.arange(B, device=p.device)[:, None] * gh + centre[..., 1] + reach) * gw + centre[..., 0] + reach
    key = torch.where(valid, key, B * gh * gw)  # invalid samples share a dummy slot
    top = torch.full((B * gh * gw + 1,), -1, dtype=torch.long, device=p.device)
    valid = valid & (prio == top.scatter_reduce(0, key.flatten(), prio.flatten(), "amax")[key])
    bi, si = valid.nonzero(as_tuple=True)  # the M painting samples
    pix = centre[bi, si][:, None] + offsets  # (M, F, 2)
    inside = (pix >= 0).all(-1) & (pix[..., 0] < width) & (pix[..., 1] < height)
    mi, fi = inside.nonzero(as_tuple=True)
    bi, si, px = bi[mi], si[mi], pix[mi, fi]
    flat = (bi * height + px[:, 1]) * width + px[:, 0]
    pr = prio[bi, si]
    best = torch.full((B * height * width,), -1, dtype=torch.long, device=p.device)
    best = best.scatter_reduce(0, flat, pr, "amax")
    win = pr == best[flat]
    flow = p.new_zeros(B * height * width, 2)
    flow[flat[win]] = samples.d.flatten(1, 2)[bi[win], si[win]]
    flow = flow.view(B, height, width, 2).permute(0, 3, 1, 2).contiguous()
    owner = torch.full((B * height * width,), -1, dtype=torch.long, device=p.device)
    owner[flat[win]] = si[win] // samples.valid.shape[-1]
    return flow, (best >= 0).view(B, height, width), owner.view(B, height, width)


def _check_inputs(joints_t: Tensor, joints_t1: Tensor, height: int, width: int, **per_joint: Tensor | None) -> None:
    if joints_t.ndim != 3 or joints_t.shape[-1] != 2 or joints_t1.shape != joints_t.shape:
        raise ValueError(
            "joints_t, joints_t1: expected equal shapes (B, K, 2), "
            f"got {tuple(joints_t.shape)}, {tuple(joints_t1.shape)}"
        )
    if height < 1 or width < 1:
        raise ValueError(f"height, width: expected >= 1, got {height}, {width}")
    for name, value in per_joint.items():
        if value is not None and tuple(value.shape) != tuple(joints_t.shape[:2]):
            raise ValueError(f"{name}: expected shape {tuple(joints_t.shape[:2])}, got {tuple(value.shape)}")


def sketch_flow(
    joints_t: Tensor,
    joints_t1: Tensor,
    bones: Tensor | list[tuple[int, int]] | tuple[tuple[int, int], ...],
    height: int,
    width: int,
    *,
    confidence_t: Tensor | None = None,
    confidence_t1: Tensor | None = None,
    depths: Tensor | None = None,
    base_flow: Tensor | None = None,
    config: SketchConfig = SketchConfig(),
    groups: Tensor | None = None,
) -> SketchResult:
    """Draw the stick-man flow of B frame pairs (see the module docstring).

    joints_t, joints_t1: (B, K, 2) px in frames t and t+1 (projected 3D joints or 2D
    keypoints); bones: (E, 2) index pairs into K; confidence_t, confidence_t1: (B, K) in
    [0, 1] or None (all confident); depths: (B, K) camera z of the frame-t joints (mm; nearer
    wins overlaps) or None (drawing order wins); base_flow: (B, 2, H, W) px, the flow the
    sketch will be painted over, used by the disagreement guard (skipped when None); groups:
    (K,) long, the person each joint belongs to when several are drawn at once (the jump
    guard's person size is each one's), or None (one person). Everything is computed on
    ``joints_t``'s device.
    """
    _check_inputs(joints_t, joints_t1, height, width, confidence_t=confidence_t, confidence_t1=confidence_t1,
                  depths=depths)  # fmt: skip
    device = joints_t.device
    dtype = joints_t.dtype if joints_t.is_floating_point() else torch.float32
    B, K = joints_t.shape[:2]
    if base_flow is not None and tuple(base_flow.shape) != (B, 2, height, width):
        raise ValueError(f"base_flow: expected shape {(B, 2, height, width)}, got {tuple(base_flow.shape)}")
    bones = torch.as_tensor(bones, dtype=torch.long, device=device).reshape(-1, 2)
    if bones.numel() and not (0 <= int(bones.min()) and int(bones.max()) < K):
        raise ValueError(f"bones: indices must lie in 0..{K - 1}, got {bones.min()}..{bones.max()}")
    E = bones.shape[0]

    jt, jt1 = joints_t.to(dtype), joints_t1.to(device, dtype)
    ok_t, ok_t1 = torch.isfinite(jt).all(-1), torch.isfinite(jt1).all(-1)  # (B, K): usable joints
    if confidence_t is not None:
        ok_t = ok_t & (confidence_t.to(device) > config.confidence_threshold)
    if confidence_t1 is not None:
        ok_t1 = ok_t1 & (confidence_t1.to(device) > config.confidence_threshold)
    ok = ok_t & ok_t1
    jt, jt1 = torch.where(ok_t[..., None], jt, 0.0), torch.where(ok[..., None], jt1, 0.0)
    conf_ok = ok[:, bones].all(-1)  # (B, E)
    jump_ok = torch.ones_like(conf_ok)
    if config.guard and K > 0:  # person size from the frame-t confident joints
        groups = None if groups is None else torch.as_tensor(groups, dtype=torch.long, device=device)
        jump_ok = _plausible_joints(jt, jt1, ok_t, config.max_joint_jump, groups)[:, bones].all(-1)
    keep = conf_ok & jump_ok
    rejected = {"confidence": int((~conf_ok).sum()), "jump": int((conf_ok & ~jump_ok).sum()),
                "disagreement": 0, "points": 0}  # fmt: skip

    offsets = _offsets(config.footprint, int(config.size), device)
    reach = int(_offsets(config.footprint, int(config.size), torch.device("cpu")).abs().max())  # px, no sync
    z = None if depths is None else depths.to(device, dtype)
    samples = _sample_bones(jt, jt1, bones, keep, z, height, width, config, reach)
    ends = torch.stack([jt[:, bones[:, 0]], jt[:, bones[:, 1]]], 2)  # (B, E, 2, 2)
    if samples.valid.shape[-1] == 0:
        empty = jt.new_zeros(B, 2, height, width)
        nowhere = torch.zeros(B, height, width, dtype=torch.bool, device=device)
        return SketchResult(empty, nowhere, keep, rejected, torch.full(nowhere.shape, -1, device=device), ends)

    if config.guard and base_flow is not None:
        N = samples.valid.shape[-1]
        base = sample_flow_at_points(base_flow.to(device, dtype), samples.p.flatten(1, 2)).view(B, E, N, 2)
        err = (samples.d - base).norm(dim=-1)  # (B, E, N)
        agree = ~(_median(err, samples.valid) > config.max_disagreement_px)  # bones without samples agree
        rejected["disagreement"] = int((keep & ~agree).sum())
        keep = keep & agree
        bad = samples.valid & keep[..., None] & (err > config.point_disagreement_factor * config.max_disagreement_px)
        rejected["points"] = int(bad.sum())
        samples.valid = samples.valid & keep[..., None] & ~bad

    flow, mask, owner = _paint(samples, offsets, reach, height, width)
    return SketchResult(flow, mask, keep, rejected, owner, ends)


def sketch_from_layout(
    layout: JointLayout | str,
    joints_t: Tensor,
    joints_t1: Tensor,
    height: int,
    width: int,
    *,
    confidence_t: Tensor | None = None,
    confidence_t1: Tensor | None = None,
    depths: Tensor | None = None,
    base_flow: Tensor | None = None,
    config: SketchConfig = SketchConfig(),
) -> SketchResult:
    """:func:`sketch_flow` with ``layout.sketch_bones``: joints (B, K, 2) in the layout's
    order get its virtual joints appended (joints and depths as the layout's weighted means,
    confidences as the minimum of their parts). ``bone_drawn`` follows ``layout.sketch_bones``.
    Several people at once: :func:`~lit_boot.flow.people_sketch.sketch_people`."""
    layout = get_layout(layout)
    jt, ct = layout.with_virtual(joints_t, confidence_t)
    jt1, ct1 = layout.with_virtual(joints_t1, confidence_t1)
    if depths is not None:
        depths = layout.with_virtual(depths[..., None])[0][..., 0]
    return sketch_flow(jt, jt1, layout.sketch_bones, height, width, confidence_t=ct, confidence_t1=ct1,
                       depths=depths, base_flow=base_flow, config=config)  # fmt: skip


def target_flow(base_flow: Tensor, sketch: SketchResult) -> Tensor:
    """The target: ``sketch.flow`` on its painted pixels, ``base_flow`` (B, 2, H, W) elsewhere
    (in the method the base is RAFT's own prediction for the pair). Returns (B, 2, H, W)."""
    if base_flow.shape != sketch.flow.shape:
        raise ValueError(f"base_flow: expected shape {tuple(sketch.flow.shape)}, got {tuple(base_flow.shape)}")
    return torch.where(sketch.mask[:, None].to(base_flow.device), sketch.flow.to(base_flow), base_flow)
