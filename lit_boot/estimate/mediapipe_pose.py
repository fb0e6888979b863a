"""2D keypoints, 3D joints and weak-perspective cameras for any video, from MediaPipe Pose.

MediaPipe is an optional extra (``pip install "lit-boot[mediapipe]"``, pinned to
mediapipe==0.10.14, whose full pose model ships inside the package so it runs offline); it is
imported only when an estimate is made. Output conventions (see :mod:`.world_to_lsp`):

- keypoints2d (T, 17, 2) px, COCO-17, pixel centres at integer coordinates; keypoints_conf
  (T, 17) = the landmark's visibility (times its presence when reported);
- joints3d (T, 14, 3) mm, LSP-14, hip-centred, camera axes (x right, y down, z forward), from
  MediaPipe's world landmarks, the head top extrapolated (``HEAD_TOP_FACTOR``);
- cameras: METRO/HMR weak perspective on a 224 px square crop around the keypoints, fitted
  per frame to the confidence-weighted keypoints.

Frames where nobody is found are kept, with keypoints 0 and confidence 0, and listed in
``metadata["missing_frames"]``; their 3D joints and cameras are copied from the nearest frame
with a person (``metadata["filled_from"]``) so downstream optimisation stays finite. A
detection whose box centre moves more than ``max_jump`` box sizes per frame is listed in
``metadata["jumps"]`` and kept (``on_jump="keep"``) or treated as nobody (``"drop"``). A video in
which nobody is found in any frame has no pose to bootstrap: :func:`estimate_pose_file` (and the
command line) refuse it with :class:`NoPersonFound`, writing nothing.
"""

from __future__ import annotations

import os
import time
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..core.joints import COCO17
from ..core.scene import Scene
from ..data.readers.pose_file import PoseEstimates, save_poses
from .id_checks import checks_line
from .tracking import JUMP_POLICIES, drop_jumps, find_jumps
from .world_to_lsp import HEAD_TOP_FACTOR, fit_cameras, landmark_confidence, landmarks_to_coco17, nearest_found
from .world_to_lsp import world_to_lsp14

__all__ = [
    "MEDIAPIPE_VERSION",
    "INSTALL_HINT",
    "MediaPipeUnavailable",
    "import_mediapipe",
    "mediapipe_available",
    "run_mediapipe",
    "poses_from_landmarks",
    "estimate_poses",
    "estimate_pose_file",
    "summary_line",
    "NoPersonFound",
    "require_person",
]

#: The MediaPipe version lit-boot's extra pins (its legacy ``mp.solutions.pose`` API).
MEDIAPIPE_VERSION = "0.10.14"
INSTALL_HINT = f'pip install "lit-boot[mediapipe]"  (installs mediapipe=={MEDIAPIPE_VERSION})'
_MODEL_FILES = {0: "pose_landmark_lite.tflite", 1: "pose_landmark_full.tflite", 2: "pose_landmark_heavy.tflite"}


class MediaPipeUnavailable(ImportError):
    """MediaPipe (or the pose model asked for) is not available; the message says what to do."""


def import_mediapipe() -> Any:
    """Import and return the ``mediapipe`` module, or raise :class:`MediaPipeUnavailable`."""
    try:
        import mediapipe as mp
    except ImportError as err:
        raise MediaPipeUnavailable(
            f"MediaPipe Pose needs the mediapipe extra ({err}); install it with: {INSTALL_HINT}"
        ) from err
    if not hasattr(getattr(mp, "solutions", None), "pose"):
        raise MediaPipeUnavailable(
            f"mediapipe {getattr(mp, '__version__', '?')} has no mp.solutions.pose; lit-boot needs "
            f"mediapipe=={MEDIAPIPE_VERSION}: {INSTALL_HINT}"
        )
    return mp


def mediapipe_available() -> bool:
    """True when :func:`import_mediapipe` succeeds."""
    try:
        import_mediapipe()
    except ImportError:
        return False
    return True


