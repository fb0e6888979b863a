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

__all__ = ["sketch_people"]


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
