"""The flow stage's self-check (lit_boot.bootstrap.selfcheck) on tiny synthetic scenes (CPU)."""

from __future__ import annotations

import csv
import json

import kornia
import pytest
from numpy import load as np_load
import torch

import lit_boot
from lit_boot.bootstrap import Bootstrap, BootstrapConfig, bootstrap
from lit_boot.bootstrap.config import WHOLE_FRAME_MAX_CHANGE_PX, SelfCheckConfig
from lit_boot.bootstrap import runner as runner_module
from lit_boot.bootstrap.decisions import DECISION_COLOURS, decision_image, load_decisions, load_mask
from lit_boot.bootstrap.selfcheck import (blend_weights, changed_box, check_stage, choose_pixels, choose_regions,
                                         region_labels, region_names, self_check)
from lit_boot.flow import person_region
from lit_boot.flow.evidence import photometric_error

TILE = 32


def fast_run(shared, **options):
    flow = {"weights": str(shared / "checkpoints/raft-small.pth"), "train_updates": 2, "predict_updates": 3}
    return dict(flow=flow, flow_epochs=1, cycles=0, progress_bar=False, video=False, zoom={"method": "off"},
                self_check=SelfCheckConfig(method="photometric", tile=TILE), **options)  # fmt: skip


@pytest.fixture(scope="module")
def scene():
    return lit_boot.make_scene(motion="run", frames=3, height=64, width=96, seed=0)


def test_regions_are_tiles_split_into_person_and_background():
    person = torch.zeros(1, 64, 96, dtype=torch.bool)
    person[0, 10:40, 40:50] = True
    labels = region_labels(person, TILE)
    names = region_names(64, 96, TILE)
    cells = ["0_0", "0_1", "0_2", "1_0", "1_1", "1_2"]
    assert names == [f"tile_{c}" for c in cells] + [f"person_{c}" for c in cells]
    assert names[int(labels[0, 0, 0])] == "tile_0_0" and names[int(labels[0, 63, 95])] == "tile_1_2"
    assert names[int(labels[0, 20, 45])] == "person_0_1" and names[int(labels[0, 35, 45])] == "person_1_1"
    assert names[int(labels[0, 20, 39])] == "tile_0_1"
    assert set(labels[person].tolist()) == {names.index("person_0_1"), names.index("person_1_1")}


def test_a_corrupted_tile_gets_the_initial_flow_and_an_exact_region_keeps_the_tuned(scene):
    gt = scene.gt.flow.float()
    person = scene.gt.person_mask[:-1]
    bad = torch.zeros(64, 96, dtype=torch.bool)
    bad[32:, 64:] = True  # tile_1_2
    initial = torch.where(bad, gt, gt + 1.5)  # exact in tile_1_2, 1.5 px off elsewhere
    tuned = torch.where(bad, gt + 5.0, gt)  # 5 px off in tile_1_2, exact elsewhere
    config = SelfCheckConfig(margin=0.02, tile=TILE, blend=2, window=5, own=False)  # the box alone decides (own: below)
    flows, record, _ = self_check(scene.frames, initial, tuned, person, config=config)
    for pair in record["per_pair"]:
        kept_initial = set(pair["regions"]) - set(pair["tuned"])
        assert kept_initial == {"tile_1_2"}  # the corrupted tile only
        err_initial, err_tuned, pixels = pair["regions"]["tile_1_2"]
        assert err_initial < err_tuned and pixels > 0
        err_initial, err_tuned, pixels, kept = pair["person"]  # the person, judged pixel by pixel
        assert err_tuned < err_initial and pixels > 0 and kept > 0.5
    assert record["regions_initial"] == 2 and record["person_tuned_fraction"] > 0.5
    # farther from the corrupted corner than the window and the blend (2 + 2 px), the output is
    # exactly one flow or the other, on the person and off it
    far_bad = torch.zeros_like(bad)
    far_bad[37:, 69:] = True
    far_good = torch.zeros_like(bad)
    far_good[:27, :59] = True
    assert torch.equal(flows[:, :, far_bad], initial[:, :, far_bad])
    assert torch.equal(flows[:, :, far_good], tuned[:, :, far_good])
    assert 0.5 < record["kept_tuned_fraction"] < 1.0


