"""The people tracker (lit_boot.estimate.people_track) on detections with known tracks."""

import pytest
import torch

import lit_boot.estimate.track_cost as track_cost
from lit_boot.estimate.people_track import parse_people, select_people, track_people


def box(cx: float, cy: float, w: float = 20.0, h: float = 40.0, score: float = 0.9) -> list[float]:
    return [cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2, score]


def frames_of(*per_frame: list[list[float]]) -> list[torch.Tensor]:
    return [torch.tensor(f, dtype=torch.float32).reshape(-1, 5) for f in per_frame]


def crossing(T: int = 12, speed: float = 8.0, hide: int | None = None,
             shuffle: bool = True) -> tuple[list[torch.Tensor], torch.Tensor]:  # fmt: skip
    """Person A walks right, B (a little smaller) walks left; they cross in the middle, each
    box overlapping the other for several frames. ``hide``: a frame where B is not detected
    (occluded by A). Detections are listed in a different order every frame. Returns the
    detections and the true centres (2, T) x of A and B."""
    xa = torch.tensor([20 + speed * t for t in range(T)])
    xb = torch.tensor([20 + speed * (T - 1) - speed * t for t in range(T)])
    dets = []
    for t in range(T):
        a, b = box(float(xa[t]), 50), box(float(xb[t]), 52, 18, 36, 0.8)
        row = [a] if t == hide else ([b, a] if shuffle and t % 2 else [a, b])
        dets.append(row)
    return frames_of(*dets), torch.stack([xa, xb])


def centre_x(tracks: torch.Tensor) -> torch.Tensor:
    return (tracks[..., 0] + tracks[..., 2]) / 2


def test_two_people_who_cross_keep_their_ids():
    dets, truth = crossing()
    tracks = track_people(dets)
    assert tracks.shape == (2, 12, 5)
    assert (tracks[..., 4] > 0).all()  # both found in every frame
    # person 0 is the more prominent (A: larger box, higher score) and stays A in every frame
    torch.testing.assert_close(centre_x(tracks), truth, atol=1e-4, rtol=0)


def test_an_occluded_frame_during_the_crossing_is_bridged_without_a_switch():
    dets, truth = crossing(hide=6)
    tracks = track_people(dets)
    assert tracks.shape[0] == 2
    torch.testing.assert_close(centre_x(tracks), truth, atol=1e-4, rtol=0)  # B's frame 6 interpolated
    assert tracks[1, 6, 4] == pytest.approx(0.8)


def test_without_the_motion_prediction_a_nearest_box_rule_would_switch():
    """The scene is hard: at the frame after the crossing, each box overlaps the *other*
    person's last box more than its own (so an IoU-only tracker swaps the ids)."""
    dets, truth = crossing(speed=14.0)
    last_a = torch.tensor(box(float(truth[0, 5]), 50)[:4])
    now = dets[6][:, :4] if dets[6][0, 4] > 0.85 else dets[6].flip(0)[:, :4]  # row 0: A
    lo = torch.maximum(last_a[:2], now[:, :2])
    hi = torch.minimum(last_a[2:], now[:, 2:])
    inter = (hi - lo).clamp_min(0).prod(-1)
    assert inter[1] > inter[0]  # A's last box overlaps B's new box more than A's own
    tracks = track_people(dets)
    torch.testing.assert_close(centre_x(tracks), truth, atol=1e-4, rtol=0)


def test_a_stray_detection_is_dropped_and_a_late_entry_gets_its_own_track():
    T = 8
    dets = [[box(30 + 4 * t, 50)] for t in range(T)]
    dets[2].append(box(200, 20, 10, 10, 0.4))  # one frame only: dropped
    for t in range(4, T):
        dets[t].append(box(150, 60 + 3 * t, 30, 60, 0.95))  # enters at frame 4, larger
    tracks = track_people(frames_of(*dets))
    assert tracks.shape[0] == 2
    late = tracks[0]  # the larger box over 4 frames is more prominent than 8 frames of the small one
    assert (late[:4, 4] == 0).all() and (late[4:, 4] > 0).all() and (late[:4, :4] == 0).all()
    torch.testing.assert_close(centre_x(tracks[1]), torch.tensor([30.0 + 4 * t for t in range(T)]))


def test_a_gap_longer_than_max_gap_ends_the_track():
    dets = [[box(30 + 2 * t, 50)] if t not in (3, 4, 5) else [] for t in range(10)]
    assert track_people(frames_of(*dets), max_gap=3).shape[0] == 1
    split = track_people(frames_of(*dets), max_gap=2)
    assert split.shape[0] == 2
    assert ((split[..., 4] > 0).sum(0) <= 1).all()  # never both at once
    assert (split[0, 6:, 4] > 0).all() and (split[1, :3, 4] > 0).all()  # the longer piece first


