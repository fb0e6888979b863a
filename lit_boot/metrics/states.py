"""Per-scene metric states, merged over scenes into pooled dataset metrics.

A scene's *states* are the float64 sum states of the ``Metric`` objects behind
:func:`~lit_boot.metrics.scene_flow_metrics` and :func:`~lit_boot.metrics.scene_pose_metrics`,
as plain floats ``{metric name: {state name: value}}`` (JSON-ready, exact):

- ``epe``, ``epe_unmatched``, ``epe_all_pixels``, ``epe_person``, ``epe_background``, ``epe_joints``:
  ``{"epe_sum", "count"}`` (px, pixels or joints);
- ``mpjpe_mm``, ``pa_mpjpe_mm``, ``accel_mm_per_frame2``, ``proj2d_px``, ``kp2d_px``:
  ``{"error_sum", "count"}`` (mm, mm/frame^2 or px; joints of frames);
- with several people, the same under the pooled and per-person names (``kp2d_px_all``,
  ``kp2d_px_person3``: :func:`~lit_boot.metrics.suite.people_metric_objects`).

Summing them over scenes (:func:`merge_metric_states`) and computing (:func:`compute_metric_states`)
gives what one process scoring every scene at once would: every pixel / joint weighs the same.
"""

from __future__ import annotations

from collections.abc import Iterable

import torch
from torch import Tensor
from torchmetrics import Metric

from ..core import Scene
from .suite import FlowMetrics, PoseMetrics, base_metric_name, scene_flow_metric_objects, scene_pose_metric_objects

__all__ = ["METRIC_NAMES", "scene_metric_states", "merge_metric_states", "compute_metric_states"]

States = dict[str, dict[str, float]]

#: The PoseMetrics member behind each pose metric name.
_POSE_MEMBERS = {
    "mpjpe_mm": "mpjpe",
    "pa_mpjpe_mm": "pa_mpjpe",
    "accel_mm_per_frame2": "accel",
    "proj2d_px": "points",
    "kp2d_px": "points",
}
_FLOW_NAMES = tuple(name for name, _ in FlowMetrics().named_children())
#: Every metric name the states may hold, in reporting order (flow, then pose).
METRIC_NAMES: tuple[str, ...] = (*_FLOW_NAMES, *_POSE_MEMBERS)


def _states(metric: Metric) -> dict[str, float]:
    return {name: float(value) for name, value in metric.metric_state.items()}


def scene_metric_states(scene: Scene, flows: Tensor, mode: str) -> States:
    """The states of the metrics ``scene_flow_metrics(scene.gt, flows)`` and
    ``scene_pose_metrics(scene, mode)`` report; flows: (T-1, 2, H, W) px. {} without GT."""
    metrics = {**scene_flow_metric_objects(scene.gt, flows, scene.track_id), **scene_pose_metric_objects(scene, mode)}
    return {name: _states(metric) for name, metric in metrics.items()}


def merge_metric_states(states: Iterable[States]) -> States:
    """Element-wise sums of each metric's states over scenes; a metric is merged over the scenes
    that have it. Raises ValueError if a metric's state names differ between scenes."""
    merged: States = {}
    for scene in states:
        for name, values in scene.items():
            if name not in merged:
                merged[name] = {key: float(value) for key, value in values.items()}
            elif set(values) != set(merged[name]):
                raise ValueError(f"metric {name!r}: states {sorted(values)} differ from {sorted(merged[name])}")
            else:
                merged[name] = {key: merged[name][key] + float(value) for key, value in values.items()}
    return merged


def _blank(name: str) -> Metric:
    """A fresh metric of the class that reports ``name`` (also a pooled or per-person name)."""
    name = base_metric_name(name)
    if name in _FLOW_NAMES:
        return getattr(FlowMetrics(), name)
    if name in _POSE_MEMBERS:
        return getattr(PoseMetrics(), _POSE_MEMBERS[name])
    raise ValueError(f"unknown metric {name!r}; expected one of {', '.join(METRIC_NAMES)}")


def compute_metric_states(states: States) -> dict[str, float]:
    """{name: value} of (merged) states, by the reporting metric classes' own ``compute``
    (NaN where a count is 0)."""
    out = {}
    for name, values in states.items():
        metric = _blank(name)
        if set(values) != set(metric.metric_state):
            raise ValueError(f"metric {name!r}: states {sorted(values)}, expected {sorted(metric.metric_state)}")
        metric.merge_state({key: torch.tensor(value, dtype=torch.float64) for key, value in values.items()})
        # the class's compute itself: torchmetrics' wrapper would warn that update was never called
        out[name] = float(type(metric).compute(metric))
    return out
