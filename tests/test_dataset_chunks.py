"""Chunks of long scenes (lit_boot.dataset.chunks): planning, cutting a scene, stitching results."""

from __future__ import annotations

import pytest
import torch

from lit_boot.core import Person
from lit_boot.core.cameras import Cameras
from lit_boot.data import save_scene
from lit_boot.data.readers.pose_file import PoseEstimates
from lit_boot.dataset.chunks import (
    chunk_name,
    plan_chunks,
    slice_scene,
    stitch_estimates,
    stitch_pairs,
    stitch_sequences,
)
from lit_boot.dataset.tasks import Task, safe_name
from lit_boot.synth import make_scene

TASK = Task("clip", "video", {"path": "/videos/clip.mp4"}, poses="/videos/clip.npz")


def _check_plan(chunks: list[Task], num_frames: int, length: int, overlap: int) -> None:
    spans = [c.frames for c in chunks]
    assert spans[0][0] == 0 and spans[-1][1] == num_frames
    for (a0, a1), (b0, b1) in zip(spans, spans[1:]):
        assert a1 - b0 == overlap and a0 < b0
    for c in chunks:
        start, stop = c.frames
        assert overlap + 2 <= stop - start <= length
        assert c.name == f"clip--{start:05d}-{stop:05d}" == safe_name(c.name)
        assert c.parent == "clip" and c.scene_name == "clip"
        assert (c.kind, c.args, c.poses) == (TASK.kind, TASK.args, TASK.poses)
        assert Task.from_dict(c.to_dict()) == c


def test_plan_short_video_is_the_task_itself() -> None:
    assert plan_chunks(TASK, 50, 50, 8) == [TASK]
    assert plan_chunks(TASK, 1, 10, 2) == [TASK]


def test_plan_exact_multiple() -> None:
    chunks = plan_chunks(TASK, 100 + 3 * 90, 100, 10)  # 4 chunks of exactly 100
    assert [c.frames for c in chunks] == [(0, 100), (90, 190), (180, 280), (270, 370)]
    _check_plan(chunks, 370, 100, 10)