def test_no_detections_give_no_tracks_and_bad_input_is_named():
    assert track_people(frames_of([], [])).shape == (0, 2, 5)
    with pytest.raises(ValueError, match=r"detections\[1\]"):
        track_people([torch.zeros(0, 5), torch.zeros(3, 4)])
    with pytest.raises(ValueError, match="max_gap"):
        track_people(frames_of([]), max_gap=-1)
    with pytest.raises(ValueError, match="min_iou"):
        track_people(frames_of([]), min_iou=0)
    with pytest.raises(ValueError, match="smoothing: expected a number in"):
        track_people(frames_of([]), smoothing=0)


def test_select_people():
    dets, _ = crossing()
    tracks = track_people(dets)
    assert select_people(tracks, "all").shape[0] == 2
    assert torch.equal(select_people(tracks, "largest"), tracks[:1])
    assert select_people(tracks, 1).shape[0] == 1 and select_people(tracks, "5").shape[0] == 2
    assert parse_people("3") == 3
    for bad in ("some", 0, -1, True, 1.5):
        with pytest.raises(ValueError, match="people: expected"):
            parse_people(bad)


def test_a_good_match_is_not_traded_for_two_poor_ones():
    """Frame 3: A's person is detected where A predicts her; a small stray box lies near A (too
    far for B), and B, walking the other way, is not detected but could reach A's person. Forcing
    every track onto a detection would give A the stray and B A's person; A keeps her."""
    xa = [529.0, 532.0, 535.0, 538.0]
    dets = [[box(xa[0], 237, 60, 170)],
            [box(xa[1], 237, 60, 170), box(617.5, 240, 40, 150)],
            [box(xa[2], 237, 60, 170), box(610.0, 240, 40, 150)],
            [box(xa[3], 237, 60, 170), box(500.0, 214, 30, 100, 0.5)]]  # fmt: skip
    tracks = track_people(frames_of(*dets))
    torch.testing.assert_close(centre_x(tracks[0]), torch.tensor(xa))
    assert tracks.shape[0] == 2 and (tracks[1, 3, 4] == 0) and (tracks[1, 1:3, 4] > 0).all()


def synthetic_crossing(seed: int, motion: str = "walk", jitter: float = 0.0, miss: float = 0.0, people: int = 2):
    """Two (``people``) people of a synthetic scene who cross (the far one hidden behind the near one, its
    box shrinking to its visible part): their true boxes as detections (edges jittered by
    ``jitter`` x the box's larger side, each missed with probability ``miss``), shuffled in each
    frame, each one's simulated keypoints (x, y, confidence), and the true person of each."""
    from lit_boot.synth import make_scene

    scene = make_scene(frames=16, height=128, width=256, motion=motion, seed=seed, people=people)
    boxes = torch.stack([p.person_boxes for p in scene.people()])  # (2, T, 5)
    poses = torch.stack([torch.cat([p.keypoints2d, p.keypoints_conf[..., None]], -1) for p in scene.people()])
    g = torch.Generator().manual_seed(0)
    dets, keypoints, owners = [], [], []
    for t in range(boxes.shape[1]):
        order = [p for p in torch.randperm(people, generator=g).tolist() if torch.rand(1, generator=g).item() >= miss]
        side = (boxes[order, t, 2:4] - boxes[order, t, :2]).amax(-1, keepdim=True)
        noisy = boxes[order, t, :4] + torch.randn(len(order), 4, generator=g) * jitter * side
        box = torch.cat([torch.minimum(noisy[:, :2], noisy[:, 2:]), torch.maximum(noisy[:, :2], noisy[:, 2:])], 1)
        dets.append(torch.cat([box, boxes[order, t, 4:]], 1))
        keypoints.append(poses[order, t])
        owners.append(order)
    return dets, keypoints, owners


def followed(tracks: torch.Tensor, dets: list[torch.Tensor], owners: list[list[int]]) -> list[set[int]]:
    """The true people each track covers, over the frames where its box is a detection."""
    return [{owners[t][int((dets[t] == track[t]).all(-1).nonzero()[0])] for t in range(len(dets))
             if track[t, 4] > 0 and (dets[t] == track[t]).all(-1).any()} for track in tracks]  # fmt: skip