def test_a_change_beyond_max_change_keeps_the_initial_flow_whatever_the_frames_say(scene):
    gt = scene.gt.flow.float()
    person = scene.gt.person_mask[:-1]
    initial = gt.clone()
    initial[:, 0, :, :48] += 10.0  # 10 px off on the left half
    initial[:, 0, :, 48:] += 2.0  # 2 px off on the right half
    tuned = gt  # exact: better everywhere, by a change of 10 px on the left, 2 px on the right
    gated = SelfCheckConfig(tile=TILE, max_change_px=8.0)
    flows, record, weight = self_check(scene.frames, initial, tuned, person, config=gated)
    assert (weight[:, :, :48] == 0).all()  # refused: a change of 10 px
    assert weight[:, :, 56:].mean() > 0.5  # a refinement of 2 px, confirmed by the frames
    assert record["max_change_px"] == 8.0
    _, _, free = self_check(scene.frames, initial, tuned, person, config=SelfCheckConfig(tile=TILE, max_change_px=None))
    assert free[:, :, :40].mean() > 0.5  # without the gate the frames decide alone
    with pytest.raises(ValueError, match="self_check.max_change_px"):
        SelfCheckConfig(max_change_px=0.0)


def test_auto_limits_the_change_only_where_the_whole_frame_is_tuned(scene):
    """``max_change_px`` "auto" (the default): the authors' whole-frame fine-tune gets the zoom's
    16 px refinement limit (a held-out Sintel window, fog and fast motion: the frames preferred
    changes of about 30 px that were wrong), the crop fine-tune none."""
    gt = scene.gt.flow.float()
    person = scene.gt.person_mask[:-1]
    initial = gt.clone()
    initial[:, 0, :, :48] += 20.0  # 20 px off on the left half: the exact flow is a change of 20 px there
    crop = BootstrapConfig(self_check={"method": "photometric", "tile": TILE})
    whole = BootstrapConfig(self_check={"method": "photometric", "tile": TILE}, flow={"crop_margin": None})
    assert crop.self_check.max_change_px == "auto" and whole.self_check.max_change_px == "auto"
    assert (crop.change_limit, whole.change_limit) == (None, WHOLE_FRAME_MAX_CHANGE_PX) == (None, 16.0)
    _, record, weight = check_stage(crop, scene, initial, gt, person)
    assert record["max_change_px"] is None and weight[:, :, :40].mean() > 0.5  # the frames decide
    _, record, weight = check_stage(whole, scene, initial, gt, person)
    assert record["max_change_px"] == 16.0 and (weight[:, :, :48] == 0).all()  # refused: not a refinement
    explicit = BootstrapConfig(self_check={"max_change_px": None}, flow={"crop_margin": None})
    assert explicit.change_limit is None and BootstrapConfig(self_check={"max_change_px": 8}).change_limit == 8


def test_ties_keep_the_initial_flow(scene):
    gt = scene.gt.flow.float()
    person = scene.gt.person_mask[:-1]
    initial = gt + 0.7
    flows, record, _ = self_check(scene.frames, initial, initial.clone(), person, config=SelfCheckConfig(tile=TILE))
    assert torch.equal(flows, initial)
    assert record["kept_tuned_fraction"] == 0.0 and record["regions_tuned"] == 0
    # a gain within the margin is a tie too: the tuned flow must be clearly better
    flows, record, _ = self_check(scene.frames, initial, initial + 1e-3, person,
                                  config=SelfCheckConfig(margin=0.02, tile=TILE))
    assert torch.equal(flows, initial)


