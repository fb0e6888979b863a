"""The fast fine-tune (lit_boot.flow.warm): cached features, warm start, crops (tiny scenes, CPU)."""

from __future__ import annotations

import pytest
import torch

from lit_boot.flow import FlowTTT, SceneFlowData, SketchConfig, person_region, predict_flow
from lit_boot.flow.raft import load_raft
from lit_boot.flow.warm import MIN_CELLS, FeatureCache, box_region, crop_box, paste
from lit_boot.synth import make_scene

WARM = dict(weights=None, train_parts="update_block", warm_start=True, train_updates=2, predict_updates=3,
            sketch=SketchConfig(size=3, guard=False))  # fmt: skip


@pytest.fixture(scope="module")
def scene():
    return make_scene(motion="run", frames=3, height=64, width=96, seed=0)


def test_the_cache_holds_each_frames_features_once_and_rafts_own_flow(scene):
    torch.manual_seed(0)
    model = load_raft("raft_small", None).eval()
    cache = FeatureCache.build(model, scene.frames, updates=3)
    T = scene.num_frames
    assert cache.fmaps.shape[0] == T and cache.hidden.shape[0] == cache.flow8.shape[0] == T - 1
    assert cache.cells == (16, 16) and cache.pad == (16, 16, 32, 32)  # 64x96 padded to 128x128
    with torch.no_grad():
        own = torch.cat([predict_flow(model, scene.frames[t], scene.frames[t + 1], 3) for t in range(T - 1)])
    torch.testing.assert_close(cache.base, own, rtol=1e-4, atol=1e-4)
    assert cache.fits(scene.frames) and cache.fits(scene.frames.clone())
    assert not cache.fits(scene.frames.flip(0))


@pytest.mark.parametrize("margin", [0, 5, 24])
def test_a_crop_box_covers_the_mask_plus_margin_inside_the_grid(margin):
    pad, cells, size = (16, 16, 32, 32), (16, 32), (64, 224)  # a 64x224 frame padded to 128x256
    mask = torch.zeros(size, dtype=torch.bool)
    mask[10:30, 150:170] = True
    box = crop_box(mask, margin, pad, cells)
    y0, y1, x0, x1 = box
    assert 0 <= y0 < y1 <= cells[0] and 0 <= x0 < x1 <= cells[1]
    assert y1 - y0 >= MIN_CELLS and x1 - x0 >= MIN_CELLS  # torchvision's correlation pyramid needs 16
    (fy0, fy1, fx0, fx1), inner = box_region(box, pad, size)
    assert fy0 <= max(0, 10 - margin) and fy1 >= min(64, 30 + margin)
    assert fx0 <= 150 - margin and fx1 >= 170 + margin
    assert inner[1] - inner[0] == fy1 - fy0 and inner[3] - inner[2] == fx1 - fx0
    assert x1 - x0 < cells[1]  # a crop, not the frame
    assert crop_box(torch.zeros(size, dtype=torch.bool), margin, pad, cells) is None
    moving = torch.zeros(2, *size)
    moving[0, 10:30, 150:170] = 40.0  # the pixels go 40 px right: the box reaches there
    _, _, _, x1_moving = crop_box(mask, margin, pad, cells, moving)
    assert x1_moving >= x1 and x1_moving * 8 - pad[0] >= min(size[1], 170 + 40 + margin)
    assert crop_box(mask, None, pad, cells) == (0, cells[0], 0, cells[1])


def test_paste_changes_only_the_boxs_region():
    pad, size, box = (0, 0, 0, 0), (128, 256), (0, 16, 8, 24)
    base, flow = torch.zeros(2, *size), torch.ones(1, 2, 128, 128)
    out = paste(base, flow, box, pad)
    assert out[:, :, 64:192].eq(1).all() and out[:, :, :64].eq(0).all() and out[:, :, 192:].eq(0).all()
    assert base.eq(0).all()  # the input is left alone


