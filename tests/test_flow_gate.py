"""The evidence gate (lit_boot.flow.gate): wrong sketches fall back to the base flow, right ones
stay, the counts are right, FlowTTT reports them (tiny synthetic scenes, CPU)."""

from __future__ import annotations

import math

import pytest
import torch

from lit_boot.flow import (
    GATE_REPORT_KEYS,
    FlowTTT,
    SketchConfig,
    forward_backward_check,
    gate_sketch,
    load_raft,
    photometric_error,
    predict_flow,
    sketch_flow,
    sketch_from_layout,
    sketch_inputs,
    target_flow,
)
from lit_boot.synth import make_scene

GUARDLESS = {"guard": False, "footprint": "cross", "size": 5}  # the gate alone decides


@pytest.fixture(scope="module")
def scene():
    return make_scene(motion="run", frames=3, height=128, width=128, seed=0)


@pytest.fixture(scope="module")
def base(scene, shared):
    """Pretrained RAFT-small's forward and backward flows of the scene's pairs (12 updates)."""
    raft = load_raft("raft_small", str(shared / "checkpoints/raft-small.pth")).eval()
    f = scene.frames
    with torch.no_grad():
        return predict_flow(raft, f[:-1], f[1:], 12).float(), predict_flow(raft, f[1:], f[:-1], 12).float()


def draw(scene, base_fw, shift: float = 0.0, **config):
    """The GT joints' sketch over ``base_fw``, frame t+1 joints moved right by ``shift`` px."""
    inp = sketch_inputs(scene, "gt")
    cfg = SketchConfig(**config)
    sk = sketch_from_layout(inp.layout, inp.joints_t, inp.joints_t1 + torch.tensor([shift, 0.0]),
                            scene.height, scene.width, depths=inp.depths, base_flow=base_fw, config=cfg)  # fmt: skip
    return sk, cfg


