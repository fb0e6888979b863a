"""The no-GT measures of how usable a flow is (lit_boot.metrics.coherence), on flows built by hand."""

from __future__ import annotations

import math

import pytest
import torch

from lit_boot.metrics.coherence import border_step, changed_pixels, roughness, speckle


def test_a_change_in_one_region_is_not_speckle_and_one_on_scattered_pixels_is():
    block = torch.zeros(1, 20, 20, dtype=torch.bool)
    block[0, 5:15, 5:15] = True
    assert speckle(block) == pytest.approx(4 / 100)  # only the block's 4 corners see 3 of 8 changed
    scattered = torch.zeros(1, 20, 20, dtype=torch.bool)
    scattered[0, ::3, ::3] = True  # isolated single pixels
    assert speckle(scattered) == 1.0
    assert speckle(torch.zeros(1, 4, 4, dtype=torch.bool)) == 0.0
    corner = torch.zeros(1, 4, 4, dtype=torch.bool)
    corner[0, :2, :2] = True  # at the image corner a pixel has 3 neighbours, all changed; the block's inner
    assert speckle(corner) == 0.25  # corner (1, 1) sees 3 of 8: the one pixel of four that disagrees


def test_changed_pixels_use_the_end_point_distance():
    flow, ref = torch.zeros(1, 2, 2, 2), torch.zeros(1, 2, 2, 2)
    flow[0, 0, 0, 0], flow[0, :, 1, 1] = 0.04, torch.tensor([0.04, 0.04])  # 0.04 px, and 0.057 px
    assert changed_pixels(flow, ref).tolist() == [[[False, False], [False, True]]]


def test_roughness_is_the_jacobians_norm():
    ys, xs = torch.meshgrid(torch.arange(8.0), torch.arange(8.0), indexing="ij")
    ramp = torch.stack([0.5 * xs, 0.0 * ys])[None]  # u = x / 2: a gradient of 0.5 everywhere inside
    inside = torch.zeros(1, 8, 8, dtype=torch.bool)
    inside[0, 1:-1, 1:-1] = True
    assert roughness(ramp, inside) == pytest.approx(0.5)
    assert roughness(torch.zeros(1, 2, 8, 8)) == 0.0
    spike = torch.zeros(1, 2, 8, 8)
    spike[0, 0, 4, 4] = 2.0  # one pixel off by 2 px: its 4 neighbours see a gradient of 1
    assert roughness(spike) == pytest.approx(4 * 1.0 / 64)
    assert math.isnan(roughness(spike, torch.zeros(1, 8, 8, dtype=torch.bool)))


def test_the_border_step_is_measured_across_the_box_sides_inside_the_frame():
    flow = torch.zeros(2, 10, 10)
    flow[0, 2:6, 3:7] = 3.0  # a box whose flow differs by 3 px from its surroundings: a seam
    assert border_step(flow, (2, 6, 3, 7)) == pytest.approx(3.0)
    assert border_step(flow, (0, 10, 0, 10)) != border_step(flow, (0, 10, 0, 10))  # NaN: no side inside the frame
    smooth = torch.zeros(2, 10, 10)
    assert border_step(smooth, (2, 6, 3, 7)) == 0.0
