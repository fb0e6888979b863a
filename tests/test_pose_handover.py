"""A person's poses handed from one track to the next are joined (lit_boot.estimate.pose_handover)."""

from __future__ import annotations

import torch

from lit_boot.core.people import Person
from lit_boot.estimate.pose_handover import MAX_GAP, MAX_STEP, continue_poses, handovers

T = 8
#: A pose 80 px tall (its size), 17 joints in a slanted column.
POSE = torch.stack([torch.linspace(-10.0, 10.0, 17), torch.linspace(20.0, 100.0, 17)], -1)


def person(track_id: int, posed: list[int], boxed: list[int] = (), x: float = 100.0, step: float = 0.0) -> Person:
    """A person with a pose at ``x`` (moving ``step`` px per frame) in frames ``posed`` and a box
    (score 0.5) in those and ``boxed``."""
    kp, conf, boxes = torch.zeros(T, 17, 2), torch.zeros(T, 17), torch.zeros(T, 5)
    for t in posed:
        kp[t], conf[t] = POSE + torch.tensor([x + step * t, 0.0]), 0.9
    for t in [*posed, *boxed]:
        boxes[t] = torch.tensor([x + step * t - 20, 10.0, x + step * t + 20, 110.0, 0.5])
    return Person(track_id=track_id, keypoints2d=kp, keypoints_conf=conf, person_boxes=boxes)


def posed_frames(p: Person) -> list[int]:
    return (p.keypoints_conf > 0).any(-1).nonzero().flatten().tolist()


def test_poses_going_on_on_another_track_are_joined_and_the_boxes_left_behind_trade_places():
    a = person(0, [0, 1, 2, 3], boxed=[4, 5], step=2.0)  # A's box goes on without a pose
    b = person(1, [4, 5, 6, 7], step=2.0)  # B's poses continue A's: the same person
    far = person(2, [4, 5, 6, 7], x=300.0)  # another person starting as well, elsewhere
    assert [(i, j, last) for _, i, j, last in handovers([a, b, far])] == [(0, 1, 3)]
    people, said = continue_poses([a, b, far], list(range(10, 10 + T)))
    assert [p.track_id for p in people] == [0, 1, 2]
    assert posed_frames(people[0]) == list(range(T)) and posed_frames(people[1]) == []
    assert torch.equal(people[0].person_boxes[4:], b.person_boxes[4:])
    assert torch.equal(people[1].person_boxes[4:6], a.person_boxes[4:6])  # A's pose-less boxes
    assert said == ["swap 0 1 at 14-: persons 0 and 1 traded frames 14-17"]
    assert torch.equal(people[2].keypoints2d, far.keypoints2d)


def test_the_step_and_the_gap_decide_from_both_sides():
    size = 80.0  # the pose's larger side
    for gap, step, joined in [(1, MAX_STEP * size - 0.5, True), (1, MAX_STEP * size + 0.5, False),
                              (MAX_GAP, MAX_STEP * size * MAX_GAP - 1.0, True), (MAX_GAP + 1, 0.0, False)]:  # fmt: skip
        a = person(0, [0, 1])
        b = person(1, list(range(1 + gap, T)), x=100.0 + step)
        assert bool(handovers([a, b])) == joined, (gap, step)


def test_two_people_posed_in_the_same_frame_or_with_few_shared_joints_are_not_joined():
    a = person(0, [0, 1, 2, 3])
    both = person(1, [3, 4, 5])  # B has a pose in A's last frame: two people, not one
    assert handovers([a, both]) == []
    few = person(1, [4, 5])
    few.keypoints_conf[4, :3] = 0
    few.keypoints_conf[4, 11:] = 0  # its first pose: joints 3-10
    a.keypoints_conf[3, 6:] = 0  # A's last: joints 0-5, three shared
    assert handovers([a, few]) == []
    a.keypoints_conf[3, 6] = 0.9  # four shared: compared, and one person
    assert len(handovers([a, few])) == 1
    people, said = continue_poses([person(0, [0, 1, 2, 3]), both], list(range(T)))
    assert said == [] and [posed_frames(p) for p in people] == [[0, 1, 2, 3], [3, 4, 5]]


def test_a_pose_handed_on_twice_is_followed_and_a_track_left_with_nothing_goes():
    a, b, c = person(0, [0, 1]), person(1, [2, 3, 4]), person(2, [5, 6, 7])  # one person on three tracks
    people, said = continue_poses([c, a, b], list(range(T)))
    assert said == ["swap 0 1 at 2-: persons 0 and 1 traded frames 2-7", "person 1 has no frame left and goes",
                    "swap 0 2 at 5-: persons 0 and 2 traded frames 5-7", "person 2 has no frame left and goes"]
    assert [p.track_id for p in people] == [0] and posed_frames(people[0]) == list(range(T))
