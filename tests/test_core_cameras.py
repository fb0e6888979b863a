"""Camera projections (lit_boot.core.cameras) on hand-computed numbers and known geometry."""

from __future__ import annotations

import pytest
import torch

from lit_boot.core.cameras import (
    CAMERA_MODELS,
    Cameras,
    fit_weak_perspective,
    project_pinhole,
    project_weak_perspective,
)

D = torch.float64


def t(values) -> torch.Tensor:
    return torch.tensor(values, dtype=D)


# --- weak perspective ---------------------------------------------------------------------------


def test_weak_perspective_hand_computed():
    # s = 2, t = (0.1, -0.2) m; crop: scale 0.5, start (300, 200); crop size 224 (half = 112).
    params = t([2.0, 0.1, -0.2])
    crops = t([0.5, 300.0, 200.0])
    points = t([[100.0, 50.0, 3000.0], [0.0, 0.0, 0.0]])[None]  # (1, 2, 3) mm
    # point 0: X = (0.1, 0.05) m -> x = 2*(0.2, -0.15) = (0.4, -0.3)
    #   u224 = 1.4*112 = 156.8, v224 = 0.7*112 = 78.4
    #   u = (156.8 + 300 - 112)/0.5 = 689.6, v = (78.4 + 200 - 112)/0.5 = 332.8
    # point 1: x = 2*(0.1, -0.2) = (0.2, -0.4) -> (134.4, 67.2) -> (644.8, 310.4)
    expected = t([[689.6, 332.8], [644.8, 310.4]])[None]
    out = project_weak_perspective(points, params, crops)
    assert out.shape == (1, 2, 2)
    torch.testing.assert_close(out, expected)


def test_weak_perspective_depth_is_ignored_and_crop_size_is_used():
    params = t([[1.0, 0.0, 0.0]])
    crops = t([[1.0, 128.0, 128.0]])
    a = project_weak_perspective(t([[[500.0, -250.0, 10.0]]]), params, crops, crop_size=256.0)
    b = project_weak_perspective(t([[[500.0, -250.0, 9000.0]]]), params, crops, crop_size=256.0)
    torch.testing.assert_close(a, b)
    # x = (0.5, -0.25); u256 = 1.5*128 = 192, v256 = 0.75*128 = 96; + 128 - 128
    torch.testing.assert_close(a, t([[[192.0, 96.0]]]))


@pytest.mark.parametrize("params", [[1.0, 0.0, 0.0], [3.5, 0.1, -0.2], [0.7, -0.05, 0.3]])
def test_weak_perspective_crop_centre_maps_to_start_over_scale(params):
    params = t(params)
    crops = t([0.25, 90.0, 40.0])
    # x = 0 when X[:2] = -t (in metres) -> u224 = 112 (crop centre) -> u_img = start / scale
    centre = torch.cat([-params[1:3] * 1000.0, t([1234.0])])[None, None]
    out = project_weak_perspective(centre, params, crops)
    torch.testing.assert_close(out, t([[[360.0, 160.0]]]))


