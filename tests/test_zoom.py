"""The zoom: RAFT on a zoomed crop around the person (lit_boot.flow.zoom) and the zoom stage that
keeps it unless the frames refuse it (lit_boot.bootstrap.zoom)."""

from __future__ import annotations

import dataclasses

import pytest
import torch

import lit_boot
from lit_boot.bootstrap import BootstrapConfig, bootstrap
from lit_boot.bootstrap.config import ZoomConfig
from lit_boot.bootstrap.zoom import box_masks, keep_pixels, person_boxes, zoom_flows
from lit_boot.flow import zoom as flow_zoom
from lit_boot.flow.zoom import boxes_from_points, pair_boxes, paste_region, refines, zoom_crop, zoom_pair, zoom_scale

RANDOM_RAFT = {"weights": None, "train_updates": 2, "predict_updates": 3}
FAST = dict(flow_epochs=1, pose_steps=15, progress_bar=False, video=False)
ZOOM = dict(max_scale=2.0, min_scale=1.25, reach_px=60.0, context=0.25, min_context_px=16, border_px=8, min_updates=8,
            max_updates=16)


def test_boxes_from_points_bound_the_counted_points_and_mark_nobody():
    points = torch.tensor([[[10.0, 20.0], [30.0, 5.0], [99.0, 99.0]], [[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]])
    keep = torch.tensor([[True, True, False], [True, False, False]])
    boxes = boxes_from_points(points, keep)
    assert boxes[0].tolist() == [10.0, 5.0, 30.0, 20.0, 1.0]  # the third point does not count
    assert boxes[1].tolist() == [0.0] * 5  # one point: nobody


def test_pair_boxes_hold_both_frames_boxes_or_the_one_found():
    boxes = torch.tensor([[10.0, 10, 20, 30, 1], [15, 5, 40, 25, 1], [0, 0, 0, 0, 0], [0, 0, 0, 0, 0]])
    pairs = pair_boxes(boxes)
    assert pairs[0].tolist() == [10, 5, 40, 30]
    assert pairs[1].tolist() == [15, 5, 40, 25]
    assert pairs[2] is None


def test_zoom_crop_adds_the_context_inside_the_frame():
    box = torch.tensor([40.0, 10.0, 80.0, 110.0])  # 40 wide, 100 tall: margin 25 px
    assert zoom_crop(box, (120, 200), context=0.25, min_context_px=16) == (0, 120, 15, 106)
    small = torch.tensor([50.0, 50.0, 54.0, 54.0])  # margin at least 16 px
    assert zoom_crop(small, (120, 200), context=0.25, min_context_px=16) == (34, 71, 34, 71)


def test_the_scale_keeps_the_zoomed_motion_within_reach():
    box = torch.tensor([0.0, 0.0, 9.0, 9.0])
    base = torch.zeros(2, 10, 10)
    base[0] = 10.0  # 10 px everywhere: 60 / 10 would allow 6x, capped at 2
    assert zoom_scale(base, box, max_scale=2.0, min_scale=1.25, reach_px=60.0) == (2.0, 10.0)
    base[0] = 40.0  # 60 / 40 = 1.5
    assert zoom_scale(base, box, max_scale=2.0, min_scale=1.25, reach_px=60.0)[0] == pytest.approx(1.5)
    base[0] = 55.0  # 60 / 55 < 1.25: not zoomed
    assert zoom_scale(base, box, max_scale=2.0, min_scale=1.25, reach_px=60.0)[0] == 1.0
    assert zoom_scale(torch.zeros(2, 10, 10), box, max_scale=2.0, min_scale=1.25, reach_px=60.0)[0] == 2.0


def test_the_iterations_grow_with_the_zoomed_motion_in_cells():
    from lit_boot.flow.zoom import zoom_updates

    assert zoom_updates(2.0, 0.0, min_updates=8, max_updates=16) == 8
    assert zoom_updates(2.0, 3.9, min_updates=8, max_updates=16) == 9  # 7.8 px zoomed: one cell
    assert zoom_updates(2.0, 4.1, min_updates=8, max_updates=16) == 10  # 8.2 px: into a second cell
    assert zoom_updates(1.5, 40.0, min_updates=8, max_updates=16) == 16  # 60 px: capped
    with pytest.raises(ValueError, match="zoom.max_updates"):
        ZoomConfig(updates=12, max_updates=10)


def test_paste_region_drops_the_crops_inner_edges_only():
    assert paste_region((0, 50, 30, 100), (50, 100), 8) == (0, 50, 38, 100)
    assert paste_region((10, 40, 30, 70), (50, 100), 8) == (18, 32, 38, 62)


def test_refines_is_a_change_below_the_limit():
    base = torch.zeros(2, 1, 3)
    zoomed = torch.tensor([[[3.0, 8.0, 0.0]], [[4.0, 0.0, 7.9]]])  # changes 5, 8, 7.9
    assert refines(base, zoomed, 8.0).tolist() == [[True, False, True]]


def test_the_zoomed_flow_is_scaled_back_to_the_frames_pixels(monkeypatch):
    """A stand-in for RAFT that answers a constant flow at the size it is given: the crop's flow is
    that flow divided by the zoom in each axis, at the crop's size."""
    seen = {}

    def fake_predict(model, a, b, updates):
        seen["size"], seen["updates"] = tuple(a.shape[-2:]), updates
        flow = torch.zeros(1, 2, *a.shape[-2:])
        flow[:, 0], flow[:, 1] = 6.0, -4.0
        return flow

    monkeypatch.setattr(flow_zoom, "predict_flow", fake_predict)
    frames = torch.zeros(2, 3, 100, 160, dtype=torch.uint8)
    flow = flow_zoom.zoomed_flow(torch.nn.Linear(1, 1), frames[0], frames[1], (10, 60, 20, 120), 2.0, 7)
    assert seen == {"size": (100, 200), "updates": 7}
    assert flow.shape == (2, 50, 100)
    assert torch.allclose(flow[0], torch.full((50, 100), 3.0)) and torch.allclose(flow[1], torch.full((50, 100), -2.0))


def test_zoom_pair_pastes_the_zoomed_flow_into_its_region_only(monkeypatch):
    monkeypatch.setattr(flow_zoom, "zoomed_flow", lambda model, a, b, crop, scale, updates, *rest: torch.ones(
        2, crop[1] - crop[0], crop[3] - crop[2]))  # fmt: skip
    frames = torch.zeros(2, 3, 120, 200, dtype=torch.uint8)
    base = torch.zeros(2, 120, 200)
    pair = zoom_pair(torch.nn.Linear(1, 1), frames[0], frames[1], base, torch.tensor([60.0, 40.0, 100.0, 80.0]), **ZOOM)
    assert pair.scale == 2.0 and pair.crop == (24, 97, 44, 117) and pair.region == (32, 89, 52, 109)
    assert pair.updates == 8 and pair.record()["updates"] == 8  # no motion: the fewest iterations
    y0, y1, x0, x1 = pair.region
    assert (pair.candidate[:, y0:y1, x0:x1] == 1).all()
    assert pair.candidate.sum() == 2 * (y1 - y0) * (x1 - x0)  # nothing outside the region
    assert pair.cost == pytest.approx(73 * 73 * 4 / (120 * 200))
    assert (base == 0).all()  # the input is not modified
    # nobody, or a motion beyond reach: the base itself
    assert zoom_pair(None, frames[0], frames[1], base, None, **ZOOM).region is None
    fast = torch.full((2, 120, 200), 50.0)
    assert zoom_pair(None, frames[0], frames[1], fast, torch.tensor([60.0, 40, 100, 80]), **ZOOM).region is None


def _textured_pair(shift: int, frames: int = 2) -> torch.Tensor:
    """Frames (frames, 3, 96, 128) uint8 of a smooth random texture (blobs of about 4 px), each
    the previous one moved right by ``shift`` px."""
    g = torch.Generator().manual_seed(0)
    width = 128 + shift * (frames - 1)
    coarse = torch.rand(1, 3, 24, width // 4 + 1, generator=g)
    smooth = torch.nn.functional.interpolate(coarse, size=(96, width), mode="bicubic", align_corners=False)[0]
    texture = (smooth.clamp(0, 1) * 255).to(torch.uint8)
    start = shift * (frames - 1)
    return torch.stack([texture[:, :, start - shift * t : start - shift * t + 128] for t in range(frames)])


def test_the_stage_keeps_a_confirmed_refinement_and_refuses_a_large_change():
    frames = _textured_pair(3)  # pixel x of frame 0 is at x + 3 in frame 1
    truth = torch.zeros(2, 96, 128)
    truth[0] = 3.0
    base = truth.clone()
    base[0, 20:70, 30:90] = 0.5  # RAFT's flow wrong on the person
    region = (20, 70, 30, 90)
    config = ZoomConfig(confirm="census")
    keep = keep_pixels(frames, base, truth, region, config)
    assert keep[25:65, 40:80].float().mean() > 0.95  # confirmed by the frames, a change of 2.5 px
    assert not keep[:20].any() and not keep[:, :30].any()  # only within the region
    far = base.clone()
    far[0, 20:70, 30:90] = 3.0 + 16.0  # no better, and a change of 18.5 px
    assert not keep_pixels(frames, base, far, region, config).any()
    near = truth.clone()
    near[0, 20:70, 30:90] = 2.0  # 1 px off
    wrong = truth.clone()
    wrong[0, 20:70, 30:90] = 0.0  # a small change (2 px) to a worse flow: the frames refuse it
    assert keep_pixels(frames, near, wrong, region, config)[25:65, 40:80].float().mean() < 0.05
    alone = ZoomConfig(confirm="none")  # the refinement limit alone: the small worse change is kept too
    assert keep_pixels(frames, near, wrong, region, alone)[20:70, 30:90].all()
    assert not keep_pixels(frames, near, wrong, region, alone)[:20].any()
    assert not keep_pixels(frames, base, far, region, alone).any()  # ... and the large change refused


def test_the_veto_keeps_the_zoomed_flow_unless_the_frames_refuse_it():
    """confirm="veto": the zoomed flow is kept where the frames cannot tell (a flat region, where
    census keeps RAFT's), and refused where they say RAFT's is better."""
    frames = _textured_pair(3)
    truth = torch.zeros(2, 96, 128)
    truth[0] = 3.0
    region = (20, 70, 30, 90)
    veto, census = ZoomConfig(confirm="veto"), ZoomConfig(confirm="census")
    base = truth.clone()
    base[0, 20:70, 30:90] = 0.5
    assert keep_pixels(frames, base, truth, region, veto)[25:65, 40:80].float().mean() > 0.95  # better: kept
    near, wrong = truth.clone(), truth.clone()
    near[0, 20:70, 30:90], wrong[0, 20:70, 30:90] = 2.0, 0.0
    assert keep_pixels(frames, near, wrong, region, veto)[25:65, 40:80].float().mean() < 0.05  # worse: refused
    flat = torch.full_like(frames, 128)
    assert keep_pixels(flat, base, truth, region, veto)[20:70, 30:90].all()  # no evidence either way: kept
    assert not keep_pixels(flat, base, truth, region, census).any()
    assert not keep_pixels(flat, base, truth, region, veto)[:20].any()  # only within the region
    far = base.clone()
    far[0, 20:70, 30:90] = 3.0 + 16.0
    assert not keep_pixels(frames, base, far, region, veto).any()  # the refinement limit holds


def test_zoom_flows_records_every_pair(monkeypatch):
    frames = _textured_pair(3, frames=3)
    scene = lit_boot.Scene(frames=frames)
    base = torch.zeros(2, 2, 96, 128)
    boxes = torch.tensor([[40.0, 30, 80, 60, 1], [40, 30, 80, 60, 1], [0, 0, 0, 0, 0]])
    truth = torch.zeros(2, 96, 128)
    truth[0] = 3.0
    monkeypatch.setattr(flow_zoom, "zoomed_flow", lambda model, a, b, crop, scale, updates, *rest: truth[
        :, crop[0] : crop[1], crop[2] : crop[3]])  # fmt: skip
    flows, kept, record = zoom_flows(None, scene, base, boxes, ZoomConfig().for_mode("3d"))
    assert record["zoomed_pairs"] == 2 and len(record["per_pair"]) == 2
    assert kept[0].any() and kept[1].any() and record["kept_fraction"] == pytest.approx(float(kept.float().mean()))
    whole, none = (kept == 1)[:, None].expand_as(flows), (kept == 0)[:, None].expand_as(flows)
    assert torch.equal(flows[whole], truth.expand_as(flows)[whole])  # the zoomed flow where its weight is 1
    assert torch.equal(flows[none], base[none])  # RAFT's where it is 0
    torch.testing.assert_close(flows, base + kept[:, None] * (truth - base))  # a blend of the two between
    assert box_masks(boxes, (96, 128))[1, 30:61, 40:81].all() and not box_masks(boxes, (96, 128))[:, :30].any()


def test_every_person_is_zoomed_in_turn(monkeypatch):
    from lit_boot.bootstrap.zoom import _zoom_people, zoom_line
    from lit_boot.core import Person

    frames = _textured_pair(3, frames=3)
    a = torch.tensor([[10.0, 30, 50, 60, 1]] * 3)
    b = torch.tensor([[80.0, 20, 120, 70, 1]] * 3)
    conf = torch.ones(3, 17)
    scene = lit_boot.Scene(frames=frames, keypoints2d=torch.full((3, 17, 2), 20.0), keypoints_conf=conf,
                           person_boxes=a, others=(Person(track_id=4, keypoints2d=torch.full((3, 17, 2), 90.0),
                                                          keypoints_conf=conf, person_boxes=b),))  # fmt: skip
    truth = torch.full((2, 96, 128), 3.0)
    monkeypatch.setattr(flow_zoom, "zoomed_flow", lambda model, a, b, crop, scale, updates, *rest: truth[
        :, crop[0] : crop[1], crop[2] : crop[3]])  # fmt: skip
    base = torch.zeros(2, 2, 96, 128)
    config = ZoomConfig().for_mode("2d")
    flows, kept, record, person = _zoom_people(None, scene, base, "2d", config)
    main_only = zoom_flows(None, scene.person(0), base, a, config)[1]
    assert kept[:, 30:61, 80:121].any() and not main_only[:, :, 75:].any()  # the second person's box zoomed too
    assert person[:, 30:61, 10:51].all() and person[:, 20:71, 80:121].all()
    assert [p["track_id"] for p in record["people"]] == [0, 4] and record["zoomed_pairs"] == 4
    assert "4 pairs of 2 people (2 pairs each) zoomed" in zoom_line(record, 2)


def test_person_boxes_come_from_the_pose_when_the_scene_has_none():
    scene = lit_boot.make_scene(motion="run", frames=3, height=64, width=96, seed=0)
    boxes = person_boxes(scene, "2d")
    points, keep = scene.pose_points("2d")
    assert boxes.shape == (3, 5)
    for t in range(3):
        p = points[t][keep[t]]
        assert boxes[t, :4].tolist() == pytest.approx([*p.min(0).values.tolist(), *p.max(0).values.tolist()])


def test_config_turns_the_zoom_stage_on_in_the_default_preset_only():
    assert BootstrapConfig().stages() == ["zoom", "flow_1", "pose_1", "flow_2"]
    assert BootstrapConfig(preset="paper").stages() == ["flow_1", "pose_1", "flow_2"]
    assert BootstrapConfig(zoom={"method": "off"}).stages() == ["flow_1", "pose_1", "flow_2"]
    assert BootstrapConfig(preset="paper", zoom={"method": "person"}).zooming == "person"
    with pytest.raises(ValueError, match="zoom.reach_px"):
        BootstrapConfig(zoom={"reach_px": 0})
    with pytest.raises(ValueError, match="zoom: unknown key 'scale'"):
        BootstrapConfig(zoom={"scale": 2})
    with pytest.raises(ValueError, match="zoom.teach"):
        ZoomConfig(teach="sketch")
    with pytest.raises(ValueError, match="zoom.confirm: expected one of"):
        ZoomConfig(confirm="flow")


def test_a_run_records_the_zoom_stage_and_resumes_past_it(tmp_path, monkeypatch):
    scene = lit_boot.make_scene(motion="run", frames=3, height=64, width=96, seed=0)
    result = bootstrap(scene, tmp_path / "run", flow=RANDOM_RAFT, cycles=0, **FAST)
    zoom = result.history[1]
    assert zoom["stage"] == "zoom" and zoom["kind"] == "zoom"
    assert set(zoom["info"]["zoom"]) >= {"kept_fraction", "zoomed_pairs", "cost", "seconds", "per_pair"}
    assert (tmp_path / "run/stages/zoom/flows.npz").is_file() and (tmp_path / "run/stages/zoom/decisions.npz").is_file()
    from lit_boot.bootstrap import zoom as stage

    monkeypatch.setattr(stage, "zoom_flows", lambda *a, **k: pytest.fail("a finished zoom stage ran again"))
    again = bootstrap(scene, tmp_path / "run", flow=RANDOM_RAFT, cycles=0, **FAST)
    assert torch.equal(again.flows, result.flows)


def test_the_zoom_makes_rafts_flow_on_the_person_better(shared):
    """Real RAFT-small on a synthetic scene with GT: the zoom stage lowers the person's EPE and
    leaves the background no worse."""
    scene = lit_boot.make_scene(motion="run", frames=3, height=128, width=256, seed=0)
    model = lit_boot.flow.load_raft("raft_small", str(shared / "checkpoints/raft-small.pth"))
    with torch.no_grad():
        base = torch.stack([lit_boot.flow.predict_flow(model, scene.frames[t : t + 1], scene.frames[t + 1 : t + 2])[0]
                            for t in range(2)])  # fmt: skip
    flows, kept, _ = zoom_flows(model, scene, base, person_boxes(scene, "2d"), ZoomConfig().for_mode("3d"))
    gt = scene.gt
    valid = gt.flow_mask()
    person, background = valid & gt.person_mask[:-1], valid & ~gt.person_mask[:-1]

    def epe(f, m):
        return float((f - gt.flow).norm(dim=1)[m].mean())

    assert (kept > 0).any()
    assert epe(flows, person) < 0.9 * epe(base, person)
    assert epe(flows, background) <= epe(base, background) * 1.01


def test_the_command_line_spells_the_zoom_settings_nested(tmp_path):
    from lit_boot.cli.console import dataclass_from
    from lit_boot.cli.runs import bootstrap_parser

    for config in ("configs/bootstrap.yaml", "configs/bootstrap_2d.yaml"):
        args = bootstrap_parser().parse_args(["--config", config, "--data.scene", str(tmp_path), "--zoom.method", "off",
                                              "--zoom.max_scale", "3", "--zoom.teach", "confirmed"])  # fmt: skip
        parsed = dataclass_from(args, BootstrapConfig)
        assert parsed.zoom == ZoomConfig(method="off", max_scale=3.0, teach="confirmed") and parsed.zooming == "off"
        default = dataclass_from(bootstrap_parser().parse_args(["--config", config, "--data.scene", str(tmp_path)]),
                                 BootstrapConfig)  # fmt: skip
        assert default.zoom == ZoomConfig()  # the config files state the defaults


def test_frame2s_crop_follows_the_person_inside_the_frame():
    from lit_boot.flow.zoom import box_motion, shifted_crop

    base = torch.zeros(2, 50, 80)
    base[0, 10:30, 20:40], base[1, 10:30, 20:40] = 12.4, -3.0
    base[0, 10:12, 20:40] = 100.0  # a few outliers: the median holds
    assert box_motion(base, torch.tensor([20.0, 10, 39, 29])).tolist() == pytest.approx([12.4, -3.0])
    assert shifted_crop((5, 35, 10, 50), torch.tensor([12.4, -3.0]), (50, 80)) == (12, -3)
    assert shifted_crop((5, 35, 10, 50), torch.tensor([45.0, -9.0]), (50, 80)) == (30, -5)  # held at the edges
    with pytest.raises(ValueError, match="zoom.start: expected one of"):
        ZoomConfig(start="base")


def test_a_shifted_or_warm_started_zoom_follows_a_motion_beyond_rafts_reach(shared):
    """Real RAFT-small on a texture moved 64 px and a crop 40 px wide: frame2's same crop does not
    hold what frame1's shows (and zoomed 2x the motion is 128 px), so RAFT from zero fails; with
    frame2's crop following the motion (shift, 4 px short), or moved 44 px with RAFT started from a
    flow 4 px off (warm), the zoomed flow is right."""
    frames = _textured_pair(64)
    model = lit_boot.flow.load_raft("raft_small", str(shared / "checkpoints/raft-small.pth")).eval()
    crop = (8, 88, 4, 44)
    truth = torch.tensor([64.0, 0.0])[:, None, None]

    def error(flow):
        return float((flow - truth).norm(dim=0)[8:-8, 8:-8].mean())

    zero = flow_zoom.zoomed_flow(model, frames[0], frames[1], crop, 2.0, 12)
    shifted = flow_zoom.zoomed_flow(model, frames[0], frames[1], crop, 2.0, 12, shift=(60, 0))
    near = torch.zeros(2, 80, 40)
    near[0] = 60.0
    warm = flow_zoom.zoomed_flow(model, frames[0], frames[1], crop, 2.0, 12, shift=(44, 0), start=near)
    assert error(zero) > 10.0
    assert error(shifted) < 1.0 and error(warm) < 1.0


def test_a_small_persons_crop_is_zoomed_more_at_the_same_cost(monkeypatch):
    from lit_boot.flow.zoom import scale_cap

    # a crop of a quarter of the frame's pixels: 2x costs one frame, so no more than max_scale
    assert scale_cap((0, 50, 0, 100), (100, 200), max_scale=2.0, small_scale=4.0, max_cost=1.0) == 2.0
    # a crop of 1/16 of the frame: 4x costs one frame
    assert scale_cap((0, 25, 0, 50), (100, 200), max_scale=2.0, small_scale=4.0, max_cost=1.0) == pytest.approx(4.0)
    # 1/9: 3x; and never more than small_scale however small
    assert scale_cap((0, 20, 0, 50), (90, 100), max_scale=2.0, small_scale=4.0, max_cost=1.0) == pytest.approx(3.0)
    assert scale_cap((0, 5, 0, 5), (100, 200), max_scale=2.0, small_scale=4.0, max_cost=1.0) == 4.0
    frames = torch.zeros(2, 3, 200, 400, dtype=torch.uint8)
    seen = {}

    def fake(model, a, b, crop, scale, updates, *rest):
        seen["scale"] = scale
        return torch.zeros(2, crop[1] - crop[0], crop[3] - crop[2])

    monkeypatch.setattr(flow_zoom, "zoomed_flow", fake)
    box = torch.tensor([190.0, 90.0, 210.0, 110.0])  # a 20 px person: its crop (52 px) is 1/30 of the frame
    pair = zoom_pair(None, frames[0], frames[1], torch.zeros(2, 200, 400), box, **ZOOM, small_scale=4.0)
    assert pair.scale == 4.0 and seen["scale"] == 4.0
    assert zoom_pair(None, frames[0], frames[1], torch.zeros(2, 200, 400), box, **ZOOM).scale == 2.0
    fast = torch.zeros(2, 200, 400)
    fast[0] = 20.0  # 20 px of motion: the reach (60 px) allows 3x only
    assert zoom_pair(None, frames[0], frames[1], fast, box, **ZOOM, small_scale=4.0).scale == pytest.approx(3.0)
    with pytest.raises(ValueError, match="zoom.small_scale"):
        ZoomConfig(small_scale=1.5)


def test_the_zoomed_crop_keeps_within_max_pixels(monkeypatch):
    """RAFT's correlation memory grows with the square of the zoomed pixels: ``max_pixels`` bounds
    them whatever the person's size, and a pair it would zoom less than min_scale is not zoomed."""
    from lit_boot.data.memory import ZOOM_PIXELS

    frames = torch.zeros(2, 3, 200, 400, dtype=torch.uint8)
    seen = {}

    def fake(model, a, b, crop, scale, updates, *rest):
        seen["pixels"] = (crop[1] - crop[0]) * (crop[3] - crop[2]) * scale**2
        return torch.zeros(2, crop[1] - crop[0], crop[3] - crop[2])

    monkeypatch.setattr(flow_zoom, "zoomed_flow", fake)
    base, box = torch.zeros(2, 200, 400), torch.tensor([150.0, 50.0, 250.0, 150.0])  # a 100 px person
    assert zoom_pair(None, frames[0], frames[1], base, box, **ZOOM).scale == 2.0  # no limit: 90000 px
    bounded = zoom_pair(None, frames[0], frames[1], base, box, **ZOOM, max_pixels=50_000)
    y0, y1, x0, x1 = bounded.crop  # about 150 x 150 px
    assert bounded.scale < 2.0 and bounded.scale == pytest.approx((50_000 / ((y1 - y0) * (x1 - x0))) ** 0.5)
    assert seen["pixels"] == pytest.approx(50_000)
    assert zoom_pair(None, frames[0], frames[1], base, box, **ZOOM, max_pixels=30_000).scale == 1.0  # < 1.25x
    small = torch.tensor([190.0, 90.0, 210.0, 110.0])  # a small person zoomed up to small_scale: bounded too
    assert zoom_pair(None, frames[0], frames[1], base, small, **ZOOM, small_scale=4.0, max_pixels=10_000).scale < 2.0
    assert ZoomConfig().max_pixels == ZOOM_PIXELS  # the memory check assumes the default
    with pytest.raises(ValueError, match="zoom.max_pixels"):
        ZoomConfig(max_pixels=0)


def test_the_zooms_cost_is_the_modes_unless_given(monkeypatch):
    """``max_cost`` "auto" (the default): two frames of pixels in 3D mode, four in 2D mode (each
    mode's speed bar); a small person's crop is then zoomed more in 2D; a number holds in both."""
    from lit_boot.bootstrap.stage_configs import ZOOM_COST
    from lit_boot.bootstrap.zoom import zoom_stage

    assert ZoomConfig().max_cost == "auto" and ZOOM_COST == {"3d": 2.0, "2d": 4.0}
    assert ZoomConfig().for_mode("3d").max_cost == 2.0 and ZoomConfig().for_mode("2d").max_cost == 4.0
    assert ZoomConfig(max_cost=3.0).for_mode("2d").max_cost == 3.0
    with pytest.raises(ValueError, match="mode: expected one of"):
        ZoomConfig().for_mode("4d")
    for bad in (0.0, -1.0, "lots"):
        with pytest.raises(ValueError, match="zoom.max_cost: expected 'auto' or > 0 frames"):
            ZoomConfig(max_cost=bad)
    box = torch.tensor([[56.0, 40, 72, 56, 1]] * 3)  # a 17 px person in a 96x128 frame: capped by the cost
    scene = dataclasses.replace(lit_boot.make_scene(motion="run", frames=3, height=96, width=128, seed=0),
                                person_boxes=box)  # both modes' poses; the detector's box  # fmt: skip
    monkeypatch.setattr(flow_zoom, "zoomed_flow", lambda model, a, b, crop, scale, updates, *rest: torch.zeros(
        2, crop[1] - crop[0], crop[3] - crop[2]))  # fmt: skip
    base = torch.zeros(2, 2, 96, 128)
    with pytest.raises(ValueError, match="zoom.max_cost 'auto' depends on the mode"):
        zoom_flows(None, scene, base, box, ZoomConfig())
    raft = torch.nn.Linear(1, 1)  # moved to the device and back; the zoomed flow is monkeypatched
    zooms = {mode: zoom_stage(raft, scene, base, mode=mode, config=ZoomConfig(small_scale=8.0), device="cpu")[0]
             for mode in ("3d", "2d")}  # fmt: skip
    info = {mode: record["info"]["zoom"] for mode, record in zooms.items()}
    assert info["3d"]["max_cost"] == 2.0 and info["2d"]["max_cost"] == 4.0
    scale = {mode: info[mode]["per_pair"][0]["scale"] for mode in info}
    assert scale["2d"] == pytest.approx(scale["3d"] * 2**0.5, rel=1e-3)  # twice the pixels (records: 4 digits)
    assert info["2d"]["cost"] == pytest.approx(2 * info["3d"]["cost"], rel=1e-3)
    fixed = zoom_stage(raft, scene, base, mode="2d", config=ZoomConfig(small_scale=8.0, max_cost=2.0), device="cpu")
    assert fixed[0]["info"]["zoom"]["per_pair"][0]["scale"] == pytest.approx(scale["3d"])



def test_the_zoomed_flow_fades_in_inside_its_region_and_not_at_the_frames_edge():
    """No step where the crop ends: 0 on the region's outermost row, 1 at FADE_PX px inside; a
    side on the frame's edge does not fade (there is nothing beyond it to step from)."""
    from lit_boot.bootstrap.zoom import FADE_PX, fade_in

    weight = fade_in((10, 60, 0, 50), (80, 100))  # its left side is the frame's edge
    assert weight[:10].eq(0).all() and weight[60:].eq(0).all() and weight[:, 50:].eq(0).all()
    assert weight[10, 20] == 0 and weight[10 + FADE_PX // 2, 20] == pytest.approx(0.5)
    assert weight[10 + FADE_PX, 20] == 1 and weight[35, 0] == 1  # inside, and along the frame's edge
    assert weight[35, 49] == 0 and weight[35, 49 - FADE_PX] == 1


def test_a_scattered_choice_is_made_coherent():
    """A pixel keeps the candidate only where most of its 3x3 neighbourhood chose it: stray single
    pixels go, regions stay, and a refused pixel is never given the candidate."""
    from lit_boot.bootstrap.zoom import coherent
    from lit_boot.metrics.coherence import speckle

    choice = torch.zeros(20, 20, dtype=torch.bool)
    choice[4:12, 4:12] = True  # a region
    choice[15, 15] = True  # a stray pixel chosen
    choice[7, 7] = False  # a stray pixel refused inside the region
    out = coherent(choice)
    assert not out[15, 15] and not out[7, 7] and out[5:11, 5:11].sum() == 35 and not out[:3].any()
    assert speckle(out[None]) < speckle(choice[None])
