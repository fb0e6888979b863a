"""What a run's evidence says, in plain sentences, and how sure it is.

Without ground truth the frames are the only judge: where the final flow differs from RAFT's,
does frame t+1 warped by it match frame t better (a lower census error)? :class:`EvidenceTally`
pools that over the pairs; its certainty is a z value over tiles of 16x16 px (neighbouring
pixels' errors are not independent, tiles nearly are): the mean gain over the tiles where the
flow changed, in standard errors. With ground truth, :func:`gt_sentence` says what it measured;
with several people, :func:`ids_sentence` where a person's id may have switched.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import torch
import torch.nn.functional as F

from ..estimate.id_checks import checks_line, scene_checks
from .metric_history import before_after
from .pair_maps import CHANGED_PX, PairMaps

__all__ = ["EvidenceTally", "certainty", "evidence_sentence", "gt_sentence", "TILE_PX"]

TILE_PX = 16  #: the tiles the certainty is counted over
MIN_TILE_PIXELS = 16  #: changed pixels a tile needs to count


@dataclass
class EvidenceTally:
    """The census errors of RAFT's and the final flow over the changed pixels, pooled over the
    pairs added, and the gain (RAFT - final) per tile."""

    pixels: int = 0
    changed: int = 0
    raft_sum: float = 0.0
    final_sum: float = 0.0
    pairs: int = 0
    pairs_changed: int = 0
    pairs_better: int = 0
    tile_gains: list[torch.Tensor] = field(default_factory=list)

    def add(self, maps: PairMaps) -> None:
        """Count one pair (``maps`` with census maps)."""
        on = maps.valid & (maps.change > CHANGED_PX)
        self.pairs += 1
        self.pixels += maps.change.numel()
        n = int(on.sum())
        if n == 0:
            return
        raft, final = float(maps.census_raft[on].double().sum()), float(maps.census_final[on].double().sum())
        self.changed, self.raft_sum, self.final_sum = self.changed + n, self.raft_sum + raft, self.final_sum + final
        self.pairs_changed += 1
        self.pairs_better += final < raft
        gain = torch.where(on, maps.census_raft - maps.census_final, 0.0)
        sums = F.avg_pool2d(gain[None, None].double(), TILE_PX, ceil_mode=True, divisor_override=1)
        counts = F.avg_pool2d(on[None, None].double(), TILE_PX, ceil_mode=True, divisor_override=1)
        enough = counts >= MIN_TILE_PIXELS
        self.tile_gains.append((sums[enough] / counts[enough]).float())

    @property
    def z(self) -> float:
        """Mean tile gain over its standard error (NaN with fewer than 2 tiles; ±inf if all equal)."""
        gains = torch.cat(self.tile_gains) if self.tile_gains else torch.zeros(0)
        if gains.numel() < 2:
            return float("nan")
        se = float(gains.double().std()) / math.sqrt(gains.numel())
        mean = float(gains.double().mean())
        return mean / se if se > 0 else math.copysign(math.inf, mean) if mean else 0.0

    @property
    def tiles(self) -> int:
        return int(sum(g.numel() for g in self.tile_gains))


def certainty(z: float) -> str:
    """How sure a gain of ``z`` standard errors is, in words (negative: a loss)."""
    if math.isnan(z):
        return "too few changed tiles to tell"
    size = abs(z)
    way = "that it got better" if z > 0 else "that it got worse"
    if size >= 3:
        return f"strong evidence {way}"
    if size >= 2:
        return f"moderate evidence {way}"
    if size >= 1:
        return f"weak evidence {way}"
    return "no clear evidence either way"


def _pct(a: float, b: float) -> str:
    return f"{100 * (b - a) / abs(a):+.1f}%" if a else "n/a"


def _self_checked(history: Sequence[dict[str, Any]]) -> bool:
    return any(r.get("kind") == "flow" and r.get("info", {}).get("self_check") for r in history)


def _zoomed(history: Sequence[dict[str, Any]]) -> bool:
    """A zoom stage that was kept: it keeps its flow only where the frames' census error is lower."""
    return any(r.get("kind") == "zoom" and not r.get("rolled_back") for r in history)


def _painted(history: Sequence[dict[str, Any]]) -> float:
    return max((r.get("info", {}).get("target", {}).get("target/painted_fraction", 0.0) or 0.0
                for r in history if r.get("kind") == "flow"), default=0.0)  # fmt: skip


