"""Per frame pair, the maps the run report shows, and the scales the whole report shares.

For pair t (frame t -> t+1) of a :class:`~lit_boot.bootstrap.finished.FinishedRun`:

- the change: |final flow - RAFT's flow| px per pixel;
- the image evidence (needs the frames): the census error (0..48, 7x7 soft census:
  :func:`~lit_boot.flow.evidence.photometric_error`) of frame t against frame t+1 warped by
  RAFT's flow and by the final flow, counted where both warps land inside the image;
- with a GT flow, each flow's end-point error px where the GT counts (valid, not occluded; the
  metrics' pixels).

:func:`pair_panels` draws them (HWC uint8, scaled to a width) with the frame and both skeletons
and the decision map. Every map of one kind uses one scale (:class:`Scales`) across the report,
so pairs compare by colour.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..data.visualize import flow_image
from ..flow.evidence import photometric_error
from .decisions import decision_map
from .finished import FinishedRun
from .overlay import (CHANGE_CMAP, change_image, clean_flow, draw_poses, flow_colour_scale, nice_ceiling, resize_image,
                      other_people, sequential_image)  # fmt: skip

__all__ = ["PairMaps", "Panel", "Scales", "pair_maps", "pair_stats", "shared_scales", "pair_panels", "pick_pairs",
           "CHANGED_PX", "SEQUENTIAL", "DIVERGING"]

CHANGED_PX = 0.1  #: a pixel's flow changed when the final flow is farther than this from RAFT's (px)
SEQUENTIAL = {"change": CHANGE_CMAP, "census": "inferno", "epe": "inferno"}  #: colour maps (Matplotlib names)
DIVERGING = "RdBu_r"  #: after - before: blue lower (better), white unchanged, red higher (worse)


@dataclass
class PairMaps:
    """One pair's maps, (H, W) CPU tensors: ``change`` px; ``census_raft`` / ``census_final``
    (0..48) and ``valid`` (bool, both warps inside the image), None without frames;
    ``epe_raft`` / ``epe_final`` px and ``gt_valid`` (bool), None without a GT flow."""

    change: torch.Tensor
    census_raft: torch.Tensor | None = None
    census_final: torch.Tensor | None = None
    valid: torch.Tensor | None = None
    epe_raft: torch.Tensor | None = None
    epe_final: torch.Tensor | None = None
    gt_valid: torch.Tensor | None = None


@dataclass
class Scales:
    """The report's shared scales: flow colour (px: full colour at this length), change px,
    census error and its change (0..48 units), EPE and its change px (None without GT)."""

    flow: float
    change: float
    census: float | None
    census_change: float | None
    epe: float | None
    epe_change: float | None


@dataclass
class Panel:
    """One image of a pair: its row ("flow", "evidence", "gt"), title, legend key (a
    :class:`Scales` field, "flow" for the colour wheel, "decisions", "poses") and HWC uint8 image."""

    row: str
    title: str
    legend: str
    image: np.ndarray


def pick_pairs(pairs: int, most: int) -> list[int]:
    """At most ``most`` pair indices of ``pairs``, evenly spaced, the first and last included."""
    if pairs <= most:
        return list(range(pairs))
    return sorted({int(round(i)) for i in np.linspace(0, pairs - 1, most)})


@torch.no_grad()
def pair_maps(run: FinishedRun, t: int) -> PairMaps:
    """Pair ``t``'s maps (see the module doc)."""
    raft, final = clean_flow(run.initial_flows[t]), clean_flow(run.flows[t])
    maps = PairMaps(change=(final - raft).norm(dim=0))
    scene = run.scene
    if scene is None:
        return maps
    a, b = scene.frames[t : t + 1], scene.frames[t + 1 : t + 2]
    (census_raft,), (valid_raft,) = photometric_error(a, b, raft[None])
    (census_final,), (valid_final,) = photometric_error(a, b, final[None])
    maps.census_raft, maps.census_final, maps.valid = census_raft, census_final, valid_raft & valid_final
    gt = scene.gt
    if gt is not None and gt.flow is not None:
        target = clean_flow(gt.flow[t])
        maps.epe_raft, maps.epe_final = (raft - target).norm(dim=0), (final - target).norm(dim=0)
        maps.gt_valid = gt.flow_mask()[t].cpu()
    return maps


