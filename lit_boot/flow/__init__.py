"""The flow half of the method: RAFT models and weights (more to come: the target sketch,
FlowTTT). Never imports lit_boot.pose."""

from .raft import load_raft, pad_to_multiple, predict_flow, prepare_pair
from .weights import checkpoint_dirs, convert_original_state_dict, load_state_dict_file, resolve_weights

__all__ = [
    "load_raft",
    "pad_to_multiple",
    "predict_flow",
    "prepare_pair",
    "checkpoint_dirs",
    "convert_original_state_dict",
    "load_state_dict_file",
    "resolve_weights",
]
