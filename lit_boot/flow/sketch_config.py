"""The sketch's settings and result (:mod:`lit_boot.flow.sketch` draws it): how the stick-man is
drawn, which bones are trusted, and what a drawn sketch holds. Conventions as in
:mod:`lit_boot.flow.sketch`: px, flows (B, 2, H, W) forward from frame t to t+1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from torch import Tensor

__all__ = ["FOOTPRINTS", "GATES", "GATE_LEVELS", "REASONS", "SketchConfig", "SketchResult", "check_footprint"]

FOOTPRINTS = ("cross", "square", "disk")
GATES = ("off", "photometric", "photometric+fb")
GATE_LEVELS = ("pixel", "bone", "bone+pixel")
REASONS = ("confidence", "jump", "disagreement", "points")


@dataclass(frozen=True)
class SketchConfig:
    """How the stick-man is drawn and which bones are trusted.

    Args:
        footprint: shape that every bone sample paints: "cross" (the paper's text), "square"
            (the authors' code) or "disk".
        size: footprint size in px. cross: arm length (radius; 15 in the paper), 4*size+1
            pixels; square: side (30 in the authors' code; an even side n spans offsets
            -n//2 .. n//2-1); disk: radius (offsets with dx^2 + dy^2 <= size^2).
        points_per_bone: samples per bone, both ends included (22 in the authors' code).
            None = dense: consecutive samples at most 0.5 px apart in frame t, so the footprint
            dilates a continuous line (only the part of the bone near the image is sampled).
        confidence_threshold: a bone is drawn only when both its ends have confidence strictly
            above this, in frame t and (when given) in frame t+1.
        guard: apply the plausibility guards: the joint-jump test, and the disagreement tests
            when a base flow is given. The confidence gate applies regardless.
        max_disagreement_px: a bone whose median end-point distance (px) between its sketch
            displacement and the base flow at its sample points exceeds this is not painted.
        point_disagreement_factor: samples of a kept bone whose own disagreement exceeds this
            times ``max_disagreement_px`` are not painted (counted under "points").
        max_joint_jump: a joint that moves between t and t+1 by more than this fraction of the
            person's size (the diagonal of the bounding box of the confident joints in frame t)
            is implausible: the bones touching it are not painted.
        gate: the image-evidence gate (:mod:`lit_boot.flow.gate`, needs the frames): "off",
            "photometric" (keep sketch pixels whose census error is at most the base flow's
            plus ``gate_margin``) or "photometric+fb" (also keep them where the base flow fails
            its forward-backward check; one more RAFT pass per pair).
        gate_margin: census error units (7x7 window, 0..48) the sketch may lose by.
        gate_level: "pixel" (each pixel on its own), "bone" (a bone's mean difference over
            its comparable core pixels decides for all its pixels) or "bone+pixel" (both: the
            best measured, benchmarks/gate_check.py).
        gate_core: px; a bone is judged on its pixels within this distance of its frame-t
            segment (the limb itself, not the footprint's background).
        gate_search: px; > 0 first shifts each bone's displacement by the integer offset
            within +-gate_search that best explains its core pixels (0: off).
    """

    footprint: str = "cross"
    size: int = 15
    points_per_bone: int | None = None
    confidence_threshold: float = 0.6
    guard: bool = True
    max_disagreement_px: float = 12.0
    point_disagreement_factor: float = 2.0
    max_joint_jump: float = 0.35
    gate: str = "off"
    gate_margin: float = 0.0
    gate_level: str = "bone+pixel"
    gate_core: float = 3.0
    gate_search: int = 0

    def __post_init__(self) -> None:
        check_footprint(self.footprint, self.size)
        if self.points_per_bone is not None and self.points_per_bone < 1:
            raise ValueError(f"points_per_bone: expected None or >= 1, got {self.points_per_bone}")
        for name in ("max_disagreement_px", "point_disagreement_factor", "max_joint_jump"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name}: expected >= 0, got {getattr(self, name)}")
        if self.gate not in GATES:
            raise ValueError(f"gate: expected one of {GATES}, got {self.gate!r}")
        if self.gate_level not in GATE_LEVELS:
            raise ValueError(f"gate_level: expected one of {GATE_LEVELS}, got {self.gate_level!r}")
        if int(self.gate_search) != self.gate_search or self.gate_search < 0:
            raise ValueError(f"gate_search: expected an integer >= 0, got {self.gate_search}")
        if not self.gate_core >= 0:
            raise ValueError(f"gate_core: expected >= 0, got {self.gate_core}")
        if not math.isfinite(self.gate_margin):
            raise ValueError(f"gate_margin: expected a finite number, got {self.gate_margin}")


@dataclass
class SketchResult:
    """A drawn sketch.

    flow: (B, 2, H, W) px, zeros where unpainted; mask: (B, H, W) bool, painted pixels;
    bone_drawn: (B, E) bool, bones that passed every gate (one lying outside the image may
    still paint nothing); rejected: counts over the batch, each bone under the first failing
    reason in the order "confidence" (non-finite joints count as unconfident), "jump",
    "disagreement"; "points" counts the samples of drawn bones dropped for disagreement;
    owner: (B, H, W) long, the bone (index into the bones drawn) that painted each pixel, -1
    where unpainted, and bone_ends: (B, E, 2, 2) px, each bone's ends (a, b) in frame t (both
    None when unknown).
    """

    flow: Tensor
    mask: Tensor
    bone_drawn: Tensor
    rejected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REASONS, 0))
    owner: Tensor | None = None
    bone_ends: Tensor | None = None


def check_footprint(footprint: str, size: int) -> None:
    """ValueError unless ``footprint`` is one of :data:`FOOTPRINTS` and ``size`` (px) fits it."""
    if footprint not in FOOTPRINTS:
        raise ValueError(f"footprint: expected one of {FOOTPRINTS}, got {footprint!r}")
    least = 1 if footprint == "square" else 0
    if int(size) != size or size < least:
        raise ValueError(f"size: expected an integer >= {least} for footprint {footprint!r}, got {size}")