def test_bad_gate_options_are_refused():
    for bad in ({"gate": "census"}, {"gate_level": "joint"}, {"gate_core": -1.0}, {"gate_margin": math.nan}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            SketchConfig(**bad)


def test_sketch_records_which_bone_painted_each_pixel():
    joints_t = torch.tensor([[[10.0, 10.0], [10.0, 30.0], [40.0, 10.0], [40.0, 30.0]]])
    sk = sketch_flow(joints_t, joints_t + 1.0, [(0, 1), (2, 3)], 48, 64, config=SketchConfig(footprint="disk", size=2))
    assert (sk.owner[0, 10:31, 10] == 0).all() and (sk.owner[0, 10:31, 40] == 1).all()
    assert ((sk.owner >= 0) == sk.mask).all()
    assert torch.equal(sk.bone_ends[0, 1], joints_t[0, 2:4])


def test_gate_off_changes_nothing(scene, base):
    sk, cfg = draw(scene, base[0], **GUARDLESS)
    gated, report = gate_sketch(scene.frames[:-1], scene.frames[1:], base[0], sk, cfg)
    assert gated is sk and report == {}


def test_a_wrong_displacement_is_rejected_and_the_target_is_the_base_there(scene, base):
    frames1, frames2 = scene.frames[:-1], scene.frames[1:]
    right, cfg = draw(scene, base[0], gate="photometric", gate_level="bone", **GUARDLESS)
    wrong, _ = draw(scene, base[0], shift=10.0, gate="photometric", gate_level="bone", **GUARDLESS)
    kept_right = gate_sketch(frames1, frames2, base[0], right, cfg)[1]["gate_kept_fraction"]
    gated, report = gate_sketch(frames1, frames2, base[0], wrong, cfg)
    assert kept_right > 0.8  # the GT joints' displacement explains the images: mostly kept
    assert report["gate_kept_fraction"] < 0.5 * kept_right and report["gate_rejected_bones"] >= 5
    assert gated.mask.sum() == round(report["gate_kept_fraction"] * wrong.mask.sum().item())
    target = target_flow(base[0], gated)
    dropped = wrong.mask & ~gated.mask
    assert dropped.any() and torch.equal(target.permute(0, 2, 3, 1)[dropped], base[0].permute(0, 2, 3, 1)[dropped])
    gt = scene.gt.flow
    epe = lambda f, m: (f - gt).norm(dim=1)[m].mean()  # noqa: E731
    assert epe(target, wrong.mask) < epe(target_flow(base[0], wrong), wrong.mask) - 2.0  # less harm


def test_pixel_level_keeps_exactly_the_pixels_the_images_prefer(scene, base):
    sk, cfg = draw(scene, base[0], gate="photometric", gate_level="pixel", gate_margin=0.5, **GUARDLESS)
    frames1, frames2 = scene.frames[:-1], scene.frames[1:]
    gated, report = gate_sketch(frames1, frames2, base[0], sk, cfg)
    err_s, ok_s = photometric_error(frames1, frames2, sk.flow)
    err_b, ok_b = photometric_error(frames1, frames2, base[0])
    expected = sk.mask & ok_s & ok_b & (err_s <= err_b + 0.5)
    assert torch.equal(gated.mask, expected) and 0 < expected.sum() < sk.mask.sum()
    worse = sk.mask & ok_s & ok_b & ~expected
    assert report["gate_worse_fraction"] == pytest.approx(float(worse.sum() / sk.mask.sum()))
    assert (gated.flow.permute(0, 2, 3, 1)[~gated.mask] == 0).all() and torch.equal(
        gated.flow.permute(0, 2, 3, 1)[gated.mask], sk.flow.permute(0, 2, 3, 1)[gated.mask])


def test_bone_plus_pixel_keeps_the_pixels_both_levels_keep(scene, base):
    sk, _ = draw(scene, base[0], **GUARDLESS)
    frames1, frames2 = scene.frames[:-1], scene.frames[1:]
    masks = {}
    for level in ("pixel", "bone", "bone+pixel"):
        config = SketchConfig(gate="photometric", gate_level=level)
        masks[level] = gate_sketch(frames1, frames2, base[0], sk, config)[0].mask
    assert torch.equal(masks["bone+pixel"], masks["bone"] & masks["pixel"])
    assert 0 < masks["bone+pixel"].sum() < min(masks["bone"].sum(), masks["pixel"].sum())


def test_fb_gate_also_keeps_pixels_where_the_base_fails_its_check(scene, base):
    wrong, cfg = draw(scene, base[0], shift=10.0, gate="photometric+fb", gate_level="pixel", **GUARDLESS)
    frames1, frames2 = scene.frames[:-1], scene.frames[1:]
    with pytest.raises(ValueError, match="base_flow_bw"):
        gate_sketch(frames1, frames2, base[0], wrong, cfg)
    no_fb = gate_sketch(frames1, frames2, base[0], wrong, SketchConfig(gate="photometric", gate_level="pixel"))[0]
    zero_bw = torch.zeros_like(base[0])  # disagrees wherever the forward flow moves > ~0.7 px
    gated, report = gate_sketch(frames1, frames2, base[0], wrong, cfg, zero_bw)
    failed = forward_backward_check(base[0], zero_bw)[1] & wrong.mask
    assert torch.equal(gated.mask, no_fb.mask | failed)
    assert report["gate_fb_failed_fraction"] == pytest.approx(float(failed.sum() / wrong.mask.sum()))
    consistent = gate_sketch(frames1, frames2, base[0], wrong, cfg, base[1])[1]  # RAFT's own backward flow
    assert consistent["gate_fb_failed_fraction"] < report["gate_fb_failed_fraction"]


def test_flow_ttt_gates_its_targets_and_reports_the_counts(scene, shared):
    weights = str(shared / "checkpoints/raft-small.pth")
    inputs = sketch_inputs(scene, "gt")
    off = FlowTTT(weights=weights, train_updates=8, sketch=SketchConfig(**GUARDLESS))
    base, bw = off.base_flows(scene)
    assert bw is None  # no backward pass unless the fb gate asks for it
    report_off = off.targets_from(scene, base, inputs=inputs)
    assert not any(k.startswith("target/gate_") for k in report_off)
    gated = SketchConfig(gate="photometric+fb", gate_level="bone", **GUARDLESS)
    on = FlowTTT(weights=weights, train_updates=8, sketch=gated)
    report = on.prepare(scene, inputs)
    assert {f"target/{k}" for k in GATE_REPORT_KEYS} <= report.keys()
    kept = on.sketch_masks.sum() / off.sketch_masks.sum()
    assert report["target/gate_kept_fraction"] == pytest.approx(float(kept)) and 0.5 < kept < 1.0
    assert (on.sketch_masks <= off.sketch_masks).all()
    assert report["target/painted_fraction"] == pytest.approx(on.sketch_masks.float().mean().item())
    outside = ~on.sketch_masks[:, None].expand_as(base)
    # outside the kept pixels the target is the base flow (the same RAFT, run again)
    assert torch.allclose(on.targets[outside], base[outside], atol=1e-4)


def test_search_recovers_a_small_displacement_error(scene, base):
    frames1, frames2 = scene.frames[:-1], scene.frames[1:]
    wrong, cfg = draw(scene, base[0], shift=2.0, gate="photometric", gate_level="bone", **GUARDLESS)
    searched = SketchConfig(gate="photometric", gate_level="bone", gate_search=2, **GUARDLESS)
    plain, report_plain = gate_sketch(frames1, frames2, base[0], wrong, cfg)
    fixed, report = gate_sketch(frames1, frames2, base[0], wrong, searched)
    assert report_plain["gate_search_shift_px"] == 0.0 and 1.5 < report["gate_search_shift_px"] < 2.5
    assert report["gate_kept_fraction"] > report_plain["gate_kept_fraction"] + 0.2
    gt = scene.gt.flow
    epe = lambda f, m: (f - gt).norm(dim=1)[m].mean()  # noqa: E731
    right = draw(scene, base[0], **GUARDLESS)[0]
    # the searched sketch is nearer the right one than the wrong one
    assert epe(fixed.flow, fixed.mask) < (epe(wrong.flow, wrong.mask) + epe(right.flow, right.mask)) / 2