def test_the_blend_is_smooth_and_exact_away_from_borders():
    choice = torch.zeros(2, 40, 60, dtype=torch.bool)
    choice[:, :, 30:] = True
    weight = blend_weights(choice, blend=4)
    assert torch.equal(weight[:, :, :26], torch.zeros(2, 40, 26))
    assert torch.equal(weight[:, :, 35:], torch.ones(2, 40, 25))
    ramp = weight[0, 20, 25:36]
    assert (ramp.diff() >= 0).all() and ramp.diff().max() <= 1 / 9 + 1e-6  # steps of 1/(2*4+1)
    assert torch.allclose(weight[0, 0], weight[0, 20])  # no fall-off at the frame's edge
    assert torch.equal(blend_weights(choice, 0), choice.float())


def test_config_checks_the_self_check_options():
    assert BootstrapConfig().checking == "photometric" and BootstrapConfig(preset="paper").checking == "off"
    assert BootstrapConfig(self_check=SelfCheckConfig(method="off")).checking == "off"
    given = BootstrapConfig(self_check={"method": "off", "tile": 16})  # a dict is taken too
    assert given.self_check == SelfCheckConfig(method="off", tile=16)
    for bad, message in [({"method": "x"}, "self_check.method: expected one of"),
                         ({"margin": 1.0}, "self_check.margin: expected 0 <= margin < 1"),
                         ({"tile": 0}, "self_check.tile: expected >= 1 px"),
                         ({"blend": -1}, "self_check.blend: expected >= 0 px"),
                         ({"window": 0}, "self_check.window: expected >= 1 px"),
                         ({"z": -1.0}, "self_check.z: expected >= 0"),
                         ({"tiles": 16}, "self_check: unknown key 'tiles'")]:  # fmt: skip
        with pytest.raises(ValueError, match=message):
            BootstrapConfig(self_check=bad)
    with pytest.raises(ValueError, match="self_check: expected a SelfCheckConfig or a dict of its fields"):
        BootstrapConfig(self_check="off")  # the method is self_check.method
    with pytest.raises(TypeError):
        SelfCheckConfig("off")  # keyword-only


def test_the_command_line_spells_the_self_check_settings_nested(tmp_path):
    from lit_boot.cli.console import dataclass_from
    from lit_boot.cli.runs import bootstrap_parser

    args = bootstrap_parser().parse_args(["--config", "configs/bootstrap.yaml", "--data.scene", str(tmp_path),
                                          "--self_check.margin", "0.05", "--self_check.method", "off"])  # fmt: skip
    config = dataclass_from(args, BootstrapConfig)
    assert config.self_check == SelfCheckConfig(method="off", margin=0.05)
    assert BootstrapConfig(**config.to_dict()) == config  # a stored config (config.json, a dataset's) reads back


