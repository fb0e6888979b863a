"""Pose estimation for any video with MediaPipe Pose (lit_boot.estimate, ``lit-boot estimate-pose``).

The conversions run without MediaPipe; tests marked ``mediapipe`` need the extra and skip
(reason "needs the mediapipe extra") when it is not importable.
"""

from __future__ import annotations

import importlib.util
import sys

import cv2
import pytest
import torch

from lit_boot.cli import main
import lit_boot
from lit_boot.core import COCO17, LSP14, MEDIAPIPE33, Cameras, map_joints
from lit_boot.core.joints import MEDIAPIPE33_TO_COCO17
from lit_boot.data.readers.pose_file import load_poses
from lit_boot.estimate import (
    HEAD_TOP_FACTOR,
    MediaPipeUnavailable,
    fit_cameras,
    import_mediapipe,
    landmark_confidence,
    landmarks_to_coco17,
    poses_from_landmarks,
    world_to_lsp14,
)



def _have_mediapipe() -> bool:
    try:
        return importlib.util.find_spec("mediapipe") is not None
    except (ImportError, ValueError):  # ValueError: sys.modules["mediapipe"] is None (blocked)
        return False


HAVE_MEDIAPIPE = _have_mediapipe()
needs_mediapipe = pytest.mark.skipif(
    not HAVE_MEDIAPIPE, reason='needs the mediapipe extra: pip install -e ".[mediapipe]"'
)
VIDEO = "data/videos/football_720p_10f"


def _world(T: int = 1, seed: int = 0) -> torch.Tensor:
    """A standing person's 33 MediaPipe world landmarks (T, 33, 3) metres, hips at the origin,
    y down, with small per-frame noise."""
    pos = {
        "nose": (0.0, -0.62, -0.1), "left_ear": (0.07, -0.60, 0.0), "right_ear": (-0.07, -0.60, 0.0),
        "left_shoulder": (0.18, -0.42, 0.0), "right_shoulder": (-0.18, -0.42, 0.0),
        "left_elbow": (0.22, -0.15, 0.05), "right_elbow": (-0.22, -0.15, 0.05),
        "left_wrist": (0.25, 0.08, 0.0), "right_wrist": (-0.25, 0.08, -0.1),
        "left_hip": (0.1, 0.0, 0.0), "right_hip": (-0.1, 0.0, 0.0), "left_knee": (0.11, 0.42, 0.05),
        "right_knee": (-0.11, 0.42, -0.05), "left_ankle": (0.12, 0.82, 0.1), "right_ankle": (-0.12, 0.82, 0.0),
    }  # fmt: skip
    def where(name: str) -> tuple[float, float, float]:  # face -> nose, hand -> wrist, foot -> ankle
        side = name.split("_")[0]
        if name in pos:
            return pos[name]
        if any(part in name for part in ("heel", "foot")):
            return pos[f"{side}_ankle"]
        return pos[f"{side}_wrist"] if any(p in name for p in ("pinky", "index", "thumb")) else pos["nose"]

    base = torch.tensor([where(name) for name in MEDIAPIPE33.names])
    g = torch.Generator().manual_seed(seed)
    return base + 0.01 * torch.randn(T, 33, 3, generator=g)


def test_mediapipe33_to_coco17_keypoints_and_confidences():
    landmarks = torch.arange(33 * 2, dtype=torch.float32).reshape(1, 33, 2)
    conf = torch.linspace(0.0, 1.0, 33)[None]
    kp, kc = landmarks_to_coco17(landmarks, conf)
    assert kp.shape == (1, 17, 2) and kc.shape == (1, 17)
    idx = list(MEDIAPIPE33_TO_COCO17)
    assert torch.equal(kp[0], landmarks[0, idx]) and torch.equal(kc[0], conf[0, idx])
    assert idx[0] == MEDIAPIPE33.index("nose") and idx[16] == MEDIAPIPE33.index("right_ankle")
    # visibility x presence, in [0, 1]
    conf = landmark_confidence(torch.tensor([0.5, 1.2]), torch.tensor([0.5, 1.0]))
    assert torch.allclose(conf, torch.tensor([0.25, 1.0]))


def test_world_landmarks_to_lsp14_in_mm_with_a_head_top():
    world = _world(2)
    joints = world_to_lsp14(world)
    assert joints.shape == (2, 14, 3)
    mm = world * 1000 - (world[:, [23, 24]] * 1000).mean(1, keepdim=True)
    for name in ("right_ankle", "left_knee", "right_hip", "left_wrist", "right_shoulder"):
        assert torch.allclose(joints[:, LSP14.index(name)], mm[:, MEDIAPIPE33.index(name)], atol=1e-3)
    assert torch.allclose(joints[:, list(LSP14.root)].mean(1), torch.zeros(2, 3), atol=1e-3)
    neck, head = joints[:, LSP14.index("neck")], joints[:, LSP14.index("head_top")]
    assert torch.allclose(neck, mm[:, [11, 12]].mean(1), atol=1e-3)
    ears = mm[:, [7, 8]].mean(1)
    assert torch.allclose(head, ears + HEAD_TOP_FACTOR * (ears - neck), atol=1e-3)
    assert (head[:, 1] < ears[:, 1] - 80).all()  # 10+ cm above the ears (y down)


