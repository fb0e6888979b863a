"""External multi-person keypoint files read with every person: by the file's track ids, or linked
by the person tracker when it has none (two people crossing keep their ids)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from PIL import Image

from lit_boot import load_scene
from lit_boot.cli import main
from lit_boot.data.readers import DatasetFormatError, read_estimates
from lit_boot.estimate import link_keypoint_people, read_tracked_estimates

T = 8
XA = lambda t: 60.0 + 12 * t  # noqa: E731  (A's left edge, px)
XB = lambda t: 160.0 - 12 * t  # noqa: E731


def person(x: float, y: float, size: float, score: float = 0.9) -> list[float]:
    """17 keypoints (flat x, y, v) on a size x 2 size grid with its top-left corner at (x, y)."""
    return [v for k in range(17) for v in (x + size * (k % 4) / 3, y + 2 * size * (k // 4) / 4, score)]


def crossing(track_ids: bool, tmp_path, shuffle: bool = True):
    """A COCO results file: A (large, walking right) and B (smaller, walking left) cross at t 3-4;
    the detections of a frame in a random order; a stray detection in frame 5 only."""
    rng = np.random.default_rng(0)
    results = []
    for t in range(T):
        dets = [("A", person(XA(t), 40, 40)), ("B", person(XB(t), 50, 30))]
        if t == 5:
            dets.append(("C", person(300, 10, 10, 0.3)))
        if shuffle:
            rng.shuffle(dets)
        for name, kp in dets:
            entry = {"image_id": t, "category_id": 1, "keypoints": kp, "score": 0.9}
            if track_ids:
                entry["track_id"] = {"A": 7, "B": 3, "C": 11}[name]
            results.append(entry)
    path = tmp_path / "results.json"
    path.write_text(json.dumps(results))
    return path


def x_of(keypoints: torch.Tensor) -> torch.Tensor:
    return keypoints[:, 0, 0]


def test_the_files_track_ids_give_every_person(tmp_path):
    est = read_estimates(crossing(True, tmp_path), person="all")
    assert [p.track_id for p in est.people()] == [7, 3, 11]  # by prominence: A, B, then C
    a, b, c = est.people()
    assert torch.allclose(x_of(a.keypoints2d), XA(torch.arange(T).float()))
    assert torch.allclose(x_of(b.keypoints2d), XB(torch.arange(T).float()))
    assert (c.keypoints_conf.sum(-1) > 0).tolist() == [t == 5 for t in range(T)]
    assert est.metadata["linked_by"] == "track_id"


def test_without_track_ids_the_tracker_links_them_through_the_crossing(tmp_path):
    path = crossing(False, tmp_path)
    with pytest.raises(DatasetFormatError, match=r"results.json: person 'all': not every detection has a track_id"):
        read_estimates(path, person="all")
    est = read_tracked_estimates(path)
    assert est.num_people == 2 and est.metadata["linked_by"] == "tracker"  # C, seen once, dropped
    a, b = est.people()
    assert torch.allclose(x_of(a.keypoints2d), XA(torch.arange(T).float()))  # no identity switch
    assert torch.allclose(x_of(b.keypoints2d), XB(torch.arange(T).float()))
    assert (a.keypoints_conf > 0).all() and (b.keypoints_conf > 0).all()
    assert read_tracked_estimates(path, people="largest").num_people == 1
    assert read_tracked_estimates(crossing(True, tmp_path), people=2).num_people == 2


def test_link_labels_each_detection_and_leaves_strays_out():
    people = [[np.array(person(0, 0, 20), dtype=float).reshape(17, 3)] for _ in range(3)]
    people[1].append(np.zeros((17, 3)))  # nothing found: no box
    labels = link_keypoint_people(people)
    assert labels == [[0], [0, -1], [0]]


def test_import_reads_every_person_of_a_pose_file(tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    for t in range(T):
        Image.fromarray(np.full((120, 320, 3), 40 * (t % 4), np.uint8)).save(frames / f"{t:03d}.png")
    path = crossing(False, tmp_path)
    out = tmp_path / "scene"
    assert main(["import", "video", str(frames), "--poses", str(path), "--people", "all", "--out", str(out)]) == 0
    scene = load_scene(out)
    assert scene.num_people == 2 and torch.allclose(x_of(scene.keypoints2d), XA(torch.arange(T).float()))
    one = tmp_path / "one"
    assert main(["import", "video", str(frames), "--poses", str(path), "--out", str(one)]) == 0
    assert load_scene(one).num_people == 1