def test_a_synthetic_crossing_keeps_both_ids():
    """Each track follows one person, and each person is one track (linking frame by frame with
    smoothing 0.5 and no stitching, the hidden one split in three; the stitch joins its pieces
    again)."""
    dets, _, owners = synthetic_crossing(30)
    assert sorted(followed(track_people(dets), dets, owners), key=min) == [{0}, {1}]
    for smoothing, stitch, whole in ((0.1, True, True), (0.1, False, True), (0.5, False, False), (0.5, True, True)):
        who = followed(track_people(dets, smoothing=smoothing, stitch=stitch, beam=1), dets, owners)
        assert all(len(w) == 1 for w in who)
        assert (len(who) == 2 and sorted(min(w) for w in who) == [0, 1]) == whole


def test_keypoints_keep_the_ids_where_the_boxes_alone_switch(monkeypatch):
    """Seed 40: in frames 1-3 the far person's box lies inside the near one's, before either
    track has a velocity; by the boxes alone the two tracks swap people there. Each detection's
    keypoints (joints moved on by the track's velocity against the detection's) tell them apart."""
    dets, keypoints, owners = synthetic_crossing(40)
    assert sorted(followed(track_people(dets, keypoints=keypoints), dets, owners), key=min) == [{0}, {1}]
    monkeypatch.setattr(track_cost, "SCALE_WEIGHT", 0.0)  # the boxes' size change, which also tells them apart here
    boxes_only = followed(track_people(dets), dets, owners)
    assert any(len(w) > 1 for w in boxes_only)  # a track that covers both people: a switch
    assert followed(track_people(dets, keypoints=keypoints, keypoint_weight=0), dets, owners) == boxes_only
    with_pose = followed(track_people(dets, keypoints=keypoints), dets, owners)
    assert sorted(with_pose, key=min) == [{0}, {1}]


# Where a test below takes one term out of the cost to show what it does, it links frame by frame
# (beam=1): the beam search could make up for the missing term by hindsight; some also start the
# velocity from the first step as it is (MEAN_START off) and leave the boxes' size change out
# (SCALE_WEIGHT 0), as the tracker did when the term came.


def test_the_joints_give_the_velocity_where_an_occluder_moves_the_box(monkeypatch):
    """Seed 39, noisy boxes (10% jitter, 10% missed): where the far person is hidden, its box
    shrinks to the visible part and the box's centre moves although the person does not; the
    velocity from the box centres then carries the track onto the other person. From the joints
    (their median motion) each person is one track (the pose's shape in the cost, which also
    keeps them apart here, left out)."""
    dets, keypoints, owners = synthetic_crossing(39, jitter=0.1, miss=0.1)
    assert sorted(followed(track_people(dets, keypoints=keypoints), dets, owners), key=min) == [{0}, {1}]
    assert sorted(followed(track_people(dets, keypoints=keypoints, beam=1), dets, owners), key=min) == [{0}, {1}]
    monkeypatch.setattr(track_cost, "MEAN_START", False)
    monkeypatch.setattr(track_cost, "KEYPOINT_SHAPE_WEIGHT", 0.0)
    assert sorted(followed(track_people(dets, keypoints=keypoints, beam=1), dets, owners), key=min) == [{0}, {1}]
    monkeypatch.setattr(track_cost, "JOINT_VELOCITY", False)
    by_box = followed(track_people(dets, keypoints=keypoints, beam=1), dets, owners)
    assert any(len(w) > 1 for w in by_box)


def test_the_keypoint_distance_is_per_frame_since_the_pose_was_seen(monkeypatch):
    """Seed 30, exact boxes, half the poses not found: person 1's pose is missing in frames 6-8,
    so in frame 9 its track's keypoints are 4 frames old. Their raw distance from its own
    detection then costs more than a miss and the track splits in two; per frame since the pose
    was seen, each person is one track."""
    dets, keypoints, owners = synthetic_crossing(30)
    g = torch.Generator().manual_seed(1)
    keypoints = [k * (torch.rand(k.shape[0], 1, 1, generator=g) >= 0.5) for k in keypoints]
    assert sorted(followed(track_people(dets, keypoints=keypoints), dets, owners), key=min) == [{0}, {1}]
    assert sorted(followed(track_people(dets, keypoints=keypoints, beam=1), dets, owners), key=min) == [{0}, {1}]
    monkeypatch.setattr(track_cost, "KEYPOINT_PER_FRAME", False)
    assert len(followed(track_people(dets, keypoints=keypoints, stitch=False, beam=1), dets, owners)) == 3


