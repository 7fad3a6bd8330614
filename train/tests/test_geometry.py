"""Geometry: the least-squares calibration, warps, depth → flow."""

from __future__ import annotations

import numpy as np
import torch

from dear_train.geometry import (
    Calibration,
    convt_flow,
    flow_from_depth,
    solve_calibration,
    solve_calibration_robust,
    warp_bilinear,
    warp_depth,
)


def _scene(
    n: int = 2, h: int = 20, w: int = 24, dtype: torch.dtype = torch.float64
) -> torch.Tensor:
    ys, xs = torch.meshgrid(torch.arange(h), torch.arange(w), indexing="ij")
    depth = (1.0 + 0.1 * xs + 0.05 * ys).to(dtype)[None, None].repeat(n, 1, 1, 1)
    depth[:, :, 3:7, 5:9] = 0.0  # holes
    depth[1:] *= 1.5
    return depth


def test_lsq_recovers_known_calibration_exactly() -> None:
    depth = _scene()
    truth = torch.tensor([[9.0, -3.0, 2.5, -1.5], [-4.0, 6.0, -0.75, 3.25]], dtype=torch.float64)
    flow, _ = flow_from_depth(truth, depth)
    flow = torch.where(depth > 0, flow, torch.full_like(flow, 1e3))  # garbage at holes
    got = solve_calibration(flow, depth)
    assert torch.allclose(got, truth, atol=1e-6), got


def test_lsq_in_float32_is_accurate() -> None:
    depth = _scene(dtype=torch.float32)
    truth = torch.tensor([[9.0, -3.0, 2.5, -1.5], [-4.0, 6.0, -0.75, 3.25]])
    flow, _ = flow_from_depth(truth, depth)
    assert torch.allclose(solve_calibration(flow, depth), truth, atol=2e-3)


def test_lsq_respects_weights_and_masks() -> None:
    depth = _scene(1)
    truth = torch.tensor([[5.0, 1.0, -2.0, 0.5]], dtype=torch.float64)
    flow, _ = flow_from_depth(truth, depth)
    mask = torch.ones_like(depth, dtype=torch.bool)
    mask[..., :, :4] = False
    flow[..., :, :4] += 50.0  # wrong where masked out
    assert torch.allclose(solve_calibration(flow, depth, mask), truth, atol=1e-6)


def test_lsq_is_differentiable() -> None:
    depth = _scene(1, 6, 7)
    flow = torch.randn(1, 2, 6, 7, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda f: solve_calibration(f, depth), (flow,))


def test_lsq_degenerate_plane_stays_finite() -> None:
    depth = torch.full((1, 1, 8, 8), 2.0)
    flow = torch.full((1, 2, 8, 8), 3.0)
    calib = solve_calibration(flow, depth)
    assert torch.isfinite(calib).all()
    pred, _ = flow_from_depth(calib, depth)
    assert torch.allclose(pred, flow, atol=1e-3)


def test_robust_fit_ignores_outliers() -> None:
    depth = _scene(1)
    truth = torch.tensor([[5.0, 1.0, -2.0, 0.5]], dtype=torch.float64)
    flow, _ = flow_from_depth(truth, depth)
    rng = np.random.default_rng(0)
    bad = torch.from_numpy(rng.random(depth.shape) < 0.15)
    flow = torch.where(bad, flow + 15.0, flow)
    plain = solve_calibration(flow, depth)
    robust = solve_calibration_robust(flow, depth, huber_delta_px=0.5, iterations=50)
    assert (robust - truth).abs().sum() < 0.25 * (plain - truth).abs().sum()


def test_flow_from_depth_matches_the_formula_and_marks_invalid() -> None:
    depth = torch.tensor([[[[2.0, 0.0], [4.0, float("nan")]]]])
    c = Calibration(tx=8.0, ty=-4.0, cx=1.0, cy=0.5)
    flow, valid = flow_from_depth(c.as_tensor()[None], depth)
    assert valid[0, 0].tolist() == [[True, False], [True, False]]
    assert flow[0, :, 0, 0].tolist() == [5.0, -1.5]
    assert flow[0, :, 1, 0].tolist() == [3.0, -0.5]
    assert flow[0, :, 0, 1].tolist() == [0.0, 0.0]


def test_convt_flow_falls_back_where_depth_is_invalid() -> None:
    depth = torch.tensor([[[[2.0, 0.0]]]])
    rough = torch.full((1, 2, 1, 2), 7.0)
    out, _valid = convt_flow(torch.tensor([[2.0, 2.0, 0.0, 0.0]]), depth, rough)
    assert out[0, :, 0, 0].tolist() == [1.0, 1.0]
    assert out[0, :, 0, 1].tolist() == [7.0, 7.0]


def test_bilinear_warp_marks_outside_invalid_instead_of_zero_filling() -> None:
    src = torch.arange(20.0).reshape(1, 1, 4, 5) + 1
    flow = torch.zeros(1, 2, 4, 5)
    flow[:, 0] = 0.5
    out, valid = warp_bilinear(src, flow)
    assert not valid[0, 0, :, 4].any() and valid[0, 0, :, :4].all()
    assert torch.allclose(out[0, 0, :, :4], src[0, 0, :, :4] + 0.5)


def test_depth_warp_does_not_blend_across_a_step() -> None:
    src = torch.tensor([[[[1.0, 3.0], [1.0, 3.0]]]])
    flow = torch.tensor([[[[0.4]], [[0.3]]]])
    out, _ = warp_depth(src, flow)
    assert abs(out.item() - 1.0) < 1e-6  # bilinear would give 1.8
    flow[0, 0] = 0.6
    out, _ = warp_depth(src, flow)
    assert abs(out.item() - 3.0) < 1e-6


def test_depth_warp_gradient_reaches_flow() -> None:
    src = torch.tensor([[[[2.0, 2.02], [2.0, 2.02]]]])
    flow = torch.tensor([[[[0.25]], [[0.0]]]], requires_grad=True)
    out, _ = warp_depth(src, flow)
    out.sum().backward()
    assert flow.grad is not None and abs(flow.grad[0, 0].item() - 0.02) < 1e-5
