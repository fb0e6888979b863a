"""The settings of the zoom stage and of the flow stages' self-check (:class:`ZoomConfig`,
:class:`SelfCheckConfig`), the nested parts of :class:`~lit_boot.bootstrap.BootstrapConfig`
(``zoom``, ``self_check``). Plain dataclasses: the CLI reads them without torch.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

__all__ = ["SELF_CHECKS", "ZOOMS", "ZOOM_TEACHING", "ZOOM_STARTS", "ZOOM_CONFIRM", "WHOLE_FRAME_MAX_CHANGE_PX",
           "ZOOM_COST", "SelfCheckConfig", "ZoomConfig"]

#: The flow stages' self-check against the frames (see :mod:`lit_boot.bootstrap.selfcheck`).
SELF_CHECKS = ("off", "photometric")
#: The zoom stage (see :mod:`lit_boot.bootstrap.zoom`): off, or RAFT zoomed on the person.
ZOOMS = ("off", "person")
#: What the flow stages learn from the zoom: nothing (off), its flow as the base the stick-man is
#: painted over (base), or that and its confirmed pixels painted instead of the stick-man (confirmed).
ZOOM_TEACHING = ("off", "base", "confirmed")
#: How RAFT starts on the zoomed crops (as lit_boot.flow.zoom.ZOOM_STARTS; see ZoomConfig.start).
ZOOM_STARTS = ("zero", "shift", "warm")
#: What the frames say of the zoomed flow, beside the refinement limit: not worse (veto), better
#: (census), or nothing (none).
ZOOM_CONFIRM = ("census", "veto", "none")

#: The self-check's refinement limit (px) where the flow stages tune the whole frame
#: (``self_check.max_change_px`` "auto"): the zoom stage's (``ZoomConfig.max_change_px``).
WHOLE_FRAME_MAX_CHANGE_PX = 16.0

#: The zoom's cost per mode (``zoom.max_cost`` "auto"), in frames of pixels: each mode's speed
#: bar (3D 5x, 2D 10x plain RAFT) decides how much of it the zoom may spend. Four frames gain more
#: on every set measured, but take a 3D run to the 5x bar; a 2D run (50 epochs) stays near 7x
#: (BENCHMARKS.md, "The zoom's cost, four frames" and "The zoom's cost per mode").
ZOOM_COST = {"3d": 2.0, "2d": 4.0}


@dataclass(frozen=True, kw_only=True)
class SelfCheckConfig:
    """The flow stages' self-check against the frames (:mod:`lit_boot.bootstrap.selfcheck`).

    Args:
        method: None (the preset's: photometric in default, off in paper), off, or photometric
            (per pair, keep the tuned flow only where its census error is clearly lower than
            the initial flow's: on the person pixel by pixel, over a small window, elsewhere
            per tile). The stage's flows are then the checked flows.
        margin: how much lower (a fraction of the initial flow's error) the tuned flow's error
            must be to be kept; ties keep the initial flow.
        tile: background tile size, px.
        window: the box (px) over which each person pixel's errors are averaged.
        z: how many standard errors a background tile's gain must clear (noisy evidence, as on
            blurred frames, keeps the initial flow).
        blend: px over which the two flows are blended where the choice changes (0: none; a
            blend gives the tuned flow to pixels beside the person that were judged for the
            initial flow).
        own: a person pixel also needs its own error to be lower, not only its window's (else
            the band of background beside a limb, whose window holds limb pixels, goes with
            the limb).
        max_change_px: the tuned flow is kept only where it moves the flow it is checked
            against by less than this (px): a larger change is another match, which the frames
            cannot be trusted to judge (fog, blur, fast motion). "auto": 16 px
            (:data:`WHOLE_FRAME_MAX_CHANGE_PX`) where the flow stages tune the whole frame
            (``flow.crop_margin`` None, the authors' fine-tune), no limit with the crop fine-tune
            (BENCHMARKS.md, "The self-check's refinement limit"); None: no limit.
    """

    method: str | None = None
    margin: float = 0.02
    tile: int = 32
    window: int = 5
    z: float = 1.0
    blend: int = 0
    own: bool = True
    max_change_px: float | Literal["auto"] | None = "auto"

    def __post_init__(self) -> None:
        limit = self.max_change_px
        if limit not in (None, "auto") and (isinstance(limit, str) or not limit > 0):
            raise ValueError(f"self_check.max_change_px: expected 'auto', None or > 0 px, got {limit!r}")
        if self.method not in (None, *SELF_CHECKS):
            raise ValueError(f"self_check.method: expected one of {(None, *SELF_CHECKS)}, got {self.method!r}")
        if not 0 <= self.margin < 1:
            raise ValueError(f"self_check.margin: expected 0 <= margin < 1, got {self.margin}")
        if self.z < 0:
            raise ValueError(f"self_check.z: expected >= 0 standard errors, got {self.z}")
        for name, least in (("tile", 1), ("window", 1), ("blend", 0)):
            if getattr(self, name) < least:
                raise ValueError(f"self_check.{name}: expected >= {least} px, got {getattr(self, name)}")


@dataclass(frozen=True, kw_only=True)
class ZoomConfig:
    """The zoom stage: RAFT on a zoomed crop around the person, kept unless the frames refuse it
    (:mod:`lit_boot.bootstrap.zoom`, :mod:`lit_boot.flow.zoom`).

    Args:
        method: None (the preset's: person in default, off in paper), off, or person.
        max_scale: the largest upsampling of the crop (but see ``small_scale``).
        small_scale: a small person's crop may be upsampled more, up to this (4), as far as
            the zoomed crop stays within ``max_cost`` frames of pixels; None: ``max_scale`` for
            everyone. A large person's crop is zoomed ``max_scale`` as before (BENCHMARKS.md,
            "Small people zoomed more, the default").
        max_cost: see ``small_scale``: the zoomed crop's pixels, in frames; "auto": the mode's
            (:data:`ZOOM_COST`: 2 in 3D, 4 in 2D), resolved by :meth:`for_mode`.
        max_pixels: the zoomed crop's pixels at most, whatever the scale (2**21, e.g. 1448 x
            1448): RAFT's all-pairs correlation memory grows with their square (8.2 GiB measured
            at this many); a pair whose scale would fall below ``min_scale`` is not zoomed.
            None: no limit (a large person's crop zoomed 2x in a 1080p frame can need tens of
            GiB). Kept equal to lit_boot.data.memory.ZOOM_PIXELS, which the memory check uses.
        min_scale: a pair whose scale would be below this is not zoomed: its motion is close to
            RAFT's reach at the zoomed size, where the zoom does harm (market_5 at full size,
            zoomed 1.25x: +1.7%; BENCHMARKS.md, "Resolution where the person is").
        reach_px: the largest zoomed motion, px: the scale is at most reach_px / the 95th
            percentile of RAFT's flow magnitude on the person's box (a zoomed displacement
            beyond RAFT's reach is a failure, not a refinement).
        context: the crop's margin around the person's box, as a fraction of its larger side.
        min_context_px: the smallest margin, px.
        border_px: the zoomed flow along the crop's inner edges (no context there) is not used.
        updates: the fewest RAFT iterations on the zoomed crop; one more per cell of RAFT's
            grid (8 px) the zoomed motion spans, at most ``max_updates``.
        max_updates: the most RAFT iterations on the zoomed crop.
        max_change_px: the zoomed flow is kept only where it moves RAFT's flow by less than
            this, px (16: two cells of RAFT's grid): a refinement, not another match.
        confirm: veto (kept unless the frames say RAFT's flow is better: its census error
            averaged over ``window`` lower by ``margin``), census (the frames must say the
            zoomed flow is better: its averaged error lower by ``margin``, and the pixel's own
            lower too) or none (the refinement limit alone). BENCHMARKS.md, "The zoom stage's
            veto".
        window: the box (px) over which each pixel's census errors are averaged.
        margin: how much lower (a fraction of the other's) the winning flow's averaged error
            must be (veto: RAFT's to refuse the zoomed flow; census: the zoomed flow's to be
            kept).
        start: how RAFT starts on the zoomed crops: zero (from zero, on the same crop of both
            frames), shift (frame2's crop follows the person's median motion, and the scale is
            chosen from the motion left) or warm (shift, and RAFT starts from its own flow).
        teach: what the flow stages' fine-tune learns from the zoom: off, base (the stick-man is
            painted over the zoom stage's flow instead of RAFT's) or confirmed (that, and where
            the zoomed flow was kept it is the target instead of the stick-man).
    """

    method: str | None = None
    max_scale: float = 2.0
    small_scale: float | None = 4.0
    max_cost: float | Literal["auto"] = "auto"
    max_pixels: int | None = 2**21
    min_scale: float = 1.5
    reach_px: float = 60.0
    context: float = 0.5
    min_context_px: int = 16
    border_px: int = 8
    updates: int = 8
    max_updates: int = 16
    max_change_px: float = 16.0
    confirm: str = "veto"
    window: int = 5
    margin: float = 0.02
    start: str = "zero"
    teach: str = "off"

    def __post_init__(self) -> None:
        if self.confirm not in ZOOM_CONFIRM:
            raise ValueError(f"zoom.confirm: expected one of {ZOOM_CONFIRM}, got {self.confirm!r}")
        if self.start not in ZOOM_STARTS:
            raise ValueError(f"zoom.start: expected one of {ZOOM_STARTS}, got {self.start!r}")
        if self.teach not in ZOOM_TEACHING:
            raise ValueError(f"zoom.teach: expected one of {ZOOM_TEACHING}, got {self.teach!r}")
        if self.method not in (None, *ZOOMS):
            raise ValueError(f"zoom.method: expected one of {(None, *ZOOMS)}, got {self.method!r}")
        if not 1.0 <= self.min_scale <= self.max_scale:
            raise ValueError(f"zoom.min_scale / zoom.max_scale: expected 1 <= min_scale <= max_scale, "
                             f"got {self.min_scale} / {self.max_scale}")  # fmt: skip
        if self.small_scale is not None and not self.small_scale >= self.max_scale:
            raise ValueError(f"zoom.small_scale: expected None or >= max_scale ({self.max_scale}), "
                             f"got {self.small_scale}")  # fmt: skip
        if self.max_pixels is not None and not self.max_pixels > 0:
            raise ValueError(f"zoom.max_pixels: expected None or > 0, got {self.max_pixels}")
        cost = self.max_cost
        if cost != "auto" and (isinstance(cost, str) or not cost > 0):
            raise ValueError(f"zoom.max_cost: expected 'auto' or > 0 frames, got {cost!r}")
        for name in ("reach_px", "max_change_px", "context"):
            if not getattr(self, name) > 0:
                raise ValueError(f"zoom.{name}: expected > 0, got {getattr(self, name)}")
        for name, least in (("min_context_px", 0), ("border_px", 0), ("updates", 1), ("window", 1),
                            ("max_updates", self.updates)):
            if getattr(self, name) < least:
                raise ValueError(f"zoom.{name}: expected >= {least}, got {getattr(self, name)}")
        if not 0 <= self.margin < 1:
            raise ValueError(f"zoom.margin: expected 0 <= margin < 1, got {self.margin}")

    def for_mode(self, mode: str) -> ZoomConfig:
        """This config with ``max_cost`` "auto" resolved for ``mode`` (3d or 2d; :data:`ZOOM_COST`)."""
        if mode not in ZOOM_COST:
            raise ValueError(f"mode: expected one of {tuple(ZOOM_COST)}, got {mode!r}")
        return self if self.max_cost != "auto" else replace(self, max_cost=ZOOM_COST[mode])