def _pose_solution(mp: Any, model_complexity: int, min_detection_confidence: float, min_tracking_confidence: float,
                   static_image_mode: bool = False):  # fmt: skip
    if model_complexity not in _MODEL_FILES:
        raise ValueError(f"model_complexity: expected 0, 1 or 2, got {model_complexity!r}")
    for name, value in (("min_detection_confidence", min_detection_confidence),
                        ("min_tracking_confidence", min_tracking_confidence)):  # fmt: skip
        if not 0.0 <= value <= 1.0:
            raise ValueError(f"{name}: expected a value in [0, 1], got {value!r}")
    model = Path(mp.__file__).parent / "modules" / "pose_landmark" / _MODEL_FILES[model_complexity]
    try:
        return mp.solutions.pose.Pose(static_image_mode=static_image_mode, model_complexity=model_complexity,
                                      min_detection_confidence=min_detection_confidence,
                                      min_tracking_confidence=min_tracking_confidence)  # fmt: skip
    except OSError as err:  # 0 and 2 are downloaded on first use; only 1 ships with mediapipe
        raise MediaPipeUnavailable(
            f"model_complexity={model_complexity}: mediapipe could not download {model.name} into {model.parent} "
            f"({err}); connect once to fetch it, or use model_complexity=1 (shipped with mediapipe)"
        ) from err


def run_mediapipe(
    frames: torch.Tensor,
    model_complexity: int = 1,
    min_detection_confidence: float = 0.5,
    min_tracking_confidence: float = 0.5,
) -> dict[str, torch.Tensor]:
    """Run MediaPipe Pose (tracking mode) over frames (T, 3, H, W) uint8 RGB, in order.

    Returns float32 tensors: landmarks (T, 33, 2) px, visibility (T, 33), presence (T, 33)
    (ones when not reported), world (T, 33, 3) metres, found (T,) bool, and seconds (T,)
    per frame. Rows of frames with nobody are zeros.
    """
    mp = import_mediapipe()
    T, _, H, W = frames.shape
    out = {"landmarks": torch.zeros(T, 33, 2), "visibility": torch.zeros(T, 33), "presence": torch.zeros(T, 33),
           "world": torch.zeros(T, 33, 3), "found": torch.zeros(T, dtype=torch.bool),
           "seconds": torch.zeros(T)}  # fmt: skip
    with _pose_solution(mp, model_complexity, min_detection_confidence, min_tracking_confidence) as pose:
        for t in range(T):
            image = np.ascontiguousarray(frames[t].permute(1, 2, 0).numpy())
            start = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # protobuf deprecation noise
                result = pose.process(image)
            out["seconds"][t] = time.perf_counter() - start
            if result.pose_landmarks is None or result.pose_world_landmarks is None:
                continue
            lms = result.pose_landmarks.landmark
            out["landmarks"][t] = torch.tensor([[lm.x * W - 0.5, lm.y * H - 0.5] for lm in lms])
            out["visibility"][t] = torch.tensor([lm.visibility for lm in lms])
            out["presence"][t] = torch.tensor([lm.presence if lm.HasField("presence") else 1.0 for lm in lms])
            out["world"][t] = torch.tensor([[lm.x, lm.y, lm.z] for lm in result.pose_world_landmarks.landmark])
            out["found"][t] = True
    return out


#: COCO-17 shoulders and hips: the torso that anchors a detection in the picture.
TORSO = tuple(COCO17.names.index(n) for n in ("left_shoulder", "right_shoulder", "left_hip", "right_hip"))


def _drop_far_outside(keypoints: torch.Tensor, conf: torch.Tensor, image_size: tuple[int, int]) -> tuple[torch.Tensor, int]:
    """Confidence 0 for COCO-17 keypoints (T, 17, 2) px more than one image size outside the frame:
    MediaPipe extrapolates body parts that are out of the picture (a cut-off leg's ankle),
    sometimes with a visibility above 0. A frame whose torso (a shoulder or a hip) lies that far
    out holds no person in the picture: all its confidences become 0. Returns the new
    confidences and how many keypoints were dropped."""
    H, W = image_size
    x, y = keypoints[..., 0], keypoints[..., 1]
    far = ((x < -W) | (x > 2 * W) | (y < -H) | (y > 2 * H)) & (conf > 0)
    far = far | (far[:, list(TORSO)].any(-1, keepdim=True) & (conf > 0))
    return torch.where(far, torch.zeros_like(conf), conf), int(far.sum())