def test_warm_start_needs_frozen_encoders():
    with pytest.raises(ValueError, match="warm_start: needs train_parts='update_block'"):
        FlowTTT(weights=None, warm_start=True)


def test_warm_fine_tune_follows_the_target_and_pasted_keeps_the_untuned_flow_outside_the_crop(shared, trainer):
    torch.manual_seed(0)
    wide = make_scene(motion="run", frames=3, height=96, width=256, seed=0)  # the crop is narrower than the frame
    model = FlowTTT(**{**WARM, "weights": str(shared / "checkpoints/raft-small.pth")}, lr=1e-4, crop_margin=0)
    assert model.hparams.paste_crop  # the default
    data = SceneFlowData(wide, pose_source="gt", shuffle=False)
    untuned = torch.cat([o["flow"] for o in trainer().predict(model, datamodule=data)])  # RAFT's own: builds the cache
    cache = model.warm.cache
    assert cache is not None
    torch.testing.assert_close(untuned, cache.base)
    encoders = {k: v.clone() for k, v in model.raft.state_dict().items() if k.startswith(("feature_encoder", "context_encoder"))}
    trainer(epochs=3, limit_val_batches=0).fit(model, datamodule=data)
    assert model.warm.cache is cache  # built once: the initial prediction's features are reused
    assert all(torch.equal(v, model.raft.state_dict()[k]) for k, v in encoders.items())
    torch.testing.assert_close(model.targets[~model.sketch_masks[:, None].expand_as(untuned)],
                               untuned[~model.sketch_masks[:, None].expand_as(untuned)])  # painted over it  # fmt: skip
    tuned = torch.cat([o["flow"] for o in trainer().predict(model, datamodule=data)])
    painted = model.sketch_masks[:, None].expand_as(tuned)
    before = (untuned - model.targets).abs()[painted].mean()
    after = (tuned - model.targets).abs()[painted].mean()
    assert after < 0.95 * before  # measured: 0.88
    for i, box in enumerate(model.warm.boxes):  # outside its box a pair's flow is the untuned one, exactly
        (fy0, fy1, fx0, fx1), _ = box_region(box, cache.pad, tuned.shape[-2:])
        outside = torch.ones(tuned.shape[-2:], dtype=torch.bool)
        outside[fy0:fy1, fx0:fx1] = False
        assert outside.any()
        assert torch.equal(tuned[i][:, outside], untuned[i][:, outside])


def test_the_cache_is_built_with_the_untuned_network_after_resuming_tuned_weights(scene):
    torch.manual_seed(0)
    model = FlowTTT(**WARM)
    own = FeatureCache.build(model.raft, scene.frames, updates=3).base
    with torch.no_grad():  # as a resumed run loads a tuned update block before building the cache
        for p in model.raft.update_block.parameters():
            p.add_(0.05 * torch.randn_like(p))
    tuned = model.raft.update_block.state_dict()
    torch.testing.assert_close(model.warm.build(scene.frames).base, own)
    assert all(torch.equal(v, model.raft.update_block.state_dict()[k]) for k, v in tuned.items())  # restored


def test_after_a_fit_other_frames_are_predicted_warm_from_their_own_untuned_flow(scene, trainer):
    torch.manual_seed(0)
    model = FlowTTT(lr=1e-3, **WARM)
    trainer(limit_val_batches=0).fit(model, datamodule=SceneFlowData(scene, pose_source="gt"))
    other = make_scene(motion="walk", frames=2, height=64, width=96, seed=1)
    flow = torch.cat([o["flow"] for o in trainer().predict(model, datamodule=SceneFlowData(other, shuffle=False))])
    cache = model.warm.cache
    assert cache.fits(other.frames) and model.warm.boxes is None  # rebuilt for these frames, the fit's boxes dropped
    untuned = FlowTTT(**WARM)
    untuned.raft.load_state_dict({**model.raft.state_dict(), **model.warm.untuned})
    with torch.no_grad():
        # the same flow by two paths; their float sums differ by CPU (1.4e-5 px on an AMD EPYC): 1e-4 px
        untuned_flow = predict_flow(untuned.raft.eval(), other.frames[0], other.frames[1], 3)
        torch.testing.assert_close(cache.base, untuned_flow, atol=1e-4, rtol=1e-4)
        whole = (0, cache.cells[0], 0, cache.cells[1])
        tuned = cache.flows(model.raft.eval(), 0, whole, 2)[-1]
    _, (by0, by1, bx0, bx1) = box_region(whole, cache.pad, flow.shape[-2:])
    torch.testing.assert_close(flow[0], tuned[0, :, by0:by1, bx0:bx1])
    assert not torch.equal(flow, cache.base)  # the tuned iterations moved it


