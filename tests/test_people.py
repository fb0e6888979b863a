"""Several people in one scene: Scene.others, PoseEstimates with a person axis, the pose file
version 2 (version 1 still read), saved scenes and chunks that keep every person."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from lit_boot.core import Cameras, Person, Scene, SceneValidationError
from lit_boot.data.readers import PoseEstimates, load_poses, save_poses
from lit_boot.data.scene_io import load_scene, save_scene
from lit_boot.dataset.chunks import slice_scene

T, K = 4, 17


def person_fields(seed: int, T: int = T) -> dict:
    g = torch.Generator().manual_seed(seed)
    conf = torch.rand(T, K, generator=g)
    conf[1] = 0  # absent in frame 1
    boxes = torch.tensor([[10.0 + seed, 20.0, 60.0 + seed, 120.0, 0.9]] * T)
    boxes[1] = 0
    cams = Cameras("weak_perspective", torch.tensor([[0.9, 0.01 * seed, 0.2]] * T),
                   torch.tensor([[0.5, 30.0 * seed, 20.0]] * T))  # fmt: skip
    return dict(keypoints2d=torch.rand(T, K, 2, generator=g) * 100, keypoints_conf=conf,
                joints3d=torch.randn(T, 14, 3, generator=g) * 300, cameras=cams, person_boxes=boxes)  # fmt: skip


def three_people(**kw) -> PoseEstimates:
    others = (Person(track_id=4, **person_fields(1)), Person(track_id=2, **person_fields(2)))
    return PoseEstimates(**person_fields(0), track_id=7, others=others, image_size=(240, 320), source="test", **kw)


def same_person(a: Person, b: Person) -> None:
    assert a.track_id == b.track_id
    for key in ("joints3d", "keypoints2d", "keypoints_conf", "person_boxes"):
        assert torch.equal(getattr(a, key), getattr(b, key)), key
    assert torch.equal(a.cameras.params, b.cameras.params) and torch.equal(a.cameras.crops, b.cameras.crops)


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_a_pose_file_keeps_every_person(tmp_path, suffix):
    est = three_people()
    back = load_poses(save_poses(est, tmp_path / f"people{suffix}"))
    assert back.num_people == 3 and [p.track_id for p in back.people()] == [7, 4, 2]
    for a, b in zip(est.people(), back.people()):
        same_person(a, b)


def test_a_version_1_file_reads_as_one_person(tmp_path):
    f = person_fields(0)
    header = {"format": "lit-boot-pose-estimates", "version": 1, "image_size": [240, 320],
              "cameras": {"model": "weak_perspective", "crop_size": 224.0}}  # fmt: skip
    arrays = {"frame_indices": np.arange(T), "keypoints2d": f["keypoints2d"].numpy(),
              "keypoints_conf": f["keypoints_conf"].numpy(), "joints3d": f["joints3d"].numpy(),
              "cameras_params": f["cameras"].params.numpy(), "cameras_crops": f["cameras"].crops.numpy(),
              "person_boxes": f["person_boxes"].numpy()}  # fmt: skip
    np.savez(tmp_path / "v1.npz", header=np.array(json.dumps(header)), **arrays)
    back = load_poses(tmp_path / "v1.npz")
    assert back.num_people == 1 and back.track_id == 0
    same_person(back.people()[0], Person(track_id=0, **f))


def test_apply_to_gives_the_scene_every_person_rescaled_and_selected():
    est = three_people(frame_indices=torch.tensor([0, 2, 4, 6]))
    scene = Scene(torch.zeros(2, 3, 120, 160, dtype=torch.uint8), metadata={"frame_indices": [2, 6]})
    out = est.apply_to(scene)  # rows 1 and 3, half the size
    assert out.num_people == 3 and out.track_id == 7 and [p.track_id for p in out.others] == [4, 2]
    for mine, theirs in zip(out.people(), est.people()):
        assert torch.allclose(mine.keypoints2d, (theirs.keypoints2d[[1, 3]] + 0.5) / 2 - 0.5)
        assert torch.allclose(mine.person_boxes[:, :4], (theirs.person_boxes[[1, 3], :4] + 0.5) / 2 - 0.5)
        assert torch.equal(mine.keypoints_conf, theirs.keypoints_conf[[1, 3]])
    assert out.metadata["pose_estimates"][-1]["people"] == [7, 4, 2]
    single = out.person(2)
    assert single.num_people == 1 and single.track_id == 2
    assert torch.equal(single.keypoints2d, out.others[1].keypoints2d)
    assert single.frames is out.frames


def test_the_people_are_validated_by_name():
    f = person_fields(0)
    with pytest.raises(SceneValidationError, match=r"others\[0\].keypoints_conf: expected shape"):
        PoseEstimates(**f, others=(Person(track_id=1, **(f | {"keypoints_conf": torch.ones(T, 5)})),))
    with pytest.raises(SceneValidationError, match="track ids must be unique"):
        PoseEstimates(**f, track_id=3, others=(Person(track_id=3, **f),))
    with pytest.raises(SceneValidationError, match=r"others\[0\]: expected the main person's fields"):
        PoseEstimates(**f, others=(Person(track_id=1, keypoints2d=f["keypoints2d"], keypoints_conf=f["keypoints_conf"]),
                                   ))  # fmt: skip
    with pytest.raises(SceneValidationError, match="others: expected a tuple"):
        Scene(torch.zeros(T, 3, 8, 8, dtype=torch.uint8), **f, others=[Person(track_id=1, **f)])
    scene = Scene(torch.zeros(T, 3, 8, 8, dtype=torch.uint8), **f, others=(Person(track_id=1, **f),))
    with pytest.raises(IndexError, match="person 2 of 2"):
        scene.person(2)
    assert "people: 2" in scene.summary()


def test_a_saved_scene_and_its_chunks_keep_every_person(tmp_path):
    est = three_people()
    scene = est.apply_to(Scene(torch.randint(0, 255, (T, 3, 240, 320), dtype=torch.uint8)))
    back = load_scene(save_scene(scene, tmp_path / "scene"))
    assert back.num_people == 3
    for a, b in zip(scene.people(), back.people()):
        same_person(a, b)
    cut = slice_scene(scene, 1, 3)
    assert cut.num_people == 3
    for a, b in zip(cut.people(), scene.people()):
        assert torch.equal(a.keypoints2d, b.keypoints2d[1:3]) and torch.equal(a.cameras.crops, b.cameras.crops[1:3])


def test_a_synthetic_scene_with_several_people_is_cut_with_every_persons_truth():
    from lit_boot.synth import make_scene

    scene = make_scene(frames=5, height=64, width=128, people=2, seed=0)
    cut = slice_scene(scene, 1, 4)
    assert cut.num_people == 2 and len(cut.gt.others) == 1
    assert torch.equal(cut.gt.others[0].person_mask, scene.gt.others[0].person_mask[1:4])
    assert torch.equal(cut.others[0].keypoints2d, scene.others[0].keypoints2d[1:4])
    assert "ground truth: flow" in cut.summary() and "every person's (2 people)" in cut.summary()
    assert "every person's" not in make_scene(frames=3, height=64, width=128, seed=0).summary()
