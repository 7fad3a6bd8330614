"""Losses: Sobel signs, masking, FlowNet scale weights."""

from __future__ import annotations

import torch

from dear_train.losses import (
    depth_loss,
    downsample_flow,
    flownet_weights,
    multiscale_flow_loss,
    sobel,
)


def test_sobel_signs() -> None:
    ys, xs = torch.meshgrid(torch.arange(6.0), torch.arange(7.0), indexing="ij")
    gx = sobel((2 * xs)[None, None])
    gy = sobel((3 * ys)[None, None])
    # Interior: depth growing to the right → +x gradient; growing downwards → +y gradient.
    assert torch.allclose(gx[0, 0, 1:-1, 1:-1], torch.full((4, 5), 16.0))
    assert torch.allclose(gx[0, 1, 1:-1, 1:-1], torch.zeros(4, 5))
    assert torch.allclose(gy[0, 1, 1:-1, 1:-1], torch.full((4, 5), 24.0))
    assert torch.allclose(gy[0, 0, 1:-1, 1:-1], torch.zeros(4, 5))


def test_depth_loss_ignores_invalid_pixels() -> None:
    gt = torch.rand(1, 1, 10, 10) + 1
    valid = torch.ones_like(gt, dtype=torch.bool)
    valid[..., :, :4] = False
    pred = gt.clone()
    pred[..., :, :2] += 5.0  # wrong only where invalid (and ≥ 2 px from any valid pixel)
    assert depth_loss(pred, gt, valid).item() == 0.0
    pred[..., 5, 7] += 1.0
    plain = depth_loss(pred, gt, valid, lam=0.0).item()
    assert abs(plain - 1.0 / 60) < 1e-6
    assert depth_loss(pred, gt, valid).item() > plain


def test_flownet_weights_are_coarse_to_fine() -> None:
    assert flownet_weights(6) == [0.32, 0.08, 0.02, 0.01, 0.005, 0.0]
    assert flownet_weights(5) == [0.08, 0.02, 0.01, 0.005, 0.0]


def test_downsampled_target_ignores_holes() -> None:
    flow = torch.full((1, 2, 4, 4), 3.0)
    valid = torch.ones(1, 1, 4, 4, dtype=torch.bool)
    flow[..., 0, 0] = 0.0
    valid[..., 0, 0] = False
    valid[..., 2:, 2:] = False
    f, v = downsample_flow(flow, valid, 2)
    assert torch.allclose(f[0, :, 0, 0], torch.tensor([3.0, 3.0]))
    assert v[0, 0].tolist() == [[True, True], [True, False]]


def test_multiscale_loss_weights_each_scale() -> None:
    gt = torch.zeros(1, 2, 8, 8)
    valid = torch.ones(1, 1, 8, 8, dtype=torch.bool)
    coarse = torch.zeros(1, 2, 2, 2)
    coarse[:, 0] = 1.0  # EPE 1 px
    fine = torch.zeros(1, 2, 8, 8)
    fine[:, 1] = 2.0  # EPE 2 px
    loss = multiscale_flow_loss([coarse, fine], gt, valid, [0.32, 0.005])
    assert torch.isclose(loss, torch.tensor(0.32 * 1 + 0.005 * 2))