def _mean(values: torch.Tensor | None, mask: torch.Tensor | None) -> float:
    if values is None or mask is None or not bool(mask.any()):
        return float("nan")
    return float(values[mask].double().mean())


def pair_stats(maps: PairMaps, decisions: dict[str, torch.Tensor] | None, t: int) -> dict[str, float]:
    """Pair ``t``'s numbers: ``changed`` (share of the pixels whose flow changed by more than
    :data:`CHANGED_PX`), the mean census error of each flow over the valid pixels
    (``census_raft``, ``census_final``) and over the changed ones (``*_changed``), the mean EPE of
    each where the GT counts (``epe_raft``, ``epe_final``), and the shares ``painted``,
    ``tuned_kept`` (the tuned flows' mean weight) and, after a zoom stage, ``zoom_kept`` (the
    zoomed flow's) of the decision maps; NaN where not defined."""
    changed = maps.change > CHANGED_PX
    on = maps.valid & changed if maps.valid is not None else None
    stats = {"changed": float(changed.float().mean()),
             "census_raft": _mean(maps.census_raft, maps.valid), "census_final": _mean(maps.census_final, maps.valid),
             "census_raft_changed": _mean(maps.census_raft, on), "census_final_changed": _mean(maps.census_final, on),
             "epe_raft": _mean(maps.epe_raft, maps.gt_valid),
             "epe_final": _mean(maps.epe_final, maps.gt_valid)}  # fmt: skip
    if decisions is not None:
        stats["painted"] = float(decisions["painted"][t].float().mean())
        stats["tuned_kept"] = float(decisions["kept"][t].float().mean())
        if "zoom" in decisions:
            stats["zoom_kept"] = float(decisions["zoom"][t].float().mean())
    return stats


