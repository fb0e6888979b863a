"""Readers of public datasets (MPI-Sintel, 3DPW, Human3.6M) into :class:`~lit_boot.core.scene.Scene`."""

from ._common import DatasetFormatError
from .h36m import (
    H36M_CAMERA_IDS,
    H36M_CAMERAS,
    H36M_EVAL_CAMERA,
    H36M_EVAL_STRIDE,
    H36M_EVAL_SUBJECTS,
    H36M_FPS,
    H36M_KEEP_JOINTS,
    H36MCamera,
    list_h36m_actions,
    read_h36m,
)
from .pw3d import OPENPOSE18_TO_COCO17, PW3D_FPS, PW3D_SPLITS, list_3dpw_sequences, load_3dpw_pickle, read_3dpw
from .sintel import SINTEL_FPS, SINTEL_HUMAN_PASS, SINTEL_HUMAN_SCENES, SINTEL_PASSES, list_sintel_scenes, read_sintel

__all__ = [
    "DatasetFormatError",
    "H36M_CAMERA_IDS",
    "H36M_CAMERAS",
    "H36M_EVAL_CAMERA",
    "H36M_EVAL_STRIDE",
    "H36M_EVAL_SUBJECTS",
    "H36M_FPS",
    "H36M_KEEP_JOINTS",
    "H36MCamera",
    "list_h36m_actions",
    "read_h36m",
    "OPENPOSE18_TO_COCO17",
    "PW3D_FPS",
    "PW3D_SPLITS",
    "list_3dpw_sequences",
    "load_3dpw_pickle",
    "read_3dpw",
    "SINTEL_FPS",
    "SINTEL_HUMAN_PASS",
    "SINTEL_HUMAN_SCENES",
    "SINTEL_PASSES",
    "list_sintel_scenes",
    "read_sintel",
]

# Pose estimates (lit-boot pose files, METRO, DCPose, COCO) and any video.
from .estimates import ESTIMATE_KINDS, read_coco_keypoints, read_dcpose, read_estimates, read_metro  # noqa: E402
from .pose_file import POSES_FORMAT, POSES_FORMAT_VERSION, PoseEstimates, load_poses, save_poses  # noqa: E402
from .video import read_video  # noqa: E402

__all__ += [
    "ESTIMATE_KINDS",
    "read_coco_keypoints",
    "read_dcpose",
    "read_estimates",
    "read_metro",
    "POSES_FORMAT",
    "POSES_FORMAT_VERSION",
    "PoseEstimates",
    "load_poses",
    "save_poses",
    "read_video",
]