def test_weak_perspective_per_frame_params_broadcast():
    params = t([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    crops = t([[1.0, 112.0, 112.0], [2.0, 112.0, 112.0]])
    points = t([[100.0, 200.0, 0.0]]).expand(2, 1, 3)
    out = project_weak_perspective(points, params, crops)
    # frame 0: x = (0.1, 0.2) -> (123.2, 134.4) + 0 -> /1
    # frame 1: x = (0.2, 0.4) -> (134.4, 156.8) -> /2 = (67.2, 78.4)
    torch.testing.assert_close(out, t([[[123.2, 134.4]], [[67.2, 78.4]]]))


def _random_setup(T=3, J=14, seed=0):
    g = torch.Generator().manual_seed(seed)
    points = torch.randn(T, J, 3, generator=g, dtype=D) * 400.0
    params = torch.stack(
        [
            0.5 + torch.rand(T, generator=g, dtype=D) * 2,
            (torch.rand(T, generator=g, dtype=D) - 0.5) * 0.4,
            (torch.rand(T, generator=g, dtype=D) - 0.5) * 0.4,
        ],
        -1,
    )
    crops = torch.stack(
        [
            0.3 + torch.rand(T, generator=g, dtype=D),
            torch.rand(T, generator=g, dtype=D) * 500,
            torch.rand(T, generator=g, dtype=D) * 300,
        ],
        -1,
    )
    return points, params, crops


def test_fit_weak_perspective_recovers_known_params():
    points, params, crops = _random_setup()
    pixels = project_weak_perspective(points, params, crops)
    fitted = fit_weak_perspective(points, pixels, crops)
    assert fitted.shape == (3, 3)
    torch.testing.assert_close(fitted, params, rtol=1e-9, atol=1e-9)


def test_fit_weak_perspective_hand_example():
    # two points, s = 1, t = 0, crop scale 1 start (112, 112): pixel = 112 + 112 * X_m
    points = t([[[0.0, 0.0, 0.0], [1000.0, 500.0, 0.0]]])
    pixels = t([[[112.0 + 112 * 0.5 * 0.2, 112.0 + 112 * 0.5 * 0.2],
                 [112.0 + 112 * 0.5 * 1.2, 112.0 + 112 * 0.5 * 0.7]]])  # s = 0.5, t = (0.2, 0.2)
    fitted = fit_weak_perspective(points, pixels, t([[1.0, 112.0, 112.0]]))
    torch.testing.assert_close(fitted, t([[0.5, 0.2, 0.2]]))


def test_fit_weak_perspective_zero_weight_ignores_corrupted_joint():
    points, params, crops = _random_setup(seed=3)
    pixels = project_weak_perspective(points, params, crops)
    corrupted = pixels.clone()
    corrupted[:, 5] += t([80.0, -60.0])
    weights = torch.ones(3, 14, dtype=D)
    weights[:, 5] = 0.0
    # the corruption matters without weights ...
    unweighted = fit_weak_perspective(points, corrupted, crops)
    assert (unweighted - params).abs().max() > 1e-3
    # ... and is ignored with weight 0
    fitted = fit_weak_perspective(points, corrupted, crops, weights=weights)
    torch.testing.assert_close(fitted, params, rtol=1e-9, atol=1e-9)


# --- pinhole ------------------------------------------------------------------------------------


def test_pinhole_hand_computed_with_translation():
    params = t([1000.0, 800.0, 320.0, 240.0, 10.0, -20.0, 500.0])
    points = t([[[90.0, 120.0, 1500.0], [0.0, 0.0, 1000.0]]])
    # p0 = (100, 100, 2000): u = 1000*0.05 + 320 = 370, v = 800*0.05 + 240 = 280
    # p1 = (10, -20, 1500): u = 1000*10/1500 + 320, v = 800*(-20)/1500 + 240
    expected = t([[[370.0, 280.0], [320.0 + 20.0 / 3.0, 240.0 - 32.0 / 3.0]]])
    torch.testing.assert_close(project_pinhole(points, params[None]), expected)


def test_pinhole_optical_axis_maps_to_principal_point():
    params = t([[500.0, 500.0, 64.0, 48.0, 0.0, 0.0, 0.0]])
    out = project_pinhole(t([[[0.0, 0.0, 10.0], [0.0, 0.0, 5000.0]]]), params)
    torch.testing.assert_close(out, t([[[64.0, 48.0], [64.0, 48.0]]]))


def test_pinhole_translation_equals_moving_points():
    g = torch.Generator().manual_seed(4)
    points = torch.randn(2, 6, 3, generator=g, dtype=D) * 100 + t([0.0, 0.0, 3000.0])
    trans = t([[30.0, -40.0, 200.0], [-5.0, 15.0, -100.0]])
    intr = t([[900.0, 900.0, 100.0, 80.0], [700.0, 750.0, 60.0, 50.0]])
    a = project_pinhole(points, torch.cat([intr, trans], -1))
    b = project_pinhole(points + trans[:, None], torch.cat([intr, torch.zeros(2, 3, dtype=D)], -1))
    torch.testing.assert_close(a, b)
    assert not torch.allclose(a, project_pinhole(points, torch.cat([intr, torch.zeros(2, 3, dtype=D)], -1)))


def test_pinhole_gradients_hand_computed():
    params = t([[1000.0, 800.0, 320.0, 240.0, 10.0, -20.0, 500.0]]).requires_grad_()
    points = t([[[90.0, 120.0, 1500.0]]]).requires_grad_()
    project_pinhole(points, params).sum().backward()  # L = u + v, p = (100, 100, 2000)
    # dL/d(fx, fy, cx, cy) = (X/Z, Y/Z, 1, 1); dL/dt = (fx/Z, fy/Z, -(fx X + fy Y)/Z^2)
    grad_p = t([[0.05, 0.05, 1.0, 1.0, 0.5, 0.4, -0.045]])
    torch.testing.assert_close(params.grad, grad_p)
    torch.testing.assert_close(points.grad, t([[[0.5, 0.4, -0.045]]]))


def test_pinhole_and_weak_perspective_pass_gradcheck():
    g = torch.Generator().manual_seed(5)
    points = (torch.randn(2, 4, 3, generator=g, dtype=D) * 100 + t([0.0, 0.0, 2000.0])).requires_grad_()
    pin = t([[800.0, 820.0, 64.0, 48.0, 5.0, -3.0, 100.0], [700.0, 700.0, 60.0, 40.0, 0.0, 0.0, 0.0]])
    pin.requires_grad_()
    assert torch.autograd.gradcheck(project_pinhole, (points, pin))
    wp = t([[1.2, 0.1, -0.1], [0.8, 0.0, 0.05]]).requires_grad_()
    crops = t([[0.5, 100.0, 80.0], [0.7, 90.0, 70.0]])
    assert torch.autograd.gradcheck(lambda p, c: project_weak_perspective(p, c, crops), (points, wp))


def test_gradients_finite_and_nonzero_float32():
    points = (torch.randn(3, 14, 3) * 200 + torch.tensor([0.0, 0.0, 4000.0])).requires_grad_()
    params = torch.tensor([[1000.0, 1000.0, 320.0, 240.0, 0.0, 0.0, 0.0]]).repeat(3, 1).requires_grad_()
    project_pinhole(points, params).square().mean().backward()
    for grad in (points.grad, params.grad):
        assert grad is not None and torch.isfinite(grad).all() and (grad != 0).any()
    cams = Cameras("weak_perspective", torch.tensor([[1.0, 0.0, 0.0]] * 3), torch.tensor([[1.0, 112.0, 112.0]] * 3))
    wp = cams.params.clone().requires_grad_()
    pts = points.detach().clone().requires_grad_()
    cams.project(pts, wp).square().mean().backward()
    for grad in (pts.grad, wp.grad):
        assert grad is not None and torch.isfinite(grad).all() and (grad != 0).any()
    assert (pts.grad[..., 2] == 0).all()  # depth has no effect under weak perspective


# --- Cameras container --------------------------------------------------------------------------


def test_camera_models_listed():
    assert set(CAMERA_MODELS) == {"weak_perspective", "pinhole"}


def test_cameras_project_matches_functional_calls():
    points, params, crops = _random_setup(T=2, J=5, seed=6)
    cams = Cameras("weak_perspective", params, crops, crop_size=256.0)
    assert len(cams) == 2
    torch.testing.assert_close(cams.project(points), project_weak_perspective(points, params, crops, 256.0))
    new = params * 1.5
    out = cams.project(points, new)
    torch.testing.assert_close(out, project_weak_perspective(points, new, crops, 256.0))
    assert not torch.allclose(out, cams.project(points))

    pin_params = t([[800.0, 800.0, 50.0, 40.0, 0.0, 0.0, 3000.0]] * 2)
    pin = Cameras("pinhole", pin_params)
    torch.testing.assert_close(pin.project(points), project_pinhole(points, pin_params))
    new = pin_params + t([100.0, 0.0, 5.0, 0.0, 10.0, 0.0, 0.0])
    torch.testing.assert_close(pin.project(points, new), project_pinhole(points, new))


def test_cameras_to_dtype():
    cams = Cameras("weak_perspective", torch.ones(2, 3), torch.ones(2, 3), 200.0).to(D)
    assert cams.params.dtype == D and cams.crops.dtype == D and cams.crop_size == 200.0
    pin = Cameras("pinhole", torch.ones(2, 7)).to(D)
    assert pin.params.dtype == D and pin.crops is None


@pytest.mark.parametrize(
    "kwargs,field",
    [
        (dict(model="orthographic", params=torch.ones(2, 3), crops=torch.ones(2, 3)), "Cameras.model"),
        (dict(model="weak_perspective", params=torch.ones(2, 7), crops=torch.ones(2, 3)), "Cameras.params"),
        (dict(model="weak_perspective", params=torch.ones(3), crops=torch.ones(1, 3)), "Cameras.params"),
        (dict(model="pinhole", params=torch.ones(2, 3)), "Cameras.params"),
        (dict(model="pinhole", params=torch.ones(2, 1, 7)), "Cameras.params"),
        (dict(model="weak_perspective", params=torch.ones(2, 3)), "Cameras.crops"),
        (dict(model="weak_perspective", params=torch.ones(2, 3), crops=torch.ones(3, 3)), "Cameras.crops"),
        (dict(model="weak_perspective", params=torch.ones(2, 3), crops=torch.ones(2, 2)), "Cameras.crops"),
        (dict(model="pinhole", params=torch.ones(2, 7), crops=torch.ones(2, 3)), "Cameras.crops"),
    ],
)
def test_cameras_validation_names_field(kwargs, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        Cameras(**kwargs)


def test_cameras_valid_constructions():
    Cameras("weak_perspective", torch.ones(4, 3), torch.ones(4, 3))
    Cameras("pinhole", torch.ones(4, 7))