def poses_from_landmarks(
    landmarks: torch.Tensor,
    confidence: torch.Tensor,
    world: torch.Tensor,
    found: torch.Tensor,
    image_size: tuple[int, int],
    frame_indices: torch.Tensor | None = None,
    *,
    max_jump: float = 0.5,
    on_jump: str = "keep",
    source: str = f"mediapipe-{MEDIAPIPE_VERSION}",
    metadata: dict[str, Any] | None = None,
) -> PoseEstimates:
    """Assemble :class:`PoseEstimates` from MediaPipe-33 output (no mediapipe needed).

    landmarks (T, 33, 2) px, confidence (T, 33) in [0, 1], world (T, 33, 3) metres, found (T,)
    bool, image_size (H, W), frame_indices (T,) (default 0..T-1). See the module docstring for
    missing frames and jumps.
    """
    if on_jump not in JUMP_POLICIES:
        raise ValueError(f"on_jump: expected one of {JUMP_POLICIES}, got {on_jump!r}")
    T = landmarks.shape[0]
    frame_indices = torch.arange(T, dtype=torch.int64) if frame_indices is None else frame_indices.long()
    found = found.bool() & (confidence > 0).any(-1)
    keypoints, conf = landmarks_to_coco17(landmarks.float(), confidence.float())
    conf, far = _drop_far_outside(keypoints, conf, image_size)
    found = found & (conf > 0).any(-1)  # a frame whose keypoints all lie far outside has nobody
    if on_jump == "drop":
        jumps, found = drop_jumps(keypoints, conf, found, max_jump)
    else:
        jumps = find_jumps(keypoints, conf, found, max_jump)
    keypoints = torch.where(found[:, None, None], keypoints, torch.zeros_like(keypoints))
    conf = torch.where(found[:, None], conf, torch.zeros_like(conf))
    joints3d, cameras, filled = torch.zeros(T, 14, 3), None, []
    if found.any():
        near = nearest_found(found)
        joints3d = world_to_lsp14(world.float())[near]
        cameras = fit_cameras(joints3d, keypoints[near], conf[near])
        filled = [[int(frame_indices[t]), int(frame_indices[near[t]])] for t in range(T) if not found[t]]
    meta = dict(metadata or {})
    meta.update({
        "missing_frames": [int(frame_indices[t]) for t in range(T) if not found[t]],
        "filled_from": filled,
        "jumps": [int(frame_indices[t]) for t in jumps],
        "far_outside_dropped": far,
        "on_jump": on_jump,
        "max_jump": max_jump,
        "keypoints_conf": "MediaPipe landmark visibility (x presence when reported); 0 = nobody found",
        "head_top_factor": HEAD_TOP_FACTOR,
    })  # fmt: skip
    return PoseEstimates(
        keypoints2d=keypoints.float(), keypoints_conf=conf.float(), keypoints_layout="coco17",
        joints3d=joints3d.float(), joints3d_layout="lsp14", cameras=cameras, frame_indices=frame_indices,
        image_size=(int(image_size[0]), int(image_size[1])), source=source, metadata=meta,
    )  # fmt: skip


