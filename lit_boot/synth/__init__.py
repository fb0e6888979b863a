"""Synthetic human scenes with exact ground truth (lit-boot's own benchmark data).

:func:`make_scene` renders a textured articulated body (procedural motions or a BVH file) in
front of textured planes, seen by a perspective camera, and returns a
:class:`lit_boot.core.Scene` with exact forward flow, occlusions, person masks, 3D/2D joints,
and simulated METRO-like and DCPose-like estimates.
"""

from .bvh import BvhData, bvh_duration, bvh_motion, read_bvh
from .estimates import EstimateConfig
from .generator import SynthConfig, make_scene
from .motions import MOTION_KINDS, procedural_motion, procedural_skeleton

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
