"""Tests of the target flow sketch: hand-made cases with exact outcomes, and GT synthetic scenes."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from lit_boot.core.joints import COCO17, LSP14
from lit_boot.flow.sketch import (
    SketchConfig,
    SketchResult,
    footprint_offsets,
    sketch_flow,
    sketch_from_layout,
    target_flow,
)

H, W = 48, 64


def _pair(points_t, points_t1) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.tensor([points_t], dtype=torch.float32), torch.tensor([points_t1], dtype=torch.float32)


def _dilated(pixels: set[tuple[int, int]], footprint: str, size: int) -> torch.Tensor:
    """Reference dilation, written out: (H, W) bool of every pixel + offset inside the image."""
    out = torch.zeros(H, W, dtype=torch.bool)
    for x, y in pixels:
        for dx, dy in footprint_offsets(footprint, size).tolist():
            if 0 <= x + dx < W and 0 <= y + dy < H:
                out[y + dy, x + dx] = True
    return out


@pytest.mark.parametrize(
    ("footprint", "size", "count"),
    [("cross", 2, 9), ("square", 4, 16), ("disk", 2, 13), ("cross", 15, 61), ("square", 30, 900), ("cross", 0, 1)],
)
def test_zero_length_bone_paints_one_footprint(footprint: str, size: int, count: int) -> None:
    jt, jt1 = _pair([[20.0, 20.0], [20.0, 20.0]], [[23.0, 18.0], [23.0, 18.0]])
    cfg = SketchConfig(footprint=footprint, size=size, guard=False)  # one point: no person size for the jump guard
    res = sketch_flow(jt, jt1, [(0, 1)], 64, 64, config=cfg)
    assert int(res.mask.sum()) == count == len(footprint_offsets(footprint, size))
    assert torch.equal(res.flow[0, :, res.mask[0]], torch.tensor([[3.0], [-2.0]]).expand(2, count))


def test_footprint_shapes() -> None:
    square = {(x, y) for x in range(-2, 2) for y in range(-2, 2)}
    assert set(map(tuple, footprint_offsets("square", 4).tolist())) == square
    assert set(map(tuple, footprint_offsets("cross", 1).tolist())) == {(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)}
    assert all(dx * dx + dy * dy <= 9 for dx, dy in footprint_offsets("disk", 3).tolist())
    with pytest.raises(ValueError, match="footprint"):
        SketchConfig(footprint="star")
    with pytest.raises(ValueError, match="size"):
        SketchConfig(footprint="square", size=0)


@pytest.mark.parametrize(("footprint", "size"), [("cross", 2), ("square", 4), ("disk", 2)])
def test_translating_bone_paints_its_dilated_line(footprint: str, size: int) -> None:
    jt, jt1 = _pair([[10.0, 20.0], [30.0, 20.0]], [[13.0, 18.0], [33.0, 18.0]])
    res = sketch_flow(jt, jt1, torch.tensor([[0, 1]]), H, W, config=SketchConfig(footprint=footprint, size=size))
    assert torch.equal(res.mask[0], _dilated({(x, 20) for x in range(10, 31)}, footprint, size))
    painted = res.flow[0].permute(1, 2, 0)[res.mask[0]]
    assert torch.equal(painted, torch.tensor([3.0, -2.0]).expand_as(painted))
    assert not res.flow[0, :, ~res.mask[0]].any()
    assert res.bone_drawn.tolist() == [[True]] and res.rejected == dict.fromkeys(res.rejected, 0)


def test_fixed_points_per_bone() -> None:
    """22 points on a 21 px bone: every pixel of the line is a sample centre (the authors' setting)."""
    jt, jt1 = _pair([[10.0, 20.0], [31.0, 20.0]], [[11.0, 20.0], [32.0, 20.0]])
    res = sketch_flow(jt, jt1, [(0, 1)], H, W, config=SketchConfig(footprint="square", size=6, points_per_bone=22))
    assert torch.equal(res.mask[0], _dilated({(x, 20) for x in range(10, 32)}, "square", 6))


def test_dense_sampling_draws_a_connected_line() -> None:
    jt, jt1 = _pair([[5.0, 5.0], [40.0, 30.0]], [[6.0, 5.0], [41.0, 30.0]])
    res = sketch_flow(jt.double(), jt1.double(), [(0, 1)], H, W, config=SketchConfig(size=0))
    assert res.flow.dtype == torch.float64
    assert res.mask[0, 5:31].any(1).all() and res.mask[0, :, 5:41].any(0).all()  # no gap in any row or column
    assert int(res.mask.sum()) <= 36 + 26  # and no blob: at most one pixel per row plus one per column


def test_rotating_bone_displacement_grows_linearly() -> None:
    """A bone turning 30 degrees about its first end: pixel at distance r moves by (r / L) (b' - b)."""
    a, L = (20.0, 30.0), 20.0
    b1 = (a[0] + L * math.cos(math.pi / 6), a[1] - L * math.sin(math.pi / 6))
    jt, jt1 = _pair([a, [a[0] + L, a[1]]], [a, b1])
    res = sketch_flow(jt, jt1, [(0, 1)], H, W, config=SketchConfig(size=0, guard=False))
    tip = torch.tensor(b1) - torch.tensor([a[0] + L, a[1]])
    for r in (0, 5, 10, 15, 20):
        got = res.flow[0, :, int(a[1]), int(a[0]) + r]
        torch.testing.assert_close(got, tip * r / L, atol=1e-5, rtol=0)
    # a thick bone: the same growth along it, within the footprint's reach (later samples win)
    thick = sketch_flow(jt, jt1, [(0, 1)], H, W, config=SketchConfig(size=2, guard=False))
    for r in (0, 5, 10, 15):
        got = thick.flow[0, :, int(a[1]), int(a[0]) + r]
        assert float((got - tip * r / L).norm()) <= float(tip.norm()) * 2.5 / L


def test_clipping_at_the_border_never_wraps() -> None:
    jt, jt1 = _pair([[W - 3.0, 10.0], [W + 40.0, 10.0], [-50.0, -50.0], [-20.0, -60.0]], [[W - 1.0, 10.0]] * 4)
    for points in (None, 22):
        cfg = SketchConfig(footprint="square", size=30, points_per_bone=points)
        res = sketch_flow(jt, jt1, [(0, 1), (2, 3)], H, W, config=cfg)
        assert res.mask.any() and not res.mask[0, :, : W - 20].any() and not res.mask[0, H - 10 :].any()
        cols = res.mask[0].any(0).nonzero().flatten()
        assert int(cols.min()) == W - 3 - 15 and int(cols.max()) == W - 1


def test_far_off_bone_is_cheap_and_empty() -> None:
    jt, jt1 = _pair([[-1e5, 5.0], [1e5, 5.0]], [[-1e5, 6.0], [1e5, 6.0]])
    res = sketch_flow(jt, jt1, [(0, 1)], H, W, config=SketchConfig(size=1, guard=False))
    assert torch.equal(res.mask[0], _dilated({(x, 5) for x in range(W)}, "cross", 1))


def _crossing() -> tuple[torch.Tensor, torch.Tensor]:
    """Bone 0 horizontal moving by (1, 0), bone 1 vertical moving by (0, 1); they cross at (32, 24)."""
    return _pair([[22, 24], [42, 24], [32, 14], [32, 34]], [[23, 24], [43, 24], [32, 15], [32, 35]])


@pytest.mark.parametrize("bones", [[(0, 1), (2, 3)], [(2, 3), (0, 1)]])
def test_nearer_bone_wins_regardless_of_order(bones: list[tuple[int, int]]) -> None:
    jt, jt1 = _crossing()
    near_horizontal = torch.tensor([[1000.0, 1000.0, 2000.0, 2000.0]])
    res = sketch_flow(jt, jt1, bones, H, W, depths=near_horizontal, config=SketchConfig(size=2))
    assert res.flow[0, :, 24, 32].tolist() == [1.0, 0.0]
    res = sketch_flow(jt, jt1, bones, H, W, depths=near_horizontal.flip(-1), config=SketchConfig(size=2))
    assert res.flow[0, :, 24, 32].tolist() == [0.0, 1.0]


def test_without_depths_the_later_bone_wins() -> None:
    jt, jt1 = _crossing()
    assert sketch_flow(jt, jt1, [(0, 1), (2, 3)], H, W).flow[0, :, 24, 32].tolist() == [0.0, 1.0]
    assert sketch_flow(jt, jt1, [(2, 3), (0, 1)], H, W).flow[0, :, 24, 32].tolist() == [1.0, 0.0]
    # equal depths fall back to drawing order
    same = torch.full((1, 4), 3000.0)
    assert sketch_flow(jt, jt1, [(2, 3), (0, 1)], H, W, depths=same).flow[0, :, 24, 32].tolist() == [1.0, 0.0]


@pytest.mark.parametrize("frame", ["t", "t1"])
def test_low_confidence_end_rejects_the_bone(frame: str) -> None:
    jt, jt1 = _crossing()
    low = torch.tensor([[0.9, 0.6, 0.9, 0.9]])  # 0.6 is not above the threshold 0.6
    high = torch.full((1, 4), 0.9)
    conf = {"confidence_t": low, "confidence_t1": high}
    if frame == "t1":
        conf = {"confidence_t": high, "confidence_t1": low}
    res = sketch_flow(jt, jt1, [(0, 1), (2, 3)], H, W, **conf, config=SketchConfig(size=1))
    assert res.bone_drawn.tolist() == [[False, True]]
    assert res.rejected == {"confidence": 1, "jump": 0, "disagreement": 0, "points": 0}
    assert not res.mask[0, 24, 22:30].any() and res.mask[0, 14:35, 32].all()


def test_non_finite_joint_counts_as_unconfident() -> None:
    jt, jt1 = _crossing()
    jt[0, 0, 0] = math.nan
    res = sketch_flow(jt, jt1, [(0, 1), (2, 3)], H, W)
    assert res.bone_drawn.tolist() == [[False, True]] and res.rejected["confidence"] == 1
    assert torch.isfinite(res.flow).all()


def _chain() -> tuple[torch.Tensor, torch.Tensor]:
    """Three joints 10 px apart (person size 20 px) translating by (1, 1)."""
    return _pair([[20, 20], [30, 20], [40, 20]], [[21, 21], [31, 21], [41, 21]])


def test_jumping_joint_rejects_its_bones() -> None:
    jt, jt1 = _chain()
    jt1[0, 2, 0] += W / 2  # joint 2 jumps by half the image
    res = sketch_flow(jt, jt1, [(0, 1), (1, 2)], H, W, config=SketchConfig(size=1))
    assert res.bone_drawn.tolist() == [[True, False]]
    assert res.rejected == {"confidence": 0, "jump": 1, "disagreement": 0, "points": 0}
    assert res.mask[0, 20, 20:31].all() and not res.mask[0, 20, 32:].any()
    unguarded = sketch_flow(jt, jt1, [(0, 1), (1, 2)], H, W, config=SketchConfig(size=1, guard=False))
    assert unguarded.bone_drawn.all() and sum(unguarded.rejected.values()) == 0


def test_disagreeing_base_flow_rejects_the_bone() -> None:
    jt, jt1 = _chain()
    base = torch.tensor([1.0, 1.0]).view(1, 2, 1, 1).repeat(1, 1, H, W)
    base[0, 0, :, 33:] += 30.0  # disagrees by 30 px along most of bone 1
    res = sketch_flow(jt, jt1, [(0, 1), (1, 2)], H, W, base_flow=base, config=SketchConfig(size=1))
    assert res.bone_drawn.tolist() == [[True, False]]
    assert res.rejected == {"confidence": 0, "jump": 0, "disagreement": 1, "points": 0}
    assert res.mask[0, 20, 20:31].all() and not res.mask[0, 20, 32:].any()


def test_disagreeing_points_of_a_kept_bone_are_dropped() -> None:
    jt, jt1 = _pair([[20, 20], [40, 20]], [[21, 21], [41, 21]])
    base = torch.tensor([1.0, 1.0]).view(1, 2, 1, 1).repeat(1, 1, H, W)
    base[0, 0, :, 36:] += 30.0  # the last fifth of the bone
    res = sketch_flow(jt, jt1, [(0, 1)], H, W, base_flow=base, config=SketchConfig(size=0))
    # samples every 0.5 px; bilinear base flow: 15 px off at x = 35.5 (kept), 30 px from x = 36 on (9 dropped)
    assert res.bone_drawn.tolist() == [[True]] and res.rejected["points"] == 9
    assert res.mask[0, 20, 20:37].all() and not res.mask[0, 20, 37:].any()


def test_median_matches_torch_nanmedian() -> None:
    from lit_boot.flow.sketch import _median

    g = torch.Generator().manual_seed(0)
    for n in (1, 2, 7, 10):
        x, valid = torch.randn(30, 4, n, generator=g), torch.rand(30, 4, n, generator=g) > 0.3
        valid[0, 0] = False
        expected = torch.where(valid, x, math.nan).nanmedian(-1).values
        torch.testing.assert_close(_median(x, valid), expected, equal_nan=True, rtol=0, atol=0)


def _random_inputs(B: int, K: int = 6, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    jt = torch.rand(B, K, 2, generator=g) * torch.tensor([W, H])
    return {
        "joints_t": jt,
        "joints_t1": jt + torch.randn(B, K, 2, generator=g) * 3,
        "confidence_t": torch.rand(B, K, generator=g) * 0.5 + 0.5,
        "depths": torch.rand(B, K, generator=g) * 1000 + 2000,
        "base_flow": torch.randn(B, 2, H, W, generator=g) * 4,
    }


@pytest.mark.parametrize("points_per_bone", [None, 22])
@pytest.mark.parametrize("with_depths", [True, False])
def test_batch_equals_single_calls(points_per_bone: int | None, with_depths: bool) -> None:
    inputs = _random_inputs(3)
    if not with_depths:
        inputs.pop("depths")
    bones = [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (1, 4)]
    cfg = SketchConfig(size=3, points_per_bone=points_per_bone, max_disagreement_px=4.0)
    joint = sketch_flow(bones=bones, height=H, width=W, config=cfg, **inputs)
    singles = [sketch_flow(bones=bones, height=H, width=W, config=cfg, **{k: v[i : i + 1] for k, v in inputs.items()})
               for i in range(3)]  # fmt: skip
    assert torch.equal(joint.flow, torch.cat([s.flow for s in singles]))
    assert torch.equal(joint.mask, torch.cat([s.mask for s in singles]))
    assert torch.equal(joint.bone_drawn, torch.cat([s.bone_drawn for s in singles]))
    assert joint.rejected == {k: sum(s.rejected[k] for s in singles) for k in joint.rejected}
    assert joint.mask.any() and not joint.bone_drawn.all()  # the case exercises both painting and rejection


def test_target_flow_keeps_the_base_outside_the_mask() -> None:
    inputs = _random_inputs(2, seed=1)
    res = sketch_flow(bones=[(0, 1), (2, 3)], height=H, width=W, config=SketchConfig(guard=False), **inputs)
    target = target_flow(inputs["base_flow"], res)
    m = res.mask[:, None].expand_as(target)
    assert res.mask.any() and torch.equal(target[m], res.flow[m])
    assert torch.equal(target[~m], inputs["base_flow"][~m])


def test_empty_bones_and_no_bones_drawn() -> None:
    inputs = _random_inputs(2)
    res = sketch_flow(bones=torch.empty(0, 2, dtype=torch.long), height=H, width=W, **inputs)
    assert isinstance(res, SketchResult) and res.flow.shape == (2, 2, H, W) and not res.mask.any()
    assert res.bone_drawn.shape == (2, 0)
    inputs["confidence_t"] = torch.zeros(2, 6)
    res = sketch_flow(bones=[(0, 1)], height=H, width=W, **inputs)
    assert not res.mask.any() and res.rejected["confidence"] == 2


def test_bad_inputs_raise() -> None:
    jt, jt1 = _chain()
    with pytest.raises(ValueError, match="bones"):
        sketch_flow(jt, jt1, [(0, 3)], H, W)
    with pytest.raises(ValueError, match="joints"):
        sketch_flow(jt, jt1[:, :2], [(0, 1)], H, W)
    with pytest.raises(ValueError, match="base_flow"):
        sketch_flow(jt, jt1, [(0, 1)], H, W, base_flow=torch.zeros(1, 2, H, W + 1))


def test_config_fields_are_documented() -> None:
    args = SketchConfig.__doc__.split("Args:")[1]
    assert all(f"{f.name}:" in args for f in dataclasses.fields(SketchConfig))


def test_coco_layout_draws_head_nose_and_nose_neck() -> None:
    kp = torch.zeros(1, 17, 2)
    names = {"nose": (32, 14), "left_ear": (36, 12), "right_ear": (28, 12), "left_shoulder": (40, 24),
             "right_shoulder": (24, 24), "left_eye": (34, 12), "right_eye": (30, 12)}  # fmt: skip
    conf = torch.zeros(1, 17)
    for name, xy in names.items():
        kp[0, COCO17.index(name)] = torch.tensor(xy, dtype=torch.float32)
        conf[0, COCO17.index(name)] = 0.9
    res = sketch_from_layout(COCO17, kp, kp + 2.0, H, W, confidence_t=conf, depths=torch.full((1, 17), 3000.0),
                             config=SketchConfig(size=1))  # fmt: skip
    drawn = {COCO17.sketch_bones[i] for i in res.bone_drawn[0].nonzero().flatten().tolist()}
    nose, neck, head = COCO17.index("nose"), COCO17.index("neck"), COCO17.index("head")
    assert {(head, nose), (nose, neck)} <= drawn
    assert res.mask[0, 12:25, 31:34].any(1).all()  # nose (32, 14), head (32, 12), neck (32, 24)
    assert res.flow[0, :, 14, 32].tolist() == [2.0, 2.0]


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_matches_cpu() -> None:
    inputs = _random_inputs(3)
    bones = [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (1, 4)]
    cfg = SketchConfig(size=3, max_disagreement_px=4.0)
    cpu = sketch_flow(bones=bones, height=H, width=W, config=cfg, **inputs)
    gpu = sketch_flow(bones=bones, height=H, width=W, config=cfg, **{k: v.cuda() for k, v in inputs.items()})
    assert gpu.flow.is_cuda and gpu.mask.is_cuda
    assert torch.equal(cpu.mask, gpu.mask.cpu()) and cpu.rejected == gpu.rejected
    torch.testing.assert_close(cpu.flow, gpu.flow.cpu())


@pytest.mark.shared
def test_gt_sketch_beats_raft_on_synthetic_scene(shared) -> None:
    """With GT joints the sketch is close to the GT flow on its pixels, closer than RAFT-small."""
    from lit_boot.flow.raft import load_raft, predict_flow
    from lit_boot.metrics import flow_errors
    from lit_boot.synth import make_scene

    scene = make_scene(motion="run", frames=4, height=128, width=256, seed=0)
    gt = scene.gt
    res = sketch_from_layout(LSP14, gt.joints2d[:-1], gt.joints2d[1:], 128, 256, depths=gt.joints3d[:-1, :, 2],
                             config=SketchConfig(footprint="cross", size=3, guard=False))  # fmt: skip
    assert res.bone_drawn.all()
    pixels = res.mask & ~gt.flow_occluded
    assert int(pixels.sum()) > 1500
    model = load_raft("raft_small", shared / "checkpoints" / "raft-small.pth").eval()
    with torch.no_grad():
        raft = predict_flow(model, scene.frames[:-1], scene.frames[1:], num_flow_updates=12)
    sketch_epe = float(flow_errors(res.flow, gt.flow, pixels)["epe"])  # measured 1.36 px
    raft_epe = float(flow_errors(raft, gt.flow, pixels)["epe"])  # measured 3.55 px
    magnitude = float(gt.flow.norm(dim=1)[pixels].mean())  # measured 4.50 px
    assert sketch_epe < 0.4 * magnitude and sketch_epe < 2.0
    assert sketch_epe < raft_epe


def test_a_segment_is_clipped_to_the_box_from_its_last_entry_to_its_first_exit() -> None:
    """Liang-Barsky by hand, box [0, 20]^2: (-10, -30) -> (10, 10) is inside in x for s in
    [0.5, 1.5] and in y for s in [0.75, 1.25], so it enters at s = 0.75 (the point (5, 0)) and
    leaves at the bone's end; (-20, 10) -> (10, -20) is inside in x for s >= 2/3 but in y only
    for s <= 1/3: it misses the box (s0 > s1); a segment inside stays whole; a flat segment
    (dy = 0) outside in y is empty."""
    from lit_boot.flow.sketch import _clip_segment

    a = torch.tensor([[-10.0, -30.0], [-20.0, 10.0], [2.0, 3.0], [-5.0, 25.0]])
    b = torch.tensor([[10.0, 10.0], [10.0, -20.0], [18.0, 19.0], [30.0, 25.0]])
    s0, s1 = _clip_segment(a, b, torch.tensor([0.0, 0.0]), torch.tensor([20.0, 20.0]))
    torch.testing.assert_close(s0[:3], torch.tensor([0.75, 2 / 3, 0.0]))
    torch.testing.assert_close(s1[:3], torch.tensor([1.0, 1 / 3, 1.0]))
    assert s0[3] > s1[3]  # flat and outside: empty
    torch.testing.assert_close(a[0] + s0[0] * (b[0] - a[0]), torch.tensor([5.0, 0.0]))  # on the box's top edge
