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
  poses.npz + poses.json, read back by :func:`load_pose_result`).

Never imports lit_boot.flow: the two halves meet only in the orchestrator.
"""

from .api import make_trainer, refine_poses
from .camera import CameraModel
from .data import DEFAULT_STEPS, PoseData, StepIndices
from .flows import FlowSourceError, load_flows
from .keypoints import AUTHORS_KEYPOINT_JOINTS, CONFIDENCE_MODES, confidence_weights, keypoints_for_layout
from .objective import Objective, Term
from .losses import (
    bone_length_loss,
    bone_lengths,
    bone_matrix,
    deviation_loss,
    flow_consistency_loss,
    flow_residual,
    keypoint_loss,
    smooth_l1_per_frame,
    temporal_loss,
    temporal_residual,
)
from .refiner import PoseLossWeights, PoseRefiner
from .refiner2d import KeypointLossWeights, KeypointRefiner
from .result import PoseResult, load_pose_result
from .stopping import LossPlateauStopping

__all__ = [
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
    "smooth_l1_per_frame",
    "flow_residual",
    "temporal_residual",
    "flow_consistency_loss",
    "deviation_loss",
    "keypoint_loss",
    "temporal_loss",
    "bone_matrix",
    "bone_lengths",
    "bone_length_loss",
]
