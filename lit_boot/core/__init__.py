"""The core: scene data model, joint layouts and bones, camera projections.

Imports nothing else from lit_boot; everything else builds on it.
"""

from .cameras import (
    CAMERA_MODELS,
    Cameras,
    fit_weak_perspective,
    inside_image,
    project_pinhole,
    project_weak_perspective,
)
from .joints import COCO17, H36M17, LAYOUTS, LSP14, MEDIAPIPE33, JointLayout, get_layout, map_joints, mapping_matrix
from .people import Person
from .scene import POSE_MODES, GroundTruth, PersonTruth, Scene, SceneValidationError

__all__ = [
    "CAMERA_MODELS",
    "Cameras",
    "inside_image",
    "fit_weak_perspective",
    "project_pinhole",
    "project_weak_perspective",
    "COCO17",
    "H36M17",
    "LAYOUTS",
    "LSP14",
    "MEDIAPIPE33",
    "JointLayout",
    "get_layout",
    "map_joints",
    "mapping_matrix",
    "GroundTruth",
    "Person",
    "PersonTruth",
    "POSE_MODES",
    "Scene",
    "SceneValidationError",
]
