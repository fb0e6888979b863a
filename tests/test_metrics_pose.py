"""Tests for lit_boot.metrics.pose against hand-computed values."""

from __future__ import annotations

import math

import pytest
import torch

from lit_boot.metrics import (
    MPJPE,
    AccelerationError,
    MeanPerJointPositionError,
    acceleration_error,
    align_root,
    mpjpe,
    n_mpjpe,
    pa_mpjpe,
    procrustes_align,
    procrustes_transform,
    scale_align,
)

F64 = torch.float64


def _rotation(axis: tuple[float, float, float], angle: float) -> torch.Tensor:
    """Proper rotation (3, 3) about ``axis`` by ``angle`` radians (matrix exponential)."""
    x, y, z = torch.nn.functional.normalize(torch.tensor(axis, dtype=F64), dim=0) * angle
    skew = torch.tensor([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]], dtype=F64)
    return torch.linalg.matrix_exp(skew)


def _skeleton(*lead: int, seed: int = 0) -> torch.Tensor:
    """Random non-planar LSP-14-sized joints (*lead, 14, 3) in mm."""
    g = torch.Generator().manual_seed(seed)
    return 300.0 * torch.randn(*lead, 14, 3, generator=g, dtype=F64)


def test_pa_mpjpe_of_similarity_transform_is_zero_and_recovers_it() -> None:
    gt = _skeleton()
    rot, scale, shift = _rotation((1.0, -2.0, 0.5), 2.1), 1.7, torch.tensor([40.0, -25.0, 900.0], dtype=F64)
    pred = (gt - shift) @ rot / scale  # so that gt = scale * rot @ p + shift
    assert pa_mpjpe(pred, gt).item() == pytest.approx(0.0, abs=1e-9)
    s, r, t = procrustes_transform(pred, gt)
    assert s.item() == pytest.approx(scale)
    torch.testing.assert_close(r, rot)
    torch.testing.assert_close(t, shift)
    torch.testing.assert_close(procrustes_align(pred, gt), gt)
    assert pa_mpjpe(pred.float(), gt.float()).item() == pytest.approx(0.0, abs=1e-2)


def test_procrustes_never_reflects_a_mirrored_prediction() -> None:
    gt = _skeleton()
    mirror = torch.diag(torch.tensor([-1.0, 1.0, 1.0], dtype=F64))
    pred = 0.8 * gt @ mirror @ _rotation((0.0, 1.0, 1.0), 0.7).T + 10.0
    centred_pred, centred_gt = pred - pred.mean(dim=0), gt - gt.mean(dim=0)
    u, _, vh = torch.linalg.svd(centred_gt.T @ centred_pred)
    assert torch.linalg.det(u @ vh).item() == pytest.approx(-1.0)  # the unfixed SVD would reflect
    _, r, _ = procrustes_transform(pred, gt)
    assert torch.linalg.det(r).item() == pytest.approx(1.0)
    torch.testing.assert_close(r @ r.T, torch.eye(3, dtype=F64))
    assert pa_mpjpe(pred, gt).item() > 50.0  # a reflection would have given ~0


def test_procrustes_is_batched_over_leading_dims_and_respects_mask() -> None:
    gt, pred = _skeleton(2, 3, seed=1), _skeleton(2, 3, seed=2)
    mask = torch.rand(2, 3, 14, generator=torch.Generator().manual_seed(3)) > 0.2
    batched = mpjpe(pred, gt, mask, alignment="procrustes")
    for i in range(2):
        for j in range(3):
            m = mask[i, j]
            single = mpjpe(pred[i, j][m], gt[i, j][m], alignment="procrustes")
            torch.testing.assert_close(batched[i, j][m], single)
    # corrupted joints outside the mask do not disturb the fit
    noisy = gt.clone()
    noisy[..., 0, :] += 5000.0
    valid = torch.ones(2, 3, 14, dtype=torch.bool)
    valid[..., 0] = False
    assert pa_mpjpe(noisy, gt, valid).item() == pytest.approx(0.0, abs=1e-9)


def test_root_aligned_mpjpe_of_translated_copy_is_zero() -> None:
    gt = _skeleton(4)
    pred = gt + torch.tensor([120.0, -30.0, 2000.0], dtype=F64)
    torch.testing.assert_close(mpjpe(pred, gt), torch.zeros(4, 14, dtype=F64))
    centred = align_root(gt)
    torch.testing.assert_close(centred[..., [2, 3], :].mean(dim=-2), torch.zeros(4, 3, dtype=F64))


def test_n_mpjpe_of_scaled_copy_is_zero() -> None:
    gt = _skeleton(3)
    pred = 2.5 * gt + torch.tensor([7.0, 8.0, 9.0], dtype=F64)
    assert n_mpjpe(pred, gt).item() == pytest.approx(0.0, abs=1e-9)
    assert mpjpe(pred, gt).mean().item() > 100.0
    one = torch.tensor([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]], dtype=F64)
    torch.testing.assert_close(scale_align(one, 2 * one), 2 * one)  # s = <p,g>/<p,p> = 2


