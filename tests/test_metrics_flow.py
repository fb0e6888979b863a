"""Tests for lit_boot.metrics.flow against hand-computed values."""

from __future__ import annotations

import math
import warnings

import pytest
import torch

from lit_boot.metrics import (
    EndPointError,
    FlowErrorRates,
    PointEndPointError,
    endpoint_error,
    epe_at_points,
    flow_errors,
    sample_flow_at_points,
)


def _hand_made() -> tuple[torch.Tensor, torch.Tensor]:
    """(1, 2, 2, 3) gt / pred whose EPEs are [0.5, 2, 4, 4, 6, 6] (pure v offsets).

    gt u is 100 at pixel 3 and 200 at pixel 5, so their 4 px / 6 px errors are within 5 % of
    |gt| and are not Fl outliers; pixels 2 and 4 (|gt| = 0) are.
    """
    gt = torch.zeros(1, 2, 2, 3, dtype=torch.float64)
    gt[0, 0] = torch.tensor([[0.0, 0.0, 0.0], [100.0, 0.0, 200.0]])
    pred = gt.clone()
    pred[0, 1] = torch.tensor([[0.5, 2.0, 4.0], [4.0, 6.0, 6.0]])
    return pred, gt


def test_endpoint_error_constant_offset_is_five() -> None:
    gt = torch.randn(2, 2, 4, 5, dtype=torch.float64)
    pred = gt + torch.tensor([3.0, 4.0], dtype=torch.float64)[None, :, None, None]
    epe = endpoint_error(pred, gt)
    assert epe.shape == (2, 4, 5)
    torch.testing.assert_close(epe, torch.full_like(epe, 5.0))
    assert endpoint_error(pred[0], gt[0]).shape == (4, 5)
    assert flow_errors(pred.float(), gt.float())["epe"].item() == pytest.approx(5.0)


@pytest.mark.parametrize(
    ("pred", "gt", "word"),
    [
        (torch.zeros(1, 3, 4, 4), torch.zeros(1, 3, 4, 4), "pred"),
        (torch.zeros(1, 2, 4, 4), torch.zeros(1, 2, 4, 5), "gt"),
        (torch.zeros(4, 4), torch.zeros(4, 4), "pred"),
    ],
)
def test_endpoint_error_shape_errors_name_argument(pred: torch.Tensor, gt: torch.Tensor, word: str) -> None:
    with pytest.raises(ValueError, match=f"`{word}`"):
        endpoint_error(pred, gt)


def test_flow_errors_rates_and_fl_all_on_hand_made_flow() -> None:
    pred, gt = _hand_made()
    expected_epe = torch.tensor([0.5, 2, 4, 4, 6, 6], dtype=torch.float64)
    torch.testing.assert_close(endpoint_error(pred, gt).flatten(), expected_epe)
    out = flow_errors(pred, gt)
    assert out["epe"].item() == pytest.approx(22.5 / 6)
    assert out["1px"].item() == pytest.approx(1 / 6)
    assert out["3px"].item() == pytest.approx(2 / 6)
    assert out["5px"].item() == pytest.approx(4 / 6)
    assert out["fl_all"].item() == pytest.approx(2 / 6)


def test_flow_errors_masked() -> None:
    pred, gt = _hand_made()
    mask = torch.ones(1, 2, 3, dtype=torch.bool)
    mask[0, 1, 1] = False  # drop pixel 4 (EPE 6, outlier)
    out = flow_errors(pred, gt, mask)
    assert out["epe"].item() == pytest.approx(16.5 / 5)
    assert [out[k].item() for k in ("1px", "3px", "5px", "fl_all")] == pytest.approx([1 / 5, 2 / 5, 4 / 5, 1 / 5])
    with pytest.raises(ValueError, match="`mask`"):
        flow_errors(pred, gt, mask.double())


