"""Every person's pose, top-down: the person detector's tracks, MediaPipe Pose on each one's crops.

:func:`estimate_people` runs the detector on every frame, links the boxes into tracks
(:func:`~.people_track.track_people`), keeps the ones ``people`` asks for (all, the largest, or
the N most prominent) and runs MediaPipe Pose (static-image mode) on square crops around each
track's box in every frame it has one (:func:`~.crop_pose.crop_landmarks`, the framings of
:data:`~.crop_pose.CROP_ATTEMPTS` in turn). A crop may show a neighbour more clearly than the
track's person: a pose counts for the track only where the centre of its confident keypoints'
box lies inside the track's box (else the frame has confidence 0 for that person, counted in
``metadata["people"][i]["not_theirs"]``). A track on which no pose is found in any frame is left
out (``metadata["people_without_pose"]``). Person 0 (the main person) is the most prominent
track with a pose; track ids number the tracks by prominence.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import torch

from ..core.people import Person
from ..data.readers.pose_file import PoseEstimates
from .people_track import select_people, track_people
from .tracking import body_box

__all__ = ["estimate_people", "pose_in_box"]


def pose_in_box(keypoints: torch.Tensor, conf: torch.Tensor, boxes: torch.Tensor) -> torch.Tensor:
    """(T,) bool: frames whose confident keypoints (T, K, 2) px, conf (T, K), have their box's
    centre inside ``boxes`` (T, 5) (x0, y0, x1, y1, score > 0)."""
    inside = torch.zeros(keypoints.shape[0], dtype=torch.bool)
    for t in range(keypoints.shape[0]):
        if (conf[t] > 0).any() and boxes[t, 4] > 0:
            (cx, cy), _ = body_box(keypoints[t], conf[t])
            inside[t] = bool(boxes[t, 0] <= cx <= boxes[t, 2] and boxes[t, 1] <= cy <= boxes[t, 3])
    return inside


def _one_person(pose: Any, frames: torch.Tensor, boxes: torch.Tensor, assemble: Any) -> tuple[PoseEstimates, int]:
    """The estimates of the person in ``boxes`` (T, 5), and how many crops showed someone else."""
    from .crop_pose import crop_landmarks
    from .world_to_lsp import landmark_confidence

    raw = crop_landmarks(pose, frames, boxes, boxes[:, 4] > 0)
    conf = landmark_confidence(raw["visibility"], raw["presence"])
    est = assemble(raw["landmarks"], conf, raw["world"], raw["found"])
    others = est.found() & ~pose_in_box(est.keypoints2d, est.keypoints_conf, boxes)
    if not bool(others.any()):
        return est, 0
    return assemble(raw["landmarks"], conf, raw["world"], raw["found"] & ~others), int(others.sum())


def _nobody(assemble: Any, T: int) -> PoseEstimates:
    """Estimates of nobody in T frames (every confidence 0)."""
    return assemble(torch.zeros(T, 33, 2), torch.zeros(T, 33), torch.zeros(T, 33, 3), torch.zeros(T, dtype=torch.bool))


def estimate_people(pose: Any, frames: torch.Tensor, detector: Any, people: str | int, assemble: Any,
                    meta: dict[str, Any]) -> PoseEstimates:  # fmt: skip
    """Every tracked person's estimates in frames (T, 3, H, W) uint8 RGB (module docstring).

    ``pose``: a static-image-mode MediaPipe Pose; ``detector``: a
    :class:`~.detector.PersonDetector`; ``assemble(landmarks, confidence, world, found)``: the
    estimates of one person from MediaPipe-33 arrays (:func:`~.mediapipe_pose.poses_from_landmarks`
    with the run's options); ``meta``: the run's own metadata, merged into the main person's.
    Returns the main person's estimates with the others in ``others``; with no pose found, the
    confidences are 0 everywhere (and the most prominent track's boxes are kept, if any)."""
    tracks = select_people(track_people(detector.detect_frames(frames)), people)
    estimates, records = [], []
    for track_id, boxes in enumerate(tracks):
        est, not_theirs = _one_person(pose, frames, boxes, assemble)
        estimates.append(replace(est, person_boxes=boxes, track_id=track_id))
        records.append({"track_id": track_id, "box_frames": int((boxes[:, 4] > 0).sum()),
                        "pose_frames": int(est.found().sum()), "not_theirs": not_theirs})  # fmt: skip
    with_pose = [est for est in estimates if bool(est.found().any())]
    meta = {**meta, "people": records, "people_asked": people, "tracks": len(tracks),
            "people_without_pose": [r["track_id"] for r in records if not r["pose_frames"]]}  # fmt: skip
    if not with_pose:
        nobody = _nobody(assemble, frames.shape[0])
        return replace(nobody, person_boxes=tracks[0] if len(tracks) else None, metadata={**nobody.metadata, **meta})
    main = with_pose[0]
    return replace(main, metadata={**main.metadata, **meta}, others=tuple(Person.of(est) for est in with_pose[1:]))