@pytest.mark.shared
def test_a_run_outputs_the_checked_flows(shared, scene, tmp_path, monkeypatch):
    real = runner_module.predict_flows
    initial = []

    def designed(*args, **kwargs):  # the flow stage "predicts" the GT left of x = 32, RAFT's + 3 px elsewhere
        flows = real(*args, **kwargs)
        if not initial:
            initial.append(flows)
            return flows
        left = torch.arange(96) < TILE
        return torch.where(left, scene.gt.flow.float(), initial[0] + 3.0)

    monkeypatch.setattr(runner_module, "predict_flows", designed)
    boot = Bootstrap(scene, tmp_path / "run", **fast_run(shared))
    result = boot.run()
    person = person_region(boot.models[0].sketch_masks)
    check = json.loads((tmp_path / "run/stages/flow_1/stage.json").read_text())["info"]["self_check"]
    for pair in check["per_pair"]:
        assert not {"tile_0_1", "tile_0_2", "tile_1_1", "tile_1_2"} & set(pair["tuned"])
        assert {name for name in ("tile_0_0", "tile_1_0") if name in pair["regions"]} <= set(pair["tuned"])
    far = ~person_region(person, margin=4)  # beyond the blend around the person region
    right, left = far.clone(), far.clone()
    right[..., : TILE + 4] = False
    left[..., TILE - 4 :] = False
    assert left.any() and right.any()
    flows, gt = result.flows.transpose(0, 1), scene.gt.flow.float().transpose(0, 1)
    assert torch.equal(flows[:, right], initial[0].transpose(0, 1)[:, right])  # exactly RAFT's
    assert torch.equal(flows[:, left], gt[:, left])  # exactly the tuned (here the GT) flow
    with np_load(tmp_path / "run/stages/flow_1/flows.npz") as saved:
        assert torch.equal(torch.from_numpy(saved["flow"]), result.flows)
    # the decisions: saved per flow stage, returned, summarised, drawn
    decisions = load_decisions(tmp_path / "run/stages/flow_1/decisions.npz")
    assert torch.equal(decisions["painted"], boot.models[0].sketch_masks)
    assert (decisions["kept"][left] == 1).all() and (decisions["kept"][right] == 0).all()
    assert torch.allclose(result.decisions["kept"], decisions["kept"], atol=1 / 255)
    summary = json.loads((tmp_path / "run/summary.json").read_text())
    entry = summary["decisions"][0]
    assert entry["stage"] == "flow_1" and not entry["rolled_back"]
    assert entry["kept_tuned_fraction"] == pytest.approx(check["kept_tuned_fraction"])
    assert entry["painted_fraction"] == pytest.approx(float(decisions["painted"].float().mean()))
    with open(tmp_path / "run/logs/csv/summary/metrics.csv") as f:
        rows = [r for r in csv.DictReader(f) if r.get("decisions/kept_tuned_fraction")]
    assert [float(r["decisions/kept_tuned_fraction"]) for r in rows] == pytest.approx([check["kept_tuned_fraction"]])
    image = decision_image(scene.frames[0], decisions["painted"][0], decisions["kept"][0])
    assert (image[:, decisions["painted"][0]] == torch.tensor(DECISION_COLOURS["painted"])[:, None]).all()
    plain = decision_image(scene.frames[0], torch.zeros_like(decisions["painted"][0]), torch.zeros(64, 96))
    blue = image.float()[2] - plain.float()[2]
    assert (blue[left[0] & ~decisions["painted"][0]] > 0).all() and (blue[right[0]] == 0).all()


@pytest.mark.shared
def test_a_run_with_the_self_check_records_it_does_no_harm_and_resumes(shared, scene, tmp_path):
    result = bootstrap(scene, tmp_path / "run", **fast_run(shared))
    stage = json.loads((tmp_path / "run/stages/flow_1/stage.json").read_text())
    check = stage["info"]["self_check"]
    assert check["regions_tuned"] + check["regions_initial"] > 0 and len(check["per_pair"]) == 2
    summary = json.loads((tmp_path / "run/summary.json").read_text())
    assert summary["stages"][-1]["info"]["self_check"]["kept_tuned_fraction"] == check["kept_tuned_fraction"]
    assert "epe" in check["tuned_metrics"]
    unjudged = load_mask(tmp_path / "run/stages/initial/unjudged.npz")  # RAFT's forward-backward check, saved once
    assert unjudged.shape == (2, 64, 96) and check["unjudged_fraction"] == pytest.approx(float(unjudged.float().mean()))
    kept = load_decisions(tmp_path / "run/stages/flow_1/decisions.npz")["kept"]
    assert not (kept[unjudged] > 0).any()  # the tuned flow is kept nowhere the frames cannot judge
    # the final flows are no worse than the initial flows in any region (up to the blend at borders)
    person = torch.zeros(2, 64, 96, dtype=torch.bool)
    labels = region_labels(person, TILE)
    for flows_t, init_t, f0, f1, lab in zip(result.flows, result.initial_flows, scene.frames[:-1], scene.frames[1:],
                                            labels):  # fmt: skip
        err_f, ok_f = photometric_error(f0[None], f1[None], flows_t[None])
        err_i, ok_i = photometric_error(f0[None], f1[None], init_t[None])
        ok = (ok_f & ok_i)[0]
        for r in lab.unique():
            sel = ok & (lab == r)
            assert err_f[0][sel].mean() <= err_i[0][sel].mean() * 1.02 + 0.05
    again = bootstrap(scene, tmp_path / "run", **fast_run(shared))  # loaded, not run again
    assert torch.equal(again.flows, result.flows)