def test_fitted_camera_reprojects_the_joints_onto_the_keypoints():
    T = 4
    world = _world(T, seed=1)
    joints = world_to_lsp14(world)
    true = Cameras("weak_perspective", torch.tensor([[0.9, 0.1, -0.2]]).repeat(T, 1),
                   torch.tensor([[0.5, 300.0, 200.0]]).repeat(T, 1))  # fmt: skip
    mp_mm = world * 1000 - (world[:, [23, 24]] * 1000).mean(1, keepdim=True)
    landmarks = true.project(mp_mm) + 2.0 * torch.randn(T, 33, 2, generator=torch.Generator().manual_seed(3))
    conf = torch.full((T, 33), 0.9)
    landmarks[:, MEDIAPIPE33.index("left_wrist")] += 400.0  # a wild keypoint ...
    conf[:, MEDIAPIPE33.index("left_wrist")] = 1e-4  # ... that the detector doubts
    kp, kc = landmarks_to_coco17(landmarks, conf)
    cams = fit_cameras(joints, kp, kc)
    assert cams.model == "weak_perspective" and cams.crops.shape == (T, 3) and torch.isfinite(cams.params).all()
    target, _, w = map_joints(kp, "coco17", LSP14, kc)
    err = (cams.project(joints) - target).norm(dim=-1)[:, :13]
    good = w[:, :13] > 0.5
    assert err[good].max() < 8.0 and err[good].median() < 4.0, err
    size = (kp.amax(1) - kp.amin(1)).amax(-1)  # the crop holds the person (HMR: side 1.2 x box)
    assert torch.allclose(cams.crops[:, 0] * (size * 1.2 + 1), torch.full((T,), 224.0), rtol=1e-4)


def test_frames_without_a_person_are_kept_with_zero_confidence_and_filled():
    T = 5
    world = _world(T)
    landmarks = torch.rand(T, 33, 2, generator=torch.Generator().manual_seed(0)) * 50 + 100
    conf = torch.full((T, 33), 0.8)
    found = torch.tensor([True, True, False, True, True])
    landmarks[2], conf[2], world[2] = 0.0, 0.0, 0.0
    landmarks[4] += 300.0  # jumps far away: another person?
    est = poses_from_landmarks(landmarks, conf, world, found, (480, 640), torch.arange(10, 15))
    assert est.num_frames == T and est.source == "mediapipe-0.10.14" and est.image_size == (480, 640)
    assert torch.equal(est.found(), found)
    assert (est.keypoints_conf[2] == 0).all() and (est.keypoints2d[2] == 0).all()
    assert torch.equal(est.joints3d[2], est.joints3d[1])  # nearest frame with a person (earlier on ties)
    assert torch.equal(est.cameras.params[2], est.cameras.params[1]) and torch.isfinite(est.joints3d).all()
    assert est.metadata["missing_frames"] == [12] and est.metadata["filled_from"] == [[12, 11]]
    assert est.metadata["jumps"] == [14] and est.keypoints_conf[4].min() > 0  # flagged, kept
    dropped = poses_from_landmarks(landmarks, conf, world, found, (480, 640), on_jump="drop")
    assert dropped.metadata["missing_frames"] == [2, 4] and (dropped.keypoints_conf[4] == 0).all()
    assert torch.equal(dropped.joints3d[4], dropped.joints3d[3])
    nobody = poses_from_landmarks(landmarks * 0, conf * 0, world, torch.zeros(T, dtype=torch.bool), (480, 640))
    assert nobody.cameras is None and (nobody.keypoints_conf == 0).all() and len(nobody.metadata["missing_frames"]) == T


def test_keypoints_far_outside_the_frame_are_dropped_not_refused():
    T = 4
    landmarks = torch.rand(T, 33, 2, generator=torch.Generator().manual_seed(1)) * 50 + 100
    conf = torch.full((T, 33), 0.8)
    landmarks[1, 27:33, 1] = 2 * 218 + 1.0  # a cut-off leg's ankles and feet, extrapolated below the frame
    landmarks[2] += 2000.0  # every keypoint far outside: nobody in this frame
    landmarks[3, 23:33, 1] = -218 - 5.0  # hips and legs far above the frame: no person in the picture
    est = poses_from_landmarks(landmarks, conf, _world(T), torch.ones(T, dtype=torch.bool), (218, 512))
    ankles = [COCO17.names.index(n) for n in ("left_ankle", "right_ankle")]
    assert (est.keypoints_conf[1, ankles] == 0).all() and (est.keypoints_conf[1, :15] > 0).all()
    assert est.found().tolist() == [True, True, False, False] and est.metadata["far_outside_dropped"] == 2 + 17 + 17
    scene = lit_boot.make_scene(motion="run", frames=T, height=218, width=512, seed=0)
    assert est.apply_to(scene).keypoints2d.shape == (T, 17, 2)  # the scene's check accepts them now


