"""lit-boot: test-time bootstrapping of human optical flow and human pose.

The public API:

- the scene model: :class:`Scene`, :class:`GroundTruth`, :class:`Cameras`, joint layouts
  (:data:`LSP14`, :data:`COCO17`, :data:`H36M17`, :data:`MEDIAPIPE33`) and :func:`map_joints`;
- scene folders: :func:`load_scene`, :func:`save_scene`; Middlebury flow: :func:`read_flo`,
  :func:`write_flo`;
- synthetic scenes with exact ground truth: :func:`make_scene`, :class:`SynthConfig`;
- metrics: ``lit_boot.metrics`` (EPE, Fl-all, MPJPE, PA-MPJPE, acceleration error);
- the pose stage (``lit_boot.pose``): :class:`PoseRefiner` (3D joints and cameras) with
  :class:`PoseLossWeights`, :class:`KeypointRefiner` (2D-only) with
  :class:`KeypointLossWeights`, their data :class:`PoseData`, the one-call
  :func:`refine_poses`, and its :class:`PoseResult` (read back by :func:`load_pose_result`).
"""

from .core import (
    COCO17,
    H36M17,
    LSP14,
    MEDIAPIPE33,
    Cameras,
    GroundTruth,
    JointLayout,
    Scene,
    SceneValidationError,
    get_layout,
    map_joints,
)
from .data import load_scene, read_flo, save_scene, write_flo
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

__version__ = "0.1.0"

__all__ = [
    "COCO17",
    "H36M17",
    "LSP14",
    "MEDIAPIPE33",
    "Cameras",
    "GroundTruth",
    "JointLayout",
    "Scene",
    "SceneValidationError",
    "get_layout",
    "map_joints",
    "load_scene",
    "read_flo",
    "save_scene",
    "write_flo",
    "SynthConfig",
    "make_scene",
    "PoseRefiner",
    "PoseLossWeights",
    "KeypointRefiner",
    "KeypointLossWeights",
    "PoseData",
    "PoseResult",
    "load_pose_result",
    "refine_poses",
    "__version__",
]