def estimate_poses(
    video: torch.Tensor | Scene | str | os.PathLike,
    *,
    model_complexity: int = 1,
    min_detection_confidence: float = 0.5,
    min_tracking_confidence: float = 0.5,
    max_jump: float = 0.5,
    on_jump: str = "keep",
    stride: int = 1,
    max_frames: int | None = None,
    resize: Any = None,
    detector: Any = None,
    crops: bool = False,
    people: str | int | None = None,
    pose_model: str | os.PathLike | None = None,
) -> PoseEstimates:
    """MediaPipe Pose on every frame of ``video``: frames (T, 3, H, W) uint8 RGB, a Scene, or a
    video file / folder of frames (read with ``read_video(path, stride, max_frames, resize)``;
    ``stride``, ``max_frames`` and ``resize`` apply to paths only). Keypoints are in pixels of
    the frames MediaPipe saw (``image_size``). With a ``detector`` (a YOLOX model path or name,
    e.g. ``"yolox_nano"``, a :class:`~.detector.PersonDetector`, or any other
    :class:`~.detector.PersonBoxDetector`: an object with ``detect_frames``) the main person's box in
    every frame is found too (``person_boxes``; :func:`~.person_track.person_boxes`): the
    region the method spends resolution on, also where MediaPipe misses the person. There, with
    ``crops``, MediaPipe runs again on crops around the box, enlarged and upsampled
    (:mod:`.crop_pose`; ``metadata["crop_found"]`` counts the frames it found; off by default:
    on the Sintel samples most of the poses it adds lie on non-human figures). With ``people``
    ("all", "largest" or a number N) every tracked person gets a pose instead, top-down
    (:mod:`.people_pose`: the detector's tracks, default ``"yolox_nano"``, MediaPipe on each
    one's crops; the main person is the most prominent, the others in ``others``). Returns
    PoseEstimates with source ``mediapipe-<version>``; see the module docstring for conventions.
    With ``pose_model`` (the path of a SimCC pose model exported to ONNX, e.g. RTMPose's) that model
    takes MediaPipe's place on each tracked person's crops (:mod:`.onnx_pose`: 2D keypoints only,
    ``people`` "largest" where None; MediaPipe's own options do not apply)."""
    mp = import_mediapipe() if pose_model is None else None
    frame_indices = None
    if isinstance(video, (str, os.PathLike)):
        from ..data.readers.video import read_video

        video = read_video(video, stride=stride, max_frames=max_frames, resize=resize)
    if isinstance(video, Scene):
        frame_indices = _scene_frame_indices(video)
        video = video.frames
    if not (isinstance(video, torch.Tensor) and video.ndim == 4 and video.shape[1] == 3 and video.dtype == torch.uint8):
        got = getattr(video, "shape", type(video))
        raise ValueError(f"estimate_poses: expected frames (T, 3, H, W) uint8, a Scene or a path, got {got}")
    if pose_model is not None:
        from .onnx_pose import estimate_onnx_people

        return estimate_onnx_people(video, pose_model, people=people or "largest", detector=detector,
                                    frame_indices=frame_indices)  # fmt: skip
    if people is not None:
        return _people(mp, video, frame_indices, people, detector, model_complexity, min_detection_confidence,
                       max_jump, on_jump)  # fmt: skip
    raw = run_mediapipe(video, model_complexity, min_detection_confidence, min_tracking_confidence)
    meta = {"model_complexity": model_complexity, "min_detection_confidence": min_detection_confidence,
            "min_tracking_confidence": min_tracking_confidence, "mediapipe_version": mp.__version__,
            "seconds_per_frame": float(raw["seconds"].mean())}  # fmt: skip
    boxes = None
    if detector is not None:
        from .detector import as_detector, detector_name
        from .person_track import person_boxes

        detector = as_detector(detector)
        boxes = person_boxes(video, detector)
        meta.update({"detector": detector_name(detector), "detector_found": int((boxes[:, 4] > 0).sum())})
        if crops:
            raw = _with_crops(mp, raw, video, boxes, model_complexity, min_detection_confidence, meta)
    est = poses_from_landmarks(
        raw["landmarks"], landmark_confidence(raw["visibility"], raw["presence"]), raw["world"], raw["found"],
        tuple(video.shape[2:]), frame_indices, max_jump=max_jump, on_jump=on_jump,
        source=f"mediapipe-{mp.__version__}", metadata=meta,
    )  # fmt: skip
    return est if boxes is None else replace(est, person_boxes=boxes)


def _people(mp: Any, frames: torch.Tensor, frame_indices: torch.Tensor | None, people: str | int, detector: Any,
            model_complexity: int, min_detection_confidence: float, max_jump: float, on_jump: str) -> PoseEstimates:  # fmt: skip
    """Every tracked person's pose, top-down (:func:`~.people_pose.estimate_people`)."""
    from .detector import as_detector, detector_name
    from .people_pose import MediaPipeCrops, estimate_people
    from .people_track import parse_people

    people = parse_people(people)
    detector = as_detector(detector)
    source, size = f"mediapipe-{mp.__version__}", tuple(frames.shape[2:])

    def assemble(landmarks, confidence, world, found):
        return poses_from_landmarks(landmarks, confidence, world, found, size, frame_indices, max_jump=max_jump,
                                    on_jump=on_jump, source=source)  # fmt: skip

    def video_pose():
        return _pose_solution(mp, model_complexity, min_detection_confidence, 0.5, static_image_mode=False)

    meta = {"model_complexity": model_complexity, "min_detection_confidence": min_detection_confidence,
            "mediapipe_version": mp.__version__, "detector": detector_name(detector),
            "mode": "top-down: static crops per detection, video mode on a crop following each track"}
    with _pose_solution(mp, model_complexity, min_detection_confidence, 0.5, static_image_mode=True) as pose:
        return estimate_people(MediaPipeCrops(pose, assemble, video_pose), frames, detector, people, meta)