def test_missing_mediapipe_gives_the_pip_command(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "mediapipe", None)  # import mediapipe -> ImportError
    with pytest.raises(MediaPipeUnavailable, match=r'pip install "lit-boot\[mediapipe\]"'):
        import_mediapipe()
    video = tmp_path / "frames"
    video.mkdir()
    assert main(["estimate-pose", str(video), "--out", str(tmp_path / "p.npz")]) == 2
    err = capsys.readouterr().err
    assert "mediapipe" in err and 'pip install "lit-boot[mediapipe]"' in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "p.npz").exists()


@pytest.mark.mediapipe
@needs_mediapipe
def test_mediapipe_keeps_frames_with_nobody():
    from lit_boot.estimate import estimate_poses

    est = estimate_poses(torch.full((2, 3, 64, 96), 128, dtype=torch.uint8))
    assert est.num_frames == 2 and est.image_size == (64, 96) and (est.keypoints_conf == 0).all()
    assert est.metadata["missing_frames"] == [0, 1] and est.cameras is None and (est.joints3d == 0).all()
    with pytest.raises(ValueError, match="model_complexity"):
        estimate_poses(torch.zeros(1, 3, 8, 8, dtype=torch.uint8), model_complexity=3)


@pytest.fixture(scope="module")
def football(shared):
    """The 10 real 1280x720 football frames plus a blank gray one, and MediaPipe's estimates."""
    from lit_boot.data.readers.video import read_video
    from lit_boot.estimate import estimate_poses

    frames = read_video(shared / VIDEO).frames
    frames = torch.cat([frames, torch.full_like(frames[:1], 128)])
    return frames, estimate_poses(frames)


@pytest.mark.shared
@pytest.mark.mediapipe
@needs_mediapipe
def test_mediapipe_finds_the_player_and_keeps_an_empty_frame(football):
    frames, est = football
    T = frames.shape[0]
    assert est.num_frames == T == 11 and est.image_size == (720, 1280)
    found = est.found()
    assert found[:10].sum() >= 8, est.metadata
    assert not found[10] and (est.keypoints_conf[10] == 0).all() and est.metadata["missing_frames"] == [10]
    assert torch.equal(est.joints3d[10], est.joints3d[est.metadata["filled_from"][0][1]])
    assert est.metadata["model_complexity"] == 1 and est.metadata["seconds_per_frame"] < 2.0
    # keypoints inside the frame, on a person of plausible size; the 3D skeleton has metric bones
    kp = est.keypoints2d[found]
    assert (kp[..., 0] > -50).all() and (kp[..., 0] < 1330).all() and (kp[..., 1] > -50).all()
    thigh = (est.joints3d[:, 2] - est.joints3d[:, 1]).norm(dim=-1)
    assert ((thigh > 250) & (thigh < 650)).all(), thigh
    target, _, w = map_joints(est.keypoints2d, "coco17", LSP14, est.keypoints_conf)
    err = (est.cameras.project(est.joints3d) - target).norm(dim=-1)[found][w[found] > 0.5]
    size = (kp.amax(1) - kp.amin(1)).amax(-1).mean()
    assert err.median() < 0.1 * size, (err.median(), size)


@pytest.mark.shared
@pytest.mark.mediapipe
@needs_mediapipe
def test_cli_writes_a_loadable_pose_file_and_refuses_to_overwrite(shared, tmp_path, capsys):
    out = tmp_path / "poses.npz"
    args = ["estimate-pose", str(shared / VIDEO), "--out", str(out), "--max-frames", "3", "--resize", "0.5"]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "3 frames" in printed and "with a person" in printed and "mean keypoint confidence" in printed
    est = load_poses(out)
    assert est.num_frames == 3 and est.image_size == (360, 640) and est.source == "mediapipe-0.10.14"
    assert est.keypoints2d.shape == (3, 17, 2) and est.joints3d.shape == (3, 14, 3) and est.cameras is not None
    before = out.stat().st_mtime_ns
    assert main(args) == 2
    assert "--overwrite" in capsys.readouterr().err and out.stat().st_mtime_ns == before
    assert main([*args, "--stride", "2", "--overwrite"]) == 0
    assert load_poses(out).frame_indices.tolist() == [0, 2, 4]
    # an mp4 works the same (height 240 this time)
    frames = [cv2.imread(str(f)) for f in sorted((shared / VIDEO).glob("*.jpg"))[:3]]
    writer = cv2.VideoWriter(str(tmp_path / "clip.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 25, (1280, 720))
    for frame in frames:
        writer.write(frame)
    writer.release()
    clip_args = ["estimate-pose", str(tmp_path / "clip.mp4"), "--out", str(tmp_path / "clip.npz"), "--resize", "240"]
    assert main(clip_args) == 0
    clip = load_poses(tmp_path / "clip.npz")
    assert clip.num_frames == 3 and clip.image_size == (240, 427) and clip.found().all()
