"""Many scenes, one command: dataset runs that resume, merge exactly, and scale out on Ray.

- :func:`discover` (:mod:`.sources`): a dataset's scenes as :class:`Task` s (a Sintel, 3DPW or
  Human3.6M tree, a folder of videos, a folder of scene folders, or a list file);
- :func:`run_dataset` (:mod:`.runner`): the method on every task through an engine
  (:mod:`.engines`: ``local`` processes or ``ray``), each task's state and result in the
  folder's manifest (:mod:`.manifest`), long scenes in overlapping chunks stitched back
  (:mod:`.chunks`, :mod:`.stitch`), and the dataset's metrics merged from the scenes' metric
  states (:mod:`.summary`) into summary.md / summary.csv;
- :class:`DatasetResult`: what a run gives back.

``lit-boot bootstrap-many`` is the command line of :func:`run_dataset`.
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_attributes
from .tasks import KINDS, Task

if TYPE_CHECKING:
    from .engines import LocalEngine, RayEngine
    from .runner import DatasetResult, run_dataset
    from .sources import discover

_LAZY = {**dict.fromkeys(["run_dataset", "DatasetResult"], ".runner"), "discover": ".sources",
         **dict.fromkeys(["LocalEngine", "RayEngine"], ".engines")}  # fmt: skip

__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())

__all__ = ["Task", "KINDS", "discover", "run_dataset", "DatasetResult", "LocalEngine", "RayEngine"]
