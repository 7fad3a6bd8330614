"""Shapes, sizes, gradients and complexity of every network."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from dear_train.models import (
    VARIANTS,
    build_flow,
    build_fusion,
    build_refine,
    param_count,
)
from dear_train.models.complexity import measure
from dear_train.models.dear import DEAR
from dear_train.models.kpn import uses_classical
from dear_train.models.layers import Correlation, resize_like

H, W = 48, 64


def _inputs(n: int = 2) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    return torch.rand(n, 3, H, W), torch.rand(n, 1, H, W), 1 + 3 * torch.rand(n, 1, H, W)


@pytest.mark.parametrize("tier,levels", [("paper", 6), ("edge", 5)])
def test_flow_net_outputs(tier: str, levels: int) -> None:
    rgb, amp, _ = _inputs()
    flows = build_flow(tier)(rgb, amp)
    # levels → 2 (1/2^levels … 1/4), then full resolution.
    assert len(flows) == levels
    for f, level in zip(flows[:-1], range(levels, 1, -1), strict=True):
        assert f.shape == (2, 2, -(-H // 2**level), -(-W // 2**level))
        assert f.dtype == torch.float32
    assert flows[-1].shape == (2, 2, H, W)


def test_flow_net_handles_sizes_not_multiple_of_64() -> None:
    flows = build_flow("edge")(torch.rand(1, 3, 40, 56), torch.rand(1, 1, 40, 56))
    assert flows[-1].shape == (1, 2, 40, 56)


def test_flow_outputs_are_linear_so_negative_flow_passes() -> None:
    """No activation on flow heads (the reference code's LeakyReLU squashed negative flow)."""
    net = build_flow("edge")
    net.prior = None  # the edge tier's matching prior is tested in test_matching.py
    head = net.predict_flow2
    torch.nn.init.zeros_(head.weight)
    head.bias.data[:] = torch.tensor([-0.5, -1.0])
    flows = net(torch.rand(1, 3, H, W), torch.rand(1, 1, H, W))
    assert torch.allclose(flows[-1][0, 0], torch.full((H, W), -10.0))
    assert torch.allclose(flows[-1][0, 1], torch.full((H, W), -20.0))


@pytest.mark.parametrize("tier", ["paper", "edge"])
def test_fusion_outputs(tier: str) -> None:
    f = torch.randn(2, 2, H, W) * 5
    out = build_fusion(tier)(f, f + 1)
    assert [tuple(o.shape) for o in out] == [
        (2, 2, H // 4, W // 4),
        (2, 2, H // 2, W // 2),
        (2, 2, H, W),
    ]


def test_fusion_starts_close_to_rough_flow() -> None:
    """The fusion net predicts a correction of W_rough: small at initialisation."""
    f = torch.randn(1, 2, H, W) * 5
    out = build_fusion("paper")(f, f + 3)[-1]
    assert (out - f).abs().mean() < 1.0


@pytest.mark.parametrize("tier", ["paper", "edge"])
@pytest.mark.parametrize("variant", VARIANTS)
def test_refine_outputs(tier: str, variant: str) -> None:
    if tier == "paper" and variant not in ("kpn", "norgb", "unet", "deeptof"):
        pytest.skip("the other variants differ from kpn only in the kernel application")
    rgb, amp, depth = _inputs()
    classical = depth / 10 if uses_classical(variant) else None
    out = build_refine(tier, variant)(amp, depth / 10, rgb, classical)
    assert out.shape == (2, 1, H, W) and out.dtype == torch.float32


def test_paper_sizes_match_the_reference() -> None:
    """Parameter counts of the authors' code: FlowNetC 39.2 M, fusion 0.97 M, ToF-KPN 2.56 M."""
    assert abs(param_count(build_flow("paper")) / 39.2e6 - 1) < 0.01
    assert abs(param_count(build_fusion("paper")) / 0.97e6 - 1) < 0.10
    assert abs(param_count(build_refine("paper")) / 2.56e6 - 1) < 0.05


def test_correlation_default_has_441_channels_and_right_displacement() -> None:
    corr = Correlation()
    assert corr.out_channels == 441
    f1 = torch.zeros(1, 1, 30, 30)
    f2 = torch.zeros(1, 1, 30, 30)
    f1[0, 0, 10, 10] = 1.0
    f2[0, 0, 14, 8] = 1.0  # displacement dy = +4, dx = −2
    out = corr(f1, f2)
    k = int(out[0, :, 10, 10].argmax())
    dy, dx = divmod(k, 21)
    assert (2 * dy - 20, 2 * dx - 20) == (4, -2)


def _check_all_grads(model: torch.nn.Module, loss: torch.Tensor) -> None:
    loss.backward()
    missing = [
        n for n, p in model.named_parameters() if p.grad is None or not p.grad.abs().sum() > 0
    ]
    assert not missing, f"no gradient reaches: {missing}"


@pytest.mark.parametrize("tier", ["paper", "edge"])
def test_gradients_reach_every_parameter(tier: str) -> None:
    rgb, amp, depth = _inputs(1)
    flow = build_flow(tier)
    _check_all_grads(flow, sum((f * torch.randn_like(f)).sum() for f in flow(rgb, amp)))
    fusion = build_fusion(tier)
    f = torch.randn(1, 2, H, W)
    _check_all_grads(fusion, sum((o * torch.randn_like(o)).sum() for o in fusion(f, f + 1)))
    for variant in VARIANTS:
        refine = build_refine(tier, variant)
        # The hybrid refiner also takes the classical filter's output (here a perturbed depth).
        classical = depth / 10 + 0.01 * torch.randn_like(depth) if uses_classical(variant) else None
        out = refine(amp, depth / 10, rgb, classical)
        _check_all_grads(refine, (out * torch.randn_like(out)).sum())


def test_end_to_end_gradient_flows_through_the_calibration_solve() -> None:
    """The depth loss reaches the flow net through warp → LS solve → W_convt → fusion."""
    model = DEAR(build_flow("edge"), build_fusion("edge"), build_refine("edge"), 10.0)
    rgb, amp, depth = _inputs(1)
    out = model(rgb, amp, depth)
    out["calib"].sum().backward()  # the calibration alone depends only on the flow net
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in model.flow.parameters())


def test_edge_tier_is_50x_cheaper() -> None:
    """Total MACs of the edge tier are ≥ 50× fewer than the paper tier (at 96×128; the counts
    scale with the pixel count, so the ratio is the one at 640×480 up to border effects)."""
    paper = sum(c.macs for c in measure("paper", height=96, width=128))
    edge = sum(c.macs for c in measure("edge", height=96, width=128))
    assert paper / edge >= 50, paper / edge


@pytest.mark.parametrize("scale", [2, 4, 64])
@pytest.mark.parametrize("size", [(5, 7), (1, 3), (12, 16)])
def test_resize_like_is_bilinear_interpolation(scale: int, size: tuple[int, int]) -> None:
    h, w = size
    x = torch.randn(2, 3, h, w)
    ref = torch.zeros(1, 1, h * scale - 1, w * scale - 2)
    want = F.interpolate(x, scale_factor=float(scale), mode="bilinear", align_corners=False)
    got = resize_like(x, ref, scale)
    assert got.shape == (2, 3, h * scale - 1, w * scale - 2)
    assert torch.allclose(got, want[:, :, : h * scale - 1, : w * scale - 2], atol=1e-6)
    with pytest.raises(ValueError, match="even"):
        resize_like(x, ref, 3)