def test_the_person_is_judged_pixel_by_pixel_so_the_band_around_it_keeps_the_initial_flow():
    scene = lit_boot.make_scene(motion="run", frames=3, height=96, width=128, seed=3)
    gt, body = scene.gt.flow.float(), scene.gt.person_mask[:-1]

    def grow(mask, r):
        return kornia.morphology.dilation(mask[:, None].float(), torch.ones(2 * r + 1, 2 * r + 1))[:, 0] > 0

    # the tuned flow follows the body exactly but drags a 3 px band of background along with it
    # (the body's mean motion there), as RAFT's 1/8-resolution update does; RAFT is 0.5 px off
    band = grow(body, 3) & ~body
    motion = torch.stack([(gt[t][:, body[t]]).mean(1) for t in range(2)])[..., None, None].expand_as(gt)
    initial = gt + torch.tensor([0.5, 0.0]).view(1, 2, 1, 1)
    tuned = torch.where(band[:, None], motion, gt)
    assert (motion - gt).norm(dim=1)[band].mean() > 2  # the band's harm is real
    config = SelfCheckConfig(tile=TILE, window=3, blend=0)
    flows, record, weight = self_check(scene.frames, initial, tuned, grow(body, 8), config=config)
    epe = lambda f, m: float((f - gt).norm(dim=1)[m].mean())  # noqa: E731
    inner = ~grow(~body, 1)  # body pixels 1+ px from its edge
    assert epe(flows, inner) < 0.5 * epe(initial, inner)  # the gain on the body is kept
    assert epe(flows, band) < 0.5 * epe(tuned, band)  # the harm around it is not
    assert record["person_tuned_fraction"] > 0.2


def test_a_tile_gain_within_the_noise_keeps_the_initial_flow():
    torch.manual_seed(0)
    labels = torch.zeros(64, 64, dtype=torch.long)
    labels[:, 32:] = 1
    valid = torch.ones(64, 64, dtype=torch.bool)
    initial = torch.full((64, 64), 20.0)
    noise = 12.0 * torch.randn(64, 64)
    noise -= noise[labels == 0].mean()
    tuned = initial - 1.0 + torch.where(labels == 0, noise, 0.0)  # the same 5% gain in both tiles, the left one noisy
    won, mean_i, mean_t, _ = choose_regions(initial, tuned, valid, labels, 2, margin=0.02, z=1.0)
    assert torch.allclose(mean_t / mean_i, torch.tensor([0.95, 0.95]), atol=1e-4)
    assert won.tolist() == [False, True]  # the noisy gain is not clear of its standard error
    won, *_ = choose_regions(initial, tuned, valid, labels, 2, margin=0.02, z=0.0)
    assert won.tolist() == [True, True]