def evidence_sentence(tally: EvidenceTally, history: Sequence[dict[str, Any]]) -> str:
    """What the frames say about the flow (and the joint tracks about the poses), and how sure."""
    if tally.pairs == 0:
        return "The run has no frames to judge the flow by (its scene was not found)."
    if tally.changed == 0:
        if _painted(history) == 0:
            why = "the target painted nothing (no usable pose was found), so nothing was tuned"
        elif _self_checked(history):
            why = "the self-check kept RAFT's flow everywhere: the frames supported the tuned flow nowhere"
        else:
            why = "the tuned flow equals it"
        if _zoomed(history):
            why += "; the zoom stage's flow was kept nowhere either"
        text = (f"The final flow is RAFT's flow on every pixel (no pixel moved by more than {CHANGED_PX} px): {why}. "
                "The run neither helped nor harmed the flow.")  # fmt: skip
    else:
        raft, final = tally.raft_sum / tally.changed, tally.final_sum / tally.changed
        better = final < raft
        text = (f"What the frames say (no ground truth needed): the final flow differs from RAFT's on "
                f"{100 * tally.changed / tally.pixels:.1f}% of the pixels and is RAFT's flow elsewhere. Where it "
                f"differs, frame t+1 warped by the final flow matches frame t {'better' if better else 'worse'} than "
                f"with RAFT's: the census error there {'fell' if better else 'rose'} from {raft:.2f} to {final:.2f} "
                f"(of 48; {_pct(raft, final)}), lower in {tally.pairs_better} of the {tally.pairs_changed} pairs that "
                f"changed. How sure: {certainty(tally.z)} ({tally.z:+.1f} standard errors over {tally.tiles} tiles of "
                f"{TILE_PX}x{TILE_PX} px).")  # fmt: skip
        checks = [what for what, used in (("the self-check kept the tuned flow", _self_checked(history)),
                                           ("the zoom stage kept its zoomed flow", _zoomed(history))) if used]
        if checks:
            text += (f" Read it with care: {' and '.join(checks)} only where this same error was lower, so a fall is "
                     "partly by construction.")  # fmt: skip
        text += (" The census error compares small neighbourhoods: it cannot tell a wrong motion onto similar "
                 "texture from the right one.")  # fmt: skip
    values = before_after(history)
    if "track_error" in values:
        a, b = values["track_error"]
        way = "follow the image content better" if b < a else "follow it worse" if b > a else "follow it as well"
        text += (f" The poses: the census error along the joints' tracks went from {a:.2f} to {b:.2f} "
                 f"({_pct(a, b)}): the refined joints {way} from frame to frame.")  # fmt: skip
    return text


#: Ground-truth metrics named in :func:`gt_sentence`, with their words.
GT_WORDS = (("epe_all_pixels", "the flow's end-point error on every valid pixel (Sintel's all)"),
            ("epe", "on the pixels that stay visible (matched)"), ("epe_unmatched", "on the occluded (unmatched)"),
            ("epe_person", "on the person"), ("epe_background", "on the background"),
            ("mpjpe_mm", "the 3D joint error (MPJPE)"), ("kp2d_px", "the 2D keypoint error"))  # fmt: skip
#: ``epe``'s words where the ground truth marks no occlusions (no ``epe_all_pixels``).
EPE_WORDS = "the flow's end-point error on the valid pixels"


def gt_sentence(history: Sequence[dict[str, Any]]) -> str | None:
    """What the ground truth says (None without GT metrics): each of :data:`GT_WORDS` present,
    before -> after and the change."""
    values = before_after(history)
    parts = []
    words_of = dict(GT_WORDS) | ({} if "epe_all_pixels" in values else {"epe": EPE_WORDS})
    for key, words in words_of.items():
        if key in values and all(math.isfinite(v) for v in values[key]):
            a, b = values[key]
            unit = "mm" if key.endswith("_mm") else "px"
            parts.append(f"{words} {a:.3g} -> {b:.3g} {unit} ({_pct(a, b)})")
    return ("Against the ground truth: " + "; ".join(parts) + ". Lower is better.") if parts else None


def ids_sentence(scene: Any) -> str | None:
    """Where a person's id may have switched in a scene with several people (None for one person,
    or where nothing is to check): the frames of :func:`~lit_boot.estimate.id_checks.frames_to_check`."""
    line = checks_line(scene_checks(scene)) if scene is not None else ""
    if not line:
        return None
    return (f"Several people: {line}. Where a track took another person's pose, that person's metrics and "
            "target mix two people: look at those frames in the overlay.")