def test_a_track_seen_a_frame_ago_goes_before_one_unseen_for_longer(monkeypatch):
    """Seed 49, noisy boxes (10% jitter, 10% missed), half the poses not found: in frame 8 person 1
    is missed and person 0's detection has no pose. Person 1's track, unseen since frame 6, is
    nearer to it by its box than person 0's own track (seen in frame 7) and, without the cost per
    frame unseen, takes it: a switch."""
    dets, keypoints, owners = synthetic_crossing(49, jitter=0.1, miss=0.1)
    g = torch.Generator().manual_seed(1)
    keypoints = [k * (torch.rand(k.shape[0], 1, 1, generator=g) >= 0.5) for k in keypoints]
    assert sorted(followed(track_people(dets, keypoints=keypoints), dets, owners), key=min) == [{0}, {1}]
    assert sorted(followed(track_people(dets, keypoints=keypoints, beam=1), dets, owners), key=min) == [{0}, {1}]
    monkeypatch.setattr(track_cost, "SCALE_WEIGHT", 0.0)
    monkeypatch.setattr(track_cost, "KEYPOINT_GAP_COST", 0.0)
    assert any(len(w) > 1 for w in followed(track_people(dets, keypoints=keypoints, beam=1), dets, owners))


def test_keypoints_are_checked_against_the_detections():
    dets, keypoints, _ = synthetic_crossing(40)
    with pytest.raises(ValueError, match=r"keypoints\[2\]: expected \(2, 17, 3\)"):
        track_people(dets, keypoints=keypoints[:2] + [keypoints[2][:1]] + keypoints[3:])
    with pytest.raises(ValueError, match="keypoints: expected one tensor per frame"):
        track_people(dets, keypoints=keypoints[:3])
    with pytest.raises(ValueError, match="keypoint_weight: expected"):
        track_people(dets, keypoints=keypoints, keypoint_weight=-1)
    empty = [torch.zeros(0, 5)] + dets[1:]
    assert track_people(empty, keypoints=[torch.zeros(0, 0, 3)] + keypoints[1:]).shape[0] == 2


def test_a_track_that_a_shrunken_box_split_is_stitched_together():
    """Three synthetic people (seed 34, walk, exact boxes, every pose found): person 1, behind
    the other two, shows only a few joints: its box is 6 px by 11 px in frame 9 and 6 px by 46 px
    in frame 10; the frame-by-frame link refuses a box over 2.5 times larger than the last and
    starts a new track. The two tracklets (median sizes alike) meet within the link's reach, so
    the stitch makes one track of them."""
    dets, keypoints, owners = synthetic_crossing(34, people=3)
    split = followed(track_people(dets, keypoints=keypoints, stitch=False), dets, owners)
    assert sorted(split, key=min) == [{0}, {1}, {1}, {2}]
    assert sorted(followed(track_people(dets, keypoints=keypoints), dets, owners), key=min) == [{0}, {1}, {2}]


def test_the_poses_shape_tells_two_overlapping_people_apart(monkeypatch):
    """Three synthetic people (seed 35, run, exact boxes, every pose found): in frame 6 person 1's
    box shrinks behind person 2 and its own detection costs its track just over a match, so a new
    track starts and the orphaned one takes person 0's detection in frame 7. The pose's shape
    (its joints about their mean, wherever it is) ranks the tracks where the joints' places
    coincide: every track follows one person. Without it, a track covers two people."""
    dets, keypoints, owners = synthetic_crossing(35, motion="run", people=3)
    assert sorted(followed(track_people(dets, keypoints=keypoints), dets, owners), key=min) == [{0}, {1}, {2}]
    monkeypatch.setattr(track_cost, "SCALE_WEIGHT", 0.0)
    assert sorted(followed(track_people(dets, keypoints=keypoints, beam=1), dets, owners), key=min) == [{0}, {1}, {2}]
    monkeypatch.setattr(track_cost, "MEAN_START", False)
    assert sorted(followed(track_people(dets, keypoints=keypoints, beam=1), dets, owners), key=min) == [{0}, {1}, {2}]
    monkeypatch.setattr(track_cost, "KEYPOINT_SHAPE_WEIGHT", 0.0)
    assert any(len(w) > 1 for w in followed(track_people(dets, keypoints=keypoints, beam=1), dets, owners))