def test_without_paste_the_tuned_update_block_predicts_the_whole_frame_from_the_untuned_flow(shared, trainer):
    torch.manual_seed(0)
    wide = make_scene(motion="run", frames=3, height=96, width=256, seed=0)
    model = FlowTTT(**{**WARM, "weights": str(shared / "checkpoints/raft-small.pth")}, lr=1e-4, crop_margin=0,
                    paste_crop=False)  # fmt: skip
    data = SceneFlowData(wide, pose_source="gt", shuffle=False)
    trainer(epochs=2, limit_val_batches=0).fit(model, datamodule=data)
    tuned = torch.cat([o["flow"] for o in trainer().predict(model, datamodule=data)])
    for i, box in enumerate(model.warm.boxes):  # trained on the crop, predicted everywhere from the untuned flow
        (fy0, fy1, fx0, fx1), _ = box_region(box, model.warm.cache.pad, tuned.shape[-2:])
        outside = torch.ones(tuned.shape[-2:], dtype=torch.bool)
        outside[fy0:fy1, fx0:fx1] = False
        assert not torch.equal(tuned[i][:, outside], model.warm.cache.base[i][:, outside])
        assert (tuned[i] - model.warm.cache.base[i]).norm(dim=0)[outside].mean() < 0.5  # a warm start: near it


def test_the_gap_is_given_in_footprint_radii():
    model = FlowTTT(**{**WARM, "sketch": SketchConfig(size=2)}, sketch_weight=5.0, sketch_gap=1.5)
    assert model.loss_fn.gap == 3 and model.loss_fn.sketch_weight == 5.0  # 1.5 footprint radii of 2 px
    assert FlowTTT(**{**WARM, "sketch": SketchConfig(size=4)}, sketch_gap=2.0).loss_fn.gap == 8
    with pytest.raises(ValueError, match="sketch_gap"):
        FlowTTT(weights=None, sketch_gap=-1)


def test_with_the_gap_the_person_beside_the_sketch_follows_it(shared, trainer):
    wide = make_scene(motion="run", frames=3, height=96, width=256, seed=0)
    body = wide.gt.person_mask[:-1]
    errors = {}
    for gap in (0.0, 2.0):
        torch.manual_seed(0)
        weights, sketch = str(shared / "checkpoints/raft-small.pth"), SketchConfig(size=2, guard=False)
        model = FlowTTT(**{**WARM, "weights": weights, "sketch": sketch}, lr=3e-4, crop_margin=0, sketch_weight=5.0,
                        sketch_gap=gap)  # fmt: skip
        data = SceneFlowData(wide, pose_source="gt", shuffle=False)
        trainer(epochs=6, limit_val_batches=0).fit(model, datamodule=data)
        tuned = torch.cat([o["flow"] for o in trainer().predict(model, datamodule=data)])
        beside = body & ~model.sketch_masks & person_region(model.sketch_masks, 4)  # the person beside it
        errors[gap] = float((tuned - wide.gt.flow.float()).norm(dim=1)[beside].mean())
    assert errors[2.0] < 0.9 * errors[0.0], errors  # measured: 2.09 against 2.54 px
