"""Image evidence (lit_boot.flow.evidence): warping, census/SSIM error, forward-backward check."""

from __future__ import annotations

import math

import pytest
import torch

import lit_boot
from lit_boot.flow import load_raft, predict_flow
from lit_boot.flow.evidence import (
    Evidence,
    census_error,
    forward_backward_check,
    pair_evidence,
    photometric_error,
    region_mean,
    ssim_error,
    tile_mean,
    track_error,
    warp,
)


def _texture(x: torch.Tensor, y: torch.Tensor, seed: int = 0) -> torch.Tensor:
    """A smooth RGB texture in (0, 1) at any real coordinates: (3, *x.shape)."""
    g = torch.Generator().manual_seed(seed)
    freq = (torch.rand(3, 4, 2, generator=g) - 0.5) * 0.8  # rad/px, wavelengths above ~8 px
    phase = torch.rand(3, 4, 1, 1, generator=g) * 2 * math.pi
    waves = torch.sin(freq[..., 0, None, None] * x + freq[..., 1, None, None] * y + phase)
    return 0.5 + 0.1 * waves.sum(1)


def _translated_pair(height: int, width: int, shift: tuple[float, float], seed: int = 0):
    """(image1, image2) (1, 3, H, W) with image1(x) = image2(x + shift): the flow is ``shift``."""
    ys, xs = torch.meshgrid(torch.arange(height).float(), torch.arange(width).float(), indexing="ij")
    image1 = _texture(xs, ys, seed)
    image2 = _texture(xs - shift[0], ys - shift[1], seed)
    return image1[None], image2[None]


def _constant_flow(batch: int, height: int, width: int, u: float, v: float) -> torch.Tensor:
    return torch.tensor([u, v]).view(1, 2, 1, 1).expand(batch, 2, height, width).contiguous()


@pytest.fixture(scope="module")
def scene():
    """A panning camera: the background moves by sub-pixel amounts, the person runs."""
    return lit_boot.make_scene(motion="run", frames=3, height=96, width=128, seed=3, pan_deg_per_s=30)


def test_warp_integer_shift_is_exact_and_bounds_follow_the_target():
    big = torch.rand(1, 3, 30, 40, generator=torch.Generator().manual_seed(0))
    image1, image2 = big[..., 5:25, 5:35], big[..., 3:23, 8:38]  # image1(x) = image2(x + (-3, 2))
    warped, inside = warp(image2, _constant_flow(1, 20, 30, -3.0, 2.0))
    expected = torch.zeros(1, 20, 30, dtype=torch.bool)
    expected[:, :18, 3:] = True  # x - 3 >= 0 and y + 2 <= 19
    assert torch.equal(inside, expected)
    torch.testing.assert_close(warped[..., :18, 3:], image1[..., :18, 3:], atol=1e-6, rtol=0)
    # targets within half a pixel of the outer centres are still in the image; NaN never is
    flow = torch.zeros(1, 2, 4, 5)
    flow[0, 0, 0] = torch.tensor([-0.5, 0.0, 0.0, float("nan"), 0.49])  # x + u: -0.5, 1, 2, NaN, 4.49
    flow[0, 0, 1] = torch.tensor([-0.6, 0.0, 0.0, 0.0, 0.5])  # -0.6, ..., 4.5 (W - 0.5)
    inside = warp(torch.rand(1, 1, 4, 5), flow)[1][0]
    assert inside[:2].tolist() == [[True, True, True, False, True], [False, True, True, True, False]]


@pytest.mark.parametrize("shift", [(1.3, -0.6), (-2.5, 0.25)])
def test_warp_with_the_exact_flow_reproduces_a_translated_texture(shift):
    image1, image2 = _translated_pair(48, 64, shift)
    flow = _constant_flow(1, 48, 64, *shift)
    warped, inside = warp(image2, flow)
    assert inside[:, 4:-4, 4:-4].all()
    assert (warped - image1).abs()[..., 4:-4, 4:-4].max() < 0.01  # bilinear error only
    interior = torch.zeros(1, 48, 64, dtype=torch.bool)
    interior[:, 6:-6, 6:-6] = True  # away from the border's padding
    off = flow + torch.tensor([0.5, 0.0]).view(1, 2, 1, 1)
    for measure, near_zero in (("census", 0.3), ("ssim", 1e-3)):  # census: of 48
        error, valid = photometric_error(image1, image2, flow, measure)
        worse, _ = photometric_error(image1, image2, off, measure)
        exact, half_px = region_mean(error, valid & interior).item(), region_mean(worse, valid & interior).item()
        assert exact < near_zero and exact < half_px / 10, (measure, exact, half_px)