@pytest.mark.parametrize("num_frames", [101, 105, 191, 192, 1000, 1001])
def test_plan_short_tail_is_spread_over_the_chunks(num_frames: int) -> None:
    chunks = plan_chunks(TASK, num_frames, 100, 10)
    _check_plan(chunks, num_frames, 100, 10)
    lengths = [c.frames[1] - c.frames[0] for c in chunks]
    assert max(lengths) - min(lengths) <= 1  # no short tail: 101 frames -> 56 + 55
    fewer = plan_chunks(TASK, num_frames, 100, 10)
    assert len(fewer) == -(-(num_frames - 10) // 90)


def test_plan_bad_arguments() -> None:
    with pytest.raises(ValueError, match="overlap must be >= 2"):
        plan_chunks(TASK, 100, 20, 1)
    with pytest.raises(ValueError, match=r"length must be >= overlap \+ 2 = 12"):
        plan_chunks(TASK, 100, 11, 10)
    with pytest.raises(ValueError, match="num_frames must be >= 1"):
        plan_chunks(TASK, 0, 20, 4)
    with pytest.raises(TypeError, match="length must be an int"):
        plan_chunks(TASK, 100, 20.0, 4)
    with pytest.raises(ValueError, match="already a chunk"):
        plan_chunks(plan_chunks(TASK, 100, 20, 4)[0], 20, 10, 2)
    assert chunk_name("a", 3, 12) == "a--00003-00012"


def _trajectory(T: int) -> torch.Tensor:
    """A smooth (T, 5, 2) trajectory: a quadratic in t (constant 2nd difference)."""
    t = torch.arange(T, dtype=torch.float64)[:, None, None]
    a = torch.linspace(-0.05, 0.05, 10, dtype=torch.float64).view(1, 5, 2)
    return a * t**2 + 0.7 * t + torch.arange(10, dtype=torch.float64).view(1, 5, 2)


def _chunked(truth: torch.Tensor, spans: list[tuple[int, int]], offsets: list[float]) -> list:
    return [(a, truth[a:b] + off) for (a, b), off in zip(spans, offsets)]


def test_stitch_sequences_cross_fades_over_the_overlaps() -> None:
    T, spans, offsets = 60, [(0, 24), (16, 42), (34, 60)], [0.0, 3.0, -2.0]
    truth = _trajectory(T)
    chunks = _chunked(truth, spans, offsets)
    stitched = stitch_sequences(chunks, T)
    assert stitched.shape == truth.shape and stitched.dtype == truth.dtype
    own = {0: range(0, 16), 1: range(24, 34), 2: range(42, 60)}  # frames in one chunk only
    for i, frames in own.items():
        assert torch.equal(stitched[list(frames)], truth[list(frames)] + offsets[i])
    # Inside the overlap [16, 24) of 8 frames the later chunk's weight is (k + 1) / 9.
    w = torch.arange(1, 9, dtype=torch.float64) / 9
    expected = truth[16:24] + (w * offsets[1]).view(-1, 1, 1)
    assert torch.allclose(stitched[16:24], expected)

    hard = torch.cat([truth[0:20] + offsets[0], truth[20:38] + offsets[1], truth[38:60] + offsets[2]])
    accel = lambda x: (x[2:] - 2 * x[1:-1] + x[:-2]).abs().amax()  # noqa: E731
    true_accel = accel(truth)
    assert accel(hard) - true_accel > 1.5
    assert accel(stitched) - true_accel < 0.2 * (accel(hard) - true_accel)
    assert (stitched[1:] - stitched[:-1] - (truth[1:] - truth[:-1])).abs().amax() < 0.6  # no jump
    exact = stitch_sequences(_chunked(truth, spans, [0.0, 0.0, 0.0]), T)
    assert torch.allclose(exact, truth, atol=1e-12) and torch.isclose(accel(exact), true_accel)


def test_stitch_sequences_adjacent_chunks_and_bad_input() -> None:
    x = torch.arange(10.0)
    assert torch.equal(stitch_sequences([(0, x[:4]), (4, x[4:])], 10), x)  # no overlap: a plain join
    assert stitch_sequences([(0, torch.arange(5))], 5).dtype == torch.get_default_dtype()
    with pytest.raises(ValueError, match=r"span \[0, 8\), expected \[0, 10\)"):
        stitch_sequences([(0, x[:4]), (4, x[4:8])], 10)
    with pytest.raises(ValueError, match="in order, overlapping or adjacent"):
        stitch_sequences([(0, x[:4]), (5, x[5:])], 10)
    with pytest.raises(ValueError, match="neither inside the other"):
        stitch_sequences([(0, x[:8]), (2, x[2:5]), (4, x[4:])], 10)
    with pytest.raises(ValueError, match="chunk 1 has shape"):
        stitch_sequences([(0, x[:6, None]), (4, torch.zeros(6, 2))], 10)
    with pytest.raises(ValueError, match="no chunks"):
        stitch_sequences([], 10)


def test_stitch_pairs_switches_at_the_overlaps_middle() -> None:
    # Frames [0, 10) and [6, 16): pairs 0..8 and 6..14; the overlap's pairs 6, 7, 8.
    a, b = torch.full((9, 2, 3, 4), 1.0), torch.full((9, 2, 3, 4), 2.0)
    flows = stitch_pairs([(0, a), (6, b)], 15)
    assert flows.shape == (15, 2, 3, 4)
    assert flows[:, 0, 0, 0].tolist() == [1.0] * 8 + [2.0] * 7  # pair 7 is a tie: the earlier chunk
    # Equal-length chunks: each pair from the chunk whose centre is nearest.
    T, spans = 40, [(0, 16), (12, 28), (24, 40)]
    chunks = [(s, torch.full((e - s - 1,), float(i))) for i, (s, e) in enumerate(spans)]
    out = stitch_pairs(chunks, T - 1)
    centres = [(s + e - 1) / 2 for s, e in spans]
    for p in range(T - 1):
        inside = [i for i, (s, e) in enumerate(spans) if s <= p and p + 1 < e]
        nearest = min(inside, key=lambda i: (abs(p + 0.5 - centres[i]), i))
        assert out[p] == nearest
    with pytest.raises(ValueError, match="in order, overlapping or adjacent"):
        stitch_pairs([(0, a), (10, b)], 19)  # pair 9 (frame 9 -> 10) is in neither chunk


def _estimates(start: int, stop: int, offset: float, **kw) -> PoseEstimates:
    T = stop - start
    t = torch.arange(start, stop, dtype=torch.float32)
    return PoseEstimates(
        keypoints2d=t.view(-1, 1, 1).expand(T, 17, 2) + offset, keypoints_conf=torch.full((T, 17), 0.5 + offset / 10),
        joints3d=t.view(-1, 1, 1).expand(T, 14, 3) * 10 + offset,
        cameras=Cameras("weak_perspective", torch.stack([torch.ones(T), t, -t], 1) + offset,
                        torch.stack([torch.full((T,), 2.0), t, t], 1)), **kw,
    )  # fmt: skip


def test_stitch_estimates_keeps_layouts_and_cross_fades() -> None:
    parts = [(0, _estimates(0, 12, 0.0)), (8, _estimates(8, 20, 1.0))]
    est = stitch_estimates(parts, 20)
    assert est.num_frames == 20 and est.frame_indices.tolist() == list(range(20))
    assert (est.keypoints_layout, est.joints3d_layout, est.cameras.model) == ("coco17", "lsp14", "weak_perspective")
    w = torch.tensor([0.0] * 8 + [0.2, 0.4, 0.6, 0.8] + [1.0] * 8)  # overlap [8, 12): (k + 1) / 5
    t = torch.arange(20.0)
    share = w * 0.6 / ((1 - w) * 0.5 + w * 0.6)  # the keypoints' cross-fade is confidence-weighted too
    assert torch.allclose(est.keypoints2d[:, 0, 0], t + share)
    assert torch.allclose(est.keypoints_conf[:, 0], 0.5 + w / 10)
    assert torch.allclose(est.joints3d[:, 3, 2], 10 * t + w)
    assert torch.allclose(est.cameras.params[:, 1], t + w) and torch.allclose(est.cameras.crops[:, 1], t)
    assert est.metadata["chunks"] == [[0, 12], [8, 20]]
    # Video frame numbers (stride 2) agree on the overlap and are kept.
    fi = lambda a, b: torch.arange(a, b) * 2  # noqa: E731
    parts = [(0, _estimates(0, 12, 0.0, frame_indices=fi(0, 12))), (8, _estimates(8, 20, 0.0, frame_indices=fi(8, 20)))]
    assert stitch_estimates(parts, 20).frame_indices.tolist() == fi(0, 20).tolist()
    parts[1] = (8, _estimates(8, 20, 0.0, frame_indices=fi(8, 20) + 1))
    with pytest.raises(ValueError, match="frame_indices of the part at frame 8 disagree"):
        stitch_estimates(parts, 20)
    with pytest.raises(ValueError, match="differ in keypoints_layout"):
        odd = PoseEstimates(keypoints2d=torch.zeros(12, 14, 2), keypoints_conf=torch.ones(12, 14),
                            keypoints_layout="lsp14")  # fmt: skip
        stitch_estimates([(0, odd), (8, _estimates(8, 20, 0.0))], 20)


def test_a_keypoint_a_chunk_did_not_find_lends_no_position_to_the_overlap() -> None:
    first, second = _estimates(0, 12, 0.0), _estimates(8, 20, 1.0)
    first.keypoints2d[9:11, 3] = 0.0  # not found: MediaPipe's zeros, confidence 0
    first.keypoints_conf[9:11, 3] = 0.0
    est = stitch_estimates([(0, first), (8, second)], 20)
    assert torch.equal(est.keypoints2d[9:11, 3], second.keypoints2d[1:3, 3])  # the other chunk's, unblended
    assert (est.keypoints_conf[9:11, 3] < 0.6).all()  # the confidence still fades
    lost = [(0, torch.zeros(4, 2)), (2, torch.ones(4, 2))]
    nobody = [torch.zeros(4), torch.zeros(4)]
    assert torch.equal(stitch_sequences(lost, 6, nobody), stitch_sequences(lost, 6))  # nobody sure: the plain fade
    with pytest.raises(ValueError, match="do not lead value"):
        stitch_sequences(lost, 6, [torch.zeros(4, 3), torch.zeros(4, 3)])


@pytest.fixture(scope="module")
def synthetic():
    return make_scene(frames=6, height=64, width=96)


def test_slice_scene_keeps_every_field_consistent(synthetic) -> None:
    scene = synthetic
    part = slice_scene(scene, 2, 5)
    part.validate()
    assert part.num_frames == 3 and (part.height, part.width) == (64, 96)
    assert torch.equal(part.frames, scene.frames[2:5])
    assert torch.equal(part.joints3d, scene.joints3d[2:5]) and torch.equal(part.keypoints2d, scene.keypoints2d[2:5])
    assert torch.equal(part.keypoints_conf, scene.keypoints_conf[2:5])
    assert torch.equal(part.cameras.params, scene.cameras.params[2:5])
    assert torch.equal(part.cameras.crops, scene.cameras.crops[2:5])
    gt, whole = part.gt, scene.gt
    for key in ("flow", "flow_valid", "flow_occluded"):  # pairs 2->3 and 3->4
        assert torch.equal(getattr(gt, key), getattr(whole, key)[2:4]), key
    for key in ("joints3d", "joints2d", "person_mask", "keypoints2d"):
        assert torch.equal(getattr(gt, key), getattr(whole, key)[2:5]), key
    assert torch.equal(gt.cameras.params, whole.cameras.params[2:5]) and gt.joints_layout == whole.joints_layout
    assert part.metadata["chunk"] == {"start": 2, "stop": 5}
    assert part.metadata["camera"]["centre_mm"] == scene.metadata["camera"]["centre_mm"][2:5]
    assert slice_scene(part, 1, 3).metadata["chunk"] == {"start": 3, "stop": 5}
    assert scene.num_frames == 6  # the original is untouched
    for start, stop in [(0, 7), (3, 3), (-1, 2)]:
        with pytest.raises(ValueError, match=r"expected 0 <= start < stop <= 6"):
            slice_scene(scene, start, stop)


def test_slice_scene_per_frame_metadata() -> None:
    scene = make_scene(frames=5, height=32, width=48)
    meta = {"frame_indices": [0, 2, 4, 6, 8], "files": list("abcde"), "native_size": [5, 5], "frames": [1, 2, 3, 4, 5],
            "gt_pairs": [[1, 2], [3, 4], [4, 5]],
            "missing_masks": ["invalid/x/frame_0001.png", "occlusions/x/frame_0003.png"],
            "keypoint_failures": [{"kind": "jump", "frame": 1}, {"kind": "lock", "frames": [0, 1, 2, 3]}],
            "pose_estimates": [{"source": "s", "frame_indices": [0, 2, 4, 6, 8]}],
            "people": [{"motion": "walk", "keypoint_failures": [{"kind": "jump", "frame": 3}]}, {"track_id": 2}]}  # fmt: skip
    scene.metadata = meta
    part = slice_scene(scene, 2, 5)
    assert part.metadata["frame_indices"] == [4, 6, 8] and part.metadata["files"] == ["c", "d", "e"]
    assert part.metadata["native_size"] == [5, 5] and part.metadata["frames"] == [3, 4, 5]
    assert part.metadata["gt_pairs"] == [[3, 4], [4, 5]]
    assert part.metadata["missing_masks"] == ["occlusions/x/frame_0003.png"]
    assert part.metadata["keypoint_failures"] == [{"kind": "lock", "frames": [0, 1]}]
    assert part.metadata["pose_estimates"][0]["frame_indices"] == [4, 6, 8]
    # each other person's synthetic failures are cut too; other records are kept as they are
    assert part.metadata["people"] == [{"motion": "walk", "keypoint_failures": [{"kind": "jump", "frame": 1}]},
                                       {"track_id": 2}]  # fmt: skip


def test_task_load_with_frames_is_slice_of_the_whole(synthetic, tmp_path) -> None:
    save_scene(synthetic, tmp_path / "scene")
    task = Task("synth", "scene", {"path": str(tmp_path / "scene")})
    whole = task.load()
    chunks = plan_chunks(task, whole.num_frames, 4, 2)
    assert [c.frames for c in chunks] == [(0, 4), (2, 6)]
    for chunk in chunks:
        part, expected = chunk.load(), slice_scene(whole, *chunk.frames)
        assert part.metadata == expected.metadata and torch.equal(part.frames, expected.frames)
        for key in ("joints3d", "keypoints2d", "keypoints_conf"):
            assert torch.equal(getattr(part, key), getattr(expected, key))
        for key in ("flow", "flow_valid", "flow_occluded", "joints3d", "person_mask"):
            assert torch.equal(getattr(part.gt, key), getattr(expected.gt, key))
    with pytest.raises(ValueError, match=r"task 'x': frames \[2, 9\) but the source has 6 frames"):
        Task("x", "scene", {"path": str(tmp_path / "scene")}, frames=(2, 9)).load()


def test_stitch_estimates_keeps_every_person_of_a_multi_person_video() -> None:
    scene = make_scene(motion="walk", frames=10, height=48, width=96, seed=5, people=2)
    people = scene.people()
    main, other = people

    def part(start: int, stop: int) -> PoseEstimates:
        cut = [p.map(lambda x: x[start:stop].clone()) for p in people]
        return PoseEstimates(**cut[0].fields(), track_id=cut[0].track_id, others=tuple(cut[1:]),
                             keypoints_layout=scene.keypoints_layout, joints3d_layout=scene.joints3d_layout)

    est = stitch_estimates([(0, part(0, 6)), (4, part(4, 10))], 10)
    assert [p.track_id for p in est.people()] == [main.track_id, other.track_id]
    for mine, theirs in zip(est.people(), people):
        assert torch.allclose(mine.joints3d, theirs.joints3d, atol=1e-4)  # the same values in both parts
        assert torch.allclose(mine.cameras.params, theirs.cameras.params, atol=1e-4)
        assert torch.equal(mine.keypoints_conf > 0, theirs.keypoints_conf > 0)
        assert torch.allclose(mine.person_boxes, theirs.person_boxes, atol=1e-4)
    lone = part(4, 10)
    lone = PoseEstimates(**Person.of(lone).fields(), keypoints_layout=scene.keypoints_layout,
                         joints3d_layout=scene.joints3d_layout)  # fmt: skip
    with pytest.raises(ValueError, match="differ in people"):
        stitch_estimates([(0, part(0, 6)), (4, lone)], 10)