def _with_crops(mp: Any, raw: dict[str, torch.Tensor], frames: torch.Tensor, boxes: torch.Tensor,
                model_complexity: int, min_detection_confidence: float, meta: dict[str, Any]) -> dict[str, torch.Tensor]:  # fmt: skip
    """``raw`` (run_mediapipe's arrays) with the frames it missed filled from MediaPipe on the
    detector's crops (:func:`~.crop_pose.crop_landmarks`); ``meta`` records how many."""
    from .crop_pose import CROP_ATTEMPTS, crop_landmarks

    with _pose_solution(mp, model_complexity, min_detection_confidence, 0.5, static_image_mode=True) as pose:
        cropped = crop_landmarks(pose, frames, boxes, ~raw["found"])
    fill = cropped["found"]
    merged = {k: torch.where(fill.view(-1, *[1] * (v.ndim - 1)), cropped[k], v) for k, v in raw.items() if k != "seconds"}
    merged["seconds"] = raw["seconds"] + cropped["seconds"]
    meta.update({"crop_found": int(fill.sum()), "crop_frames": torch.nonzero(fill).flatten().tolist(),
                 "crop_attempts": [list(a) for a in CROP_ATTEMPTS]})  # fmt: skip
    return merged


def _scene_frame_indices(scene: Scene) -> torch.Tensor | None:
    """The video frame numbers a Scene's frames came from, when its reader recorded them."""
    value = scene.metadata.get("frame_indices")
    return None if value is None else torch.as_tensor(value, dtype=torch.int64)


class NoPersonFound(ValueError):
    """MediaPipe Pose found nobody in any frame: there is no pose to bootstrap."""


def require_person(est: PoseEstimates, what: str | os.PathLike) -> PoseEstimates:
    """``est`` if a person was found in at least one frame (by MediaPipe, or by the person
    detector); else :class:`NoPersonFound` naming ``what`` (the video or scene) and what to try."""
    boxes = est.person_boxes
    if not bool(est.found().any()) and (boxes is None or not bool((boxes[:, 4] > 0).any())):
        raise NoPersonFound(f"{what}: MediaPipe Pose found no person in any of the {est.num_frames} frames, so there "
                            "is no pose to bootstrap (a lower min_detection_confidence than 0.5 may find one; the "
                            "method needs one person visible in most frames)")  # fmt: skip
    return est


def summary_line(est: PoseEstimates) -> str:
    """One line: frames, frames with a person, mean keypoint confidence over those frames."""
    found = est.found()
    n, T = int(found.sum()), est.num_frames
    mean = float(est.keypoints_conf[found].mean()) if n else 0.0
    jumps = len(est.metadata.get("jumps", []))
    boxes = "" if est.person_boxes is None else f", the person detector's box in {int((est.person_boxes[:, 4] > 0).sum())}"
    if est.others:
        seen = ", ".join(str(int((p.keypoints_conf > 0).any(-1).sum())) for p in est.people())
        boxes += f"; {est.num_people} people (frames with a pose each: {seen})"
    where = checks_line([(r["track_id"], r.get("check_ids", [])) for r in est.metadata.get("people", [])])
    where = f"; {where}" if where else ""
    return (f"{T} frames, {n} with a person ({T - n} without){boxes}, mean keypoint confidence {mean:.2f} "
            f"where found, {jumps} tracking jumps; {est.source}{where}")  # fmt: skip


def estimate_pose_file(
    video: str | os.PathLike, out: str | os.PathLike, *, overwrite: bool = False, **options: Any
) -> tuple[PoseEstimates, str]:
    """Estimate poses for ``video`` (file or folder of frames) and write them atomically to
    ``out`` (.npz or .json, :func:`save_poses`); ``options`` go to :func:`estimate_poses`.
    Refuses (FileExistsError) to replace ``out`` unless ``overwrite``, and (:class:`NoPersonFound`,
    nothing written) a video in which nobody is found. Returns (estimates, :func:`summary_line`)."""
    out, video = Path(out), Path(video)
    if out.suffix.lower() not in (".npz", ".json"):
        raise ValueError(f"--out {out}: expected a .npz or .json file name")
    if out.exists() and not overwrite:
        raise FileExistsError(f"--out {out}: exists (pass --overwrite to replace it)")
    if not video.exists():
        raise FileNotFoundError(f"{video}: no such video file or folder of frames")
    if options.get("pose_model") is None:
        import_mediapipe()  # fail before decoding the video
    est = require_person(estimate_poses(video, **options), video)
    save_poses(est, out)
    return est, summary_line(est)
