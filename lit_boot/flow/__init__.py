"""The flow half of the method (paper 3.1): RAFT models and weights, the pose-sketched target
flow, and FlowTTT, which fine-tunes RAFT per scene on it. Never imports lit_boot.pose."""

from .crops import PERSON_MARGIN, person_region
from .data import POSE_SOURCES, SceneFlowData, ScenePairs, SketchInputs, sketch_inputs
from .evidence import (
    Evidence,
    census_error,
    forward_backward_check,
    pair_evidence,
    photometric_error,
    region_mean,
    ssim_error,
    tile_mean,
    warp,
)
from .gate import GATE_REPORT_KEYS, gate_sketch
from .losses import LOSSES, SketchLoss
from .module import FlowTTT
from .raft import load_raft, pad_to_multiple, predict_flow, prepare_pair
from .people_sketch import sketch_people
from .sketch import FOOTPRINTS, GATE_LEVELS, GATES, SketchConfig, SketchResult, footprint_offsets, sketch_flow, sketch_from_layout, target_flow
from .warm import FeatureCache, WarmStart
from .weights import checkpoint_dirs, convert_original_state_dict, load_state_dict_file, resolve_weights
from .writer import FlowWriter

__all__ = [
    "PERSON_MARGIN",
    "person_region",
    "POSE_SOURCES",
    "SceneFlowData",
    "ScenePairs",
    "SketchInputs",
    "sketch_inputs",
    "Evidence",
    "census_error",
    "forward_backward_check",
    "pair_evidence",
    "photometric_error",
    "region_mean",
    "ssim_error",
    "tile_mean",
    "warp",
    "GATE_REPORT_KEYS",
    "gate_sketch",
    "LOSSES",
    "SketchLoss",
    "FlowTTT",
    "load_raft",
    "pad_to_multiple",
    "predict_flow",
    "prepare_pair",
    "FOOTPRINTS",
    "GATES",
    "GATE_LEVELS",
    "SketchConfig",
    "SketchResult",
    "footprint_offsets",
    "sketch_flow",
    "sketch_from_layout",
    "sketch_people",
    "target_flow",
    "FeatureCache",
    "WarmStart",
    "checkpoint_dirs",
    "convert_original_state_dict",
    "load_state_dict_file",
    "resolve_weights",
    "FlowWriter",
]
