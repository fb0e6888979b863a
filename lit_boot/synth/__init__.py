"""Synthetic human scenes with exact ground truth (lit-boot's own benchmark data).

:func:`make_scene` renders a textured articulated body (procedural motions or a BVH file) in
front of textured planes, seen by a perspective camera, and returns a
:class:`lit_boot.core.Scene` with exact forward flow, occlusions, person masks, 3D/2D joints,
and simulated METRO-like and DCPose-like estimates. The settings (:class:`SynthConfig`,
:class:`EstimateConfig`) import without torch; the rest loads on first use.
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_attributes
from .config import MOTION_KINDS, EstimateConfig, SynthConfig

if TYPE_CHECKING:
    from .bvh import BvhData, bvh_duration, bvh_motion, read_bvh
    from .generator import make_scene
    from .motions import procedural_motion, procedural_skeleton

_LAZY = {**dict.fromkeys(["BvhData", "bvh_duration", "bvh_motion", "read_bvh"], ".bvh"),
         "make_scene": ".generator",
         **dict.fromkeys(["procedural_motion", "procedural_skeleton"], ".motions")}  # fmt: skip

__all__ = [
    "BvhData",
    "bvh_duration",
    "bvh_motion",
    "read_bvh",
    "EstimateConfig",
    "SynthConfig",
    "make_scene",
    "MOTION_KINDS",
    "procedural_motion",
    "procedural_skeleton",
]


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())