def test_flow_errors_pool_pixels_not_images() -> None:
    gt = torch.zeros(2, 2, 2, 2, dtype=torch.float64)
    pred = gt.clone()
    pred[0, 0] = 1.0  # image 0: EPE 1 everywhere
    pred[1, 0] = 5.0  # image 1: EPE 5 everywhere
    mask = torch.zeros(2, 2, 2, dtype=torch.bool)
    mask[0, 0, 0] = True  # 1 pixel of image 0
    mask[1, :, :] = True
    mask[1, 1, 1] = False  # 3 pixels of image 1
    assert flow_errors(pred, gt, mask)["epe"].item() == pytest.approx((1 + 3 * 5) / 4)  # not (1 + 5) / 2


def test_flow_errors_empty_selection_is_nan() -> None:
    pred, gt = _hand_made()
    out = flow_errors(pred, gt, torch.zeros(1, 2, 3, dtype=torch.bool))
    assert all(math.isnan(v.item()) for v in out.values())


def test_bilinear_half_pixel_is_mean_of_neighbours() -> None:
    flow = torch.randn(2, 2, 4, 5, dtype=torch.float64)
    points = torch.tensor([[[1.5, 2.0], [1.5, 2.5], [3.0, 1.0]]] * 2, dtype=torch.float64)
    out = sample_flow_at_points(flow, points)
    assert out.shape == (2, 3, 2)
    torch.testing.assert_close(out[:, 0], (flow[:, :, 2, 1] + flow[:, :, 2, 2]) / 2)
    torch.testing.assert_close(out[:, 1], flow[:, :, 2:4, 1:3].mean(dim=(-2, -1)))
    torch.testing.assert_close(out[:, 2], flow[:, :, 1, 3])  # integer point = pixel value
    torch.testing.assert_close(sample_flow_at_points(flow[0], points[0]), out[0])


def test_bilinear_outside_uses_border() -> None:
    flow = torch.randn(1, 2, 3, 4, dtype=torch.float64)
    points = torch.tensor([[[-2.0, 1.0], [10.0, 5.0]]], dtype=torch.float64)
    out = sample_flow_at_points(flow, points)
    torch.testing.assert_close(out[0, 0], flow[0, :, 1, 0])
    torch.testing.assert_close(out[0, 1], flow[0, :, 2, 3])


def test_nearest_rounds_and_clamps() -> None:
    flow = torch.randn(1, 2, 4, 5)
    points = torch.tensor([[[1.4, 2.6], [3.6, 0.2], [-3.0, 100.0]]])
    out = sample_flow_at_points(flow, points, mode="nearest")
    torch.testing.assert_close(out[0, 0], flow[0, :, 3, 1])
    torch.testing.assert_close(out[0, 1], flow[0, :, 0, 4])
    torch.testing.assert_close(out[0, 2], flow[0, :, 3, 0])
    with pytest.raises(ValueError, match="mode"):
        sample_flow_at_points(flow, points, mode="bicubic")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="`points`"):
        sample_flow_at_points(flow, points[0])


def test_bilinear_gradient_wrt_points_on_linear_ramp() -> None:
    ys, xs = torch.meshgrid(torch.arange(6.0), torch.arange(7.0), indexing="ij")
    flow = torch.stack([2 * xs + 3 * ys, -xs + 0.5 * ys])[None].double()  # u = 2x + 3y, v = -x + y/2
    points = torch.tensor([[[1.3, 2.7], [4.25, 0.6]]], dtype=torch.float64, requires_grad=True)
    out = sample_flow_at_points(flow, points)
    torch.testing.assert_close(out[0, 0], torch.tensor([2 * 1.3 + 3 * 2.7, -1.3 + 0.5 * 2.7], dtype=torch.float64))
    out.sum().backward()
    assert points.grad is not None and torch.isfinite(points.grad).all()
    expected = torch.tensor([[2.0 - 1.0, 3.0 + 0.5]] * 2, dtype=torch.float64)  # d(u+v)/dx, d(u+v)/dy
    torch.testing.assert_close(points.grad[0], expected)


