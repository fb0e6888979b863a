"""Every person's pose, top-down (lit_boot.estimate.people_pose): a stand-in detector and a
stand-in MediaPipe on frames with known people, and, with the real models, the street clip."""

from __future__ import annotations

from functools import partial
from types import SimpleNamespace

import pytest
import torch

from lit_boot.estimate.mediapipe_pose import poses_from_landmarks
from lit_boot.estimate.people_pose import MediaPipeCrops, detection_keypoints, estimate_people, mask_frames, pose_in_box
from test_estimate_mediapipe import _world, needs_mediapipe

H, W = 120, 200


class StandingAtTheBrightest:
    """MediaPipe's stand-in: a standing person whose hips are at the crop's brightest pixel
    (normalised image coordinates and metres, as MediaPipe gives them); nobody in a dark crop."""

    def __init__(self) -> None:
        self.world = _world(1)[0]

    def process(self, image):
        gray = torch.from_numpy(image).float().sum(-1)
        if gray.max() < 100:
            return SimpleNamespace(pose_landmarks=None, pose_world_landmarks=None)
        y, x = divmod(int(gray.argmax()), gray.shape[1])
        h, w = gray.shape
        image_lms = [SimpleNamespace(x=(x + 0.5) / w + 0.3 * float(p[0]), y=(y + 0.5) / h + 0.3 * float(p[1]),
                                     visibility=0.9, presence=1.0, HasField=lambda n: True) for p in self.world]
        world_lms = [SimpleNamespace(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in self.world]
        return SimpleNamespace(pose_landmarks=SimpleNamespace(landmark=image_lms),
                               pose_world_landmarks=SimpleNamespace(landmark=world_lms))  # fmt: skip


class KnownBoxes:
    """The detector's stand-in: the given boxes of each frame."""

    def __init__(self, per_frame):
        self.per_frame, self.path = per_frame, "known-boxes"

    def detect_frames(self, frames):
        return [torch.tensor(rows, dtype=torch.float32).reshape(-1, 5) for rows in self.per_frame]


def assemble(frames: torch.Tensor):
    return partial(lambda lm, c, w, f: poses_from_landmarks(lm, c, w, f, (H, W), source="fake"))


def crops(frames: torch.Tensor) -> MediaPipeCrops:
    return MediaPipeCrops(StandingAtTheBrightest(), assemble(frames))


def two_people(T: int = 4):
    """A (tall, bright) at x = 40, B (short, dimmer) at x = 150; in the last frame a third
    bright spot sits just left of B's box, inside B's crop but outside its box."""
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    frames[:, :, 60, 40] = 250
    frames[:, :, 70, 150] = 200
    frames[T - 1, :, 70, 150] = 0
    frames[T - 1, :, 70, 128] = 255  # a neighbour: not B
    a, b = [20.0, 10.0, 60.0, 110.0, 0.9], [135.0, 40.0, 165.0, 100.0, 0.8]
    return frames, KnownBoxes([[a, b]] * T)


def test_each_tracked_person_gets_the_pose_found_in_their_box():
    frames, detector = two_people()
    est = estimate_people(crops(frames), frames, detector, "all", {"run": 1})
    assert est.num_people == 2 and [p.track_id for p in est.people()] == [0, 1]
    main, other = est.people()
    hips = lambda p: p.keypoints2d[:, 11:13].mean(1)  # noqa: E731  COCO-17 hips
    assert torch.allclose(hips(main), torch.tensor([[40.0, 60.0]] * 4), atol=1.0)
    assert torch.allclose(hips(other)[:3], torch.tensor([[150.0, 70.0]] * 3), atol=1.0)
    # the last frame's crop around B showed the neighbour outside B's box: not B's pose
    assert (other.keypoints_conf[3] == 0).all() and (main.keypoints_conf > 0).any(-1).all()
    assert torch.equal(other.person_boxes[:, :4], torch.tensor([[135.0, 40.0, 165.0, 100.0]] * 4))
    records = est.metadata["people"]
    assert [r["not_theirs"] for r in records] == [0, 1] and [r["pose_frames"] for r in records] == [4, 3]
    assert est.metadata["run"] == 1 and est.cameras is not None and est.others[0].cameras is not None


class Counting(StandingAtTheBrightest):
    def __init__(self) -> None:
        super().__init__()
        self.calls = 0

    def process(self, image):
        self.calls += 1
        return super().process(image)


def test_each_detection_gets_its_pose_and_each_crop_runs_once():
    frames, detector = two_people()
    pose = Counting()
    estimator = MediaPipeCrops(pose, assemble(frames))
    keypoints = detection_keypoints(estimator, frames, detector.detect_frames(frames))
    assert [tuple(k.shape) for k in keypoints] == [(2, 17, 3)] * 4
    hips = torch.stack([k[:, 11:13, :2].mean(1) for k in keypoints])  # (T, 2 detections, 2)
    assert torch.allclose(hips[:3], torch.tensor([[40.0, 60.0], [150.0, 70.0]]).expand(3, 2, 2), atol=1.0)
    assert (keypoints[3][1, :, 2] == 0).all() and (keypoints[3][0, :, 2] > 0).all()  # B's crop: the neighbour
    assert pose.calls == 8  # every detection's crop, each found by the first framing
    est = estimate_people(estimator, frames, detector, "all")
    assert pose.calls == 8 and est.num_people == 2  # the same estimator and frames: every crop seen
    again = MediaPipeCrops(pose, assemble(frames))
    estimate_people(again, frames, detector, "all")
    assert pose.calls == 16  # the tracks' crops are the detections': MediaPipe ran once per crop
    estimate_people(again, frames.clone(), detector, "all")
    assert pose.calls == 24  # other frames: run again


def test_people_largest_or_one_keeps_the_most_prominent_and_a_track_without_a_pose_is_left_out():
    frames, detector = two_people()
    largest = estimate_people(crops(frames), frames, detector, "largest")
    assert largest.num_people == 1 and largest.person_boxes[0, 0] == 20.0
    frames[:, :, 60, 40] = 0  # A is dark: the detector's box but no pose
    est = estimate_people(crops(frames), frames, detector, "all")
    assert est.num_people == 1 and est.track_id == 1 and est.metadata["people_without_pose"] == [0]


def test_nobody_gives_zero_confidences():
    frames = torch.zeros(3, 3, H, W, dtype=torch.uint8)
    est = estimate_people(crops(frames), frames, KnownBoxes([[]] * 3), "all")
    assert est.num_people == 1 and not est.found().any() and est.person_boxes is None


def test_pose_in_box():
    kp = torch.tensor([[[10.0, 10.0], [20.0, 30.0]], [[100.0, 10.0], [120.0, 30.0]]])
    conf = torch.ones(2, 2)
    boxes = torch.tensor([[0.0, 0.0, 40.0, 40.0, 1.0]] * 2)
    assert pose_in_box(kp, conf, boxes).tolist() == [True, False]


def test_a_person_cut_off_by_the_frame_is_in_their_box():
    """The girl of alley_1 fills the frame's lower half: MediaPipe guesses her legs far below the
    frame (y up to 2.7 frame heights), which moved the keypoints' centre out of her box and lost
    every frame of her (BENCHMARKS.md, "MediaPipe on the detector's crops")."""
    H, W = 100, 200
    upper = [[80.0, 40.0], [120.0, 40.0], [85.0, 90.0], [115.0, 90.0]]  # shoulders, hips: in the frame
    legs = [[85.0, 180.0], [115.0, 180.0], [85.0, 270.0], [115.0, 270.0]]  # knees, ankles: below it
    kp, conf = torch.tensor([upper + legs]), torch.ones(1, 8)
    box = torch.tensor([[70.0, 30.0, 130.0, 99.0, 0.9]])
    assert not pose_in_box(kp, conf, box)[0]  # every keypoint: the centre (y 155) lies below the box
    assert pose_in_box(kp, conf, box, (H, W))[0]
    neighbour = kp + torch.tensor([90.0, 0.0])  # someone else, beside the box
    assert not pose_in_box(neighbour, conf, box, (H, W))[0]
    assert not pose_in_box(kp + torch.tensor([0.0, 200.0]), conf, box, (H, W))[0]  # no keypoint in the frame


@pytest.mark.shared
@pytest.mark.mediapipe
@needs_mediapipe
def test_the_street_clip_gives_several_people_each_inside_their_track(shared, tmp_path):
    from lit_boot.data.readers import load_poses
    from lit_boot.estimate import estimate_pose_file

    out = tmp_path / "street.npz"
    est, line = estimate_pose_file(shared / "data/videos/street_540p_5f.mp4", out, people="all",
                                   detector=shared / "checkpoints/yolox_nano.onnx", max_frames=3)  # fmt: skip
    back = load_poses(out)
    assert back.num_people >= 3 and "people" in line
    ids = [p.track_id for p in back.people()]
    assert len(set(ids)) == len(ids)
    for person in back.people():
        assert pose_in_box(person.keypoints2d, person.keypoints_conf, person.person_boxes).sum() == (
            (person.keypoints_conf > 0).any(-1)).sum()  # fmt: skip
    boxes = back.person_boxes
    area = lambda b: ((b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1]) * b[:, 4]).sum()  # noqa: E731
    assert all(area(boxes) >= area(p.person_boxes) for p in back.others)  # the main person is the most prominent


