"""Pose estimation for any video: MediaPipe Pose (optional extra) -> :class:`PoseEstimates`.

``estimate_poses(frames_or_path)`` gives COCO-17 2D keypoints, LSP-14 3D joints (mm) and
weak-perspective cameras; ``lit-boot estimate-pose VIDEO --out poses.npz`` writes them.
MediaPipe is imported only when an estimate is made (``pip install "lit-boot[mediapipe]"``);
the conversions in :mod:`.world_to_lsp` and :mod:`.tracking` need no MediaPipe.

``PersonDetector(model="yolox_nano").detect_frames(frames)`` gives each frame's person boxes
(YOLOX through onnxruntime, which the same extra installs and which is imported only when a
detector is built; another detector plugs in wherever a detector is taken as a
:class:`PersonBoxDetector`, any object with that ``detect_frames``); ``main_person_boxes(detections)``
follows one person over the frames, and ``person_boxes(frames, "yolox_nano")`` does both
(``estimate_poses(..., detector=...)`` adds them to the estimates: the region the method zooms on).
``track_people(detections)`` follows every person (ids kept through crossings; with
``looks=detection_looks(frames, detections, keypoints)``, the colours near each pose's joints, a
person hidden for long is found again), and
``estimate_poses(..., people="all")`` gives each tracked person a pose, top-down (the main person
first, the others in ``PoseEstimates.others``).
``estimate_people(estimator, frames, detector, people)`` runs any top-down
:class:`PersonPoseEstimator` (``estimate_person(frames, boxes)``, ``keep_frames(estimates,
keep)``; MediaPipe's is :class:`MediaPipeCrops`) on every tracked person; where two people's
boxes overlap, a pose whose look is the other's counts for neither (``borrowed_frames``).
``estimate_poses(..., pose_model="rtmpose-m.onnx")`` puts a top-down SimCC model exported to ONNX
(RTMPose's; a local path) in MediaPipe's place on each person's crops (:class:`OnnxPoseCrops`, 2D only).
``read_tracked_estimates(path)`` reads every person of an external COCO keypoint or DCPose file,
linked into tracks by the file's track ids or by the same tracker. ``frames_to_check(people)``
marks, per person, the frames where its id may have switched (people overlapping, or found again);
``id_sheet(frames, people, layout)`` draws those frames with every person named, and
``fix_ids(people, ["swap 1 2 at 7-", ...])`` mends what a user saw there (``lit-boot ids``).
"""

from .detector import (
    ORT_INSTALL_HINT,
    PERSON_CLASS,
    OnnxRuntimeUnavailable,
    PersonBoxDetector,
    PersonDetector,
    decode_yolox,
    import_onnxruntime,
    letterbox,
    select_boxes,
    to_frame,
)
from .detector_weights import DETECTOR_MODELS, resolve_detector_weights
from .mediapipe_pose import (
    INSTALL_HINT,
    MEDIAPIPE_VERSION,
    MediaPipeUnavailable,
    NoPersonFound,
    estimate_pose_file,
    estimate_poses,
    import_mediapipe,
    mediapipe_available,
    poses_from_landmarks,
    require_person,
    run_mediapipe,
    summary_line,
)
from .borrowed_poses import borrowed_frames
from .id_checks import checks_line, frame_ranges, frames_to_check, scene_checks
from .id_fixes import FIX_GRAMMAR, IdFix, fix_ids, parse_fix
from .id_sheet import id_sheet, sheet_rows
from .keypoint_tracks import link_keypoint_people, read_tracked_estimates
from .looks import detection_looks, look_distance
from .people_pose import (
    MediaPipeCrops,
    PersonPoseEstimator,
    detection_keypoints,
    estimate_people,
    mask_frames,
    pose_in_box,
)
from .onnx_pose import OnnxPoseCrops, SimccPoseModel, estimate_onnx_people
from .pose_handover import continue_poses
from .people_track import PEOPLE_CHOICES, parse_people, select_people, track_people
from .person_track import main_person_boxes, person_boxes
from .tracking import JUMP_POLICIES, drop_jumps, find_jumps
from .world_to_lsp import (
    HEAD_TOP_FACTOR,
    fit_cameras,
    landmark_confidence,
    landmarks_to_coco17,
    nearest_found,
    square_crops,
    world_to_lsp14,
)

__all__ = [
    "link_keypoint_people",
    "PersonPoseEstimator",
    "MediaPipeCrops",
    "OnnxPoseCrops",
    "SimccPoseModel",
    "estimate_onnx_people",
    "mask_frames",
    "read_tracked_estimates",
    "INSTALL_HINT",
    "MEDIAPIPE_VERSION",
    "MediaPipeUnavailable",
    "NoPersonFound",
    "require_person",
    "estimate_pose_file",
    "estimate_poses",
    "import_mediapipe",
    "mediapipe_available",
    "poses_from_landmarks",
    "run_mediapipe",
    "summary_line",
    "ORT_INSTALL_HINT",
    "PERSON_CLASS",
    "OnnxRuntimeUnavailable",
    "PersonDetector",
    "PersonBoxDetector",
    "decode_yolox",
    "import_onnxruntime",
    "letterbox",
    "select_boxes",
    "to_frame",
    "DETECTOR_MODELS",
    "resolve_detector_weights",
    "main_person_boxes",
    "estimate_people",
    "detection_keypoints",
    "pose_in_box",
    "PEOPLE_CHOICES",
    "parse_people",
    "select_people",
    "track_people",
    "detection_looks",
    "look_distance",
    "borrowed_frames",
    "continue_poses",
    "frames_to_check",
    "frame_ranges",
    "checks_line",
    "scene_checks",
    "FIX_GRAMMAR",
    "IdFix",
    "fix_ids",
    "parse_fix",
    "id_sheet",
    "sheet_rows",
    "person_boxes",
    "JUMP_POLICIES",
    "drop_jumps",
    "find_jumps",
    "HEAD_TOP_FACTOR",
    "fit_cameras",
    "landmark_confidence",
    "landmarks_to_coco17",
    "nearest_found",
    "square_crops",
    "world_to_lsp14",
]
