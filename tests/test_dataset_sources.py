"""Dataset discovery (lit_boot.dataset.sources) and Task.load on tiny trees and the shared Sintel samples."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from lit_boot.data import save_scene
from lit_boot.data.readers import DatasetFormatError, PoseEstimates, read_sintel, read_video, save_poses
from lit_boot.dataset.chunks import plan_chunks, slice_scene
from lit_boot.dataset.sources import (
    discover,
    h36m_tasks,
    manifest_tasks,
    pw3d_tasks,
    scene_tasks,
    sintel_tasks,
    video_tasks,
)
from lit_boot.dataset.tasks import Task
from lit_boot.synth import make_scene


def _write_mp4(path: Path, T: int = 6, H: int = 24, W: int = 32) -> Path:
    y, x = np.mgrid[0:H, 0:W]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (W, H))
    for t in range(T):
        writer.write(np.stack([(x * 8 + 40 * t) % 256, y * 10, np.full_like(x, 30 * t)], -1).astype(np.uint8))
    writer.release()
    return path


def _poses(T: int) -> PoseEstimates:
    keypoints = torch.arange(T, dtype=torch.float32)[:, None, None] + torch.full((T, 17, 2), 5.0)
    return PoseEstimates(keypoints2d=keypoints, keypoints_conf=torch.full((T, 17), 0.8), source="test")


@pytest.fixture()
def videos(tmp_path: Path) -> Path:
    folder = tmp_path / "videos"
    folder.mkdir()
    _write_mp4(folder / "clip.mp4")
    save_poses(_poses(6), folder / "clip.npz")
    _write_mp4(folder / "Other.MOV", T=4)
    frames = folder / "walk"
    frames.mkdir()
    for t in range(3):
        cv2.imwrite(str(frames / f"{t:03d}.png"), np.full((24, 32, 3), 50 * t, dtype=np.uint8))
    (folder / "empty").mkdir()  # no frames: not a video
    (folder / "notes.txt").write_text("not a video")
    return folder


def test_sintel_selection_on_a_minimal_tree(tmp_path: Path) -> None:
    for scene in ("alley_2", "cave_4", "mountain_1"):
        (tmp_path / "training" / "final" / scene).mkdir(parents=True)
        for n in (1, 2, 3):
            (tmp_path / "training" / "final" / scene / f"frame_{n:04d}.png").write_bytes(b"")
    assert [t.name for t in sintel_tasks(tmp_path)] == ["alley_2", "cave_4", "mountain_1"]
    human = discover("sintel", tmp_path, scenes="human", reader_args={"size": [32, 64]})
    assert [t.name for t in human] == ["alley_2", "cave_4"]
    assert human[0].args == {"root": str(tmp_path), "scene": "alley_2", "pass_name": "final", "size": [32, 64]}
    assert [t.name for t in sintel_tasks(tmp_path, scenes=["mountain_1"])] == ["mountain_1"]
    with pytest.raises(FileNotFoundError, match=r"no Sintel scene \['bamboo_9'\]; it holds \['alley_2'"):
        sintel_tasks(tmp_path, scenes=["bamboo_9"])
    with pytest.raises(FileNotFoundError, match=r"training/clean: no such folder \(expected an MPI-Sintel root"):
        sintel_tasks(tmp_path, pass_name="clean")
    with pytest.raises(ValueError, match="pass_name"):
        sintel_tasks(tmp_path, pass_name="albedo")


def test_sintel_shared_samples_discover_and_load(shared: Path) -> None:
    root = shared / "data" / "sintel_samples"
    tasks = {t.name: t for t in discover("sintel", root)}
    assert {"alley_1", "market_5_0001-0004", "market_5_0008-0011", "temple_3"} <= set(tasks)
    assert tasks["market_5_0008-0011"].args == {"root": str(root), "scene": "market_5", "pass_name": "final",
                                                "first": 8, "last": 11}  # fmt: skip
    with pytest.raises(ValueError, match=r"none of the human scenes \['alley_2', 'bamboo_2', 'cave_2', 'cave_4'\]"):
        sintel_tasks(root, scenes="human")
    task = tasks["alley_1"]
    scene, direct = task.load(estimate=False), read_sintel(root, "alley_1")
    assert torch.equal(scene.frames, direct.frames) and torch.equal(scene.gt.flow, direct.gt.flow)
    assert scene.metadata == direct.metadata
    part = Task("alley_1--00001-00004", "sintel", task.args, frames=(1, 4), parent="alley_1").load(estimate=False)
    assert torch.equal(part.gt.flow, direct.gt.flow[1:3]) and torch.equal(part.gt.flow_valid, direct.gt.flow_valid[1:3])
    assert part.metadata["frames"] == [2, 3, 4] and part.metadata["gt_pairs"] == [[2, 3]]
    window = Task.from_dict(json.loads(json.dumps(tasks["market_5_0008-0011"].to_dict()))).load(estimate=False)
    assert window.metadata["frames"] == [8, 9, 10, 11]


def _write_3dpw(root: Path, name: str, split: str, persons: int, T: int = 3) -> None:
    rng = np.random.default_rng(0)
    poses = np.tile(np.eye(4), (T, 1, 1))
    poses[:, 2, 3] = 3.0
    data = {"jointPositions": [rng.uniform(-0.5, 0.5, (T, 72)) for _ in range(persons)], "cam_poses": poses,
            "cam_intrinsics": np.array([[40.0, 0, 11.5], [0, 40.0, 7.5], [0, 0, 1]]),
            "campose_valid": [np.ones(T) for _ in range(persons)],
            "poses2d": [rng.uniform(0, 20, (T, 3, 18)) for _ in range(persons)]}  # fmt: skip
    (root / "sequenceFiles" / split).mkdir(parents=True, exist_ok=True)
    (root / "sequenceFiles" / split / f"{name}.pkl").write_bytes(pickle.dumps(data, protocol=2))
    (root / "imageFiles" / name).mkdir(parents=True, exist_ok=True)
    for t in range(T):
        cv2.imwrite(str(root / "imageFiles" / name / f"image_{t:05d}.jpg"), np.full((16, 24, 3), 60, np.uint8))


def test_3dpw_tasks_one_per_person(tmp_path: Path) -> None:
    _write_3dpw(tmp_path, "downtown_walk_00", "test", persons=2)
    _write_3dpw(tmp_path, "office_phone_00", "test", persons=1)
    _write_3dpw(tmp_path, "courtyard_basket_00", "train", persons=1)
    tasks = pw3d_tasks(tmp_path)
    assert [t.name for t in tasks] == ["downtown_walk_00_p0", "downtown_walk_00_p1", "office_phone_00_p0"]
    assert tasks[1].args == {"root": str(tmp_path), "sequence": "downtown_walk_00", "split": "test", "person": 1}
    assert [t.name for t in discover("3dpw", tmp_path, split=None, sequences=["courtyard_basket_00"])] == [
        "courtyard_basket_00_p0"
    ]
    assert [t.name for t in pw3d_tasks(tmp_path, persons=1, sequences=["downtown_walk_00"])] == ["downtown_walk_00_p1"]
    scene = tasks[1].load()
    assert scene.num_frames == 3 and scene.metadata["person"] == 1
    with pytest.raises(ValueError, match=r"sequenceFiles/validation: found no 3DPW sequence"):
        pw3d_tasks(tmp_path, split="validation")
    with pytest.raises(FileNotFoundError, match="no such folder"):
        pw3d_tasks(tmp_path / "nowhere")
    with pytest.raises(ValueError, match="persons: expected 'all'"):
        pw3d_tasks(tmp_path, persons="first")


def test_h36m_tasks_papers_protocol(tmp_path: Path) -> None:
    world = np.zeros((10, 32, 3))
    np.savez(tmp_path / "data_3d_h36m.npz", positions_3d={"S9": {"Walking 1": world, "Eating": world},
                                                          "S11": {"Walking 1": world}})  # fmt: skip
    for subject, action in [("S9", "Walking 1"), ("S11", "Walking 1")]:
        (tmp_path / subject / "Videos" / f"{action}.60457274").mkdir(parents=True)
    with pytest.raises(FileNotFoundError, match=r"no frames for \['.*S9/Videos/Eating.60457274.mp4'\]"):
        h36m_tasks(tmp_path)
    tasks = discover("h36m", tmp_path, actions=["Walking 1"])
    assert [t.name for t in tasks] == ["S9_Walking_1", "S11_Walking_1"]
    assert tasks[0].args == {"root": str(tmp_path), "subject": "S9", "action": "Walking 1"}
    (tmp_path / "S9" / "Videos" / "Eating.60457274.mp4").write_bytes(b"")
    assert len(h36m_tasks(tmp_path, subjects=["S9"])) == 2
    with pytest.raises(ValueError, match="no subject 'S5'"):
        h36m_tasks(tmp_path, subjects=["S5"])


def test_video_tasks_with_a_pose_file_beside(videos: Path) -> None:
    tasks = {t.name: t for t in discover("videos", videos, reader_args={"stride": 1})}
    assert sorted(tasks) == ["Other", "clip", "walk"]
    assert tasks["clip"].poses == str(videos / "clip.npz") and tasks["clip"].args == {"path": str(videos / "clip.mp4"),
                                                                                        "stride": 1}  # fmt: skip
    assert tasks["Other"].poses is None and tasks["walk"].poses is None
    scene, direct = tasks["clip"].load(), read_video(videos / "clip.mp4", poses=videos / "clip.npz")
    assert torch.equal(scene.frames, direct.frames) and torch.equal(scene.keypoints2d, direct.keypoints2d)
    for chunk in plan_chunks(tasks["clip"], scene.num_frames, 4, 2):  # decodes only up to the chunk's end
        part, expected = chunk.load(), slice_scene(scene, *chunk.frames)
        assert torch.equal(part.frames, expected.frames) and torch.equal(part.keypoints2d, expected.keypoints2d)
        assert part.metadata == expected.metadata
    strided = Task("clip", "video", {"path": str(videos / "clip.mp4"), "stride": 2}, poses=str(videos / "clip.npz"))
    whole = strided.load()
    part = Task(**{**strided.to_dict(), "frames": (1, 3), "parent": "clip", "name": "clip--00001-00003"}).load()
    assert part.metadata["frame_indices"] == whole.metadata["frame_indices"][1:3]  # source frames, read cut
    assert torch.equal(part.frames, whole.frames[1:3]) and part.metadata == slice_scene(whole, 1, 3).metadata
    save_poses(_poses(6), videos / "clip.json")
    with pytest.raises(ValueError, match="two pose files beside it"):
        video_tasks(videos)


def test_video_without_poses_gets_mediapipe_on_its_frames(videos: Path, monkeypatch) -> None:
    seen = []

    def fake_estimate_poses(scene):
        seen.append(scene.metadata["frame_indices"])
        T = scene.num_frames
        return PoseEstimates(keypoints2d=torch.full((T, 17, 2), 3.0), keypoints_conf=torch.ones(T, 17),
                             frame_indices=torch.tensor(scene.metadata["frame_indices"]),
                             image_size=(scene.height, scene.width), source="fake")  # fmt: skip

    monkeypatch.setattr("lit_boot.estimate.estimate_poses", fake_estimate_poses)
    task = Task("other", "video", {"path": str(videos / "Other.MOV")}, frames=(1, 3))
    scene = task.load()
    assert seen == [[1, 2]] and scene.num_frames == 2 and scene.metadata["pose_estimates"][0]["source"] == "fake"
    assert task.load(estimate=False).keypoints2d is None and len(seen) == 1


def test_any_scene_without_estimates_gets_mediapipe_and_a_pose_folder_is_used_first(
    videos: Path, scenes, tmp_path: Path, monkeypatch
) -> None:
    seen = []

    def fake_estimate_poses(scene):
        seen.append(scene.num_frames)
        T = scene.num_frames
        return PoseEstimates(keypoints2d=torch.full((T, 17, 2), 3.0), keypoints_conf=torch.ones(T, 17),
                             image_size=(scene.height, scene.width), source="fake")  # fmt: skip

    monkeypatch.setattr("lit_boot.estimate.estimate_poses", fake_estimate_poses)
    folder = tmp_path / "poses"
    folder.mkdir()
    save_poses(_poses(6), folder / "clip.npz")
    tasks = {t.name: t for t in discover("videos", videos, poses=folder)}
    assert tasks["clip"].poses == str(folder / "clip.npz") and tasks["Other"].poses is None
    assert torch.equal(tasks["clip"].load().keypoints2d, _poses(6).keypoints2d) and seen == []
    assert tasks["Other"].load().metadata["pose_estimates"][0]["source"] == "fake" and len(seen) == 1
    own = discover("scenes", scenes[0])[0].load()  # a scene with estimates of its own keeps them
    assert own.joints3d is not None and len(seen) == 1
    with pytest.raises(ValueError, match="no pose file named after any scene"):
        discover("videos", videos, poses=tmp_path)


def test_bad_videos_name_the_file(tmp_path: Path) -> None:
    (tmp_path / "corrupt.mp4").write_bytes(b"\x00\x01 not a video" * 50)
    (tmp_path / "empty.mp4").write_bytes(b"")
    for name in ("corrupt.mp4", "empty.mp4"):
        with pytest.raises(DatasetFormatError, match=rf"{name}: "):
            Task("v", "video", {"path": str(tmp_path / name)}).load()
    with pytest.raises(FileNotFoundError, match="missing.mp4: no such video file"):
        Task("v", "video", {"path": str(tmp_path / "missing.mp4")}).load()
    with pytest.raises(FileNotFoundError, match="nowhere: no such scene folder"):
        Task("s", "scene", {"path": str(tmp_path / "nowhere")}).load()
    with pytest.raises(ValueError, match=r"task 's': args \['path', 'stride'\] do not fit read_sintel"):
        Task("s", "sintel", {"path": "x", "stride": 2}).load()
    with pytest.raises(ValueError, match="kind 'scene' takes args"):
        Task("s", "scene", {"path": "x", "resize": 2}).load()


@pytest.fixture(scope="module")
def scenes(tmp_path_factory) -> tuple[Path, dict]:
    folder = tmp_path_factory.mktemp("scenes")
    made = {name: make_scene(frames=3, height=32, width=48, seed=seed) for seed, name in enumerate(["a", "b b"])}
    for name, scene in made.items():
        save_scene(scene, folder / name)
    (folder / "not_a_scene").mkdir()
    return folder, made


def test_scene_folders_discover_and_load(scenes) -> None:
    folder, made = scenes
    tasks = discover("scenes", folder)
    assert [(t.name, t.kind) for t in tasks] == [("a", "scene"), ("b_b", "scene")]
    for task, original in zip(tasks, made.values()):
        scene = task.load()
        assert torch.equal(scene.frames, original.frames) and torch.equal(scene.gt.flow, original.gt.flow)
        assert torch.equal(scene.joints3d, original.joints3d) and scene.metadata == original.metadata
    with pytest.raises(ValueError, match=r"not_a_scene: found no scene folder"):
        scene_tasks(folder / "not_a_scene")


def test_list_file_text(scenes, videos: Path) -> None:
    folder, _ = scenes
    lists = videos.parent / "lists"
    lists.mkdir()
    (lists / "scenes.txt").write_text(
        "# my scenes\n"
        "../videos/clip.mp4   ../videos/clip.npz   # with poses\n"
        f"{folder / 'a'}\n"
        "\n"
        '"../videos/walk"\n'
        "../videos/Other.MOV  # a#b is no comment\n"
    )  # fmt: skip
    tasks = discover("list", lists / "scenes.txt")
    kinds = [("clip", "video"), ("a", "scene"), ("walk", "video"), ("Other", "video")]
    assert [(t.name, t.kind) for t in tasks] == kinds
    assert tasks[0].args == {"path": str(videos / "clip.mp4")} and tasks[0].poses == str(videos / "clip.npz")
    assert tasks[1].args == {"path": str(folder / "a")} and tasks[1].load().num_frames == 3
    (lists / "bad.txt").write_text("../videos/clip.mp4\n../videos/gone.mp4\n")
    with pytest.raises(FileNotFoundError, match=r"bad.txt:2: .*gone.mp4: no such scene folder, video"):
        manifest_tasks(lists / "bad.txt")
    (lists / "wide.txt").write_text("a b c\n")
    with pytest.raises(ValueError, match=r"wide.txt:1: expected 'PATH \[POSE_FILE\]', got 3 columns"):
        manifest_tasks(lists / "wide.txt")
    (lists / "empty.txt").write_text("# nothing\n")
    with pytest.raises(ValueError, match="empty.txt: lists no scene"):
        manifest_tasks(lists / "empty.txt")


def test_list_file_json_and_yaml(videos: Path, tmp_path: Path) -> None:
    entries = [Task("clip", "video", {"path": "videos/clip.mp4"}, poses="videos/clip.npz").to_dict(),
               {"name": "s1", "kind": "sintel", "args": {"root": "/data/sintel", "scene": "alley_2"},
                "frames": [0, 10]}]  # fmt: skip
    (tmp_path / "tasks.json").write_text(json.dumps(entries))
    tasks = manifest_tasks(tmp_path / "tasks.json")
    assert tasks[0].args == {"path": str(videos / "clip.mp4")} and tasks[0].poses == str(videos / "clip.npz")
    assert tasks[1].args == {"root": "/data/sintel", "scene": "alley_2"} and tasks[1].frames == (0, 10)
    assert tasks[0].load().num_frames == 6
    import yaml

    (tmp_path / "tasks.yaml").write_text(yaml.safe_dump(entries))
    assert manifest_tasks(tmp_path / "tasks.yaml") == tasks
    (tmp_path / "twice.json").write_text(json.dumps([entries[0], entries[0]]))
    with pytest.raises(ValueError, match=r"twice.json: task names repeat: \['clip'\]"):
        manifest_tasks(tmp_path / "twice.json")
    (tmp_path / "odd.json").write_text(json.dumps([{"name": "x", "kind": "movie"}]))
    with pytest.raises(ValueError, match=r"odd.json: task 0: ValueError: .*kind 'movie' is not one of"):
        manifest_tasks(tmp_path / "odd.json")
    (tmp_path / "broken.yaml").write_text("- {name: [")
    with pytest.raises(ValueError, match="broken.yaml: unreadable YAML"):
        manifest_tasks(tmp_path / "broken.yaml")


def test_discover_errors(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"source: expected one of \('sintel', '3dpw'"):
        discover("kitti", tmp_path)
    with pytest.raises(ValueError, match=r"discover 'videos': bad options \['scenes'\]"):
        discover("videos", tmp_path, scenes="human")
    with pytest.raises(FileNotFoundError, match=r"nowhere: no such folder \(expected a folder of videos"):
        discover("videos", tmp_path / "nowhere")
    with pytest.raises(ValueError, match=r"found no video file \(.mp4, .avi, .mov, .mkv, .webm\) or folder of frames"):
        discover("videos", tmp_path)
    with pytest.raises(FileNotFoundError, match="list.txt: no such list file"):
        discover("list", tmp_path / "list.txt")
    with pytest.raises(ValueError, match="found no scene folder"):
        discover("scenes", tmp_path)
    with pytest.raises(FileNotFoundError, match="no such file"):
        discover("h36m", tmp_path)
