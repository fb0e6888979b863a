"""Evaluation metrics as pure functions and as ``torchmetrics.Metric`` classes.

``flow`` covers optical flow (end-point error, 1/3/5 px accuracy rates, KITTI Fl-all, and
errors of flow sampled at query points); ``pose`` covers 3D joints in millimetres (MPJPE
with root, scale or Procrustes alignment, and acceleration error in mm/frame^2). The
functions take ``(pred, gt, mask, ...)`` tensors on any device; the classes accumulate
float64 sum states (``dist_reduce_fx="sum"``) and divide only in ``compute()``, so results
are exact across batches and processes and NaN when nothing was seen. ``suite`` holds what
lit-boot reports (FlowTTT, the refiners, the orchestrator), under one naming scheme;
``states`` their per-scene sum states, merged over a dataset.
"""

from __future__ import annotations

from .flow import (
    EndPointError,
    FlowErrorRates,
    PointEndPointError,
    endpoint_error,
    epe_at_points,
    flow_error_sums,
    flow_errors,
    sample_flow_at_points,
)
from .pose import (
    LSP14_ROOT,
    MPJPE,
    AccelerationError,
    MeanPerJointPositionError,
    acceleration_error,
    align_root,
    mpjpe,
    n_mpjpe,
    pa_mpjpe,
    procrustes_align,
    procrustes_transform,
    scale_align,
)
from .states import METRIC_NAMES, compute_metric_states, merge_metric_states, scene_metric_states
from .suite import (
    FlowMetrics,
    PoseMetrics,
    base_metric_name,
    metric_person,
    people_metric_objects,
    scene_flow_metrics,
    scene_pose_metrics,
)

__all__ = [
    "FlowMetrics",
    "PoseMetrics",
    "scene_flow_metrics",
    "scene_pose_metrics",
    "people_metric_objects",
    "base_metric_name",
    "metric_person",
    "METRIC_NAMES",
    "scene_metric_states",
    "merge_metric_states",
    "compute_metric_states",
    "endpoint_error",
    "flow_error_sums",
    "flow_errors",
    "sample_flow_at_points",
    "epe_at_points",
    "EndPointError",
    "FlowErrorRates",
    "PointEndPointError",
    "LSP14_ROOT",
    "align_root",
    "procrustes_transform",
    "procrustes_align",
    "scale_align",
    "mpjpe",
    "pa_mpjpe",
    "n_mpjpe",
    "acceleration_error",
    "MeanPerJointPositionError",
    "MPJPE",
    "AccelerationError",
]