@pytest.mark.parametrize("measure", ["census", "ssim"])
def test_the_true_flow_scores_better_than_perturbed_ones(scene, measure):
    frames, gt = scene.frames, scene.gt
    image1, image2, flow = frames[:-1], frames[1:], gt.flow
    g = torch.Generator().manual_seed(0)
    candidates = {
        "gt+1px": flow + torch.tensor([1.0, 0.0]).view(1, 2, 1, 1),
        "gt+3px noise": flow + 3.0 * torch.randn(flow.shape, generator=g),
        "zero": torch.zeros_like(flow),
    }
    error, valid = photometric_error(image1, image2, flow, measure)
    for name, candidate in candidates.items():
        other, other_valid = photometric_error(image1, image2, candidate, measure)
        keep = valid & other_valid & ~gt.flow_occluded
        for region in (keep, keep & gt.person_mask[:-1]):
            better = region_mean(error, region) < region_mean(other, region)
            assert better.all(), f"{measure}: GT flow does not beat {name}"


def test_the_census_distance_of_a_lone_bright_pixel_is_the_hand_derived_one():
    # image1: black, one grey-10 pixel at (4, 4); image2: black. The census signature of a
    # neighbour 10 grey levels away is 10 / sqrt(0.81 + 100) (eps 0.81); of a black one 0. Each
    # neighbour whose signatures differ by d counts d^2 / (0.1 + d^2).
    image1 = torch.zeros(1, 3, 9, 9, dtype=torch.uint8)
    image1[0, :, 4, 4] = 10
    image2 = torch.zeros_like(image1)
    d2 = 100.0 / (0.81 + 100.0)
    one = d2 / (0.1 + d2)  # 0.9084 (a constant of 1 would give 0.4980)
    expected = torch.zeros(9, 9, dtype=torch.float64)
    expected[1:8, 1:8] = one  # the 48 pixels whose 7x7 window holds the bright one: one neighbour differs
    expected[4, 4] = 48 * one  # the bright pixel: all 48 neighbours differ
    error = census_error(image1, image2)[0].double()
    torch.testing.assert_close(error, expected, rtol=1e-5, atol=1e-6)
    # the joint tracks' distance is the same soft Hamming distance
    point = torch.tensor([[[4.0, 4.0]]])
    track, valid = track_error(image1, image2, point, point)
    assert valid.all() and track.item() == pytest.approx(48 * one, rel=1e-5)


def test_census_ignores_a_change_of_lighting(scene):
    image1, image2 = scene.frames[:-1], scene.frames[1:].float() / 255.0
    flow = scene.gt.flow
    noc = ~scene.gt.flow_occluded
    error, valid = photometric_error(image1, image2, flow)
    darker, _ = photometric_error(image1, image2 * 0.7 + 0.05, flow)
    shifted, _ = photometric_error(image1, image2, flow + torch.tensor([1.0, 0.0]).view(1, 2, 1, 1))
    base, dark = region_mean(error, valid & noc), region_mean(darker, valid & noc)
    assert (dark < base + 0.5).all() and (dark < region_mean(shifted, valid & noc)).all()


def test_forward_backward_of_a_translation_flags_nothing_inside():
    fw = torch.cat([_constant_flow(1, 32, 40, 2.5, -1.5), _constant_flow(1, 32, 40, -4.0, 0.0)])
    fb_error, occluded = forward_backward_check(fw, -fw)
    _, inside = warp(torch.zeros(2, 1, 32, 40), fw)
    assert torch.equal(occluded, ~inside)
    assert fb_error.max() < 1e-5
    assert not forward_backward_check(fw, -fw, outside_occluded=False)[1].any()