class AtTheBoxCentre:
    """Another estimator plugged in through the protocol: every keypoint at the box's centre,
    shifted ``shift`` px right in the frames listed in ``off`` (a neighbour's pose)."""

    def __init__(self, shift: float = 0.0, off: tuple[int, ...] = ()):
        self.shift, self.off = shift, off

    def estimate_person(self, frames, boxes):
        from lit_boot.data.readers import PoseEstimates

        centre = (boxes[:, :2] + boxes[:, 2:4]) / 2
        for t in self.off:
            centre[t, 0] += self.shift
        found = (boxes[:, 4] > 0).float()
        return PoseEstimates(keypoints2d=centre[:, None].expand(-1, 17, 2).clone(),
                             keypoints_conf=found[:, None].expand(-1, 17).clone(), keypoints_layout="coco17")

    def keep_frames(self, estimates, keep):
        return mask_frames(estimates, keep)


def test_another_estimator_plugs_in_through_the_protocol():
    frames, detector = two_people()
    est = estimate_people(AtTheBoxCentre(shift=100.0, off=(2,)), frames, detector, "all")
    assert est.num_people == 2 and est.cameras is None
    main, other = est.people()
    assert torch.allclose(other.keypoints2d[0, 0], torch.tensor([150.0, 70.0]))
    assert (main.keypoints_conf[2] == 0).all() and (main.keypoints_conf[[0, 1, 3]] == 1).all()  # frame 2: not theirs
    assert [r["not_theirs"] for r in est.metadata["people"]] == [1, 1]


