"""The whole method on one scene (paper section 3): flow -> pose -> flow, resumable.

- :class:`Bootstrap` / :func:`bootstrap`: run it into a run folder; returns a
  :class:`BootstrapResult` (refined scene, flows, poses, metrics per stage);
- :class:`BootstrapConfig`: its settings, with the ``paper`` and ``default`` presets
  (:data:`PRESETS`);
- :mod:`~lit_boot.bootstrap.evaluate`: the metrics recorded per stage (EPE, MPJPE, the
  flow-pose agreement, drift); :mod:`~lit_boot.bootstrap.report`: the plot and overlay video.

This is where lit_boot.flow and lit_boot.pose meet.
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_attributes
from .config import DRIFT_GUARDS, MODES, PRESETS, BootstrapConfig

if TYPE_CHECKING:
    from .evaluate import agreement, drift, flow_metrics, pose_metrics, pose_points
    from .result import BootstrapResult
    from .runner import Bootstrap, bootstrap

#: Names imported on first use: the runner pulls Lightning, and the CLI's help needs only the config.
_LAZY = {**dict.fromkeys(["agreement", "drift", "flow_metrics", "pose_metrics", "pose_points"], ".evaluate"),
         **dict.fromkeys(["Bootstrap", "bootstrap"], ".runner"), "BootstrapResult": ".result"}


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())

__all__ = [
    "Bootstrap",
    "BootstrapResult",
    "BootstrapConfig",
    "bootstrap",
    "PRESETS",
    "MODES",
    "DRIFT_GUARDS",
    "agreement",
    "drift",
    "flow_metrics",
    "pose_metrics",
    "pose_points",
]