def test_forward_backward_flags_the_background_a_moving_square_covers():
    height, width, (dx, dy) = 40, 48, (6, 3)
    fw, bw = torch.zeros(1, 2, height, width), torch.zeros(1, 2, height, width)
    fw[0, :, 10:22, 12:24] = torch.tensor([dx, dy], dtype=torch.float32).view(2, 1, 1)
    bw[0, :, 10 + dy : 22 + dy, 12 + dx : 24 + dx] = -torch.tensor([dx, dy], dtype=torch.float32).view(2, 1, 1)
    fb_error, occluded = forward_backward_check(fw, bw)
    square = torch.zeros(1, height, width, dtype=torch.bool)
    square[0, 10:22, 12:24] = True
    covered = torch.zeros_like(square)
    covered[0, 10 + dy : 22 + dy, 12 + dx : 24 + dx] = True
    assert torch.equal(occluded, covered & ~square)  # hidden in frame t+1: exactly these
    assert torch.allclose(fb_error[occluded], torch.tensor(math.hypot(dx, dy)))
    # looser thresholds still flag a 6.7 px disagreement; a huge alpha2 accepts everything
    assert torch.equal(forward_backward_check(fw, bw, alpha1=0.05, alpha2=2.0)[1], occluded)
    assert not forward_backward_check(fw, bw, alpha2=100.0)[1].any()


def test_uint8_and_float_images_give_the_same_evidence(scene):
    as_uint8, as_float = scene.frames, scene.frames.float() / 255.0
    flow = scene.gt.flow
    bw = -flow  # any backward flow: only the fb fields' equality matters here
    for measure in ("census", "ssim"):
        a = pair_evidence(as_uint8[:-1], as_uint8[1:], flow, bw, measure=measure)
        b = pair_evidence(as_float[:-1], as_float[1:], flow, bw, measure=measure)
        torch.testing.assert_close(a.photometric, b.photometric)
        assert torch.equal(a.valid, b.valid) and torch.equal(a.occluded, b.occluded)
    torch.testing.assert_close(census_error(as_uint8, as_uint8.flip(0)), census_error(as_float, as_float.flip(0)))
    torch.testing.assert_close(ssim_error(as_uint8, as_uint8.flip(0)), ssim_error(as_float, as_float.flip(0)))


def test_pair_evidence_fields_and_reliable_pixels(scene):
    image1, image2, flow = scene.frames[:-1], scene.frames[1:], scene.gt.flow
    alone = pair_evidence(image1, image2, flow)
    assert isinstance(alone, Evidence) and alone.fb_error is None and alone.occluded is None
    assert alone.photometric.shape == alone.valid.shape == (2, 96, 128) and alone.valid.dtype == torch.bool
    assert torch.equal(alone.reliable, alone.valid)
    both = pair_evidence(image1, image2, flow, torch.zeros_like(flow), alpha2=1.0)
    assert both.fb_error.shape == both.occluded.shape == (2, 96, 128)
    assert torch.equal(both.reliable, both.valid & ~both.occluded)


def test_photometric_error_is_differentiable_in_the_flow():
    image1, image2 = _translated_pair(24, 32, (1.0, 0.5))
    flow = _constant_flow(1, 24, 32, 0.6, 0.2).requires_grad_()
    for measure in ("census", "ssim"):
        error, valid = photometric_error(image1, image2, flow, measure)
        (grad,) = torch.autograd.grad(error[valid].mean(), flow)
        assert torch.isfinite(grad).all() and grad.abs().sum() > 0


def test_region_and_tile_means_are_nan_where_empty():
    values = torch.arange(2 * 4 * 6, dtype=torch.float32).view(2, 4, 6)
    mask = torch.zeros(2, 4, 6, dtype=torch.bool)
    mask[0, :2] = True
    poisoned = torch.where(mask, values, torch.full_like(values, float("nan")))  # NaN outside the region
    means = region_mean(poisoned, mask)
    assert means[0].item() == values[0, :2].mean().item() and means[1].isnan()
    assert torch.equal(region_mean(values), values.mean((1, 2)))
    tiles = tile_mean(poisoned, mask, tiles=(2, 3))
    assert tiles.shape == (2, 2, 3)
    assert tiles[0, 0].tolist() == values[0, :2].view(2, 3, 2).mean((0, 2)).tolist()
    assert tiles[0, 1].isnan().all() and tiles[1].isnan().all()
    odd = tile_mean(values, tiles=(3, 4))  # 4 rows in 3 tiles, 6 columns in 4: sizes differ by 1
    assert odd.shape == (2, 3, 4) and torch.isfinite(odd).all()
    with pytest.raises(ValueError, match="tiles"):
        tile_mean(values, tiles=(5, 1))
    with pytest.raises(ValueError, match="mask"):
        region_mean(values, mask.float())


