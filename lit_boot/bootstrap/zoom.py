"""The zoom stage: RAFT's flow refined where the person is, kept unless the frames refuse it.

After the initial stage (pretrained RAFT on every pair), each pair with a person is run again on
a crop around the person's box, zoomed (:mod:`lit_boot.flow.zoom`: the scale chosen from the
motion). The zoomed flow replaces RAFT's pixel by pixel where both hold:

- it refines RAFT's flow: it moves it by less than ``max_change_px`` (a large change is another
  match, which the frames cannot be trusted to judge: fog, blur and fast motion fool them);
- the frames do not refuse it (``confirm="veto"``, the default): RAFT's census error averaged
  over a ``window`` box is not below ``(1 - margin)`` x the zoomed flow's. Where the frames
  cannot tell (flat or repeated texture, small flows) the zoomed flow is kept: at the zoomed
  size RAFT resolves more, and where it bleeds over a silhouette the frames do tell. With
  ``confirm="census"`` the frames must say it is better instead (the self-check's person rule,
  :func:`~lit_boot.bootstrap.selfcheck.choose_pixels`: its averaged error below ``(1 - margin)``
  x RAFT's and the pixel's own lower too); with ``confirm="none"`` nothing is asked of them.

That choice is made coherent (:func:`coherent`: the zoomed flow
only where most of a pixel's 3x3 neighbourhood chose it too; no speckle of single pixels), and the zoomed flow
fades in over :data:`FADE_PX` px inside its region's sides (:func:`fade_in`; no step where the
crop ends): the zoomed flow's weight, ``kept``, is in [0, 1] there.

The result is the flow the flow stages start from and are checked against. The person's box per
frame: the scene's ``person_boxes`` when it has them (a person detector), else the box around
the pose's points (:func:`~lit_boot.flow.zoom.boxes_from_points`). A scene with several people
is zoomed on every person's box in turn, the main person first.
"""

from __future__ import annotations

import time
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor
from torchvision.models.optical_flow import RAFT

from ..core import Scene
from ..flow.evidence import photometric_error
from ..metrics import scene_flow_metrics
from ..flow.zoom import boxes_from_points, pair_boxes, refines, zoom_pair
from .stage_configs import ZoomConfig
from .evaluate import agreement, drift, photo_error
from .selfcheck import CENSUS_RADIUS, choose_pixels

__all__ = ["person_boxes", "box_masks", "fade_in", "coherent", "keep_pixels", "zoom_flows", "zoom_stage", "zoom_line"]


def person_boxes(scene: Scene, mode: str) -> Tensor:
    """The person's box per frame (T, 5) (x0, y0, x1, y1, score; score 0: nobody): the scene's
    ``person_boxes`` when it has them, else around the pose points of ``mode``."""
    boxes = getattr(scene, "person_boxes", None)
    if boxes is not None:
        return boxes.float()
    return boxes_from_points(*scene.pose_points(mode))


def box_masks(boxes: Tensor, size: tuple[int, int]) -> Tensor:
    """(T-1, H, W) bool: each pair's person box (:func:`~lit_boot.flow.zoom.pair_boxes` of
    ``boxes`` (T, 5)) as a mask of a frame of ``size`` (H, W): where the zoom stage acts."""
    height, width = size
    masks = torch.zeros(boxes.shape[0] - 1, height, width, dtype=torch.bool)
    for t, box in enumerate(pair_boxes(boxes)):
        if box is not None:
            x0, y0, x1, y1 = box.tolist()
            masks[t, max(0, round(y0)) : max(0, round(y1) + 1), max(0, round(x0)) : max(0, round(x1) + 1)] = True
    return masks


#: The zoomed flow fades in over this many px inside its region's sides (those inside the frame):
#: no step where the crop ends (BENCHMARKS.md, "A flow a user can use").
FADE_PX = 8


def fade_in(region: tuple[int, int, int, int], size: tuple[int, int]) -> Tensor:
    """(H, W) float in [0, 1]: 0 outside ``region`` (y0, y1, x0, x1) px and on its outermost rows
    and columns, rising linearly to 1 at :data:`FADE_PX` px inside each side that lies inside the
    frame ``size`` (H, W); a side on the frame's edge does not fade."""
    height, width = size
    y0, y1, x0, x1 = region
    ys, xs = torch.arange(height, dtype=torch.float32)[:, None], torch.arange(width, dtype=torch.float32)[None]
    far = torch.tensor(float("inf"))
    inward = [ys - y0 if y0 > 0 else far, y1 - 1 - ys if y1 < height else far,
              xs - x0 if x0 > 0 else far, x1 - 1 - xs if x1 < width else far]  # fmt: skip
    reach = torch.minimum(torch.minimum(inward[0], inward[1]), torch.minimum(inward[2], inward[3]))
    inside = (ys >= y0) & (ys < y1) & (xs >= x0) & (xs < x1)
    return torch.where(inside, (reach / FADE_PX).clamp(0, 1), torch.zeros(()))


