"""Self-check of a flow stage without ground truth: keep the tuned flow only where the frames say
it is better than the initial flow ("do no harm", issue 13).

Per pair, the frame is cut into square tiles of ``tile`` px, and each tile into its person part
(the dilated sketch, as the runner's drift) and its background part: the person is judged
locally too, since a gain on some limbs and a loss around others would cancel in one region.
In each region the mean census error (:func:`~lit_boot.flow.evidence.photometric_error`, 7x7
soft census, 0..48) of frame t against frame t+1 warped by each flow is compared, over pixels
valid under both flows. The tuned flow is kept only when its error is lower than
``(1 - margin)`` times the initial flow's (ties, empty regions and regions too small to judge
keep the initial flow). The binary choice map is blurred with a box of ``2 blend + 1`` px so the
two flows are blended over ``blend`` px on each side of a region border; elsewhere each pixel
is exactly one of the two flows.

- :func:`region_labels`: the regions, (T-1, H, W) int64.
- :func:`choose_regions`: the per-region decision from two error maps.
- :func:`blend_weights`: the smooth weight map from the binary choice.
- :func:`self_check`: all of it on a stage's flows; the checked flows and the record.
- :func:`check_stage`: what the runner calls after a flow stage; :func:`summary_line` for the console.
"""

from __future__ import annotations

import math
from typing import Any

import kornia
import torch
from torch import Tensor

from ..flow.evidence import photometric_error
from .config import SELF_CHECKS

__all__ = ["SELF_CHECKS", "region_labels", "region_names", "choose_regions", "blend_weights", "self_check",
           "check_stage", "summary_line"]

#: Regions with fewer valid pixels than this keep the initial flow (too little evidence).
MIN_PIXELS = 16


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
    error_initial: Tensor, error_tuned: Tensor, valid: Tensor, labels: Tensor, count: int, margin: float
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Which regions of one pair take the tuned flow.

    error_*: (H, W) per-pixel photometric errors; valid: (H, W) bool, pixels that count;
    labels: (H, W) int64 in [0, count). The tuned flow wins a region when its mean error is
    below ``(1 - margin)`` x the initial's and the region has >= MIN_PIXELS valid pixels.
    Returns (tuned (count,) bool, mean initial (count,), mean tuned (count,), valid pixels (count,)).
    """
    mean_initial, pixels = _region_means(error_initial, valid, labels, count)
    mean_tuned, _ = _region_means(error_tuned, valid, labels, count)
    tuned = (mean_tuned < (1.0 - margin) * mean_initial) & (pixels >= MIN_PIXELS)
    return tuned, mean_initial, mean_tuned, pixels


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


def self_check(
    frames: Tensor,
    initial: Tensor,
    tuned: Tensor,
    person: Tensor,
    margin: float = 0.02,
    tile: int = 32,
    blend: int = 4,
) -> tuple[Tensor, dict[str, Any]]:
    """The checked flows and the record of every decision.

    frames: (T, 3, H, W) uint8; initial, tuned: (T-1, 2, H, W) px; person: (T-1, H, W) bool.
    Returns (flows (T-1, 2, H, W) px: the initial flow blended with the tuned flow where it won,
    record): ``kept_tuned_fraction`` (mean weight of the tuned flow over all pixels),
    ``regions_tuned`` / ``regions_initial`` (counts over pairs and regions with pixels),
    ``person_tuned`` / ``person_regions`` (the same for the person's regions),
    ``person_tuned_fraction`` (mean weight of the tuned flow on the person region) and
    ``per_pair``: for each pair the tuned fraction, the names of the regions kept tuned, and
    ``regions``: {name: [mean census error of the initial flow, of the tuned flow, valid pixels]}
    for every region with pixels.
    """
    height, width = initial.shape[-2:]
    labels = region_labels(person, tile)
    names = region_names(height, width, tile)
    count = len(names)
    choices, per_pair = [], []
    for t in range(initial.shape[0]):  # one pair at a time: census maps are 49 channels deep
        pair = frames[t : t + 1], frames[t + 1 : t + 2]
        err_i, valid_i = photometric_error(*pair, initial[t : t + 1].float())
        err_t, valid_t = photometric_error(*pair, tuned[t : t + 1].float())
        valid = (valid_i & valid_t)[0]
        won, mean_i, mean_t, pixels = choose_regions(err_i[0], err_t[0], valid, labels[t], count, margin)
        choices.append(won[labels[t]])
        present = torch.bincount(labels[t].flatten(), minlength=count) > 0
        per_pair.append({
            "tuned": [names[r] for r in range(count) if won[r]],
            "regions": {names[r]: [round(float(mean_i[r]), 4), round(float(mean_t[r]), 4), int(pixels[r])]
                        for r in range(count) if present[r]},
        })  # fmt: skip
    weight = blend_weights(torch.stack(choices), blend)
    w = weight[:, None].to(initial.dtype)
    flows = torch.where(w == 1, tuned, torch.where(w == 0, initial, initial + w * (tuned - initial)))
    for t, record in enumerate(per_pair):
        record["tuned_fraction"] = float(weight[t].mean())
    regions = sum(len(p["regions"]) for p in per_pair)
    tuned_regions = sum(len(p["tuned"]) for p in per_pair)
    record = {"method": "photometric", "margin": margin, "tile": tile, "blend": blend,
              "kept_tuned_fraction": float(weight.mean()), "regions_tuned": tuned_regions,
              "regions_initial": regions - tuned_regions,
              "person_tuned": sum(n.startswith("person") for p in per_pair for n in p["tuned"]),
              "person_regions": sum(n.startswith("person") for p in per_pair for n in p["regions"]),
              "person_tuned_fraction": float(weight[person].mean()) if person.any() else 0.0,
              "per_pair": per_pair}  # fmt: skip
    return flows, record


def check_stage(config: Any, scene: Any, initial: Tensor, tuned: Tensor, person: Tensor) -> tuple[Tensor, dict | None]:
    """A flow stage's output under ``config.self_check`` (a BootstrapConfig): the tuned flows
    and None when off, else the checked flows and the record of :func:`self_check` with the
    tuned (unchecked) flows' GT metrics as ``tuned_metrics`` (when the scene has GT flow)."""
    if config.self_check == "off":
        return tuned, None
    from .evaluate import flow_metrics

    flows, record = self_check(scene.frames, initial, tuned, person, config.self_check_margin,
                               config.self_check_tile, config.self_check_blend)  # fmt: skip
    return flows, {**record, "tuned_metrics": flow_metrics(scene, tuned)}


def summary_line(record: dict) -> str:
    """One line for the console: how much of the tuned flow the self-check kept."""
    return (f"  self-check: kept the tuned flow on {100 * record['kept_tuned_fraction']:.0f}% of the pixels "
            f"({record['regions_tuned']} of {record['regions_tuned'] + record['regions_initial']} regions; "
            f"person {record['person_tuned']} of {record['person_regions']}), the initial flow elsewhere")
