"""Each refinement variant computes what its name says (hand-set kernels and biases)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dear_train.losses import depth_loss
from dear_train.models import build_refine
from dear_train.models.kpn import KERNEL_EPS, FilterMode, KernelApply, filter_mode
from dear_train.training.trainer import StageLoss

H, W = 5, 6


def _reference(
    depth: np.ndarray, k: np.ndarray, b: np.ndarray, normalize: bool, bias: str
) -> np.ndarray:
    """Direct per-pixel loops: D_out(p) = Σ_i ŵ_i(p) · X(p + o_i) [+ b(p)]."""
    if normalize:
        k = k / (np.abs(k) + KERNEL_EPS).sum(axis=0, keepdims=True)
    x = depth + b if bias == "before" else depth
    out = np.zeros_like(depth)
    for y in range(H):
        for xx in range(W):
            acc = 0.0
            for i in range(9):
                dy, dx = divmod(i, 3)
                yy = min(max(y + dy - 1, 0), H - 1)  # replicated border
                xc = min(max(xx + dx - 1, 0), W - 1)
                acc += k[i, y, xx] * x[yy, xc]
            out[y, xx] = acc + (b[y, xx] if bias == "after" else 0.0)
    return out


@pytest.mark.parametrize(
    "variant,normalize,bias",
    [
        ("kpn", True, "before"),
        ("nonorm", False, "before"),
        ("aftbias", True, "after"),
        ("nonormaftbias", False, "after"),
        ("nonormnobias", False, "none"),
    ],
)
def test_kernel_application_matches_the_definition(
    variant: str, normalize: bool, bias: str
) -> None:
    assert filter_mode(variant) == FilterMode(normalize, bias)
    rng = np.random.default_rng(1)
    depth = rng.uniform(1, 3, (H, W))
    k = rng.normal(size=(9, H, W))
    b = rng.normal(scale=0.3, size=(H, W))
    got = KernelApply(FilterMode(normalize, bias))(
        torch.from_numpy(depth)[None, None],
        torch.from_numpy(k)[None],
        torch.from_numpy(b)[None, None],
    )
    np.testing.assert_allclose(
        got[0, 0].numpy(), _reference(depth, k, b, normalize, bias), atol=1e-12
    )


def test_bias_before_vs_after_differ_as_defined() -> None:
    """Box kernel + a one-pixel bias: before → the bias is smoothed; after → added in place."""
    depth = torch.full((1, 1, H, W), 2.0)
    k = torch.ones(1, 9, H, W)
    b = torch.zeros(1, 1, H, W)
    b[0, 0, 2, 2] = 0.9
    before = KernelApply(FilterMode(True, "before"))(depth, k, b)
    after = KernelApply(FilterMode(True, "after"))(depth, k, b)
    assert torch.isclose(before[0, 0, 2, 2], torch.tensor(2.1), atol=1e-5)
    assert torch.isclose(before[0, 0, 1, 1], torch.tensor(2.1), atol=1e-5)
    assert torch.isclose(after[0, 0, 2, 2], torch.tensor(2.9), atol=1e-5)
    assert torch.isclose(after[0, 0, 1, 1], torch.tensor(2.0), atol=1e-5)


def test_normalisation_makes_the_kernel_scale_free() -> None:
    depth = torch.rand(1, 1, H, W) + 1
    k = torch.rand(1, 9, H, W)
    b = torch.zeros(1, 1, H, W)
    norm = KernelApply(FilterMode(True, "before"))
    raw = KernelApply(FilterMode(False, "before"))
    assert torch.allclose(norm(depth, k, b), norm(depth, 5 * k, b), atol=1e-6)
    assert torch.allclose(raw(depth, 5 * k, b), 5 * raw(depth, k, b))


class _Fixed(torch.nn.Module):
    """Stands in for a backbone: returns a preset output whatever the input."""

    def __init__(self, out: torch.Tensor) -> None:
        super().__init__()
        self.out = out
        self.seen_channels = 0

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        self.seen_channels = x.shape[1]
        return self.out


def test_variants_route_the_backbone_output() -> None:
    depth = torch.rand(1, 1, H, W) + 1
    amp, rgb = torch.rand(1, 1, H, W), torch.rand(1, 3, H, W)
    raw = torch.randn(1, 10, H, W)
    for variant in ("kpn", "aftbias", "nonorm", "nonormaftbias", "nonormnobias", "norgb"):
        net = build_refine("edge", variant)
        net.backbone = _Fixed(raw)
        mode = filter_mode(variant)
        assert mode is not None
        want = KernelApply(mode)(depth, raw[:, :9], raw[:, 9:])
        assert torch.allclose(net(amp, depth, rgb), want)
        assert net.backbone.seen_channels == (2 if variant == "norgb" else 5)
    one = torch.randn(1, 1, H, W)
    unet = build_refine("edge", "unet")
    unet.backbone = _Fixed(one)
    assert torch.equal(unet(amp, depth, rgb), one)  # regresses depth directly
    deeptof = build_refine("edge", "deeptof")
    deeptof.backbone = _Fixed(one)
    assert torch.allclose(deeptof(amp, depth), depth + one)
    assert deeptof.backbone.seen_channels == 2


def test_kpn_starts_as_identity() -> None:
    depth = torch.rand(1, 1, 16, 16) + 1
    out = build_refine("paper")(torch.rand(1, 1, 16, 16), depth, torch.rand(1, 3, 16, 16))
    assert (out - depth).abs().max() < 0.05


def test_nograd_trains_without_the_gradient_term() -> None:
    torch.manual_seed(0)
    from dear_train.models.dear import DEAR

    model = DEAR(None, None, build_refine("edge", "nograd"), 10.0)
    b = {
        "rgb": torch.rand(1, 3, 16, 16),
        "amplitude": torch.rand(1, 1, 16, 16),
        "tof_depth": torch.rand(1, 1, 16, 16) + 1,
        "gt_depth": torch.rand(1, 1, 16, 16) + 1,
        "flow": torch.zeros(1, 2, 16, 16),
        "flow_valid": torch.ones(1, 1, 16, 16, dtype=torch.bool),
    }
    loss, _ = StageLoss(model, "refine", "nograd")(b)
    pred = model.refine_depth(b["rgb"], b["amplitude"], b["tof_depth"], b["flow"])["depth"]
    assert torch.isclose(loss, depth_loss(pred, b["gt_depth"], b["flow_valid"], lam=0.0))
    assert not torch.isclose(loss, depth_loss(pred, b["gt_depth"], b["flow_valid"]))
