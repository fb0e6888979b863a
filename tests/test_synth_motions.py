"""Tests for the BVH reader and the procedural motions (CPU, real CMU files when present)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from lit_boot.synth.bvh import CMU_LANDMARKS, bvh_duration, bvh_motion, read_bvh, rest_height, sample_channels
from lit_boot.synth.motions import MOTION_KINDS, procedural_motion, procedural_skeleton
from lit_boot.synth.skeleton import LANDMARKS, Motion, axis_angle_to_matrix, forward_kinematics

TINY = """HIERARCHY
ROOT Root
{
OFFSET 1 2 3
\tCHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation
  JOINT Arm
  {
\t\tOFFSET 0 10 0
CHANNELS 3 Xrotation Zrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 5 0
\t\t}
  }
}
MOTION
Frames: 2
Frame Time: 0.5
10 20 30 90 90 0 90 90 0
10 20 30 90 90 0 90 90 0
"""
TINY_LANDMARKS = {name: "Root" for name in LANDMARKS} | {"head_top": "Arm_end"}


@pytest.fixture(scope="module")
def cmu(shared: Path) -> Path:
    """../shared/data/mocap/cmu_131 (the conftest's ``shared`` skips when ../shared is absent)."""
    path = shared / "data" / "mocap" / "cmu_131"
    if not path.is_dir():
        pytest.skip(f"CMU mocap folder {path} is absent")
    return path


@pytest.fixture(scope="module")
def walk01(cmu: Path):
    return read_bvh(cmu / "131_01.bvh")


def _write(tmp_path: Path, text: str, name: str = "tiny.bvh") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _positions(motion: Motion) -> torch.Tensor:
    return motion.global_transforms()[1]


def _assert_constant_bones(motion: Motion) -> None:
    pos = _positions(motion).double()
    parents = torch.tensor(motion.skeleton.parents[1:])
    lengths = (pos[:, 1:] - pos[:, parents]).norm(dim=-1)
    rest = motion.skeleton.offsets[1:].double().norm(dim=-1)
    assert torch.allclose(lengths, rest.expand_as(lengths), atol=1e-2, rtol=1e-4)


# --------------------------------------------------------------------------- BVH: real files


@pytest.mark.shared
def test_read_cmu_131_01(walk01) -> None:
    assert walk01.values.shape == (994, 96) and walk01.values.dtype == torch.float64
    assert walk01.frame_time == pytest.approx(1 / 120, abs=1e-6)
    assert bvh_duration(walk01) == pytest.approx(993 * walk01.frame_time)
    assert len(walk01.names) == len(walk01.parents) == walk01.offsets.shape[0] == 38
    assert walk01.parents[0] == -1 and all(p < i for i, p in enumerate(walk01.parents))
    assert walk01.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    assert walk01.channels[walk01.names.index("LeftShoulder")] == ("Zrotation", "Xrotation", "Yrotation")
    head_end = walk01.names.index("Head_end")
    assert walk01.parents[head_end] == walk01.names.index("Head") and walk01.channels[head_end] == ()
    assert set(CMU_LANDMARKS) == set(LANDMARKS) and set(CMU_LANDMARKS.values()) <= set(walk01.names)
    assert walk01.values[0, :3].tolist() == [5.23, 16.9002, -33.8986]


@pytest.mark.shared
def test_scaled_file_gives_same_positions(cmu, walk01) -> None:
    scaled = read_bvh(cmu / "scaled_131_01.bvh")
    assert scaled.names == walk01.names and scaled.values.shape[0] == 995  # last frame duplicated
    frames = torch.arange(0, 994, 9, dtype=torch.float64)
    a = _positions(bvh_motion(walk01, frames * walk01.frame_time, height_mm=1650.0))
    b = _positions(bvh_motion(scaled, frames * scaled.frame_time, height_mm=1650.0))
    assert (a - b).abs().max() < 0.5  # mm


@pytest.mark.shared
def test_cmu_bone_lengths_constant_and_rest_height(walk01) -> None:
    motion = bvh_motion(walk01, torch.linspace(0, 3, 181, dtype=torch.float64), start=1.0, height_mm=1800.0)
    assert rest_height(motion.skeleton) == pytest.approx(1800.0)
    assert motion.rotations.shape == (181, 38, 3, 3) and motion.root_positions.dtype == torch.float64
    assert motion.skeleton.landmarks["left_toe"] == walk01.names.index("LeftToe_end")
    _assert_constant_bones(motion)
    raw = bvh_motion(walk01, torch.zeros(1), height_mm=None)
    assert torch.equal(raw.skeleton.offsets, walk01.offsets.float())


@pytest.mark.shared
def test_cmu_walk_moves_forward(walk01) -> None:
    motion = bvh_motion(walk01, torch.linspace(0, 5, 101))
    root = motion.root_positions
    assert (root[-1, [0, 2]] - root[0, [0, 2]]).norm() > 1000.0
    feet = _positions(motion)[:, [motion.skeleton.landmarks[k] for k in ("left_toe", "right_toe")], 1]
    assert feet.min() > -100.0 and root[:, 1].mean() > 800.0  # on the floor, upright


@pytest.mark.shared
def test_half_frame_interpolation(walk01) -> None:
    k = 100
    t = torch.tensor([(k + 0.5) * walk01.frame_time])
    mid = sample_channels(walk01, t)[0]
    small = (walk01.values[k + 1] - walk01.values[k]).abs() < 30
    assert small[:6].all()
    expected = (walk01.values[k] + walk01.values[k + 1]) / 2
    assert torch.allclose(mid[small], expected[small], atol=1e-6)
    assert torch.allclose(sample_channels(walk01, torch.tensor([k * walk01.frame_time]))[0], walk01.values[k])


@pytest.mark.shared
def test_times_outside_clip_and_missing_landmarks(walk01) -> None:
    with pytest.raises(ValueError, match=r"duration 8\.27"):
        bvh_motion(walk01, torch.tensor([0.0, 9.0]))
    with pytest.raises(ValueError, match="duration"):
        bvh_motion(walk01, torch.tensor([0.0]), start=-0.1)
    with pytest.raises(ValueError, match=r"131_01\.bvh.*Pelvis"):
        bvh_motion(walk01, torch.zeros(1), landmarks=CMU_LANDMARKS | {"pelvis": "Pelvis"})


# --------------------------------------------------------------------------- BVH: hand-written files


def test_tiny_bvh_euler_order_and_end_site(tmp_path) -> None:
    data = read_bvh(_write(tmp_path, TINY))
    assert data.names == ("Root", "Arm", "Arm_end") and data.parents == (-1, 0, 1)
    assert data.channels[2] == () and data.frame_time == 0.5
    pos = _positions(bvh_motion(data, torch.tensor([0.25]), height_mm=None, landmarks=TINY_LANDMARKS))[0]
    # Root R = Ry(90) Rx(90): arm offset (0,10,0) -> (10,0,0); Arm R = Rx(90) Rz(90): (0,5,0) -> (-5,0,0)
    # -> globally Ry(90) Rx(90) (-5,0,0) = (0,0,5). The reversed orders would give other points.
    expected = torch.tensor([[11.0, 22.0, 33.0], [21.0, 22.0, 33.0], [21.0, 22.0, 38.0]])
    assert torch.allclose(pos, expected, atol=1e-4)
    scaled = bvh_motion(data, torch.tensor([0.25]), height_mm=30.0, landmarks=TINY_LANDMARKS)  # rest height 15
    assert torch.allclose(_positions(scaled)[0], 2 * expected, atol=1e-4)


def test_rotation_channels_unwrap_before_interpolating(tmp_path) -> None:
    text = TINY.replace("90 90 0 90 90 0\n10 20 30 90 90 0", "0 0 170 0 0 0\n10 20 30 0 0 -170", 1)
    data = read_bvh(_write(tmp_path, text))
    rot = bvh_motion(data, torch.tensor([0.25]), height_mm=None, landmarks=TINY_LANDMARKS).rotations[0, 0]
    assert torch.allclose(rot, axis_angle_to_matrix("z", torch.tensor(math.pi)), atol=1e-5)  # 180, not 0


@pytest.mark.parametrize(
    ("mutate", "line", "what"),
    [
        (lambda s: s[: s.rindex("90 90 0 90")], 20, "expected 9 values, found 3"),  # cut mid-row
        (lambda s: s.rsplit("10 20 30", 1)[0], 19, "1 of 2 motion rows"),  # cut after a row
        (lambda s: s.replace("10 20 30 90 90 0 90 90 0\n", "10 20 30 90 90 0 90 90\n", 1), 19, "expected 9"),
        (lambda s: s[: s.index("End Site")], 10, "unexpected end of hierarchy"),  # cut in the hierarchy
        (lambda s: s.replace("End Site", "Ending Site"), 10, "unknown keyword 'Ending'"),
        (lambda s: s.replace("3 Xrotation Zrotation", "3 Xrotation Wrotation"), 9, "unknown channels"),
        (lambda s: s.replace("Frame Time: 0.5", "Frame Time: x"), 18, "Frame Time"),
    ],
)
def test_malformed_files_raise_with_file_and_line(tmp_path, mutate, line, what) -> None:
    path = _write(tmp_path, mutate(TINY), "broken_file.bvh")
    with pytest.raises(ValueError, match="broken_file.bvh") as err:
        read_bvh(path)
    assert f"line {line}:" in str(err.value) and what in str(err.value)


def test_missing_file_raises_value_error(tmp_path) -> None:
    with pytest.raises(ValueError, match="nope.bvh"):
        read_bvh(tmp_path / "nope.bvh")


# --------------------------------------------------------------------------- procedural


def test_procedural_skeleton_layout() -> None:
    sk = procedural_skeleton(1600.0)
    assert set(LANDMARKS) | {"spine"} == set(sk.names) and all(sk.names[i] == n for n, i in sk.landmarks.items())
    rest = sk.rest_positions()
    lm = sk.landmarks
    assert rest_height(sk) == pytest.approx(1600.0) and rest[:, 1].min().abs() < 1e-3
    assert sk.parents[0] == -1 and rest[0, 1] == pytest.approx(0.54 * 1600)
    assert rest[lm["left_hip"], 0] > 0 > rest[lm["right_hip"], 0]  # x = the body's left
    assert rest[lm["left_toe"], 2] > rest[lm["left_ankle"], 2]  # feet point forward (+z)
    assert rest[lm["left_hand"], 1] < rest[lm["left_elbow"], 1] < rest[lm["left_shoulder"], 1]  # arms down


def test_sign_conventions_knee_and_hip() -> None:
    sk = procedural_skeleton()
    lm, angle = sk.landmarks, torch.tensor([0.5])
    rot = torch.eye(3).expand(1, len(sk.names), 3, 3).clone()
    rot[:, lm["left_knee"]] = axis_angle_to_matrix("x", angle)
    rot[:, lm["right_hip"]] = axis_angle_to_matrix("x", -angle)
    pos = forward_kinematics(sk, rot, sk.offsets[0:1])[1][0]
    assert pos[lm["left_ankle"], 2] < pos[lm["left_knee"], 2] - 100  # knee flexion: shin backwards
    assert pos[lm["right_knee"], 2] > pos[lm["right_hip"], 2] + 100  # hip flexion: thigh forward


@pytest.mark.parametrize("kind", MOTION_KINDS)
def test_every_kind_is_finite_rigid_and_seeded(kind) -> None:
    t = torch.linspace(0, 3, 121)
    motion = procedural_motion(kind, t, seed=3)
    assert torch.isfinite(_positions(motion)).all()
    _assert_constant_bones(motion)
    assert torch.allclose(torch.linalg.det(motion.rotations), torch.ones(()), atol=1e-5)
    again = procedural_motion(kind, t, seed=3)
    other = procedural_motion(kind, t, seed=4)
    assert torch.equal(again.rotations, motion.rotations) and torch.equal(again.root_positions, motion.root_positions)
    assert not torch.allclose(other.rotations, motion.rotations)
    feet = _positions(motion)[:, [motion.skeleton.landmarks[k] for k in ("left_toe", "right_toe")], 1]
    assert feet.min() > -2.0  # ground contact: never through the floor


@pytest.mark.parametrize(
    ("kind", "seed", "amplitude"), [("walk", 0, 1.0), ("run", 1, 1.2), ("jump", 2, 1.0), ("turn", 5, 0.7)]
)
def test_knees_never_hyperextend(kind, seed, amplitude) -> None:
    motion = procedural_motion(kind, torch.linspace(0, 4, 241), seed=seed, amplitude=amplitude)
    rot, pos = motion.global_transforms()
    lm = motion.skeleton.landmarks
    for side in ("left", "right"):
        knee = motion.rotations[:, lm[f"{side}_knee"]]
        assert (torch.atan2(knee[:, 2, 1], knee[:, 1, 1]) >= 0).all()
        shin = pos[:, lm[f"{side}_ankle"]] - pos[:, lm[f"{side}_knee"]]
        in_thigh = (rot[:, lm[f"{side}_hip"]].transpose(-1, -2) @ shin.unsqueeze(-1))[..., 0]
        assert (in_thigh[:, 2] <= 1e-3).all()  # ankle behind (or on) the hip-knee line


def test_walk_and_run_speeds() -> None:
    t = torch.linspace(0, 4, 161)
    for kind, speed, expected in (("walk", 1.0, 1300.0), ("walk", 1.5, 1950.0), ("run", 1.0, 3000.0)):
        root = procedural_motion(kind, t, speed=speed).root_positions
        velocity = (root[-1] - root[0]) / 4.0
        assert abs(velocity[2] - expected) < 0.3 * expected and velocity[0].abs() < 1.0
    bob = procedural_motion("walk", t).root_positions[:, 1]
    assert 10.0 < bob.max() - bob.min() < 150.0


def test_jump_rises_and_wave_raises_hand() -> None:
    t = torch.linspace(0, 2.4, 241)
    jump = procedural_motion("jump", t)
    rest_y = jump.skeleton.offsets[0, 1]
    assert jump.root_positions[:, 1].max() - rest_y > 200.0
    assert procedural_motion("jump", t, amplitude=0.5).root_positions[:, 1].max() - rest_y < 200.0
    wave = procedural_motion("wave", t)
    pos, lm = _positions(wave), wave.skeleton.landmarks
    assert (pos[:, lm["right_wrist"], 1] > pos[:, lm["head_top"], 1]).any()
    assert (pos[:, lm["left_wrist"], 1] < pos[:, lm["left_elbow"], 1]).all()
    assert torch.allclose(wave.root_positions, wave.root_positions[:1].expand_as(wave.root_positions))


def test_turn_changes_facing() -> None:
    motion = procedural_motion("turn", torch.linspace(0, 2, 81), seed=7)
    facing = motion.global_transforms()[0][:, 0, :, 2]  # the pelvis' forward axis
    yaw = torch.atan2(facing[:, 0], facing[:, 2])
    step = torch.remainder(yaw.diff() + math.pi, 2 * math.pi) - math.pi
    assert step.sum().abs() > math.radians(90)
    assert (motion.root_positions[:, [0, 2]] - motion.root_positions[:1, [0, 2]]).abs().max() < 1.0


def test_unknown_kind_and_bad_amplitude() -> None:
    with pytest.raises(ValueError, match="walk.*run.*wave.*jump.*turn"):
        procedural_motion("dance", torch.zeros(2))
    with pytest.raises(ValueError, match="amplitude"):
        procedural_motion("walk", torch.zeros(2), amplitude=-1.0)


@pytest.mark.shared
def test_procedural_motion_on_cmu_skeleton(walk01) -> None:
    cmu_skeleton = bvh_motion(walk01, torch.zeros(1)).skeleton
    motion = procedural_motion("walk", torch.linspace(0, 1, 21), skeleton=cmu_skeleton)
    assert torch.isfinite(_positions(motion)).all() and motion.rotations.shape == (21, 38, 3, 3)
