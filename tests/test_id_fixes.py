"""Fixing people's ids by hand (lit_boot.estimate.id_fixes), the id sheet, and ``lit-boot ids``."""

from __future__ import annotations

import dataclasses
import hashlib

import pytest
import torch

from lit_boot.cli import main
from lit_boot.core.people import Person
from lit_boot.data import load_scene, save_scene
from lit_boot.data.readers import PoseEstimates, load_poses, save_poses
from lit_boot.estimate import fix_ids, frames_to_check, id_sheet, parse_fix, sheet_rows
from lit_boot.estimate.id_checks import beside_line
from lit_boot.estimate.id_fixes import fix_estimates, fix_scene
from lit_boot.estimate.id_sheet import MAIN_RGB, person_colour
from lit_boot.synth import make_scene


@pytest.fixture(scope="module")
def crossing():
    """A synthetic scene: 3 people over 8 frames (exact estimates: 3D joints, cameras, keypoints, boxes)."""
    return make_scene(frames=8, height=64, width=128, seed=30, people=3)


def swapped(people: list[Person], a: int, b: int, rows: slice) -> list[Person]:
    """``people`` with persons a and b (list indices) trading every field in ``rows``: a switch made on purpose."""
    out = [p.map(lambda x: x.clone()) for p in people]
    for key in ("keypoints2d", "keypoints_conf", "joints3d", "person_boxes"):
        va, vb = getattr(out[a], key), getattr(out[b], key)
        va[rows], vb[rows] = getattr(people[b], key)[rows], getattr(people[a], key)[rows]
    for part in ("params", "crops"):
        va, vb = getattr(out[a].cameras, part), getattr(out[b].cameras, part)
        va[rows], vb[rows] = getattr(people[b].cameras, part)[rows], getattr(people[a].cameras, part)[rows]
    return out


def same(p: Person, q: Person) -> bool:
    return p.track_id == q.track_id and all(torch.equal(getattr(p, k), getattr(q, k)) for k in
                                            ("keypoints2d", "keypoints_conf", "joints3d", "person_boxes")) and \
        torch.equal(p.cameras.params, q.cameras.params) and torch.equal(p.cameras.crops, q.cameras.crops)  # fmt: skip


def test_fixes_are_read_from_their_sentences():
    fix = parse_fix("  Swap 1  2 at 3-5, 9, 12- ")
    assert (fix.verb, fix.first, fix.second, fix.spans, fix.text) == ("swap", 1, 2, ((3, 5), (9, 9), (12, None)),
                                                                      "Swap 1 2 at 3-5, 9, 12-")  # fmt: skip
    assert fix.rows(range(2, 14)).nonzero().flatten().tolist() == [1, 2, 3, 7, 10, 11]  # 12- reaches the last frame
    join = parse_fix("join 4 into 1")
    assert (join.verb, join.first, join.second, join.spans) == ("join", 1, 4, None)  # 1 stays, 4 goes into it
    assert parse_fix("drop 3").spans is None and parse_fix("split 2 at 7-").spans == ((7, None),)
    for text, words in [("swop 1 2", "not understood"), ("swap 1 1", "names person 1 twice"),
                        ("split 2", "not understood"), ("drop 2 at 5-3", "ends before it starts"),
                        ("drop 2 at five", "'five' is not a frame span")]:  # fmt: skip
        with pytest.raises(ValueError, match=words):
            parse_fix(text)
    with pytest.raises(ValueError, match="frames 20-30 are none of the clip's video frames"):
        parse_fix("drop 1 at 20-30").rows(range(8))


def test_a_swap_undoes_a_switch_exactly(crossing):
    people = crossing.people()
    ids = [p.track_id for p in people]
    broken = swapped(people, 0, 2, slice(4, None))
    fixed, notes = fix_ids(broken, [f"swap {ids[0]} {ids[2]} at 4-"])
    assert all(same(p, q) for p, q in zip(fixed, people))
    assert notes == [f"swap {ids[0]} {ids[2]} at 4-: persons {ids[0]} and {ids[2]} traded frames 4-7"]
    # with the scene's video frame numbers 100..107 the same fix reads "at 104-"
    fixed, _ = fix_ids(broken, [f"swap {ids[0]} {ids[2]} at 104-"], numbers=range(100, 108))
    assert all(same(p, q) for p, q in zip(fixed, people))


