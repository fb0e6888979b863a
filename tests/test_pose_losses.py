"""Pose-refinement loss terms: the refiners' residuals through their Objective (reduction,
robustness, and the sign of every term's gradient)."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from lit_boot.core import LSP14
from lit_boot.pose import Objective, Term, bone_lengths, bone_matrix, flow_residual, temporal_residual


def term(residual: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """One term (lambda 1) of the refiners' objective on ``residual``."""
    return Objective([Term("t", tuple(residual.shape), 1.0, weight)])([residual])


def grad(loss_fn, x: torch.Tensor) -> torch.Tensor:
    x = x.clone().requires_grad_(True)
    loss_fn(x).backward()
    return x.grad


def bone_term(x: torch.Tensor, bones) -> torch.Tensor:
    return term(temporal_residual(bone_lengths(x, bones)))


def test_a_term_sums_smooth_l1_over_elements_and_averages_over_frames():
    r = torch.tensor([[[0.5, 3.0]], [[0.0, -2.0]]])  # 2 frames, 1 joint, 2 coordinates
    # 0.5 * 0.25 + (3 - 0.5) + 0 + (2 - 0.5) = 4.125, over 2 frames
    assert term(r).item() == pytest.approx(4.125 / 2)
    w = torch.tensor([[1.0], [0.0]])
    assert term(r, w).item() == pytest.approx((0.125 + 2.5) / 2)
    empty = torch.zeros(0, 3, 2, requires_grad=True)
    assert term(empty).item() == 0.0  # no frames: 0, not NaN


def test_deviation_pulls_back_to_the_initial_value():
    x0 = torch.zeros(2, 3, 3)
    x = x0 + torch.tensor([0.2, -0.3, 5.0])
    g = grad(lambda v: term(v - x0), x)
    assert (g.sign() == torch.tensor([1.0, -1.0, 1.0])).all()  # descent moves towards x0
    torch.testing.assert_close(g[0, 0], torch.tensor([0.2, -0.3, 1.0]) / 2)  # quadratic below 1, linear above


def test_keypoint_term_pulls_projections_to_confident_detections_only():
    keypoints = torch.zeros(1, 2, 2)
    projected = torch.tensor([[[3.0, -0.5], [3.0, -0.5]]])
    weight = torch.tensor([[1.0, 0.0]])  # the second joint is undetected
    g = grad(lambda p: term(p - keypoints, weight), projected)
    torch.testing.assert_close(g[0, 0], torch.tensor([1.0, -0.5]))
    assert (g[0, 1] == 0).all()


def test_flow_term_pulls_the_displacement_towards_the_flow():
    flows = torch.zeros(1, 2, 20, 20)
    flows[:, 0] = 2.0  # everything moves 2 px to the right
    points = torch.tensor([[[10.0, 10.0]], [[10.5, 10.0]]])  # moved only 0.5 px
    g = grad(lambda p: term(flow_residual(p, flows)), points)
    assert g[1, 0, 0] < 0 and g[0, 0, 0] > 0  # frame t goes right, frame t-1 left
    assert g[:, :, 1].abs().max() == 0
    # A displacement that equals the flow costs nothing.
    exact = torch.tensor([[[10.0, 10.0]], [[12.0, 10.0]]])
    assert term(flow_residual(exact, flows)).item() == 0.0


def test_flow_term_differentiates_the_sampling_position():
    """u(x) = 0.1 x: with frame t fixed, the residual u(p0) - (p1 - p0) changes at 1.1 per px
    of p0 (1 through the displacement, 0.1 through where the flow is read)."""
    H, W = 8, 64
    flows = torch.zeros(1, 2, H, W)
    flows[0, 0] = 0.1 * torch.arange(W, dtype=torch.float32)
    p1 = torch.tensor([[40.0, 3.0]])
    p0 = torch.tensor([[20.2, 3.0]], requires_grad=True)
    loss = term(flow_residual(torch.stack([p0, p1]), flows))
    loss.backward()
    residual = 0.1 * 20.2 - (40.0 - 20.2)  # = -17.78: linear regime, d loss / d residual = -1
    assert residual < -1
    assert p0.grad[0, 0].item() == pytest.approx(-1.1, abs=1e-4)
    # The flow itself is a constant.
    f = flows.clone().requires_grad_(True)
    term(flow_residual(torch.stack([p0, p1]), f)).backward()
    assert f.grad is None


