"""The frames where a tracked person's id may have switched (lit_boot.estimate.id_checks)."""

from __future__ import annotations

import torch

from lit_boot.core.people import Person
from lit_boot.estimate import frame_ranges, frames_to_check, summary_line
from lit_boot.estimate.id_checks import beside_line
from lit_boot.estimate.people_pose import estimate_people
from test_people_pose import crops, two_people


def _person(track_id: int, xs: list[float], posed: list[bool], boxed: bool = True) -> Person:
    """A 40 x 80 px person whose box's left edge is at xs[t], its 17 keypoints spread over the box;
    a pose (confidence 0.9) in the frames ``posed``."""
    T = len(xs)
    x0 = torch.tensor(xs)[:, None]
    grid = torch.linspace(0, 1, 17)[None]
    keypoints = torch.stack([x0 + 40 * grid, 10 + 80 * grid.expand(T, 17)], -1)
    conf = torch.tensor(posed, dtype=torch.float32)[:, None].expand(T, 17) * 0.9
    boxes = torch.cat([x0, torch.full((T, 1), 10.0), x0 + 40, torch.full((T, 1), 90.0), torch.ones(T, 1)], -1)
    return Person(track_id=track_id, keypoints2d=keypoints, keypoints_conf=conf.clone(),
                  person_boxes=boxes if boxed else None)  # fmt: skip


def test_overlaps_and_returns_are_marked_and_nothing_else():
    # A walks right; B walks left through A: same-size boxes d px apart have IoU (40 - d) / (40 + d)
    xa, xb = [0, 10, 20, 30, 40, 50, 60], [120, 100, 80, 50, 40, 20, 0]
    a = _person(0, xa, [True] * 7)
    b = _person(1, xb, [False, True, True, True, False, True, True])
    overlap = [abs(u - v) < 40 and (40 - abs(u - v)) / (40 + abs(u - v)) >= 0.3 for u, v in zip(xa, xb)]
    assert overlap == [False, False, False, True, True, False, False]  # d = 20 (IoU 0.33) and 0
    marks_a, marks_b = frames_to_check([a, b])
    assert marks_a.tolist() == overlap  # A has a pose throughout: its overlaps alone
    # B: first seen in frame 1 (after the clip's start), overlaps A in 3 (in 4 it has no pose),
    # back in 5 after a frame without a pose; frame 6 is clear
    assert marks_b.tolist() == [False, True, False, True, False, True, False]


def test_the_why_line_names_who_is_beside_whom_in_video_frame_numbers():
    xa, xb = [0, 10, 20, 30, 40, 50, 60], [120, 100, 80, 50, 40, 20, 0]  # as above: overlaps in 3 and 4
    a = _person(0, xa, [True] * 7)
    b = _person(7, xb, [False, True, True, True, False, True, True])
    marks = frames_to_check([a, b])
    numbers = [10 + t for t in range(7)]  # video frames 10-16
    assert beside_line([a, b], marks, numbers) == ("person 0 beside 7 at 13-14; "
                                                   "person 7 beside 0 at 13, new or back at 11, 15")
    assert beside_line([a, b], [torch.zeros(7, dtype=torch.bool)] * 2, numbers) == ""
    assert beside_line([], [], []) == ""


def test_without_boxes_the_keypoints_extent_counts_and_a_person_without_keypoints_has_none():
    a = _person(0, [0, 0, 0], [True] * 3, boxed=False)
    b = _person(1, [100, 5, 100], [True] * 3, boxed=False)
    assert [m.tolist() for m in frames_to_check([a, b])] == [[False, True, False]] * 2
    boxes_only = Person(track_id=2, person_boxes=torch.tensor([[0.0, 10.0, 40.0, 90.0, 1.0]] * 3))
    marks = frames_to_check([a, boxes_only])
    assert marks[0].tolist() == [True] * 3 and marks[1].tolist() == [False] * 3
    assert frames_to_check([]) == []


def test_frame_ranges():
    assert frame_ranges([1, 2, 3, 5, 9, 10]) == "1-3, 5, 9-10"
    assert frame_ranges([]) == ""
    assert frame_ranges([0, 2, 4, 6], most=2) == "0, 2, ..."


def test_the_built_in_estimator_lists_a_person_found_again_and_the_summary_names_it():
    frames, detector = two_people(T=5)
    frames[4, :, 70, 128] = 0  # two_people's neighbour is in the last frame; move it to frame 2
    frames[4, :, 70, 150] = 200
    frames[2, :, 70, 150] = 0
    frames[2, :, 70, 128] = 255
    est = estimate_people(crops(frames), frames, detector, "all")
    records = est.metadata["people"]
    assert [r["pose_frames"] for r in records] == [5, 4]
    assert [r["check_ids"] for r in records] == [[], [3]]  # B's pose is back in frame 3
    line = summary_line(est)
    assert line.endswith("; ids to check (people overlapping, new or found again), video frames: person 1 at 3")


def test_scene_checks_number_the_frames_as_the_video_does():
    import dataclasses

    from lit_boot.estimate import scene_checks
    from lit_boot.synth import make_scene

    scene = make_scene(frames=6, height=64, width=128, seed=30, people=2)
    marks = frames_to_check(scene.people())
    rows = [m.nonzero().flatten().tolist() for m in marks]
    assert any(rows)  # the other person crosses the main one
    assert scene_checks(scene) == [(p.track_id, r) for p, r in zip(scene.people(), rows)]
    stepped = dataclasses.replace(scene, metadata={**scene.metadata, "frame_indices": [10, 12, 14, 16, 18, 20]})
    assert scene_checks(stepped) == [(p.track_id, [10 + 2 * t for t in r]) for p, r in zip(scene.people(), rows)]
    alone = dataclasses.replace(scene, others=())
    assert scene_checks(alone) == []


def test_the_report_of_a_run_with_several_people_names_the_frames_to_check(tmp_path):
    import lit_boot
    from lit_boot.bootstrap import bootstrap
    from lit_boot.bootstrap.html_report import REPORT_HTML
    from lit_boot.bootstrap.verdict import ids_sentence
    from lit_boot.estimate import checks_line, scene_checks

    scene = lit_boot.make_scene(motion="walk", frames=5, height=64, width=96, seed=30, people=2)
    line = checks_line(scene_checks(scene))
    assert line.startswith("ids to check")  # the other person crosses the main one
    bootstrap(scene, tmp_path / "run", flow={"weights": None, "train_updates": 2, "predict_updates": 3},
              flow_epochs=1, pose_steps=15, progress_bar=False, video=False, accelerator="cpu")  # fmt: skip
    html = (tmp_path / "run" / REPORT_HTML).read_text()
    assert f"Several people: {line}." in html.replace("&#x27;", "'")
    assert ids_sentence(scene.person(0)) is None  # one person: nothing to check
