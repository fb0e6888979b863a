"""lit-boot: test-time bootstrapping of human optical flow and human pose.

The public API:

- the scene model: :class:`Scene`, :class:`GroundTruth`, :class:`Cameras`, the other people of a
  scene (:class:`Person`, :class:`PersonTruth`), joint layouts
  (:data:`LSP14`, :data:`COCO17`, :data:`H36M17`, :data:`MEDIAPIPE33`) and :func:`map_joints`;
- scene folders: :func:`load_scene`, :func:`save_scene`; Middlebury flow: :func:`read_flo`,
  :func:`write_flo`;
- synthetic scenes with exact ground truth: :func:`make_scene`, :class:`SynthConfig`;
- metrics: ``lit_boot.metrics`` (EPE, Fl-all, MPJPE, PA-MPJPE, acceleration error);
- the pose stage (``lit_boot.pose``): :class:`PoseRefiner` (3D joints and cameras) with
  :class:`PoseLossWeights`, :class:`KeypointRefiner` (2D-only) with
  :class:`KeypointLossWeights`, their data :class:`PoseData`, the one-call
  :func:`refine_poses`, and its :class:`PoseResult` (read back by :func:`load_pose_result`);
- the flow stage (``lit_boot.flow``): :class:`FlowTTT` with its :class:`SketchConfig`;
- the whole method (``lit_boot.bootstrap``): :class:`Bootstrap` (``Bootstrap(scene, out).run()``),
  :class:`BootstrapConfig` and :class:`BootstrapResult`;
- many scenes (``lit_boot.dataset``): :func:`discover` (a dataset's scenes as :class:`Task` s) and
  :func:`run_dataset` (all of them, resumable, on local worker processes or Ray);
- real data (``lit_boot.data.readers``): :func:`read_video` (a video file or a folder of
  frames), :func:`read_estimates` (pose files of several formats) and :class:`PoseEstimates`.

The names are imported on first use (``import lit_boot`` does not import torch or Lightning),
so the command line starts fast.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ._lazy import lazy_attributes

if TYPE_CHECKING:  # what the lazy names below resolve to, for type checkers and IDEs
    from .bootstrap import Bootstrap, BootstrapConfig, BootstrapResult
    from .dataset import Task, discover, run_dataset
    from .core import (
        COCO17,
        H36M17,
        LSP14,
        MEDIAPIPE33,
        Cameras,
        GroundTruth,
        JointLayout,
        Person,
        PersonTruth,
        Scene,
        SceneValidationError,
        get_layout,
        map_joints,
    )
    from .data import load_scene, read_flo, save_scene, write_flo
    from .data.readers import PoseEstimates, read_estimates, read_video
    from .flow import FlowTTT, SketchConfig
    from .pose import (
        KeypointLossWeights,
        KeypointRefiner,
        PoseData,
        PoseLossWeights,
        PoseRefiner,
        PoseResult,
        load_pose_result,
        refine_poses,
    )
    from .synth import SynthConfig, make_scene

from ._version import __version__

#: Public name -> the subpackage that defines it (imported when the name is first used).
_LAZY = {
    **dict.fromkeys(["COCO17", "H36M17", "LSP14", "MEDIAPIPE33", "Cameras", "GroundTruth", "JointLayout",
                     "Person", "PersonTruth", "Scene", "SceneValidationError", "get_layout", "map_joints"], ".core"),
    **dict.fromkeys(["load_scene", "read_flo", "save_scene", "write_flo"], ".data"),
    **dict.fromkeys(["SynthConfig", "make_scene"], ".synth"),
    **dict.fromkeys(["PoseRefiner", "PoseLossWeights", "KeypointRefiner", "KeypointLossWeights", "PoseData",
                     "PoseResult", "load_pose_result", "refine_poses"], ".pose"),
    **dict.fromkeys(["FlowTTT", "SketchConfig"], ".flow"),
    **dict.fromkeys(["Bootstrap", "BootstrapConfig", "BootstrapResult"], ".bootstrap"),
    **dict.fromkeys(["run_dataset", "discover", "Task"], ".dataset"),
    **dict.fromkeys(["read_video", "read_estimates", "PoseEstimates"], ".data.readers"),
}  # fmt: skip

#: Subpackages, reachable as attributes (``lit_boot.metrics.epe``) without importing them first.
_SUBPACKAGES = ("bootstrap", "core", "data", "dataset", "estimate", "flow", "metrics", "pose", "synth")

__all__ = [*_LAZY, "__version__"]


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals(), _SUBPACKAGES)