def test_mpjpe_two_joint_hand_example() -> None:
    pred = torch.tensor([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]], dtype=F64)
    gt = torch.zeros(2, 3, dtype=F64)
    torch.testing.assert_close(mpjpe(pred, gt, alignment="none"), torch.tensor([0.0, 5.0], dtype=F64))
    # root = mean of both joints = (1.5, 2, 0): each joint is 2.5 mm from it
    torch.testing.assert_close(mpjpe(pred, gt, root=(0, 1)), torch.tensor([2.5, 2.5], dtype=F64))
    torch.testing.assert_close(mpjpe(pred, gt, alignment="root", root=0), torch.tensor([0.0, 5.0], dtype=F64))
    metric = MeanPerJointPositionError(alignment="none")
    metric.update(pred, gt, torch.tensor([False, True]))
    assert metric.compute().item() == pytest.approx(5.0)
    with pytest.raises(ValueError, match="`root`"):
        mpjpe(pred, gt)  # default LSP-14 root (2, 3) does not exist for J = 2
    with pytest.raises(ValueError, match="alignment"):
        mpjpe(pred, gt, alignment="rigid")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="`gt`"):
        mpjpe(pred, gt[:1])


def test_acceleration_error_constant_velocity_is_zero() -> None:
    t = torch.arange(6, dtype=F64)[:, None, None]
    base, velocity = _skeleton(seed=4), _skeleton(seed=5) / 100
    pred = base + t * velocity
    gt = base.expand(6, 14, 3)
    for root in ((2, 3), None):
        err = acceleration_error(pred, gt, root=root)
        assert err.shape == (4, 14)
        torch.testing.assert_close(err, torch.zeros(4, 14, dtype=F64))


def test_acceleration_error_quadratic_motion() -> None:
    t = torch.arange(5, dtype=F64)
    gt = torch.zeros(5, 14, 3, dtype=F64)
    pred = gt.clone()
    pred[:, 0, 0] = 1.5 * t**2  # second difference 2 * 1.5 = 3 mm/frame^2, root (hips) static
    expected = torch.zeros(3, 14, dtype=F64)
    expected[:, 0] = 3.0
    torch.testing.assert_close(acceleration_error(pred, gt), expected)
    whole = gt + (1.5 * t**2)[:, None, None] * torch.tensor([0.0, 0.6, 0.8], dtype=F64)  # all joints move
    torch.testing.assert_close(acceleration_error(whole, gt, root=None), torch.full((3, 14), 3.0, dtype=F64))
    torch.testing.assert_close(acceleration_error(whole, gt), torch.zeros(3, 14, dtype=F64))  # root removes it
    batched = acceleration_error(torch.stack([pred, gt]), torch.stack([gt, gt]))
    torch.testing.assert_close(batched, torch.stack([expected, torch.zeros_like(expected)]))
    with pytest.raises(ValueError, match="`pred`"):
        acceleration_error(pred[0], gt[0])


@pytest.mark.parametrize("alignment", ["root", "procrustes", "scale", "none"])
def test_mpjpe_metric_matches_functional_on_concatenation(alignment: str) -> None:
    metric = MPJPE(alignment=alignment)
    preds, gts, masks = [], [], []
    for i, b in enumerate((3, 1, 5)):
        gts.append(_skeleton(b, seed=10 + i))
        preds.append(gts[-1] + _skeleton(b, seed=20 + i) / 10)
        masks.append(torch.rand(b, 14, generator=torch.Generator().manual_seed(i)) > 0.3)
        metric.update(preds[-1], gts[-1], masks[-1])
    mask = torch.cat(masks)
    expected = mpjpe(torch.cat(preds), torch.cat(gts), mask, alignment=alignment)[mask].mean()
    assert metric.compute().item() == pytest.approx(expected.item(), rel=1e-12)
    if alignment == "procrustes":
        assert pa_mpjpe(torch.cat(preds), torch.cat(gts), mask).item() == pytest.approx(expected.item(), rel=1e-12)


def test_acceleration_metric_matches_functional_on_concatenation() -> None:
    metric = AccelerationError()
    errors = []
    for i, frames in enumerate((4, 7, 3)):
        pred, gt = _skeleton(frames, seed=30 + i), _skeleton(frames, seed=40 + i)
        metric.update(pred, gt)
        errors.append(acceleration_error(pred, gt).flatten())
    assert metric.compute().item() == pytest.approx(torch.cat(errors).mean().item(), rel=1e-12)


def test_pose_metrics_nan_when_nothing_seen() -> None:
    assert MPJPE is MeanPerJointPositionError
    metric = MeanPerJointPositionError()
    gt = _skeleton(2)
    metric.update(gt, gt, torch.zeros(2, 14, dtype=torch.bool))
    assert math.isnan(metric.compute().item())
    assert math.isnan(pa_mpjpe(gt, gt, torch.zeros(2, 14, dtype=torch.bool)).item())
    accel = AccelerationError()
    accel.update(gt, gt)  # T = 2 < 3: no acceleration sample
    assert math.isnan(accel.compute().item())
    with pytest.raises(ValueError, match="alignment"):
        MeanPerJointPositionError(alignment="rigid")  # type: ignore[arg-type]
