"""Self-check of a flow stage without ground truth: keep the tuned flow only where the frames say
it is better than the initial flow ("do no harm", issue 13).

Both flows are scored per pixel by the census error (:func:`~lit_boot.flow.evidence.photometric_error`,
7x7 soft census, 0..48) of frame t against frame t+1 warped by each, over the pixels valid under
both. Then, per pair:

- On the person (the dilated sketch, as the runner's drift), pixel by pixel: the tuned flow is
  kept where its error, averaged over a ``window`` x ``window`` box, is below ``(1 - margin)``
  times the initial flow's averaged alike, and (``own``) the pixel's own error is lower too.
  The tuned flow's gain and its harm both sit at the person: the limbs it follows better, and
  the thin band of background around the silhouette that RAFT's 1/8-resolution update drags
  along with them; a coarser region mixes the two, and a box straddling the silhouette lets the
  limb carry the band (hence ``own``).
- Elsewhere, in square tiles of ``tile`` px (their background part): the tuned flow is kept in
  a tile whose mean error is below ``(1 - margin)`` times the initial flow's and whose gain is
  clear of the noise: at least ``z`` standard errors (:func:`choose_regions`). On blurred or
  foggy frames census errors are high and noisy, and a 2% gain there is no evidence.

Ties, empty tiles and tiles with fewer than :data:`MIN_PIXELS` valid pixels keep the initial
flow. So does every pixel the frames cannot judge, whatever its region decided: a pixel whose
target under either flow leaves the frame, and, with ``unjudged`` (:func:`unjudged_pixels`),
one that RAFT's forward-backward check flags as occluded in frame t+1 (or RAFT's flow as wrong
there). Frame t+1 does not show such a pixel, and the census prefers a wrong match onto similar
texture to the right flow onto the occluder: a tuned flow's change there has no evidence for it
(on a real Sintel window, market_5 8-11 in 3D mode, its changes on occluded pixels were kept
by the background tiles' rule and made the EPE there 12.5% worse). With ``blend`` > 0 the binary choice map is blurred with a box of ``2 blend + 1`` px, so
the two flows are blended over ``blend`` px on each side of a change of choice; elsewhere (and
everywhere with ``blend`` 0, the orchestrator's default) each pixel is exactly one of the two
flows.

- :func:`region_labels`: the tiles, each split into its person and background parts.
- :func:`choose_regions`: the per-region decision from two error maps.
- :func:`choose_pixels`: the per-pixel decision on the person.
- :func:`blend_weights`: the smooth weight map from the binary choice.
- :func:`changed_box`: the tiles around where the two flows differ, the only ones measured.
- :func:`unjudged_pixels`: where the frames cannot judge a flow (RAFT's forward-backward check).
- :func:`self_check`: all of it on a stage's flows; the checked flows, the record, the weights.
- :func:`check_stage`: what the runner calls after a flow stage; :func:`summary_line` for the console.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import kornia
import torch
from torch import Tensor

from ..core import Scene
from ..flow.evidence import forward_backward_check, photometric_error
from ..flow.zoom import refines
from .config import BootstrapConfig
from .stage_configs import SELF_CHECKS, SelfCheckConfig

__all__ = ["SELF_CHECKS", "SelfCheckConfig", "region_labels", "region_names", "choose_regions", "choose_pixels",
           "blend_weights", "changed_box", "unjudged_pixels",
           "self_check", "check_stage", "summary_line", "people_shares"]

#: Regions with fewer valid pixels than this keep the initial flow (too little evidence).
MIN_PIXELS = 16
#: Pixels per independent sample of the census error: a 7x7 window's neighbours share most of it.
CENSUS_PIXELS = 49
#: The census window's radius (7x7).
CENSUS_RADIUS = 3


def region_labels(person: Tensor, tile: int) -> Tensor:
    """Region of every pixel: the grid of ``tile`` px squares, each split into its person part
    and its background part.

    person: (B, H, W) bool. With ny = ceil(H / tile) and nx = ceil(W / tile) (the last row /
    column of tiles may be narrower), pixel (y, x) in tile (r, c) = (y // tile, x // tile) gets
    label r * nx + c (background) or ny * nx + r * nx + c (person). Returns (B, H, W) int64 with
    2 ny nx labels (see :func:`region_names`).
    """
    _, height, width = person.shape
    ny, nx = math.ceil(height / tile), math.ceil(width / tile)
    rows = torch.arange(height, device=person.device) // tile
    cols = torch.arange(width, device=person.device) // tile
    tiles = (rows[:, None] * nx + cols).expand_as(person)
    return tiles + person.long() * ny * nx


def region_names(height: int, width: int, tile: int) -> list[str]:
    """Label -> name in :func:`region_labels`' order: "tile_<row>_<col>" (background), then
    "person_<row>_<col>"."""
    ny, nx = math.ceil(height / tile), math.ceil(width / tile)
    cells = [f"{r}_{c}" for r in range(ny) for c in range(nx)]
    return [f"tile_{cell}" for cell in cells] + [f"person_{cell}" for cell in cells]


def _region_means(error: Tensor, valid: Tensor, labels: Tensor, count: int) -> tuple[Tensor, Tensor]:
    """Mean of ``error`` (H, W) over ``valid`` pixels per label (``count`` labels); (means, pixels)."""
    index = labels.flatten()
    weight = valid.flatten().to(error.dtype)
    values = torch.where(valid, error, torch.zeros_like(error)).flatten()
    sums = error.new_zeros(count).scatter_add_(0, index, values)
    pixels = error.new_zeros(count).scatter_add_(0, index, weight)
    return sums / pixels.clamp(min=1), pixels


def choose_regions(
    error_initial: Tensor, error_tuned: Tensor, valid: Tensor, labels: Tensor, count: int, *, margin: float,
    z: float = 1.0,
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Which regions of one pair take the tuned flow.

    error_*: (H, W) per-pixel photometric errors; valid: (H, W) bool, pixels that count;
    labels: (H, W) int64 in [0, count). The tuned flow wins a region that has >= MIN_PIXELS
    valid pixels when its mean error is below ``(1 - margin)`` x the initial's and the mean
    per-pixel difference is at least ``z`` standard errors below zero, counting the region's n
    pixels as n / :data:`CENSUS_PIXELS` independent samples (a clear gain, not noise).
    Returns (tuned (count,) bool, mean initial (count,), mean tuned (count,), valid pixels (count,)).
    """
    mean_initial, pixels = _region_means(error_initial, valid, labels, count)
    mean_tuned, _ = _region_means(error_tuned, valid, labels, count)
    mean_square, _ = _region_means((error_tuned - error_initial).square(), valid, labels, count)
    gain = mean_initial - mean_tuned
    variance = (mean_square - gain.square()).clamp_min(0)
    clear = gain > z * (variance * CENSUS_PIXELS / pixels.clamp(min=1)).sqrt()
    tuned = (mean_tuned < (1.0 - margin) * mean_initial) & clear & (pixels >= MIN_PIXELS)
    return tuned, mean_initial, mean_tuned, pixels


def choose_pixels(error_initial: Tensor, error_tuned: Tensor, valid: Tensor, select: Tensor, *, window: int,
                  margin: float, own: bool = False) -> Tensor:
    """Which ``select``-ed pixels of one pair take the tuned flow: (H, W) bool.

    error_*: (H, W) per-pixel photometric errors; valid, select: (H, W) bool. Each error is
    averaged over the valid pixels of a ``window`` x ``window`` box around the pixel; the tuned
    flow wins where its average is below ``(1 - margin)`` x the initial's (a box with no valid
    pixel: no) and, with ``own``, where the pixel's own error is lower too (a valid pixel: a
    box is swayed by its neighbours, as in the band of background beside a limb, whose box
    holds limb pixels that the tuned flow explains better)."""
    size = (window, window)
    weight = valid.float()[None, None]
    count = kornia.filters.box_blur(weight, size, border_type="replicate")
    mean_i = kornia.filters.box_blur(weight * error_initial[None, None], size, border_type="replicate")
    mean_t = kornia.filters.box_blur(weight * error_tuned[None, None], size, border_type="replicate")
    won = ((mean_t < (1.0 - margin) * mean_i) & (count > 0))[0, 0]  # the same divisor on both sides
    if own:
        won &= valid & (error_tuned < error_initial)
    return won & select


def blend_weights(choice: Tensor, blend: int) -> Tensor:
    """Smooth weight of the tuned flow: (B, H, W) bool choice -> (B, H, W) float in [0, 1].

    A box blur of ``2 blend + 1`` px (replicate padding: no fall-off at the frame border), so
    the weight is exactly 0 or 1 farther than ``blend`` px from a change of choice."""
    weight = choice.float()
    if blend <= 0:
        return weight
    size = 2 * blend + 1
    smooth = kornia.filters.box_blur(weight[:, None], (size, size), border_type="replicate")[:, 0]
    # summing size^2 ones may round to 1 - 1 ulp: snap the flat parts to exact 0 / 1
    return torch.where(smooth > 1 - 1e-5, 1.0, torch.where(smooth < 1e-5, 0.0, smooth))


def changed_box(initial: Tensor, tuned: Tensor, tile: int, reach: int) -> tuple[int, int, int, int] | None:
    """Where two flows (2, H, W) of a pair differ, widened by ``reach`` px (how far a flow's
    change moves a pixel's error and its window average) and out to whole tiles: (y0, y1, x0,
    x1) px, or None where they are equal. Outside it both flows score alike, so the initial
    flow stays there whatever is measured."""
    ys, xs = torch.nonzero((initial != tuned).any(0), as_tuple=True)
    if ys.numel() == 0:
        return None
    height, width = initial.shape[-2:]
    y0, x0 = max(0, int(ys.min()) - reach) // tile * tile, max(0, int(xs.min()) - reach) // tile * tile
    y1 = min(height, -(-(int(ys.max()) + 1 + reach) // tile) * tile)
    x1 = min(width, -(-(int(xs.max()) + 1 + reach) // tile) * tile)
    return y0, y1, x0, x1


def unjudged_pixels(forward: Tensor, backward: Tensor) -> Tensor:
    """Where the frames cannot judge a flow: (T-1, H, W) bool, the pixels of frame t that the
    forward-backward check of ``forward`` (T-1, 2, H, W) px, t -> t+1, against ``backward``
    (T-1, 2, H, W) px, t+1 -> t, flags (occluded in frame t+1, or one of the two flows wrong
    there; UnFlow's thresholds, :func:`~lit_boot.flow.evidence.forward_backward_check`) or whose
    target leaves the frame. Computed a few pairs at a time (the check's working memory is a
    few copies of the flows)."""
    out = [forward_backward_check(forward[t : t + 8].float(), backward[t : t + 8].float())[1]
           for t in range(0, forward.shape[0], 8)]  # fmt: skip
    return torch.cat(out)


def self_check(
    frames: Tensor,
    initial: Tensor,
    tuned: Tensor,
    person: Tensor,
    *,
    config: SelfCheckConfig = SelfCheckConfig(),
    unjudged: Tensor | None = None,
) -> tuple[Tensor, dict[str, Any], Tensor]:
    """The checked flows, the record of every decision and the weight map of the tuned flow.

    frames: (T, 3, H, W) uint8; initial, tuned: (T-1, 2, H, W) px; person: (T-1, H, W) bool;
    config: the rule's settings (its ``method`` is not read: this is the photometric check; its
    ``max_change_px`` "auto", which a run resolves from its flow mode
    (:attr:`~lit_boot.bootstrap.BootstrapConfig.change_limit`), is no limit here); unjudged:
    (T-1, H, W) bool, the pixels the frames cannot judge (:func:`unjudged_pixels`), which keep
    the initial flow, or None (then only the pixels whose target leaves the frame keep it).
    Returns (flows (T-1, 2, H, W) px: the initial flow blended with the tuned flow where it won,
    record, weight (T-1, H, W) float in [0, 1]: the tuned flow's share per pixel). The record:
    ``kept_tuned_fraction`` (mean weight of the tuned flow over all pixels),
    ``person_tuned_fraction`` (the same on the person), ``regions_tuned`` / ``regions_initial``
    (background tiles judged, counted over pairs) and ``per_pair``: for each pair the tuned
    fraction, the names of the tiles kept tuned, ``regions``: {name: [mean census error of the
    initial flow, of the tuned flow, valid pixels]} for every judged tile with background
    pixels, ``person``: [the same three over the judged person, the share of the person kept
    tuned], and ``unjudged``: the pixels where the rules chose the tuned flow and the frames could
    not judge it (they keep the initial flow). ``unjudged_fraction`` is the share of all pixels
    the frames cannot judge, ``refused_unjudged_fraction`` the share the rules chose but the
    frames could not judge. Only the tiles around where the two flows differ are judged
    (:func:`changed_box`); elsewhere they are the same flow.
    """
    margin, tile, window, z, blend, own = config.margin, config.tile, config.window, config.z, config.blend, config.own
    limit = None if config.max_change_px == "auto" else config.max_change_px
    height, width = initial.shape[-2:]
    labels = region_labels(person, tile)
    names = region_names(height, width, tile)
    count = len(names)
    choices, per_pair = [], []
    for t in range(initial.shape[0]):  # one pair at a time: census maps are 49 channels deep
        choice = torch.zeros(height, width, dtype=torch.bool, device=person.device)
        box = changed_box(initial[t], tuned[t], tile, CENSUS_RADIUS + window // 2 + 1)
        if box is None:  # the same flow: nothing to judge
            choices.append(choice)
            per_pair.append({"tuned": [], "regions": {}, "person": [None, None, 0, 0.0], "unjudged": 0})
            continue
        y0, y1, x0, x1 = box
        pair = frames[t : t + 1], frames[t + 1 : t + 2]
        err_i, valid_i = photometric_error(*pair, initial[t : t + 1].float(), radius=CENSUS_RADIUS, box=box)
        err_t, valid_t = photometric_error(*pair, tuned[t : t + 1].float(), radius=CENSUS_RADIUS, box=box)
        err_i, err_t, valid = err_i[0], err_t[0], (valid_i & valid_t)[0]
        on, there = person[t, y0:y1, x0:x1], labels[t, y0:y1, x0:x1]
        won, mean_i, mean_t, pixels = choose_regions(err_i, err_t, valid & ~on, there, count, margin=margin, z=z)
        on_person = choose_pixels(err_i, err_t, valid, on, window=window, margin=margin, own=own)
        chosen = torch.where(on, on_person, won[there])
        judged_here = valid if unjudged is None else valid & ~unjudged[t, y0:y1, x0:x1].to(valid.device)
        refused = int((chosen & ~judged_here).sum())
        choice[y0:y1, x0:x1] = chosen & judged_here
        on_person &= judged_here
        if limit is not None:  # only a refinement is judged by the frames
            gate = refines(initial[t, :, y0:y1, x0:x1], tuned[t, :, y0:y1, x0:x1], limit)
            choice[y0:y1, x0:x1] &= gate
            on_person &= gate
        choices.append(choice)
        judged = valid & on
        n = int(judged.sum())
        per_pair.append({
            "tuned": [names[r] for r in range(count) if won[r]],
            "regions": {names[r]: [round(float(mean_i[r]), 4), round(float(mean_t[r]), 4), int(pixels[r])]
                        for r in range(count) if pixels[r] > 0},
            "person": [round(float(err_i[judged].mean()), 4) if n else None,
                       round(float(err_t[judged].mean()), 4) if n else None, n,
                       round(float(on_person.sum()) / max(int(person[t].sum()), 1), 4)],
            "unjudged": refused,
        })  # fmt: skip
    weight = blend_weights(torch.stack(choices), blend)
    w = weight[:, None].to(initial.dtype)
    flows = torch.where(w == 1, tuned, torch.where(w == 0, initial, initial + w * (tuned - initial)))
    for t, record in enumerate(per_pair):
        record["tuned_fraction"] = float(weight[t].mean())
    regions = sum(len(p["regions"]) for p in per_pair)
    tuned_regions = sum(len(p["tuned"]) for p in per_pair)
    record = {"method": "photometric", "margin": margin, "tile": tile, "blend": blend, "window": window, "z": z, "own": own,
              "max_change_px": limit,
              "kept_tuned_fraction": float(weight.mean()), "regions_tuned": tuned_regions,
              "regions_initial": regions - tuned_regions,
              "person_tuned_fraction": float(weight[person].mean()) if person.any() else 0.0,
              "unjudged_fraction": float(unjudged.float().mean()) if unjudged is not None else None,
              "refused_unjudged_fraction": sum(p["unjudged"] for p in per_pair) / max(weight.numel(), 1),
              "per_pair": per_pair}  # fmt: skip
    return flows, record, weight


def check_stage(
    config: BootstrapConfig, scene: Scene, initial: Tensor, tuned: Tensor, person: Tensor,
    unjudged: Tensor | None = None,
) -> tuple[Tensor, dict[str, Any] | None, Tensor | None]:
    """A flow stage's output under ``config.checking``: the tuned flows (T-1, 2, H, W) px, None
    and None when off, else the checked flows, the record of :func:`self_check` (with
    ``config.self_check``) with the tuned (unchecked) flows' GT metrics as ``tuned_metrics``
    (when the scene has GT flow), and the tuned flow's weight map (T-1, H, W). ``initial``:
    (T-1, 2, H, W) px; ``person``, ``unjudged``: (T-1, H, W) bool (:func:`self_check`)."""
    if config.checking == "off":
        return tuned, None, None
    from ..metrics import scene_flow_metrics

    checking = replace(config.self_check, max_change_px=config.change_limit)
    flows, record, weight = self_check(scene.frames, initial, tuned, person, config=checking, unjudged=unjudged)
    return flows, {**record, "tuned_metrics": scene_flow_metrics(scene.gt, tuned, scene.track_id)}, weight


def people_shares(weight: Tensor, people: Tensor, track_ids: list[int]) -> list[dict[str, Any]]:
    """Each person's share of their own region kept tuned: weight (T-1, H, W) the tuned flow's
    share per pixel, people (T-1, H, W) int the person (index in ``track_ids``) who painted each
    pixel, -1 none; a person's region is their sketch dilated as the person region
    (:func:`~lit_boot.flow.crops.person_region`). [{"track_id", "tuned_fraction"}, ...]."""
    from ..flow import person_region

    out = []
    for p, track_id in enumerate(track_ids):
        region = person_region(people == p)
        share = float(weight[region.to(weight.device)].mean()) if region.any() else 0.0
        out.append({"track_id": int(track_id), "tuned_fraction": round(share, 4)})
    return out


def summary_line(record: dict) -> str:
    """One line for the console: how much of the tuned flow the self-check kept."""
    tiles = record["regions_tuned"] + record["regions_initial"]
    people = record.get("people") or []
    who = "the person,"
    if len(people) > 1:
        shares = ", ".join(f"track {p['track_id']} {100 * p['tuned_fraction']:.0f}%" for p in people)
        who = f"the people: {shares};"
    refused = record.get("refused_unjudged_fraction") or 0.0
    unjudged = f" (and on {100 * refused:.1f}% that the frames cannot judge: occluded, or leaving the frame)"
    return (f"  self-check: kept the tuned flow on {100 * record['kept_tuned_fraction']:.0f}% of the pixels "
            f"({100 * record['person_tuned_fraction']:.0f}% of {who} {record['regions_tuned']} of {tiles} "
            f"background tiles), the initial flow elsewhere{unjudged if refused else ''}")