def test_only_the_tiles_where_the_flows_differ_are_measured_and_the_decisions_are_the_whole_frames():
    scene = lit_boot.make_scene(motion="run", frames=3, height=96, width=160, seed=3)
    gt, frames = scene.gt.flow.float(), scene.frames
    person = scene.gt.person_mask[:-1]
    initial = gt + torch.tensor([0.7, -0.4]).view(1, 2, 1, 1)  # RAFT off everywhere
    tuned = initial.clone()
    tuned[0, :, 20:70, 40:100] = gt[0, :, 20:70, 40:100]  # pair 0: exact in one part; pair 1: unchanged
    config = SelfCheckConfig(tile=TILE, window=5, blend=1)
    flows, record, weight = self_check(frames, initial, tuned, person, config=config)
    labels, count = region_labels(person, TILE), 2 * 3 * 5
    choices = []
    for t in range(2):  # the same decisions measured over the whole frame
        pair = frames[t : t + 1], frames[t + 1 : t + 2]
        err_i, valid_i = photometric_error(*pair, initial[t : t + 1])
        err_t, valid_t = photometric_error(*pair, tuned[t : t + 1])
        err_i, err_t, valid = err_i[0], err_t[0], (valid_i & valid_t)[0]
        won = choose_regions(err_i, err_t, valid & ~person[t], labels[t], count, margin=0.02, z=1.0)[0]
        on_person = choose_pixels(err_i, err_t, valid, person[t], window=5, margin=0.02, own=True)
        choices.append(torch.where(person[t], on_person, won[labels[t]]))
    assert torch.equal(weight, blend_weights(torch.stack(choices), 1))
    assert weight[0].sum() > 0 and not weight[1].any()
    assert changed_box(initial[0], tuned[0], TILE, 6) == (0, 96, 32, 128)  # rows 14..76, cols 34..106: out to tiles
    assert changed_box(initial[1], tuned[1], TILE, 6) is None
    assert record["per_pair"][1]["regions"] == {} and 0 < len(record["per_pair"][0]["regions"]) < 15


def test_with_own_a_pixel_its_window_favours_still_needs_its_own_error_lower():
    initial = torch.ones(24, 24)
    tuned = torch.ones(24, 24)
    tuned[6:18, 6:18] = 0.2  # the limb: the tuned flow explains it far better
    ring = torch.zeros(24, 24, dtype=torch.bool)
    ring[5:19, 5:19] = True
    ring[6:18, 6:18] = False
    tuned[ring] = 1.5  # the band beside it: worse, but its 5x5 box holds limb pixels
    every = torch.ones(24, 24, dtype=torch.bool)
    swayed = choose_pixels(initial, tuned, every, every, window=5, margin=0.02)
    own = choose_pixels(initial, tuned, every, every, window=5, margin=0.02, own=True)
    assert swayed[ring].float().mean() > 0.5  # the window alone gives the band the tuned flow
    assert not own[ring].any()  # its own error says no
    assert own[6:18, 6:18].all()  # the limb keeps it
    flows, record, _ = self_check(torch.zeros(2, 3, 24, 24, dtype=torch.uint8), torch.zeros(1, 2, 24, 24),
                                  torch.ones(1, 2, 24, 24), every[None], config=SelfCheckConfig(own=True))  # fmt: skip
    assert record["own"] is True


def test_the_default_preset_frees_the_zone_beside_the_sketch_and_checks_each_pixel_on_its_own_error():
    for mode in ("3d", "2d"):
        config = BootstrapConfig(mode=mode)
        assert config.self_check.own is True and config.self_check.blend == 0
        assert config.flow_kwargs()["sketch_gap"] == 2.0
    assert BootstrapConfig(mode="2d").flow_kwargs()["plateau_delta"] == 0.02
    assert "sketch_gap" not in BootstrapConfig(preset="paper").flow_kwargs()  # the authors hold every pixel


def test_a_tile_gain_below_the_margin_keeps_the_initial_flow_and_one_above_it_takes_the_tuned():
    """choose_regions with margin 0.02 on noise-free tiles (a clear gain): the tuned flow wins a
    tile only where its error is below 0.98 x the initial's, so 1% better keeps the initial
    flow, 3% better takes the tuned, and 1% worse keeps the initial."""
    labels = torch.arange(3).repeat_interleave(8).expand(8, 24)  # three 8x8 tiles side by side
    valid = torch.ones(8, 24, dtype=torch.bool)
    initial = torch.full((8, 24), 20.0)
    tuned = torch.tensor([0.99, 0.97, 1.01]).repeat_interleave(8).expand(8, 24) * 20.0
    won, mean_i, mean_t, pixels = choose_regions(initial, tuned, valid, labels, 3, margin=0.02, z=1.0)
    assert pixels.tolist() == [64, 64, 64]
    assert torch.allclose(mean_t / mean_i, torch.tensor([0.99, 0.97, 1.01]))
    assert won.tolist() == [False, True, False]
    won, *_ = choose_regions(initial, tuned, valid, labels, 3, margin=0.0, z=1.0)
    assert won.tolist() == [True, True, False]  # no margin: any clear gain