def test_split_then_join_gives_the_person_back(crossing):
    people = crossing.people()
    b = people[1].track_id
    split, notes = fix_ids(people, [f"split {b} at 5-"])
    new = max(p.track_id for p in people) + 1
    assert [p.track_id for p in split] == [p.track_id for p in people] + [new]
    assert notes == [f"split {b} at 5-: frames 5-7 are a new person {new}'s"]
    kept, moved = split[1], split[-1]
    assert (kept.keypoints_conf[5:] == 0).all() and (kept.person_boxes[5:, 4] == 0).all()
    assert torch.equal(moved.keypoints2d[5:], people[1].keypoints2d[5:]) and (moved.keypoints_conf[:5] == 0).all()
    # where nobody is left, the 3D joints and cameras are the nearest posed frame's, the keypoints 0
    assert torch.equal(kept.joints3d[5:], people[1].joints3d[4:5].expand(3, -1, -1))
    assert torch.equal(moved.joints3d[:5], people[1].joints3d[5:6].expand(5, -1, -1))
    assert (kept.keypoints2d[5:] == 0).all()
    joined, notes = fix_ids(split, [f"join {new} into {b}"])
    assert all(same(p, q) for p, q in zip(joined, people)) and len(joined) == len(people)
    assert notes == [f"join {new} into {b}: person {new}'s frames 5-7 are person {b}'s"]


def test_drops_and_what_cannot_be_done(crossing):
    people = crossing.people()
    a, b, c = (p.track_id for p in people)
    dropped, notes = fix_ids(people, [f"drop {b} at 2-3", f"drop {a}"])
    assert [p.track_id for p in dropped] == [b, c]  # the main person gone: the next one leads
    assert (dropped[0].keypoints_conf[2:4] == 0).all() and (dropped[0].person_boxes[2:4, 4] == 0).all()
    assert torch.equal(dropped[0].keypoints_conf[4:], people[1].keypoints_conf[4:])
    assert notes == [f"drop {b} at 2-3: person {b} has nobody's pose in frames 2-3", f"drop {a}: person {a} removed"]
    _, notes = fix_ids(people, [f"drop {b} at 0-"])
    assert notes[-1] == f"person {b} has no frame left and goes"
    with pytest.raises(ValueError, match=rf"persons {a} and {b} are both in frames 0-7; drop one"):
        fix_ids(people, [f"join {b} into {a}"])
    with pytest.raises(ValueError, match=rf"no person 9 \(people: {a}, {b}, {c}\)"):
        fix_ids(people, ["swap 9 1"])
    with pytest.raises(ValueError, match=f"person {b} has no pose or box in those frames"):
        fix_ids(fix_ids(people, [f"drop {b} at 4-"])[0], [f"split {b} at 5-"])
    with pytest.raises(ValueError, match="the fixes leave nobody"):
        fix_ids(people, [f"drop {a}", f"drop {b}", f"drop {c}"])


def test_a_pose_file_keeps_its_fixes_and_lists_the_frames_to_check_again(crossing, tmp_path):
    people = crossing.people()
    broken = swapped(people, 0, 1, slice(3, None))
    est = PoseEstimates(keypoints2d=broken[0].keypoints2d, keypoints_conf=broken[0].keypoints_conf,
                        joints3d=broken[0].joints3d, cameras=broken[0].cameras, person_boxes=broken[0].person_boxes,
                        track_id=broken[0].track_id, others=tuple(broken[1:]), frame_indices=torch.arange(10, 18),
                        metadata={"people": [{"track_id": p.track_id, "check_ids": [99]} for p in people]})  # fmt: skip
    a, b = people[0].track_id, people[1].track_id
    fixed, notes = fix_estimates(est, [f"swap {a} {b} at 13-"])
    assert all(same(p, q) for p, q in zip(fixed.people(), people))
    assert fixed.metadata["id_fixes"] == [{"fixes": [f"swap {a} {b} at 13-"], "done": notes}]
    marks = frames_to_check(people)
    assert [r["check_ids"] for r in fixed.metadata["people"]] == [(10 + m.nonzero().flatten()).tolist() for m in marks]
    again = load_poses(save_poses(fixed, tmp_path / "fixed.npz"))
    assert all(same(p, q) for p, q in zip(again.people(), people))


def test_a_scene_reads_its_video_frame_numbers(crossing):
    scene = dataclasses.replace(crossing, metadata={**crossing.metadata, "frame_indices": list(range(40, 48))})
    b = scene.people()[1].track_id
    fixed, notes = fix_scene(scene, [f"drop {b} at 46-"])
    assert (fixed.people()[1].keypoints_conf[6:] == 0).all() and (fixed.people()[1].keypoints_conf[:6] > 0).any()
    assert fixed.metadata["id_fixes"][-1]["done"] == notes and torch.equal(fixed.gt.flow, scene.gt.flow)
    a = scene.people()[0].track_id
    led, _ = fix_scene(scene, [f"drop {a}"])  # the main person goes: the next leads, with its own truth
    truths = {t.track_id: t for t in scene.gt.truths([p.track_id for p in scene.people()])}
    assert led.track_id == b and torch.equal(led.gt.joints3d, truths[b].joints3d)
    assert torch.equal(led.gt.truths([b, a])[1].joints3d, truths[a].joints3d)