def test_temporal_term_pulls_consecutive_frames_together():
    x = torch.tensor([[[0.0, 0.0, 0.0]], [[0.3, 0.0, -0.2]]])
    g = grad(lambda v: term(temporal_residual(v)), x)
    assert g[1, 0, 0] > 0 and g[0, 0, 0] < 0 and g[1, 0, 2] < 0
    assert term(temporal_residual(x[:1])).item() == 0.0  # a single frame: nothing between frames


def test_bone_term_keeps_lengths_constant():
    bones = [(0, 1)]
    x = torch.tensor([[[0.0, 0, 0], [0.4, 0, 0]], [[0.0, 0, 0], [0.5, 0, 0]]])  # the bone grew
    g = grad(lambda v: bone_term(v, bones), x)
    assert g[1, 1, 0] > 0 and g[1, 0, 0] < 0  # descent shortens it at t ...
    assert g[0, 1, 0] < 0  # ... and lengthens it at t-1
    same = torch.tensor([[[0.0, 0, 0], [0.5, 0, 0]], [[1.0, 2, 3], [1.0, 2.5, 3]]])  # moved, same length
    assert bone_term(same, bones).item() == pytest.approx(0.0, abs=1e-7)


def test_bone_lengths_match_direct_indexing_and_survive_zero_lengths():
    x = torch.randn(4, 14, 3)
    i = torch.tensor(LSP14.length_bones)
    torch.testing.assert_close(bone_lengths(x, LSP14.length_bones), (x[:, i[:, 0]] - x[:, i[:, 1]]).norm(dim=-1))
    torch.testing.assert_close(bone_lengths(x, bone_matrix(LSP14.length_bones, 14)), bone_lengths(x, LSP14.length_bones))
    g = grad(lambda v: bone_term(v, LSP14.length_bones), torch.zeros(3, 14, 3))
    assert torch.isfinite(g).all()


def per_frame_smooth_l1(r: torch.Tensor, w: torch.Tensor | None = None) -> torch.Tensor:
    """The authors' reduction, written out: SmoothL1 summed over a frame's elements, mean over frames."""
    e = F.smooth_l1_loss(r, torch.zeros_like(r), reduction="none", beta=1.0)
    return (e if w is None else e * w[..., None]).sum() / r.shape[0]


def test_the_fused_objective_equals_the_sum_of_the_separate_terms():
    g = torch.Generator().manual_seed(0)
    x = torch.randn(5, 14, 3, generator=g, requires_grad=True)
    x0 = torch.randn(5, 14, 3, generator=g)
    p = torch.randn(5, 14, 2, generator=g) * 3
    kp = torch.randn(5, 14, 2, generator=g) * 3
    conf = torch.rand(5, 14, generator=g)
    objective = Objective([
        Term("3d", (5, 14, 3), 400.0), Term("2d", (5, 14, 2), 0.01, conf), Term("pos", (4, 14, 3), 300.0),
        Term("bone", (4, 15), 1e4), Term("off", (4, 3), 0.0), Term("empty", (0, 14, 2), 1.0),
    ])  # fmt: skip
    assert objective.names == ["3d", "2d", "pos", "bone"]
    residuals = [x - x0, p - kp, x[1:] - x[:-1], bone_lengths(x, LSP14.length_bones).diff(dim=0)]
    expected = {"3d": 400 * per_frame_smooth_l1(x - x0), "2d": 0.01 * per_frame_smooth_l1(p - kp, conf),
                "pos": 300 * per_frame_smooth_l1(x[1:] - x[:-1]),
                "bone": 1e4 * per_frame_smooth_l1(bone_lengths(x, LSP14.length_bones).diff(dim=0))}  # fmt: skip
    total = objective(residuals)
    torch.testing.assert_close(total, sum(expected.values()))
    for name, value in objective.split(residuals).items():
        torch.testing.assert_close(value, expected[name].detach())
    g_fused = torch.autograd.grad(total, x)[0]
    g_sep = torch.autograd.grad(sum(expected.values()), x)[0]
    torch.testing.assert_close(g_fused, g_sep)
    with pytest.raises(ValueError, match="residual '2d' has shape"):
        objective.split([x - x0, p[:, :3] - kp[:, :3], x[1:] - x[:-1], residuals[3]])