def test_bad_inputs_are_value_errors():
    image = torch.rand(1, 3, 8, 8)
    with pytest.raises(ValueError, match="flow"):
        warp(image, torch.zeros(1, 2, 8, 9))
    with pytest.raises(ValueError, match="flow"):
        warp(image, torch.zeros(1, 2, 8, 8, dtype=torch.int64))
    with pytest.raises(ValueError, match="image1"):
        photometric_error(image[0], image, torch.zeros(1, 2, 8, 8))
    with pytest.raises(ValueError, match="measure"):
        photometric_error(image, image, torch.zeros(1, 2, 8, 8), measure="l1")
    with pytest.raises(ValueError, match="uint8"):
        census_error(image.long(), image.long())


def test_nothing_is_made_on_another_device():
    """The meta device runs no kernel: a tensor built on the CPU inside would fail to mix in."""
    images, flow = torch.rand(2, 3, 16, 20, device="meta"), torch.rand(2, 2, 16, 20, device="meta")
    evidence = pair_evidence(images, images, flow, flow)  # census (kornia's SSIM uses autocast: no meta)
    outputs = (evidence.photometric, evidence.fb_error, evidence.reliable)
    assert all(t.device.type == "meta" and t.shape == (2, 16, 20) for t in outputs)
    assert tile_mean(evidence.photometric, evidence.reliable).device.type == "meta"
    assert region_mean(evidence.photometric, evidence.reliable).device.type == "meta"


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_runs_on_the_inputs_device(scene):
    image1, image2, flow = (t.cuda() for t in (scene.frames[:-1], scene.frames[1:], scene.gt.flow))
    evidence = pair_evidence(image1, image2, flow, -flow)
    cpu = pair_evidence(scene.frames[:-1], scene.frames[1:], scene.gt.flow, -scene.gt.flow)
    assert evidence.photometric.is_cuda and evidence.occluded.is_cuda
    torch.testing.assert_close(evidence.photometric.cpu(), cpu.photometric, atol=1e-3, rtol=1e-3)
    assert tile_mean(evidence.photometric, evidence.reliable).is_cuda


@pytest.mark.parametrize("kwargs", [dict(motion="run", seed=1), dict(motion="walk", seed=2, pan_deg_per_s=20)])
def test_raft_forward_backward_finds_the_synthetic_occlusions(shared, kwargs):
    """Occlusion estimate of RAFT-small (20 updates) vs the exact GT occlusion mask: both
    precision and recall well above a random mask's (precision = occlusion rate, recall = flagged
    fraction). Measured here: run/1 P 0.31 R 0.63 (occlusion rate 0.026, flagged 0.053); walk/2
    with pan P 0.38 R 0.56 (0.029, 0.042)."""
    scene = lit_boot.make_scene(frames=3, height=192, width=192, **kwargs)
    model = load_raft("raft_small", shared / "checkpoints" / "raft-small.pth").eval()
    with torch.no_grad():
        fw = predict_flow(model, scene.frames[:-1], scene.frames[1:], num_flow_updates=20)
        bw = predict_flow(model, scene.frames[1:], scene.frames[:-1], num_flow_updates=20)
    _, flagged = forward_backward_check(fw, bw)
    occluded = scene.gt.flow_occluded
    hits = (flagged & occluded).sum().item()
    precision, recall = hits / max(flagged.sum().item(), 1), hits / occluded.sum().item()
    assert precision > 4 * occluded.float().mean().item()
    assert recall > 4 * flagged.float().mean().item()


@pytest.mark.parametrize("measure", ["census", "ssim"])
@pytest.mark.parametrize("box", [(8, 40, 16, 60), (0, 24, 0, 30), (40, 64, 70, 96)])  # inside, at corners
def test_a_box_is_measured_as_the_whole_frame_there(scene, measure, box):
    frames, flow = scene.frames[:2], scene.gt.flow[:1]
    whole, valid = photometric_error(frames[:1], frames[1:], flow, measure)
    part, part_valid = photometric_error(frames[:1], frames[1:], flow, measure, box=box)
    y0, y1, x0, x1 = box
    assert part.shape == (1, y1 - y0, x1 - x0)
    torch.testing.assert_close(part, whole[:, y0:y1, x0:x1])
    assert torch.equal(part_valid, valid[:, y0:y1, x0:x1])
