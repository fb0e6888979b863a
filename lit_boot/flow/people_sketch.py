"""Several people's stick-men in one target sketch (the target paints every person).

The people are drawn as one skeleton of P x K joints whose bones are each person's
``layout.sketch_bones``; the jump guard measures each person's own size (``groups``), and where
people overlap the nearer wins (3D: the joints' depths), else the more confident.
"""

from __future__ import annotations

import torch
from torch import Tensor

from ..core.joints import JointLayout, get_layout
from .sketch import SketchConfig, SketchResult, sketch_flow

__all__ = ["sketch_people", "person_balance", "MAX_BALANCE"]

#: The largest factor :func:`person_balance` gives a person's pixels (a tiny person's few pixels
#: must not dominate the loss), chosen beforehand, not tuned.
MAX_BALANCE = 4.0


def sketch_people(
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
    """P people's stick-men in one sketch: joints (B, P, K, 2) px in the layout's order,
    confidences and depths (B, P, K) or None. Where people overlap the nearer wins (depths, mm),
    else the more confident (each person's mean confidence over its confident joints of frame
    t; without confidences the later person). ``bone_drawn`` (B, P x E): person 0's bones first."""
    layout = get_layout(layout)
    B, P, K = joints_t.shape[:3]
    flat = lambda x: None if x is None else x.reshape(B * P, *x.shape[2:])  # noqa: E731
    jt, ct = layout.with_virtual(flat(joints_t), flat(confidence_t))
    jt1, ct1 = layout.with_virtual(flat(joints_t1), flat(confidence_t1))
    Kv = jt.shape[1]
    unflat = lambda x: None if x is None else x.reshape(B, P * Kv, *x.shape[2:])  # noqa: E731
    if depths is not None:
        order = unflat(layout.with_virtual(flat(depths)[..., None])[0][..., 0])
    elif confidence_t is not None:  # the more confident person is "nearer"
        seen = confidence_t > config.confidence_threshold
        mean = (confidence_t * seen).sum(-1) / seen.sum(-1).clamp_min(1)
        order = (1 - mean)[..., None].expand(B, P, Kv).reshape(B, P * Kv)
    else:
        order = None
    bones = torch.as_tensor(layout.sketch_bones, dtype=torch.long).reshape(-1, 2)
    bones = torch.cat([bones + p * Kv for p in range(P)])
    groups = torch.arange(P).repeat_interleave(Kv)
    return sketch_flow(unflat(jt), unflat(jt1), bones, height, width, confidence_t=unflat(ct),
                       confidence_t1=unflat(ct1), depths=order, base_flow=base_flow, config=config,
                       groups=groups)  # fmt: skip


def person_balance(owner: Tensor, mask: Tensor, bones_per_person: int) -> Tensor:
    """Loss weights (B, H, W) float that make every painted person weigh the same: 1 off the
    painted pixels; on person p's (``owner // bones_per_person == p``, owner: the sketch's bone
    per pixel, person-major as :func:`sketch_people` draws them) mean_q(n_q) / n_p, capped at
    :data:`MAX_BALANCE`, where n_p counts person p's painted pixels over all B pairs (people
    with none left out). With fewer than two people painted: all 1."""
    person = torch.where(mask & (owner >= 0), owner // bones_per_person, torch.full_like(owner, -1))
    weight = torch.ones(owner.shape, dtype=torch.float32, device=owner.device)
    ids, counts = torch.unique(person[person >= 0], return_counts=True)
    if len(ids) < 2:
        return weight
    factors = (counts.float().mean() / counts.float()).clamp(max=MAX_BALANCE)
    for i, factor in zip(ids.tolist(), factors.tolist()):
        weight[person == i] = factor
    return weight
