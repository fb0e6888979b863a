"""The target paints every person (lit_boot.flow.people_sketch, sketch_inputs with people)."""

from __future__ import annotations

import pytest
import torch

from lit_boot.core import Person, Scene, get_layout
from lit_boot.flow import SketchConfig, sketch_from_layout, sketch_people
from lit_boot.flow.data import sketch_inputs

H, W = 64, 128
CFG = SketchConfig()


def standing(cx: float, cy: float, scale: float = 1.0) -> torch.Tensor:
    """COCO-17 keypoints (17, 2) px of a standing person about (cx, cy), ~40 px tall at scale 1."""
    y = torch.tensor([-18, -19, -19, -18, -18, -10, -10, -2, -2, 5, 5, 2, 2, 10, 10, 18, 18.0]) * scale
    x = torch.tensor([0, -1, 1, -2, 2, -5, 5, -7, 7, -8, 8, -3, 3, -3, 3, -3, 3.0]) * scale
    return torch.stack([x + cx, y + cy], -1)


def pair(*people: tuple[float, float, float]) -> tuple[torch.Tensor, torch.Tensor]:
    """joints (1, P, 17, 2) at t and t+1: each person at (cx, cy) moving ``dx`` px right."""
    t = torch.stack([standing(cx, cy) for cx, cy, _ in people])[None]
    t1 = torch.stack([standing(cx + dx, cy) for cx, cy, dx in people])[None]
    return t, t1


def test_two_apart_are_painted_as_each_alone():
    jt, jt1 = pair((30, 32, 2.0), (95, 32, -3.0))
    both = sketch_people("coco17", jt, jt1, H, W, config=CFG)
    alone = [sketch_from_layout("coco17", jt[:, p], jt1[:, p], H, W, config=CFG) for p in range(2)]
    assert torch.equal(both.mask, alone[0].mask | alone[1].mask) and not (alone[0].mask & alone[1].mask).any()
    for one in alone:
        assert torch.equal(both.flow[:, :, one.mask[0]], one.flow[:, :, one.mask[0]])
    assert both.bone_drawn.shape[1] == 2 * alone[0].bone_drawn.shape[1]
    assert torch.allclose(both.flow[0, 0][alone[1].mask[0]], torch.tensor(-3.0))


def test_where_they_overlap_the_nearer_or_the_more_confident_wins():
    jt, jt1 = pair((60, 32, 2.0), (64, 32, -3.0))
    alone = [sketch_from_layout("coco17", jt[:, p], jt1[:, p], H, W, config=CFG) for p in range(2)]
    overlap = alone[0].mask & alone[1].mask
    assert overlap.sum() > 20
    near0 = sketch_people("coco17", jt, jt1, H, W, depths=torch.tensor([[[3000.0] * 17, [5000.0] * 17]]), config=CFG)
    near1 = sketch_people("coco17", jt, jt1, H, W, depths=torch.tensor([[[5000.0] * 17, [3000.0] * 17]]), config=CFG)
    assert (near0.flow[0, 0][overlap[0]] == 2.0).all() and (near1.flow[0, 0][overlap[0]] == -3.0).all()
    conf = torch.tensor([[[0.6] * 17, [0.9] * 17]])
    confident1 = sketch_people("coco17", jt, jt1, H, W, confidence_t=conf, confidence_t1=conf, config=CFG)
    assert (confident1.flow[0, 0][overlap[0]] == -3.0).all()


def test_the_jump_guard_measures_each_person_alone():
    """A small person far from a large one jumps 0.9 of its own size: rejected, as when alone,
    though the two together span most of the frame."""
    jt = torch.stack([standing(20, 32), standing(110, 32, 0.5)])[None]
    jt1 = jt.clone()
    jt1[0, 1, :, 0] += 0.9 * 22  # the small person's diagonal is ~22 px
    both = sketch_people("coco17", jt, jt1, H, W, config=CFG)
    alone = sketch_from_layout("coco17", jt[:, 1], jt1[:, 1], H, W, config=CFG)
    assert not alone.mask.any() and alone.rejected["jump"] > 0
    E = alone.bone_drawn.shape[1]
    assert both.bone_drawn[0, :E].all() and not both.bone_drawn[0, E:].any()


def test_sketch_inputs_give_every_person_and_3d_counts_only_found_frames():
    T = 3
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    kp = lambda cx: torch.stack([standing(cx + 2 * t, 32) for t in range(T)])  # noqa: E731
    conf_b = torch.ones(T, 17)
    conf_b[1] = 0
    scene = Scene(frames, keypoints2d=kp(30), keypoints_conf=torch.ones(T, 17),
                  others=(Person(track_id=5, keypoints2d=kp(90), keypoints_conf=conf_b),))  # fmt: skip
    inputs = sketch_inputs(scene, "keypoints2d")
    assert inputs.joints_t.shape == (T - 1, 2, 17, 2) and torch.equal(inputs.joints_t1[:, 1], kp(90)[1:])
    assert torch.equal(inputs.confidence_t[:, 1], conf_b[:-1])
    single = sketch_inputs(scene.person(0), "keypoints2d")
    assert single.joints_t.shape == (T - 1, 17, 2)