def _percentile(values: list[torch.Tensor], q: float = 99.0) -> float:
    flat = torch.cat([v.reshape(-1).float() for v in values]) if values else torch.zeros(0)
    flat = flat[torch.isfinite(flat)]
    return float(np.percentile(flat[:: max(1, flat.numel() // 1_000_000)].numpy(), q)) if flat.numel() else 0.0


def shared_scales(run: FinishedRun, maps: dict[int, PairMaps]) -> Scales:
    """The scales of the shown pairs' ``maps``: the flow colour scale of both flows (all pairs:
    :func:`~lit_boot.bootstrap.overlay.flow_colour_scale`); for the change, the census errors,
    the EPE and the changes, the 99th percentile of the values shown, rounded up by
    :func:`nice_ceiling` with a floor (0.5 px, 1 and 0.5 census units, 0.5 px) so that changes
    far below a meaningful size do not fill the colour range (the census error at most 48)."""
    magnitudes = [clean_flow(f).norm(dim=1).numpy() for f in (run.initial_flows, run.flows)]
    shown = list(maps.values())
    census = [m for p in shown if p.valid is not None for m in (p.census_raft[p.valid], p.census_final[p.valid])]
    census_change = [(p.census_final - p.census_raft)[p.valid].abs() for p in shown if p.valid is not None]
    epe = [m for p in shown if p.gt_valid is not None for m in (p.epe_raft[p.gt_valid], p.epe_final[p.gt_valid])]
    epe_change = [(p.epe_final - p.epe_raft)[p.gt_valid].abs() for p in shown if p.gt_valid is not None]
    has_census, has_gt = bool(census), bool(epe)
    return Scales(flow=flow_colour_scale(magnitudes), change=nice_ceiling(_percentile([p.change for p in shown]), 0.5),
                  census=min(48.0, nice_ceiling(_percentile(census), 1.0)) if has_census else None,
                  census_change=nice_ceiling(_percentile(census_change), 0.5) if has_census else None,
                  epe=nice_ceiling(_percentile(epe), 0.5) if has_gt else None,
                  epe_change=nice_ceiling(_percentile(epe_change), 0.5) if has_gt else None)  # fmt: skip


def _poses_image(run: FinishedRun, t: int, size: tuple[int, int]) -> np.ndarray:
    """Frame t scaled to ``size`` (h, w) with the initial skeleton in red, the final in green (the
    other people's, after the run, under them in their tracks' colours)."""
    scene = run.scene
    frame = torch.from_numpy(np.ascontiguousarray(resize_image(scene.frames[t], size))).permute(2, 0, 1)
    joints = {}
    for name, (points, keep) in (("before", run.initial_points), ("after", run.final_points)):
        joints[name] = torch.where(keep[..., None], points.float(), float("nan"))
    H, W = scene.frames.shape[-2:]
    drawn = draw_poses(frame, joints, t, scene.pose_layout(run.mode), (size[1] / W, size[0] / H),
                       other_people(scene, run.mode))  # fmt: skip
    return drawn.permute(1, 2, 0).numpy()


def pair_panels(run: FinishedRun, t: int, maps: PairMaps, scales: Scales, width: int) -> list[Panel]:
    """Pair ``t``'s images, each ``width`` px wide at most (see :class:`Panel`): frame with both
    skeletons, RAFT's flow, the final flow, the change; the census error of each flow, its change
    (final - RAFT) and the decision map (where the final flow comes from); with GT, the EPE of each flow and its change."""
    H, W = run.flows.shape[-2:]
    w = min(W, width)
    size = (max(1, round(H * w / W)), w)

    def fit(image: np.ndarray | torch.Tensor) -> np.ndarray:
        return np.ascontiguousarray(resize_image(image, size))

    raft_img, final_img = flow_image(torch.stack([clean_flow(run.initial_flows[t]), clean_flow(run.flows[t])]),
                                     scales.flow)  # fmt: skip
    panels = []
    if run.scene is not None:
        title = f"frame {t}, poses before (red) and after (green)"
        panels.append(Panel("flow", title, "poses", _poses_image(run, t, size)))
    change = sequential_image(maps.change, scales.change, SEQUENTIAL["change"])
    panels += [Panel("flow", "RAFT's flow", "flow", fit(raft_img)), Panel("flow", "final flow", "flow", fit(final_img)),
               Panel("flow", "change |final - RAFT|", "change", fit(change))]
    if maps.valid is not None:
        census = [sequential_image(m, scales.census, SEQUENTIAL["census"], maps.valid)
                  for m in (maps.census_raft, maps.census_final)]  # fmt: skip
        delta = change_image(maps.census_final - maps.census_raft, maps.valid, scales.census_change)
        panels += [Panel("evidence", "census error, RAFT's flow", "census", fit(census[0])),
                   Panel("evidence", "census error, final flow", "census", fit(census[1])),
                   Panel("evidence", "census error change (final - RAFT)", "census_change", fit(delta))]  # fmt: skip
    if run.decisions is not None:
        frame = run.scene.frames[t] if run.scene is not None else torch.full((3, H, W), 160, dtype=torch.uint8)
        image = decision_map(frame, run.decisions, t)
        panels.append(Panel("evidence", f"decisions ({run.flow_stage})", "decisions", fit(image)))
    if maps.gt_valid is not None:
        epe = [sequential_image(m, scales.epe, SEQUENTIAL["epe"], maps.gt_valid)
               for m in (maps.epe_raft, maps.epe_final)]  # fmt: skip
        delta = change_image(maps.epe_final - maps.epe_raft, maps.gt_valid, scales.epe_change)
        panels += [Panel("gt", "EPE vs GT, RAFT's flow", "epe", fit(epe[0])),
                   Panel("gt", "EPE vs GT, final flow", "epe", fit(epe[1])),
                   Panel("gt", "EPE change (final - RAFT)", "epe_change", fit(delta))]  # fmt: skip
    return panels