def coherent(choice: Tensor) -> Tensor:
    """A choice of a candidate flow made coherent: a pixel of (H, W) bool ``choice`` keeps the
    candidate only where most of its 3x3 neighbourhood (itself included; at the frame's edge, of
    the pixels inside it) chose it too. A choice made pixel by pixel on noisy evidence scatters
    single pixels of the candidate inside the other flow, which a user who warps frames with the
    flow sees as speckle; those go. A pixel the evidence refused is never given the candidate
    (BENCHMARKS.md, "A flow a user can use")."""
    votes = F.avg_pool2d(choice.float()[None, None], 3, stride=1, padding=1, count_include_pad=False)[0, 0]
    return choice & (votes > 0.5)


def keep_pixels(frames: Tensor, base: Tensor, candidate: Tensor, region: tuple[int, int, int, int],
                config: ZoomConfig) -> Tensor:  # fmt: skip
    """(H, W) bool: the region's pixels where the candidate (2, H, W) refines ``base`` and the
    frames (2, 3, H, W) do not refuse it (``config.confirm``; see the module doc)."""
    height, width = base.shape[-2:]
    y0, y1, x0, x1 = region
    reach = CENSUS_RADIUS + config.window // 2 + 1  # the window's context around the region
    box = (max(0, y0 - reach), min(height, y1 + reach), max(0, x0 - reach), min(width, x1 + reach))
    by0, by1, bx0, bx1 = box
    select = torch.zeros(by1 - by0, bx1 - bx0, dtype=torch.bool)
    select[y0 - by0 : y1 - by0, x0 - bx0 : x1 - bx0] = True
    select &= refines(base[:, by0:by1, bx0:bx1], candidate[:, by0:by1, bx0:bx1], config.max_change_px)
    keep = torch.zeros(height, width, dtype=torch.bool)
    if config.confirm == "none":  # the refinement limit alone
        keep[by0:by1, bx0:bx1] = select
        return keep
    pair = frames[:1], frames[1:]
    err_b, valid_b = photometric_error(*pair, base[None].float(), radius=CENSUS_RADIUS, box=box)
    err_z, valid_z = photometric_error(*pair, candidate[None].float(), radius=CENSUS_RADIUS, box=box)
    valid = (valid_b & valid_z)[0]
    if config.confirm == "veto":  # kept unless the frames say RAFT's flow is better
        lost = choose_pixels(err_z[0], err_b[0], valid, select, window=config.window, margin=config.margin)
        keep[by0:by1, bx0:bx1] = select & ~lost
        return keep
    won = choose_pixels(err_b[0], err_z[0], valid, select, window=config.window, margin=config.margin, own=True)
    keep[by0:by1, bx0:bx1] = won
    return keep


def zoom_flows(model: RAFT, scene: Scene, base: Tensor, boxes: Tensor, config: ZoomConfig) -> tuple[Tensor, Tensor, dict[str, Any]]:
    """The zoom of every pair of ``scene``: ``base`` (T-1, 2, H, W) px RAFT's own flows, ``boxes``
    (T, 5) the person's. Returns (flows (T-1, 2, H, W) px: ``base`` with the zoomed flow where
    it was kept, kept (T-1, H, W) float in [0, 1]: the zoomed flow's weight, record). The record:
    ``kept_fraction`` (of all pixels),
    ``zoomed_pairs``, ``cost`` (zoomed pixels over the frames', summed over pairs: the zoom's
    cost in RAFT passes), ``seconds`` and ``per_pair`` (scale, motion px, crop, region, cost,
    kept fraction of the region), ``max_cost`` (frames). ``config.max_cost`` must be a number:
    "auto" depends on the run's mode (:meth:`ZoomConfig.for_mode`)."""
    if config.max_cost == "auto":
        raise ValueError("zoom.max_cost 'auto' depends on the mode: pass config.for_mode('3d' or '2d')")
    start = time.perf_counter()
    frames, flows = scene.frames, base.clone()
    kept = torch.zeros(base.shape[0], *base.shape[-2:])
    per_pair = []
    for t, box in enumerate(pair_boxes(boxes)):
        zoomed = zoom_pair(model, frames[t], frames[t + 1], base[t], box, max_scale=config.max_scale,
                           min_scale=config.min_scale, reach_px=config.reach_px, context=config.context,
                           min_context_px=config.min_context_px, border_px=config.border_px,
                           min_updates=config.updates, max_updates=config.max_updates,
                           start=config.start, small_scale=config.small_scale, max_cost=config.max_cost,
                           max_pixels=config.max_pixels)  # fmt: skip
        record = zoomed.record()
        if zoomed.region is not None:
            chosen = coherent(keep_pixels(frames[t : t + 2], base[t], zoomed.candidate, zoomed.region, config))
            kept[t] = chosen * fade_in(zoomed.region, tuple(base.shape[-2:]))
            flows[t] = base[t] + kept[t] * (zoomed.candidate - base[t])
            y0, y1, x0, x1 = zoomed.region
            record["kept_fraction"] = round(float(kept[t, y0:y1, x0:x1].mean()), 4)
        per_pair.append(record)
    record = {"kept_fraction": float(kept.float().mean()),
              "zoomed_pairs": sum(p["region"] is not None for p in per_pair),
              "cost": round(sum(p["cost"] for p in per_pair), 4), "seconds": time.perf_counter() - start,
              "max_cost": config.max_cost, "per_pair": per_pair}  # fmt: skip
    return flows, kept, record