def test_flow_ttt_paints_every_person_of_the_scene():
    from lit_boot.flow import FlowTTT

    T = 3
    g = torch.Generator().manual_seed(0)
    frames = torch.randint(0, 255, (T, 3, H, W), dtype=torch.uint8, generator=g)
    kp = lambda cx: torch.stack([standing(cx + 2 * t, 32) for t in range(T)])  # noqa: E731
    main_only = Scene(frames, keypoints2d=kp(30), keypoints_conf=torch.ones(T, 17))
    both = Scene(frames, keypoints2d=kp(30), keypoints_conf=torch.ones(T, 17),
                 others=(Person(track_id=1, keypoints2d=kp(90), keypoints_conf=torch.ones(T, 17)),))  # fmt: skip
    base = torch.zeros(T - 1, 2, H, W)
    cfg = SketchConfig(guard=False, gate="off")
    masks = []
    for scene in (main_only, both):
        model = FlowTTT(weights=None, sketch=cfg)
        model.targets_from(scene, base, inputs=sketch_inputs(scene, "keypoints2d"))
        masks.append(model.sketch_masks)
    assert masks[0].any() and (masks[1] & masks[0]).equal(masks[0])
    added = masks[1] & ~masks[0]
    assert added.any() and (added.nonzero()[:, 2] >= 60).all()  # the second person's pixels, on the right (x 67-115)


def test_3d_sketch_inputs_have_depths_and_count_a_person_only_where_found():
    from lit_boot.core import Cameras

    T = 3
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    cams = lambda: Cameras("weak_perspective", torch.tensor([[0.9, 0.0, 0.1]] * T),  # noqa: E731
                           torch.tensor([[0.5, 10.0, 5.0]] * T))  # fmt: skip
    def joints(z: float) -> torch.Tensor:
        return torch.randn(T, 14, 3, generator=torch.Generator().manual_seed(int(z))) * 100 + torch.tensor([0, 0, z])

    conf_b = torch.ones(T, 17)
    conf_b[2] = 0  # person 1 is not found in frame 2: its joints there are only filled in
    scene = Scene(frames, joints3d=joints(3000), cameras=cams(), keypoints2d=torch.rand(T, 17, 2) * 50,
                  keypoints_conf=torch.ones(T, 17),
                  others=(Person(track_id=1, joints3d=joints(5000), cameras=cams(),
                                 keypoints2d=torch.rand(T, 17, 2) * 50, keypoints_conf=conf_b),))  # fmt: skip
    inputs = sketch_inputs(scene, "joints3d")
    assert inputs.joints_t.shape == (T - 1, 2, 14, 2) and inputs.depths.shape == (T - 1, 2, 14)
    assert torch.equal(inputs.depths[:, 1], scene.others[0].joints3d[:-1, :, 2])
    assert (inputs.confidence_t[:, 0] == 1).all() and (inputs.confidence_t1[1, 1] == 0).all()
    assert (inputs.confidence_t1[0, 1] == 1).all()


def test_person_balance_makes_every_painted_person_weigh_the_same():
    from lit_boot.flow import FlowTTT
    from lit_boot.flow.people_sketch import MAX_BALANCE, person_balance

    big = torch.stack([standing(30, 32, 1.2), standing(32, 32, 1.2)])  # t, t+1
    small = torch.stack([standing(95, 32, 0.6), standing(94, 32, 0.6)])
    jt, jt1 = torch.stack([big[0], small[0]])[None], torch.stack([big[1], small[1]])[None]
    sketch = sketch_people("coco17", jt, jt1, H, W, config=SketchConfig(guard=False, gate="off"))
    E = len(get_layout("coco17").sketch_bones)
    weight = person_balance(sketch.owner, sketch.mask, E)
    person = sketch.owner // E
    on = [sketch.mask & (person == p) for p in range(2)]
    n = [int(m.sum()) for m in on]
    assert n[0] > 1.5 * n[1] > 0
    assert torch.allclose(weight[on[0]], torch.tensor((n[0] + n[1]) / 2 / n[0]))
    assert torch.allclose(weight[on[1]], torch.tensor(min((n[0] + n[1]) / 2 / n[1], MAX_BALANCE)))
    assert float(weight[on[0]].sum()) == pytest.approx(float(weight[on[1]].sum()), rel=1e-5)  # the same in all
    assert (weight[~sketch.mask] == 1).all()
    one = person_balance(sketch.owner, sketch.mask & (person == 0), E)
    assert (one == 1).all()  # one person painted: nothing to balance
    frames = torch.zeros(2, 3, H, W, dtype=torch.uint8)
    scene = Scene(frames, keypoints2d=big, keypoints_conf=torch.ones(2, 17),
                  others=(Person(track_id=1, keypoints2d=small, keypoints_conf=torch.ones(2, 17)),))  # fmt: skip
    model = FlowTTT(weights=None, sketch=SketchConfig(guard=False, gate="off"), people_balance=True)
    model.targets_from(scene, torch.zeros(1, 2, H, W), inputs=sketch_inputs(scene, "keypoints2d"))
    assert model.balance is not None and model.balance.max() > 1 and model.balance.min() < 1
    off = FlowTTT(weights=None, sketch=SketchConfig(guard=False, gate="off"))
    off.targets_from(scene, torch.zeros(1, 2, H, W), inputs=sketch_inputs(scene, "keypoints2d"))
    assert off.balance is None