def test_epe_at_points_and_visibility() -> None:
    flow = torch.zeros(1, 2, 4, 4)
    flow[:, 0], flow[:, 1] = 3.0, 4.0
    points = torch.tensor([[[1.2, 2.3], [0.0, 0.0], [float("nan"), 1.0]]])
    gt = torch.zeros(1, 3, 2)
    visible = torch.tensor([[True, False, False]])
    err = epe_at_points(flow, points, gt, mode="bilinear")
    torch.testing.assert_close(err[:, :2], torch.full((1, 2), 5.0))
    for mode in ("bilinear", "nearest"):
        masked = epe_at_points(flow, points, gt, visible, mode=mode)  # type: ignore[arg-type]
        torch.testing.assert_close(masked, torch.tensor([[5.0, 0.0, 0.0]]))


def _batches(seed: int = 0) -> list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    g = torch.Generator().manual_seed(seed)
    out = []
    for b, (h, w) in zip((2, 1, 3), ((5, 6), (5, 6), (5, 6))):
        gt = 4 * torch.randn(b, 2, h, w, generator=g, dtype=torch.float64)
        pred = gt + 3 * torch.randn(b, 2, h, w, generator=g, dtype=torch.float64)
        mask = torch.rand(b, h, w, generator=g) > 0.3
        out.append((pred, gt, mask))
    return out


def test_dense_metric_classes_match_functional_on_concatenation() -> None:
    batches = _batches()
    epe_metric, rate_metric = EndPointError(), FlowErrorRates()
    for pred, gt, mask in batches:
        epe_metric.update(pred, gt, mask)
        rate_metric.update(pred, gt, mask)
    pred, gt, mask = (torch.cat(x) for x in zip(*batches))
    expected = flow_errors(pred, gt, mask)
    assert epe_metric.compute().item() == pytest.approx(expected["epe"].item(), rel=1e-12)
    rates = rate_metric.compute()
    assert set(rates) == {"1px", "3px", "5px", "fl_all"}
    for key, value in rates.items():
        assert value.item() == pytest.approx(expected[key].item(), rel=1e-12)
    assert 0 < rates["1px"] < rates["3px"] < rates["5px"] <= 1


def test_dense_metric_classes_nan_when_nothing_seen() -> None:
    pred, gt, _ = _batches()[0]
    epe_metric, rate_metric = EndPointError(), FlowErrorRates()
    epe_metric.update(pred, gt, torch.zeros(pred.shape[0], *pred.shape[2:], dtype=torch.bool))
    assert math.isnan(epe_metric.compute().item())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torchmetrics warns on compute() before update()
        assert all(math.isnan(v.item()) for v in rate_metric.compute().values())
    epe_metric.reset()
    epe_metric.update(pred, pred)
    assert epe_metric.compute().item() == 0.0


@pytest.mark.parametrize("mode", ["bilinear", "nearest"])
def test_point_metric_matches_functional_on_concatenation(mode: str) -> None:
    g = torch.Generator().manual_seed(1)
    metric = PointEndPointError(mode=mode)
    flows, points, gts, vis = [], [], [], []
    for b in (2, 1, 3):
        flows.append(torch.randn(b, 2, 8, 9, generator=g, dtype=torch.float64))
        extent = torch.tensor([8.0, 7.0], dtype=torch.float64)  # slightly beyond the 9 x 8 image
        points.append(torch.rand(b, 5, 2, generator=g, dtype=torch.float64) * extent * 1.1 - 0.2)
        gts.append(torch.randn(b, 5, 2, generator=g, dtype=torch.float64))
        vis.append(torch.rand(b, 5, generator=g) > 0.4)
        metric.update(flows[-1], points[-1], gts[-1], vis[-1])
    visible = torch.cat(vis)
    err = epe_at_points(torch.cat(flows), torch.cat(points), torch.cat(gts), mode=mode)
    assert metric.compute().item() == pytest.approx(err[visible].mean().item(), rel=1e-12)
    with pytest.raises(ValueError, match="mode"):
        PointEndPointError(mode="bicubic")  # type: ignore[arg-type]


def test_point_metric_nan_when_no_visible_point() -> None:
    metric = PointEndPointError()
    hidden = torch.zeros(1, 2, dtype=torch.bool)
    metric.update(torch.zeros(1, 2, 3, 3), torch.ones(1, 2, 2), torch.zeros(1, 2, 2), hidden)
    assert math.isnan(metric.compute().item())