def test_the_shape_term_ranks_tracks_and_leaves_unmeasured_pairs_alone():
    """The shape distance is translation-free, and a pair whose shape cannot be measured (too few
    shared joints) pays nothing for it."""
    pose = torch.tensor([[10.0, 10.0, 1.0], [20.0, 10.0, 1.0], [15.0, 30.0, 1.0], [15.0, 50.0, 1.0]])
    moved = pose + torch.tensor([7.0, -3.0, 0.0])
    other = pose.clone()
    other[:, :2] = pose[:, :2].mean(0) + (pose[:, :2] - pose[:, :2].mean(0)) * 2  # twice as large: another layout
    tracks = [track_cost.TrackState(keypoints=k, keypoint_frame=0) for k in (pose, other)]
    where, shape = track_cost._keypoint_distance(tracks, 1, torch.stack([moved, moved * torch.tensor([1, 1, 0.0])]),
                                                   torch.tensor([40.0, 40.0]))  # fmt: skip
    assert shape[0, 0] == pytest.approx(0.0, abs=1e-6) and shape[1, 0] > 0.1 and where[0, 0] > 0.1
    assert torch.isnan(shape[:, 1]).all() and torch.isnan(where[:, 1]).all()  # no confident joint


def test_hindsight_keeps_the_ids_where_the_frame_by_frame_link_switches():
    """Two synthetic people (seed 32, walk, noisy boxes: 5% jitter, 10% missed; every pose found):
    frame 0 shows person 0 alone and frame 1 person 1 alone. Frame by frame, person 0's new track
    takes person 1's detection in frame 1 (nearer than a miss costs), and from there on both
    tracks cover both people. The beam search leaves that track alone in frame 1 and starts person
    1's own: dearer there, paid back by the frames after."""
    dets, keypoints, owners = synthetic_crossing(32, jitter=0.05, miss=0.1)
    assert owners[0] == [0] and owners[1] == [1]
    frame_by_frame = followed(track_people(dets, keypoints=keypoints, beam=1), dets, owners)
    assert any(len(w) > 1 for w in frame_by_frame)
    assert sorted(followed(track_people(dets, keypoints=keypoints), dets, owners), key=min) == [{0}, {1}]


def test_the_best_assignments_are_ranked_as_by_brute_force():
    """track_search.best_assignments against every assignment of a small problem enumerated: a
    track takes one detection or none, a detection goes to one track or none, each left alone
    costing the miss; inf pairs are never taken."""
    import itertools

    from lit_boot.estimate.track_search import assign, best_assignments

    g = torch.Generator().manual_seed(3)
    cost = torch.rand(3, 4, generator=g) * 2.5
    cost[0, 1] = cost[2, 3] = float("inf")
    every = []
    for choice in itertools.product([None, 0, 1, 2, 3], repeat=3):
        taken = [c for c in choice if c is not None]
        allowed = all(c is None or bool(torch.isfinite(cost[r, c])) for r, c in enumerate(choice))
        if len(set(taken)) < len(taken) or not allowed:
            continue
        pairs = [(r, c) for r, c in enumerate(choice) if c is not None]
        every.append((sum(float(cost[r, c]) for r, c in pairs) + 1.0 * (3 - len(pairs) + 4 - len(pairs)), pairs))
    every.sort(key=lambda x: x[0])
    ranked = best_assignments(cost, 8)
    assert [round(total, 5) for total, _ in ranked] == [round(total, 5) for total, _ in every[:8]]
    assert len({tuple(pairs) for _, pairs in ranked}) == 8  # each a different assignment
    assert sorted(ranked[0][1]) == sorted(every[0][1]) == sorted(assign(cost))
    assert len(best_assignments(cost, 10_000)) == len(every)


def test_beam_is_checked():
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="beam: expected a number of hypotheses"):
            track_people(frames_of([]), beam=bad)


def test_a_new_tracks_velocity_starts_as_the_mean_of_its_first_steps(monkeypatch):
    """Three synthetic people (seed 35, walk, noisy boxes: 10% jitter, 10% missed; every pose
    found): with a new track's first step as its velocity (then a running mean weighing each new
    step 0.1), one track follows persons 0 and 1 in turn; with the plain mean of the first steps
    until their weight falls to 0.1, each track follows one person (the boxes' size change left out
    of the cost, as when the mean start came: with it, this scene has a switch either way)."""
    dets, keypoints, owners = synthetic_crossing(35, jitter=0.1, miss=0.1, people=3)
    monkeypatch.setattr(track_cost, "SCALE_WEIGHT", 0.0)  # as when the mean start came (with it: a switch here)
    assert sorted(followed(track_people(dets, keypoints=keypoints), dets, owners), key=min) == [{0}, {1}, {2}]
    monkeypatch.setattr(track_cost, "MEAN_START", False)
    assert any(len(w) > 1 for w in followed(track_people(dets, keypoints=keypoints), dets, owners))