def zoom_stage(raft: RAFT, scene: Scene, initial: Tensor, *, mode: str, config: ZoomConfig,
               device: str) -> tuple[dict[str, Any], Tensor, dict[str, Tensor]]:  # fmt: skip
    """The zoom stage of a run: :func:`zoom_flows` with ``raft`` (moved to ``device`` for it, then
    back) over ``initial`` (T-1, 2, H, W) px, the person's boxes from the scene or the pose of
    ``mode``. Returns (the stage's record: the flow's metrics (GT when the scene has it, and the
    evidence), drift outside the person's boxes, ``info["zoom"]``; the flows (T-1, 2, H, W) px;
    the decision maps: nothing painted, ``kept`` the zoomed flow's pixels). ``config.max_cost``
    "auto" is the mode's (:meth:`ZoomConfig.for_mode`)."""
    config = config.for_mode(mode)
    original = next(raft.parameters()).device
    raft.to(device)
    try:
        flows, kept, zoom, person = _zoom_people(raft, scene, initial, mode, config)
    finally:
        raft.to(original)
    record = {**scene_flow_metrics(scene.gt, flows, scene.track_id), "drift_px": drift(flows, initial, person),
              "agreement_px": agreement(flows, *scene.pose_points(mode)),
              "photo_error": photo_error(scene.frames, flows), "info": {"zoom": zoom}}  # fmt: skip
    return record, flows, {"painted": torch.zeros(kept.shape, dtype=torch.bool), "kept": kept}


def _zoom_people(raft: RAFT, scene: Scene, initial: Tensor, mode: str,
                 config: ZoomConfig) -> tuple[Tensor, Tensor, dict[str, Any], Tensor]:  # fmt: skip
    """:func:`zoom_flows` on every person's boxes in turn (the main person first, each over the
    flows the previous one left). Returns the flows, the kept pixels, the record (one person's
    as :func:`zoom_flows` gives it; with several, the pairs, cost and seconds summed, ``per_pair``
    every person's in turn and ``people``: each one's track id, zoomed pairs and kept fraction)
    and every person's boxes as one (T-1, H, W) mask."""
    flows, kept, records = initial, None, []
    person = torch.zeros(initial.shape[0], *initial.shape[-2:], dtype=torch.bool)
    for p in range(scene.num_people):
        one = scene.person(p)
        boxes = person_boxes(one, mode)
        flows, kept_p, record = zoom_flows(raft, one, flows, boxes, config)
        kept = kept_p if kept is None else torch.maximum(kept, kept_p)
        person |= box_masks(boxes, tuple(flows.shape[-2:]))
        records.append((one.track_id, record))
    if len(records) == 1:
        return flows, kept, records[0][1], person
    zoom = {"kept_fraction": float(kept.float().mean()), "zoomed_pairs": sum(r["zoomed_pairs"] for _, r in records),
            "cost": round(sum(r["cost"] for _, r in records), 4), "seconds": sum(r["seconds"] for _, r in records),
            "max_cost": config.max_cost,
            "per_pair": [pair for _, r in records for pair in r["per_pair"]],
            "people": [{"track_id": i, "zoomed_pairs": r["zoomed_pairs"], "kept_fraction": r["kept_fraction"]}
                       for i, r in records]}  # fmt: skip
    return flows, kept, zoom, person


def zoom_line(record: dict[str, Any], pairs: int) -> str:
    """One line for the console: how many pairs were zoomed, at which scales, what was kept."""
    scales = [p["scale"] for p in record["per_pair"] if p["region"] is not None]
    at = f" at {min(scales):.2f}-{max(scales):.2f}x" if scales else ""
    people = record.get("people")
    zoomed = (f"{record['zoomed_pairs']} pairs of {len(people)} people ({pairs} pairs each) zoomed" if people
              else f"{record['zoomed_pairs']} of {pairs} pairs zoomed")  # fmt: skip
    return (f"  zoom: {zoomed}{at} (cost {record['cost']:.1f} RAFT passes); "
            f"the zoomed flow kept on {100 * record['kept_fraction']:.1f}% of the pixels, RAFT's elsewhere")