def test_a_person_pixel_gain_below_the_margin_keeps_the_initial_flow_and_one_above_it_takes_the_tuned():
    """choose_pixels with margin 0.02 on three noise-free bands of constant error: inside each
    band (beyond the 3x3 box) the tuned flow wins only where its error is below 0.98 x the
    initial's: 1% better and 1% worse keep the initial flow, 3% better takes the tuned."""
    initial = torch.full((8, 24), 10.0)
    tuned = torch.tensor([0.99, 0.97, 1.01]).repeat_interleave(8).expand(8, 24) * 10.0
    every = torch.ones(8, 24, dtype=torch.bool)
    for own in (False, True):
        won = choose_pixels(initial, tuned, every, every, window=3, margin=0.02, own=own)
        assert not won[:, 0:7].any()  # 1% better: within the margin
        assert won[:, 9:15].all()  # 3% better: beyond it
        assert not won[:, 17:24].any()  # 1% worse
    won = choose_pixels(initial, tuned, every, every, window=3, margin=0.0)
    assert won[:, 0:15].all() and not won[:, 17:24].any()  # no margin: any gain


def test_a_pixel_the_frames_cannot_judge_keeps_the_initial_flow(scene):
    """The tuned flow is the GT and the initial 1.5 px off: the rules take the tuned flow, except
    where the frames cannot judge (an ``unjudged`` pixel, or one whose target leaves the frame)."""
    gt = scene.gt.flow.float()
    initial, person = gt + 1.5, scene.gt.person_mask[:-1]
    config = SelfCheckConfig(tile=TILE, window=5, own=False)
    flows, record, _ = self_check(scene.frames, initial, gt, person, config=config)
    assert record["unjudged_fraction"] is None
    refused_at_border = sum(p["unjudged"] for p in record["per_pair"])  # targets 1.5 px beyond the frame's edge
    chose = (flows == gt).all(1)
    assert chose[:, 16:48, 16:80].float().mean() > 0.9  # the frames prefer the exact flow inside
    unjudged = torch.zeros_like(person)
    unjudged[:, 20:30, 30:60] = True  # say the forward-backward check flagged these as occluded
    flows, record, _ = self_check(scene.frames, initial, gt, person, config=config, unjudged=unjudged)
    assert torch.equal(flows[:, :, 20:30, 30:60], initial[:, :, 20:30, 30:60])
    refused = sum(p["unjudged"] for p in record["per_pair"])
    assert refused == refused_at_border + int((chose & unjudged).sum())
    assert record["unjudged_fraction"] == pytest.approx(300 / (64 * 96))
    leaving = gt.clone()
    leaving[:, 0, :, -6:] = 40.0  # the tuned target of the last 6 columns leaves the frame
    flows, _, _ = self_check(scene.frames, initial, leaving, person, config=config)
    assert torch.equal(flows[..., -6:], initial[..., -6:])


def test_the_frames_cannot_judge_an_occluded_pixel_by_the_forward_backward_check():
    """A square moving right by 4 px over a still background: the background it covers in frame
    t+1 is flagged (the backward flow there is the square's, not the background's), the rest not."""
    from lit_boot.bootstrap.selfcheck import unjudged_pixels

    forward, backward = torch.zeros(1, 2, 32, 32), torch.zeros(1, 2, 32, 32)
    forward[0, 0, 10:20, 10:20] = 4.0  # the square, frame t
    backward[0, 0, 10:20, 14:24] = -4.0  # the square, frame t+1, moving back
    flagged = unjudged_pixels(forward, backward)[0]
    assert flagged[10:20, 20:24].all()  # covered by the square in t+1: occluded
    assert not flagged[10:20, 10:20].any() and not flagged[:10].any() and not flagged[20:].any()