def test_a_box_whose_pose_another_box_fits_better_is_dropped_before_tracking():
    """A second, looser box around A beside A's own (as a detector's box around two people who
    overlap): both crops show A; the loose box is dropped in each frame (it would start a second
    track on A), A's own box keeps the pose; where the loose box is alone it stays."""
    frames, _ = two_people()
    frames[-1, :, 70, 128] = 0  # no neighbour
    a, loose = [20.0, 10.0, 60.0, 110.0, 0.9], [10.0, 5.0, 110.0, 115.0, 0.8]
    est = estimate_people(crops(frames), frames, KnownBoxes([[a, loose]] * 3 + [[loose]]), "all")
    assert est.num_people == 1 and len(est.metadata["people"]) == 1 and est.metadata["duplicate_detections"] == 3
    assert torch.equal(est.person_boxes[:3, :4], torch.tensor([a[:4]] * 3))
    assert torch.equal(est.person_boxes[3, :4], torch.tensor(loose[:4])) and est.found().all()


def test_a_box_without_a_pose_beside_one_with_a_pose_is_not_tracked():
    """A box beside A's, overlapping it (IoU 0.43) but not holding A's pose: its crop shows A, whose
    pose lies outside it, so it has no pose; it is dropped before tracking in every frame (without
    the rule it makes a third track, one without a pose) and A and B keep theirs."""
    frames, _ = two_people()
    frames[-1, :, 70, 128] = 0
    frames[-1, :, 70, 150] = 200
    a, beside, b = [20.0, 10.0, 60.0, 110.0, 0.9], [42.0, 10.0, 62.0, 110.0, 0.5], [135.0, 40.0, 165.0, 100.0, 0.8]
    est = estimate_people(crops(frames), frames, KnownBoxes([[a, beside, b]] * 4), "all")
    assert est.metadata["poseless_beside_posed"] == 4 and est.metadata["tracks"] == 2
    assert est.num_people == 2 and [r["pose_frames"] for r in est.metadata["people"]] == [4, 4]
    assert torch.equal(est.person_boxes[:, :4], torch.tensor([a[:4]] * 4))
    alone = estimate_people(crops(frames), frames, KnownBoxes([[beside, b]] * 4), "all")
    assert alone.metadata["poseless_beside_posed"] == 0 and alone.metadata["tracks"] == 2  # nothing beside: kept


