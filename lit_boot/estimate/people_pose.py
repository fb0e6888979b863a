"""Every person's pose, top-down: the person detector's tracks, MediaPipe Pose on each one's crops.

:func:`estimate_people` runs the detector on every frame, MediaPipe Pose (static-image mode) on
square crops around each detection (:func:`~.crop_pose.crop_landmarks`, the framings of
:data:`~.crop_pose.CROP_ATTEMPTS` in turn; :func:`detection_keypoints`), links the boxes into
tracks by their overlap and their keypoints (:func:`~.people_track.track_people`: who is who
where two boxes overlap; a person hidden for longer than a gap is found again by its look, the
colours near its joints, :mod:`.looks`), keeps the ones ``people`` asks for (all, the largest, or the N most
prominent) and gives each track the poses of its boxes (the estimator's ``estimate_track``:
:class:`MediaPipeCrops` follows the person in video mode on a crop that follows its boxes, and
where its pose lies outside the box the static crops, each run once; the crops of the frames a
track bridges are run then). A crop may show a neighbour more clearly
than the detection's person: a pose counts for it only where the centre of its confident
keypoints' box (those inside the frame) lies inside the box (else the frame has confidence 0 for
that person, counted in ``metadata["people"][i]["not_theirs"]``). One pose, one person
(:mod:`.pose_duplicates`): before tracking, a detection whose crop gives the same pose as another
detection's in that frame, with a box that fits the pose worse (a box around two overlapping
people beside a box of one of them), is dropped (counted in ``metadata["duplicate_detections"]``),
and so is a detection without a pose whose box overlaps one with a pose (:mod:`.poseless_boxes`: a
person half hidden behind, or a second box; ``metadata["poseless_beside_posed"]``); after, where
two tracks' boxes overlap, a pose that looks like the other's (:mod:`.borrowed_poses`: the colours
near its joints) counts for neither (``metadata["people"][i]["borrowed"]``), and then a
pose two tracks' crops both give counts for the track whose box there is a detection
rather than the tracker's guess across a gap (:func:`bridged_frames`), else for the one whose box
fits it best (the other's frames counted in ``metadata["people"][i]["duplicates"]``). Where one track's poses end and
another's begin just after, continuing them, the two trade their frames from there on (:mod:`.pose_handover`: one
person's poses stay on one track; ``metadata["pose_handovers"]`` says what was traded). A track on which no pose is
found in any frame is left out (``metadata["people_without_pose"]``). The frames where a person's id may have switched
(:func:`~.id_checks.frames_to_check`) are listed in ``metadata["people"][i]["check_ids"]`` (video frame numbers).
Person 0 (the main person) is the most prominent track with a pose; track ids number the tracks by prominence.
Another estimator plugs in through :class:`PersonPoseEstimator` (two methods); MediaPipe is :class:`MediaPipeCrops`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Protocol

import torch

from ..core.cameras import inside_image
from ..core.people import Person
from ..data.readers.pose_file import PoseEstimates
from .borrowed_poses import borrowed_frames
from .id_checks import frames_to_check
from .looks import detection_looks
from .people_track import select_people, track_people
from .person_track import frame_detections
from .pose_duplicates import duplicate_detections, duplicate_frames
from .pose_handover import continue_poses
from .poseless_boxes import poseless_beside_posed
from .tracking import body_box

__all__ = ["estimate_people", "detection_keypoints", "pose_in_box", "PersonPoseEstimator", "MediaPipeCrops",
           "mask_frames", "bridged_frames"]


def pose_in_box(keypoints: torch.Tensor, conf: torch.Tensor, boxes: torch.Tensor,
                size: tuple[int, int] | None = None) -> torch.Tensor:  # fmt: skip
    """(T,) bool: frames whose confident keypoints (T, K, 2) px, conf (T, K), have their box's
    centre inside ``boxes`` (T, 5) (x0, y0, x1, y1, score > 0). With the frames' ``size`` (H, W),
    only the keypoints inside the frame count: a person cut off by the frame's edge has limbs
    guessed beyond it, which would move the centre out of their own box."""
    inside = torch.zeros(keypoints.shape[0], dtype=torch.bool)
    if size is not None:
        conf = conf * inside_image(keypoints, *size).to(conf)
    for t in range(keypoints.shape[0]):
        if (conf[t] > 0).any() and boxes[t, 4] > 0:
            (cx, cy), _ = body_box(keypoints[t], conf[t])
            inside[t] = bool(boxes[t, 0] <= cx <= boxes[t, 2] and boxes[t, 1] <= cy <= boxes[t, 3])
    return inside


class PersonPoseEstimator(Protocol):
    """What :func:`estimate_people` needs of a pose estimator (the protocol another top-down
    estimator implements to plug in; :class:`MediaPipeCrops` is the built-in one).

    ``estimate_person(frames, boxes)``: one person's PoseEstimates over frames (T, 3, H, W) uint8
    RGB from their boxes (T, 5) (x0, y0, x1, y1 px, score; 0 = no box: confidence 0 there), in the
    frames' pixels; the boxes may be different people's (each detection's pose is asked for this
    way too). ``keep_frames(estimates, keep)``: the same person's estimates counting only
    the frames ``keep`` (T,) bool (the others are another person's pose); :func:`mask_frames` does
    it for estimators with nothing to refit. Optional, ``estimate_track(frames, boxes)``: the same
    for boxes that are one tracked person's, frame to frame (an estimator that follows a person
    over time uses it; without it, ``estimate_person`` is asked).
    """

    def estimate_person(self, frames: torch.Tensor, boxes: torch.Tensor) -> PoseEstimates: ...

    def keep_frames(self, estimates: PoseEstimates, keep: torch.Tensor) -> PoseEstimates: ...


def mask_frames(estimates: PoseEstimates, keep: torch.Tensor) -> PoseEstimates:
    """``estimates`` with confidence 0 outside the frames ``keep`` (T,) bool."""
    conf = estimates.keypoints_conf * keep[:, None].to(estimates.keypoints_conf)
    return replace(estimates, keypoints_conf=conf)


class MediaPipeCrops:
    """The built-in :class:`PersonPoseEstimator`: MediaPipe Pose (static-image mode, ``pose``) on
    square crops around each box (:func:`~.crop_pose.crop_landmarks`); each track's poses, with
    ``video_pose`` (a function making a video-mode Pose), from MediaPipe following the person on a
    crop that follows its boxes (:meth:`estimate_track`), the estimates made by
    ``assemble(landmarks, confidence, world, found)`` from MediaPipe-33 arrays
    (:func:`~.mediapipe_pose.poses_from_landmarks` with the run's options); ``keep_frames`` makes
    them again from the same landmarks (the 3D fill-in and the cameras then ignore the dropped
    frames), for any estimates it made of the same frames, its own ``keep_frames``' too.
    MediaPipe runs once per crop: a box already seen in that frame (of the same frames) reuses
    its landmarks."""

    def __init__(self, pose: Any, assemble: Any, video_pose: Any = None):
        self.pose, self.assemble, self.video_pose = pose, assemble, video_pose
        # every estimates made of the current frames, with the landmarks, confidences and found frames behind it
        self._made: list[tuple[PoseEstimates, dict[str, torch.Tensor], torch.Tensor, torch.Tensor]] = []
        self._frames: torch.Tensor | None = None
        self._seen: dict[tuple[int, tuple[float, ...]], dict[str, torch.Tensor]] = {}

    def _crops(self, frames: torch.Tensor, boxes: torch.Tensor) -> dict[str, torch.Tensor]:
        """:func:`~.crop_pose.crop_landmarks` on the boxes (T, 5), each (frame, box) run once."""
        from .crop_pose import crop_landmarks

        if frames is not self._frames:
            self._frames, self._seen, self._made = frames, {}, []
        keys = [(t, tuple(boxes[t, :4].tolist())) for t in range(boxes.shape[0])]
        todo = boxes[:, 4] > 0
        new = todo & torch.tensor([k not in self._seen for k in keys], dtype=torch.bool)
        raw = crop_landmarks(self.pose, frames, boxes, new)
        for t in torch.nonzero(todo).flatten().tolist():
            if new[t]:
                self._seen[keys[t]] = {name: value[t].clone() for name, value in raw.items()}
            else:
                for name, value in self._seen[keys[t]].items():
                    raw[name][t] = value
        return raw

    def estimate_person(self, frames: torch.Tensor, boxes: torch.Tensor) -> PoseEstimates:
        from .world_to_lsp import landmark_confidence

        if not bool((boxes[:, 4] > 0).any()):  # nobody: no crop to run MediaPipe on
            T = frames.shape[0]
            return self.assemble(torch.zeros(T, 33, 2), torch.zeros(T, 33), torch.zeros(T, 33, 3),
                                 torch.zeros(T, dtype=torch.bool))  # fmt: skip
        raw = self._crops(frames, boxes)
        conf = landmark_confidence(raw["visibility"], raw["presence"])
        est = self.assemble(raw["landmarks"], conf, raw["world"], raw["found"])
        self._made.append((est, raw, conf, raw["found"]))
        return est

    def estimate_track(self, frames: torch.Tensor, boxes: torch.Tensor) -> PoseEstimates:
        """One tracked person's estimates: with ``video_pose`` (a function making a video-mode
        ``mp.solutions.pose.Pose``), MediaPipe follows the person on a crop that follows its boxes
        (:func:`~.crop_pose.follow_landmarks`), and where its pose lies outside the box
        (:func:`pose_in_box`: it followed someone else) the static crops are used
        (:meth:`estimate_person`'s, their framings in turn); without, as :meth:`estimate_person`."""
        from .crop_pose import follow_landmarks
        from .world_to_lsp import landmark_confidence

        if self.video_pose is None or not bool((boxes[:, 4] > 0).any()):
            return self.estimate_person(frames, boxes)
        followed, cropped = follow_landmarks(self.video_pose, frames, boxes), self._crops(frames, boxes)
        video = self.assemble(followed["landmarks"], landmark_confidence(followed["visibility"], followed["presence"]),
                              followed["world"], followed["found"])  # fmt: skip
        # where video mode followed someone out of the box: the static crops' framings in turn
        away = video.found() & ~pose_in_box(video.keypoints2d, video.keypoints_conf, boxes, tuple(frames.shape[2:]))
        raw = {k: torch.where(away.view(-1, *[1] * (v.ndim - 1)), cropped[k], v) for k, v in followed.items()}
        conf = landmark_confidence(raw["visibility"], raw["presence"])
        est = self.assemble(raw["landmarks"], conf, raw["world"], raw["found"])
        self._made.append((est, raw, conf, raw["found"]))
        return est

    def keep_frames(self, estimates: PoseEstimates, keep: torch.Tensor) -> PoseEstimates:
        made = next((m for m in self._made if m[0] is estimates), None)
        if made is None:  # not made here: nothing to refit
            return mask_frames(estimates, keep)
        _, raw, conf, found = made
        est = self.assemble(raw["landmarks"], conf, raw["world"], found & keep)
        self._made.append((est, raw, conf, found & keep))
        return est


def bridged_frames(boxes: torch.Tensor, detections: list[torch.Tensor]) -> torch.Tensor:
    """(T,) bool: the frames where a track's box (``boxes`` (T, 5), score 0: absent) is none of
    that frame's ``detections`` (N_t, 5): the tracker's guess across a gap."""
    return torch.tensor([bool(box[4] > 0) and not bool((dets == box).all(-1).any())
                         for box, dets in zip(boxes, detections)], dtype=torch.bool)  # fmt: skip


def _one_person(estimator: PersonPoseEstimator, frames: torch.Tensor, boxes: torch.Tensor) -> tuple[PoseEstimates, int]:
    """The estimates of the person in ``boxes`` (T, 5) (the estimator's ``estimate_track`` where it
    has one), and how many crops showed someone else."""
    est = getattr(estimator, "estimate_track", estimator.estimate_person)(frames, boxes)
    others = est.found() & ~pose_in_box(est.keypoints2d, est.keypoints_conf, boxes, tuple(frames.shape[2:]))
    if not bool(others.any()):
        return est, 0
    return estimator.keep_frames(est, ~others), int(others.sum())


def detection_keypoints(estimator: PersonPoseEstimator, frames: torch.Tensor,
                        detections: list[torch.Tensor]) -> list[torch.Tensor]:  # fmt: skip
    """Each detection's pose: per frame (N_t, K, 3) x, y px, confidence (0 where no pose was
    found, or where the crop's pose is a neighbour's: :func:`pose_in_box`), from ``estimator``
    on frames (T, 3, H, W) and the per-frame detections (N_t, 5); one estimator call per
    detection slot (the i-th detection of every frame)."""
    T, size = frames.shape[0], tuple(frames.shape[2:])
    rows: list[list[torch.Tensor]] = [[] for _ in range(T)]
    for i in range(max((d.shape[0] for d in detections), default=0)):
        boxes = torch.stack([d[i] if d.shape[0] > i else torch.zeros(5) for d in detections])
        est = estimator.estimate_person(frames, boxes)
        conf = est.keypoints_conf * pose_in_box(est.keypoints2d, est.keypoints_conf, boxes, size)[:, None]
        poses = torch.cat([est.keypoints2d, conf[..., None]], -1)
        for t in range(T):
            if detections[t].shape[0] > i:
                rows[t].append(poses[t])
    K = next((r[0].shape[0] for r in rows if r), 0)
    return [torch.stack(r) if r else torch.zeros(0, K, 3) for r in rows]


def _without(detections: list[torch.Tensor], keypoints: list[torch.Tensor],
             drop: list[torch.Tensor]) -> tuple[list[torch.Tensor], list[torch.Tensor]]:  # fmt: skip
    """The per-frame detections (N_t, 5) and their keypoints (N_t, K, 3) without those ``drop`` marks."""
    return [d[~x] for d, x in zip(detections, drop)], [k[~x] for k, x in zip(keypoints, drop)]


def estimate_people(estimator: PersonPoseEstimator, frames: torch.Tensor, detector: Any, people: str | int,
                    meta: dict[str, Any] | None = None) -> PoseEstimates:  # fmt: skip
    """Every tracked person's estimates in frames (T, 3, H, W) uint8 RGB (module docstring).

    ``estimator``: a :class:`PersonPoseEstimator` (e.g. :class:`MediaPipeCrops`); ``detector``:
    a :class:`~.detector.PersonBoxDetector` (``detect_frames(frames)`` -> per-frame boxes (N_t, 5),
    as :class:`~.detector.PersonDetector`; checked, :func:`~.person_track.frame_detections`);
    ``meta``: the run's own metadata, merged into the main person's. Returns the main person's
    estimates with the others in ``others``; with no pose found, the confidences are 0 everywhere
    (and the most prominent track's boxes are kept, if any)."""
    detections = frame_detections(detector, frames)
    keypoints = detection_keypoints(estimator, frames, detections)
    doubled = duplicate_detections(detections, keypoints)  # a box around two people beside one of theirs
    detections, keypoints = _without(detections, keypoints, doubled)
    poseless = poseless_beside_posed(detections, keypoints)  # a hidden person's or a second box, no pose
    detections, keypoints = _without(detections, keypoints, poseless)
    looks = detection_looks(frames, detections, keypoints)
    tracks = select_people(track_people(detections, keypoints=keypoints, looks=looks), people)
    found = [_one_person(estimator, frames, boxes) for boxes in tracks]
    track_kp, track_conf = [est.keypoints2d for est, _ in found], [est.keypoints_conf for est, _ in found]
    borrowed = borrowed_frames(frames, track_kp, track_conf, list(tracks))  # a neighbour's pose in one's crop
    track_conf = [c * ~lent[:, None] for c, lent in zip(track_conf, borrowed)]
    bridged = [bridged_frames(boxes, detections) for boxes in tracks]
    duplicates = duplicate_frames(track_kp, track_conf, list(tracks), bridged)
    estimates, records = [], []
    for track_id, (boxes, (est, not_theirs), twice, lent) in enumerate(zip(tracks, found, duplicates, borrowed)):
        est = estimator.keep_frames(est, ~(twice | lent)) if bool((twice | lent).any()) else est
        estimates.append(replace(est, person_boxes=boxes, track_id=track_id))
        records.append({"track_id": track_id, "box_frames": int((boxes[:, 4] > 0).sum()),
                        "pose_frames": int(est.found().sum()), "not_theirs": not_theirs,
                        "duplicates": int(twice.sum()), "borrowed": int(lent.sum())})  # fmt: skip
    with_pose = [est for est in estimates if bool(est.found().any())]
    found, handed = _handed_over(with_pose, records)
    meta = {**(meta or {}), "people": records, "people_asked": people, "tracks": len(tracks),
            "duplicate_detections": int(sum(int(d.sum()) for d in doubled)),
            "poseless_beside_posed": int(sum(int(d.sum()) for d in poseless)), "pose_handovers": handed,
            "people_without_pose": [r["track_id"] for r in records if not r["pose_frames"]]}  # fmt: skip
    if not with_pose:
        nobody = estimator.estimate_person(frames, torch.zeros(frames.shape[0], 5))
        return replace(nobody, person_boxes=tracks[0] if len(tracks) else None, metadata={**nobody.metadata, **meta})
    return with_pose[0].with_people(found, metadata={**with_pose[0].metadata, **meta})


def _handed_over(with_pose: list[PoseEstimates], records: list[dict]) -> tuple[list[Person], list[str]]:
    """The tracks with a pose (``with_pose``, in prominence order) as people, each person's poses
    handed from one track to the next joined (:func:`~.pose_handover.continue_poses`) and those left
    without a pose dropped; ``records`` (one per track, by track id) updated in place with each one's
    pose frames and frames to check. Returns the people and what the hand-overs did."""
    if not with_pose:
        return [], []
    numbers = with_pose[0].frame_indices.tolist()
    found, handed = continue_poses([Person.of(est) for est in with_pose], numbers)
    found = [p for p in found if bool((p.keypoints_conf > 0).any())]
    for record in records:
        record["pose_frames"] = 0
    for person, check in zip(found, frames_to_check(found)):
        records[person.track_id]["pose_frames"] = int((person.keypoints_conf > 0).any(-1).sum())
        records[person.track_id]["check_ids"] = [numbers[t] for t in check.nonzero().flatten().tolist()]
    return found, handed
