"""The whole method on one scene (paper section 3): flow -> pose -> flow, resumable.

- :class:`Bootstrap` / :func:`bootstrap`: run it into a run folder; returns a
  :class:`BootstrapResult` (refined scene, flows, poses, metrics per stage);
- :class:`RunInterrupted`: what a run stopped by Ctrl-C raises (the last finished stage; a
  rerun resumes after it);
- :class:`BootstrapConfig`: its settings, with the ``paper`` and ``default`` presets
  (:data:`PRESETS`);
- :mod:`~lit_boot.bootstrap.evaluate`: what is measured per stage without ground truth (the
  flow-pose agreement, drift, image evidence; the GT metrics are :mod:`lit_boot.metrics.suite`'s); :mod:`~lit_boot.bootstrap.report`: the plot and overlay video.

This is where lit_boot.flow and lit_boot.pose meet.
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_attributes
from .config import DRIFT_GUARDS, MODES, PRESETS, BootstrapConfig
from .interrupt import RunInterrupted

if TYPE_CHECKING:
    from .evaluate import agreement, drift
    from .result import BootstrapResult
    from .runner import Bootstrap, bootstrap

#: Names imported on first use: the runner pulls Lightning, and the CLI's help needs only the config.
_LAZY = {**dict.fromkeys(["agreement", "drift"], ".evaluate"),
         **dict.fromkeys(["Bootstrap", "bootstrap"], ".runner"), "BootstrapResult": ".result"}


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())

__all__ = [
    "Bootstrap",
    "BootstrapResult",
    "BootstrapConfig",
    "RunInterrupted",
    "bootstrap",
    "PRESETS",
    "MODES",
    "DRIFT_GUARDS",
    "agreement",
    "drift",
]