class ByBoxCentre:
    """An estimator whose crop shows a pose 30 x 80 px (``layout``) at the x that ``table[t]``
    gives for the box's centre: (centre x, pose x) pairs, the nearest centre's (nobody where the
    frame's table is empty)."""

    layout = torch.stack([torch.linspace(-15, 15, 17).roll(5), torch.linspace(20, 100, 17)], -1)

    def __init__(self, table):
        self.table = table

    def estimate_person(self, frames, boxes):
        from lit_boot.data.readers import PoseEstimates

        T = boxes.shape[0]
        kp, conf = torch.zeros(T, 17, 2), torch.zeros(T, 17)
        for t in range(T):
            if boxes[t, 4] > 0 and self.table[t]:
                centre = float(boxes[t, 0] + boxes[t, 2]) / 2
                _, x = min(self.table[t], key=lambda pair: abs(pair[0] - centre))
                kp[t], conf[t] = self.layout + torch.tensor([x, 0.0]), 1.0
        return PoseEstimates(keypoints2d=kp, keypoints_conf=conf, keypoints_layout="coco17")

    def keep_frames(self, estimates, keep):
        return mask_frames(estimates, keep)


class OnWhoeverIsThere(ByBoxCentre):
    """An estimator whose crop shows the person whose pose centre is nearest the box's centre
    among those in ``seen`` (per frame, the x of each visible person)."""

    def __init__(self, seen):
        super().__init__([[(x, x) for x in xs] for xs in seen])

def test_a_pose_in_a_bridged_crop_counts_for_the_detection_that_gave_it():
    """A stands at x = 100 (a loose box); B walks across behind A, undetected in frame 2, where
    the tracker's bridged box for B is tight around A's pose: both crops show A. The pose counts
    for A's detection, not for B's guessed box, though that one fits it better."""
    a = [60.0, 10.0, 140.0, 110.0, 0.9]
    b = [[x - 15.0, 20.0, x + 15.0, 100.0, 0.8] for x in (40.0, 70.0, 100.0, 130.0, 160.0)]
    per_frame = [[a, b[t]] if t != 2 else [a] for t in range(5)]
    seen = [[100.0, 40.0], [100.0, 70.0], [100.0], [100.0, 130.0], [100.0, 160.0]]
    frames = torch.zeros(5, 3, H, W, dtype=torch.uint8)
    est = estimate_people(OnWhoeverIsThere(seen), frames, KnownBoxes(per_frame), "all")
    assert est.num_people == 2
    main, other = est.people()
    assert torch.equal(other.person_boxes[2, :4], torch.tensor([85.0, 20.0, 115.0, 100.0]))  # bridged
    posed = lambda person: (person.keypoints_conf > 0).any(-1).tolist()  # noqa: E731
    assert all(posed(main)) and posed(other) == [True, True, False, True, True]
    assert torch.allclose(main.keypoints2d[2], OnWhoeverIsThere.layout + torch.tensor([100.0, 0.0]))
    assert [r["duplicates"] for r in est.metadata["people"]] == [0, 1]