def test_the_sheet_draws_each_person_in_its_colour_where_it_is(crossing):
    people = crossing.people()
    rows = sheet_rows(people)
    assert rows == torch.stack(frames_to_check(people)).any(0).nonzero().flatten().tolist() and rows
    sheet = id_sheet(crossing.frames, people, crossing.keypoints_layout, rows=[0, 1, 2], columns=2, tile_width=256)
    assert sheet.shape == (3, 2 * 128, 2 * 256)  # 3 tiles of 256 x 128 (the frames doubled), 2 per line
    first = sheet[:, :128, :256]
    for p, person in enumerate(people):
        near = torch.zeros(128, 256, dtype=torch.bool)  # 6 px around the person's box, doubled
        x0, y0, x1, y1 = (2 * person.person_boxes[0, :4]).round().int().tolist()
        near[max(y0 - 6, 0):y1 + 7, max(x0 - 6, 0):x1 + 7] = True
        colour = torch.tensor(person_colour(p), dtype=torch.uint8)[:, None, None]
        painted = (first == colour).all(0)
        assert painted.any() and painted[near].sum() > 0.9 * painted.sum(), p
    assert person_colour(0) == MAIN_RGB
    with pytest.raises(ValueError, match="no frame to draw"):
        id_sheet(crossing.frames, people, crossing.keypoints_layout, rows=[])


def digest(folder) -> str:
    return hashlib.sha256(b"".join(f.read_bytes() for f in sorted(folder.rglob("*")) if f.is_file())).hexdigest()


def test_the_command_fixes_a_copy_and_draws_the_sheet(crossing, tmp_path, capsys):
    people = crossing.people()
    a, b = people[0].track_id, people[2].track_id
    save_scene(crossing.with_people(swapped(people, 0, 2, slice(4, None))), tmp_path / "scene")
    before = digest(tmp_path / "scene")
    assert main(["ids", str(tmp_path / "scene")]) == 0
    out = capsys.readouterr().out
    assert f"3 people (frames with them): {a} (8)" in out and "ids to check" in out and "--fix" in out
    fixed_people = load_scene(tmp_path / "scene").people()  # why each frame is listed: who overlaps whom there
    why = beside_line(fixed_people, frames_to_check(fixed_people), list(range(8)))
    assert f"  why: {why}\n" in out and " beside " in why
    args = ["ids", str(tmp_path / "scene"), "--fix", f"swap {a} {b} at 4-", "--out", str(tmp_path / "fixed"),
            "--sheet", str(tmp_path / "ids.png")]  # fmt: skip
    assert main(args) == 0
    out = capsys.readouterr().out
    assert f"persons {a} and {b} traded frames 4-7" in out and "wrote" in out and (tmp_path / "ids.png").is_file()
    assert digest(tmp_path / "scene") == before  # the input is never changed
    assert all(same(p, q) for p, q in zip(load_scene(tmp_path / "fixed").people(), people))
    save_poses(PoseEstimates(keypoints2d=people[0].keypoints2d, keypoints_conf=people[0].keypoints_conf,
                             track_id=a), tmp_path / "p.npz")  # fmt: skip
    cases = [(["--fix", "swap 0 1"], "--out: required with --fix"),
             (["--fix", f"drop {a}", "--out", str(tmp_path / "scene")], "is INPUT; write the fixed copy elsewhere"),
             (["--fix", f"drop {a}", "--out", str(tmp_path / "fixed")], "exists; add --overwrite"),
             (["--fix", "swop 0 1", "--out", str(tmp_path / "new")], "not understood"),
             (["--out", str(tmp_path / "new")], "nothing to write without --fix")]  # fmt: skip
    for extra, words in cases:
        assert main(["ids", str(tmp_path / "scene"), *extra]) == 2
        err = capsys.readouterr().err
        assert words in err and err.startswith("lit-boot ids: error: ") and len(err.splitlines()) == 1, err
    assert main(["ids", str(tmp_path / "fixed"), "--sheet", str(tmp_path / "all.png"), "--frames", "0-2, 6"]) == 0
    assert "wrote" in capsys.readouterr().out
    from lit_boot.data import read_png

    assert read_png(tmp_path / "all.png").shape[1:] == (64 * 480 // 128, 4 * 480)  # 4 tiles of 480 px in one line
    for extra, words in [(["--frames", "all"], "--frames: says which frames --sheet draws"),
                         (["--sheet", str(tmp_path / "x.png"), "--frames", "20"], "--frames: frames 20 are none")]:
        assert main(["ids", str(tmp_path / "fixed"), *extra]) == 2
        assert words in capsys.readouterr().err
    assert main(["ids", str(tmp_path / "p.npz"), "--sheet", str(tmp_path / "s.png")]) == 2
    assert "--sheet: needs the frames" in capsys.readouterr().err
    assert main(["ids", str(tmp_path / "none")]) == 2
    assert "no such scene folder or pose file" in capsys.readouterr().err
