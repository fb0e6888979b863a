"""The pose half of the method (paper 3.2 and 3.3): per-video refinement of poses against the
optical flow, as Lightning modules.

- :class:`PoseRefiner`: 3D joints and cameras (METRO weak perspective or pinhole), loss
  L_opt + L_3D + L_2D + L_temp with the paper's lambdas (:class:`PoseLossWeights`);
- :class:`KeypointRefiner`: the 2D-only mode, keypoints optimised directly
  (:class:`KeypointLossWeights`);
- :class:`PoseData`: a scene and its flows (``.flo`` folder, ``flows.npz``, or ``"gt"``);
  validating a refiner with it (``lit-boot validate``) evaluates the current poses;
- :class:`LossPlateauStopping`: the authors' early stop;
- :func:`refine_poses`: all of it in one call; :class:`PoseResult`: what comes out (saved as
  poses.npz + pose_report.json, read back by :func:`load_pose_result`).

Never imports lit_boot.flow: the two halves meet only in the orchestrator.
"""

from .api import REFINERS, make_refiner, make_trainer, refine_poses
from .camera import CameraModel
from .data import DEFAULT_STEPS, PoseData, StepIndices
from .flows import FlowSourceError, load_flows
from .keypoints import AUTHORS_KEYPOINT_JOINTS, CONFIDENCE_MODES, confidence_weights, keypoints_for_layout
from .objective import Objective, Term
from .losses import (
    bone_lengths,
    bone_matrix,
    flow_residual,
    temporal_residual,
)
from .refiner import PoseLossWeights, PoseRefiner
from .refiner2d import KeypointLossWeights, KeypointRefiner
from .result import PoseResult, load_pose_result
from .stopping import LossPlateauStopping

__all__ = [
    "REFINERS",
    "make_refiner",
    "PoseRefiner",
    "PoseLossWeights",
    "KeypointRefiner",
    "KeypointLossWeights",
    "PoseData",
    "StepIndices",
    "DEFAULT_STEPS",
    "LossPlateauStopping",
    "PoseResult",
    "load_pose_result",
    "refine_poses",
    "make_trainer",
    "load_flows",
    "FlowSourceError",
    "CameraModel",
    "AUTHORS_KEYPOINT_JOINTS",
    "CONFIDENCE_MODES",
    "confidence_weights",
    "keypoints_for_layout",
    "Objective",
    "Term",
    "flow_residual",
    "temporal_residual",
    "bone_matrix",
    "bone_lengths",
]