def test_duplicate_frames_drops_the_worse_fitting_copy_only():
    from lit_boot.estimate.pose_duplicates import duplicate_frames

    pose = torch.tensor([[10.0, 10.0], [20.0, 10.0], [10.0, 40.0], [20.0, 40.0], [15.0, 60.0]])
    elsewhere = pose + torch.tensor([50.0, 0.0])
    conf = torch.ones(3, 5)
    a = torch.stack([pose, pose, pose])
    b = torch.stack([elsewhere, pose + 0.5, pose])  # frame 1: the same pose; frame 2 too, few joints shared
    conf_b = conf.clone()
    conf_b[2, 2:] = 0
    tight = torch.tensor([[10.0, 10.0, 20.0, 60.0, 1.0]] * 3)
    loose = torch.tensor([[0.0, 0.0, 90.0, 80.0, 1.0]] * 3)
    drop_a, drop_b = duplicate_frames([a, b], [conf, conf_b], [tight, loose])
    assert drop_a.tolist() == [False, False, False] and drop_b.tolist() == [False, True, False]
    drop_a, drop_b = duplicate_frames([a, b], [conf, conf_b], [loose, tight])  # the other box fits: A's goes
    assert drop_a.tolist() == [False, True, False] and drop_b.tolist() == [False, False, False]
    bridged_b = torch.tensor([False, True, False])  # B's box in frame 1 is the tracker's guess: A's detection keeps it
    drop_a, drop_b = duplicate_frames([a, b], [conf, conf_b], [loose, tight], [torch.zeros(3, dtype=bool), bridged_b])
    assert drop_a.tolist() == [False, False, False] and drop_b.tolist() == [False, True, False]


def test_duplicate_detections_and_bridged_frames():
    from lit_boot.estimate.people_pose import bridged_frames
    from lit_boot.estimate.pose_duplicates import duplicate_detections

    pose = torch.cat([OnWhoeverIsThere.layout + torch.tensor([100.0, 0.0]), torch.ones(17, 1)], -1)
    other = pose + torch.tensor([60.0, 0.0, 0.0])
    tight, loose, far = [85.0, 20.0, 115.0, 100.0, 0.5], [40.0, 10.0, 150.0, 110.0, 0.9], [145.0, 20.0, 175.0, 100.0, 0.7]
    dets = [torch.tensor([loose, tight, far]), torch.tensor([loose, far]), torch.zeros(0, 5)]
    kps = [torch.stack([pose, pose, other]), torch.stack([pose, pose * torch.tensor([1.0, 1.0, 0.0])]),
           torch.zeros(0, 17, 3)]  # fmt: skip
    drop = duplicate_detections(dets, kps)
    assert [d.tolist() for d in drop] == [[True, False, False], [False, False], []]  # no pose: no duplicate
    boxes = torch.tensor([tight, [90.0, 20.0, 120.0, 100.0, 0.6], [0.0] * 5])
    assert bridged_frames(boxes, dets).tolist() == [False, True, False]


def test_keep_frames_refits_any_estimates_the_crops_made():
    """Dropping frames twice (a neighbour's pose, then a pose another track has too) refits the
    estimates from the landmarks both times: the dropped frames are missing and filled from the
    person's own frames, not kept with another person's pose in 3D."""
    frames, detector = two_people()
    boxes = detector.detect_frames(frames)
    a = torch.stack([d[0] for d in boxes])
    estimator = crops(frames)
    est = estimator.estimate_person(frames, a)
    once = estimator.keep_frames(est, torch.tensor([True, False, True, True]))
    twice = estimator.keep_frames(once, torch.tensor([True, True, False, True]))
    assert once.metadata["missing_frames"] == [1] and twice.metadata["missing_frames"] == [1, 2]
    assert [f for f, _ in twice.metadata["filled_from"]] == [1, 2] and (twice.keypoints_conf[1:3] == 0).all()
    other = crops(frames).estimate_person(frames, a)  # made by another estimator: masked, nothing to refit
    masked = estimator.keep_frames(other, torch.tensor([True, False, True, True]))
    assert (masked.keypoints_conf[1] == 0).all() and masked.metadata["missing_frames"] == []


def test_a_pose_borrowed_from_the_person_in_front_counts_for_neither_track():
    """A (red) stands at x = 140; B (blue) walks in from the left, clear of A in frame 0. In frame
    2 B's box overlaps A's and its crop shows A (red) a little off A's own pose, so no duplicate:
    B has no pose there, A keeps its own everywhere."""
    frames = torch.full((3, 3, H, W), 128, dtype=torch.uint8)
    frames[:, :, :, 120:161] = torch.tensor([230, 20, 20], dtype=torch.uint8)[:, None, None]
    for t, (x0, x1) in enumerate([(55, 96), (85, 119)]):
        frames[t, :, :, x0:x1] = torch.tensor([20, 20, 230], dtype=torch.uint8)[:, None, None]
    a = [100.0, 10.0, 180.0, 110.0, 0.9]
    b = [[x - 15.0, 20.0, x + 15.0, 100.0, 0.8] for x in (75.0, 105.0, 142.0)]
    table = [[(140.0, 140.0), (75.0, 75.0)], [(140.0, 140.0), (105.0, 105.0)], [(140.0, 140.0), (142.0, 150.0)]]
    est = estimate_people(ByBoxCentre(table), frames, KnownBoxes([[a, b[t]] for t in range(3)]), "all")
    assert est.num_people == 2
    main, other = est.people()
    posed = lambda person: (person.keypoints_conf > 0).any(-1).tolist()  # noqa: E731
    assert posed(main) == [True, True, True] and posed(other) == [True, True, False]
    assert [r["borrowed"] for r in est.metadata["people"]] == [0, 1]
    assert [r["duplicates"] for r in est.metadata["people"]] == [0, 0]


class Wandering(StandingAtTheBrightest):
    """A video-mode stand-in: 3 px right of the brightest pixel (to tell its poses from the static
    crops'), nobody on its 2nd crop and a pose 60 px to the left (out of A's box) on its 3rd; on A's
    crops, 150 frame px a side (A's 100 px height and 0.25 of it on both sides)."""

    calls = 0

    def process(self, image):
        Wandering.calls += 1
        result = super().process(image)
        if Wandering.calls == 2 or result.pose_landmarks is None:
            return SimpleNamespace(pose_landmarks=None, pose_world_landmarks=None)
        for lm in result.pose_landmarks.landmark:
            lm.x += (3 if Wandering.calls != 3 else -60) / 150  # frame px over the crop's side
        return result


def test_a_track_is_followed_in_video_mode_and_the_static_crops_fill_where_it_followed_someone_else():
    from contextlib import nullcontext

    frames, detector = two_people(T=4)
    boxes = detector.detect_frames(frames)
    a = torch.stack([d[0] for d in boxes])  # A's box in every frame (40 px wide, 100 tall)
    Wandering.calls = 0
    followed = MediaPipeCrops(StandingAtTheBrightest(), assemble(frames), video_pose=lambda: nullcontext(Wandering()))
    est = followed.estimate_track(frames, a)
    static = crops(frames).estimate_person(frames, a)
    assert est.found().tolist() == [True, False, True, True] and Wandering.calls == 4  # lost in frame 1: nobody
    dx = (est.keypoints2d - static.keypoints2d)[..., 0].mean(-1)  # per frame, video minus static, px
    assert (dx[[0, 3]] > 1).all()  # the followed poses, shifted right
    assert torch.equal(est.keypoints2d[2], static.keypoints2d[2])  # followed out of the box: the static crop's


def test_a_persons_poses_going_on_on_a_new_track_are_joined(monkeypatch):
    """A stands at x = 100; the detector's box around A is small in frames 0-2 and the whole frame
    in 3-5 (more than max_scale apart: the tracker starts a new track). Each track's crops show A's
    pose: the poses end on one track and go on, unchanged, on the other, and they are joined into
    one person with a pose in every frame (without the rule: two people, three frames each)."""
    import lit_boot.estimate.pose_handover as handover

    small, whole = [90.0, 40.0, 110.0, 80.0, 0.9], [0.0, 0.0, W - 1.0, H - 1.0, 0.9]
    detector = KnownBoxes([[small]] * 3 + [[whole]] * 3)
    frames = torch.zeros(6, 3, H, W, dtype=torch.uint8)
    est = estimate_people(OnWhoeverIsThere([[100.0]] * 6), frames, detector, "all")
    assert est.num_people == 1 and est.metadata["tracks"] == 2
    assert (est.keypoints_conf > 0).any(-1).all() and est.metadata["pose_handovers"][0].startswith("swap ")
    assert torch.equal(est.person_boxes[:, :4], torch.tensor([small[:4]] * 3 + [whole[:4]] * 3))
    assert sorted(r["pose_frames"] for r in est.metadata["people"]) == [0, 6]
    monkeypatch.setattr(handover, "MAX_STEP", 0.0)
    apart = estimate_people(OnWhoeverIsThere([[100.0]] * 6), frames, detector, "all")
    assert apart.num_people == 2 and [int((p.keypoints_conf > 0).any(-1).sum()) for p in apart.people()] == [3, 3]
    assert apart.metadata["pose_handovers"] == []
