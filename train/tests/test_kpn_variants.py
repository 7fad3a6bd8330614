"""Each refinement variant computes what its name says (hand-set kernels and biases)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from dear_train.losses import HARM_WEIGHT, depth_loss, guarded_losses, harm
from dear_train.models import build_refine
from dear_train.models.kpn import (
    GUARDED_CHANNELS,
    GUARDED_ERROR_UNIT,
    KERNEL_EPS,
    FilterMode,
    GuardedKernelApply,
    KernelApply,
    RefineNet,
    filter_mode,
)
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


def test_hybrid_pays_the_harm_term_only_when_its_profile_asks() -> None:
    """cpu-hybrid-harm's loss is the depth term plus the weighted damage to depth the sensor
    already got right; a hybrid profile without a harm weight trains on the depth term alone,
    and a recorded profile from before the field keeps that meaning."""
    from dear_train.models.dear import DEAR
    from dear_train.training.config import Profile, get_profile

    torch.manual_seed(0)
    model = DEAR(None, None, build_refine("edge", "hybrid"), 10.0)
    gt = torch.rand(1, 1, 16, 16) + 1
    b = {
        "rgb": torch.rand(1, 3, 16, 16),
        "amplitude": torch.rand(1, 1, 16, 16),
        # Half the pixels measured exactly, half 5 cm off: the refiner harms the first half.
        "tof_depth": gt + torch.where(torch.rand_like(gt) < 0.5, 0.0, 0.05),
        "tof_classical": gt + 0.02,
        "gt_depth": gt,
        "flow": torch.zeros(1, 2, 16, 16),
        "flow_valid": torch.ones(1, 1, 16, 16, dtype=torch.bool),
    }
    harm_profile = get_profile("cpu-hybrid-harm")
    assert harm_profile.refine_harm_weight() == 1.0
    assert get_profile("cpu-hybrid").refine_harm_weight() == 0.0
    assert get_profile("cpu-guarded").refine_harm_weight() == HARM_WEIGHT
    recorded = get_profile("cpu-hybrid-more").to_dict()
    del recorded["hybrid_harm_weight"]
    assert Profile.from_dict(recorded).refine_harm_weight() == 0.0

    _, plain = StageLoss(model, "refine", "hybrid", 0.0)(b)
    total, parts = StageLoss(model, "refine", "hybrid", 3.0)(b)
    r = model.refine_depth(b["rgb"], b["amplitude"], b["tof_depth"], b["flow"], b["tof_classical"])
    damage = float(harm(r["depth"], r["depth_warped"], gt, b["flow_valid"]).detach())
    assert "harm" not in plain and damage > 0
    assert parts["harm"] == pytest.approx(3.0 * damage, rel=1e-5)
    assert float(total.detach()) == pytest.approx(plain["depth"] + 3.0 * damage, rel=1e-5)


def _gated_maps(
    logits: torch.Tensor, bias: float = 0.0, gate: float = 1.0, sharp: float = 0.0
) -> torch.Tensor:
    """Head maps of the gated variant with a given kernel, bias, gate and log-sharpness."""
    n, _, h, w = logits.shape
    from dear_train.models.kpn import GATED_MAX_BIAS

    b = torch.full((n, 1, h, w), float(np.arctanh(bias / GATED_MAX_BIAS)))
    g = torch.full((n, 1, h, w), float(np.log(gate / (1 - gate))) if gate < 1 else 30.0)
    s = torch.full((n, 1, h, w), sharp)
    return torch.cat([logits, b, g, s], dim=1).double()


def test_gated_never_mixes_holes_into_valid_depth() -> None:
    """Neighbours with depth 0 get no weight: the output stays within the valid neighbours."""
    from dear_train.models.kpn import GatedKernelApply

    rng = np.random.default_rng(3)
    depth = torch.from_numpy(rng.uniform(0.1, 0.3, (1, 1, H, W)))
    depth[0, 0, 1:3, 2:4] = 0.0
    maps = _gated_maps(torch.from_numpy(rng.normal(size=(1, 9, H, W))), sharp=-30.0)
    out = GatedKernelApply()(depth, maps)
    assert (out[depth == 0] == 0).all()  # invalid stays invalid
    valid = depth > 0
    assert out[valid].min() >= depth[valid].min() - 1e-12
    assert out[valid].max() <= depth[valid].max() + 1e-12


def test_gated_keeps_a_depth_step_sharp_and_smooths_a_plane() -> None:
    """Uniform logits: noise on each side of a step is averaged, the step is not blurred."""
    from dear_train.models.kpn import GatedKernelApply

    rng = np.random.default_rng(4)
    clean = torch.full((1, 1, 12, 12), 0.1, dtype=torch.float64)
    clean[..., 6:] = 0.3  # a 2 m step at 10 m normalisation
    noisy = clean + torch.from_numpy(rng.normal(scale=0.0005, size=clean.shape))
    out = GatedKernelApply()(noisy, _gated_maps(torch.zeros(1, 9, 12, 12, dtype=torch.float64)))
    assert (out - clean).abs().max() < 0.003  # nothing crosses the step
    assert (out - clean).abs().mean() < 0.75 * (noisy - clean).abs().mean()


def test_gated_gate_and_bias_do_what_they_say() -> None:
    from dear_train.models.kpn import GatedKernelApply

    depth = torch.full((1, 1, H, W), 0.2, dtype=torch.float64)
    logits = torch.zeros(1, 9, H, W, dtype=torch.float64)
    closed = GatedKernelApply()(depth, _gated_maps(logits, bias=0.03, gate=1e-9))
    torch.testing.assert_close(closed, depth)  # closed gate: the input
    half = GatedKernelApply()(depth, _gated_maps(logits, bias=0.03, gate=0.5))
    torch.testing.assert_close(half, depth + 0.015)
    # The bias is bounded whatever the head says.
    maps = _gated_maps(logits, gate=0.999999)
    maps[:, 9] = 1e6
    from dear_train.models.kpn import GATED_MAX_BIAS

    assert GatedKernelApply()(depth, maps).max() <= 0.2 + GATED_MAX_BIAS + 1e-9


def test_gated_refiner_starts_close_to_the_input() -> None:
    torch.manual_seed(0)
    net = build_refine("edge", "gated").eval()
    depth = torch.rand(1, 1, 48, 64) * 0.3 + 0.05
    with torch.no_grad():
        out = net(torch.rand(1, 1, 48, 64), depth, torch.rand(1, 3, 48, 64))
    assert (out - depth).abs().mean() < 0.002


def _hybrid_maps(shape: tuple[int, int], trust: float) -> torch.Tensor:
    """Hybrid head maps: a closed gated kernel and a constant trust-in-classical logit."""
    h, w = shape
    gated = _gated_maps(torch.zeros(1, 9, h, w, dtype=torch.float64), gate=1e-9)
    return torch.cat([gated, torch.full((1, 1, h, w), trust, dtype=torch.float64)], dim=1)


def test_hybrid_chooses_between_measurement_and_classical_and_fills_holes() -> None:
    from dear_train.models.kpn import HybridKernelApply

    rng = np.random.default_rng(6)
    depth = torch.from_numpy(rng.uniform(0.1, 0.3, (1, 1, H, W)))
    classical = depth + 0.0005  # a 5 mm smoothing correction everywhere
    classical[0, 0, 2, 2] = depth[0, 0, 2, 2] + 0.05  # a 50 cm jump (a snapped flying pixel)
    depth[0, 0, 0, 0] = 0.0  # a hole the classical filter filled
    classical[0, 0, 4, 5] = 0.0  # a pixel the classical filter dropped
    apply = HybridKernelApply()
    keep = apply(depth, classical, _hybrid_maps((H, W), trust=-40.0))
    take = apply(depth, classical, _hybrid_maps((H, W), trust=40.0))
    both = (depth > 0) & (classical > 0)
    small = both.clone()
    small[0, 0, 2, 2] = False
    torch.testing.assert_close(keep[small], depth[small])  # distrusted: the measurement
    torch.testing.assert_close(take[both], classical[both])  # trusted: the classical output
    # A far jump outweighs moderate distrust: 0.05 × HYBRID_JUMP_SCALE = +15 on the logit,
    # while a 5 mm smoothing step adds only 0.15.
    wary = apply(depth, classical, _hybrid_maps((H, W), trust=-5.0))
    torch.testing.assert_close(wary[small], depth[small], atol=1e-5, rtol=0)
    assert (wary[0, 0, 2, 2] - classical[0, 0, 2, 2]).abs() < 0.05 * 1e-3
    for out in (keep, take):
        # A hole filled from the classical output; a classical gap keeps the measurement.
        assert float(out[0, 0, 0, 0]) == pytest.approx(float(classical[0, 0, 0, 0]), abs=1e-9)
        assert float(out[0, 0, 4, 5]) == pytest.approx(float(depth[0, 0, 4, 5]), abs=1e-9)


def test_hybrid_refiner_starts_close_to_the_classical_output() -> None:
    torch.manual_seed(0)
    net = build_refine("edge", "hybrid").eval()
    depth = torch.rand(1, 1, 48, 64) * 0.3 + 0.05
    classical = depth + 0.001 * torch.randn_like(depth)
    with torch.no_grad():
        out = net(torch.rand(1, 1, 48, 64), depth, torch.rand(1, 3, 48, 64), classical)
    assert (out - classical).abs().mean() < 0.3 * (depth - classical).abs().mean()
    with pytest.raises(ValueError, match="dear-synth classical"):
        net(torch.rand(1, 1, 48, 64), depth, torch.rand(1, 3, 48, 64))


def _guarded_maps(err_refined: float, err_measured: float, err_classical: float) -> torch.Tensor:
    """Guarded head maps (full resolution, 1×16×H×W): closed gate, neutral trust, and the three
    expected errors (in ``GUARDED_ERROR_UNIT``s) given."""
    maps = torch.zeros(1, GUARDED_CHANNELS, H, W)
    maps[:, 10] = -20.0  # gate closed: the refined candidate is the hybrid blend
    for k, e in enumerate((err_refined, err_measured, err_classical)):
        maps[:, 13 + k] = math.log(e)
    return maps


def test_guarded_publishes_the_candidate_with_the_smallest_expected_error() -> None:
    depth = torch.full((1, 1, H, W), 0.2)
    classical = torch.full((1, 1, H, W), 0.3)
    apply = GuardedKernelApply()
    for errs, want in [((1.0, 2.0, 3.0), None), ((2.0, 1.0, 3.0), 0.2), ((3.0, 2.0, 1.0), 0.3)]:
        published, err, refined = apply(depth, classical, _guarded_maps(*errs))
        expected = refined if want is None else torch.full_like(depth, want)
        torch.testing.assert_close(published, expected)
        torch.testing.assert_close(err, torch.full_like(err, GUARDED_ERROR_UNIT * min(errs)))
    # An invalid candidate is never published, however small its expected error; a pixel with
    # none valid publishes 0 with an infinite expected error.
    depth[0, 0, 1, 1] = 0.0
    classical[0, 0, 2, 2] = 0.0
    depth[0, 0, 3, 3] = classical[0, 0, 3, 3] = 0.0
    published, err, _ = apply(depth, classical, _guarded_maps(3.0, 1.0, 2.0))
    assert float(published[0, 0, 1, 1]) == pytest.approx(0.3)  # measurement invalid: classical
    assert float(published[0, 0, 2, 2]) == pytest.approx(0.2)
    assert float(published[0, 0, 3, 3]) == 0.0 and math.isinf(float(err[0, 0, 3, 3]))


def test_guarded_losses_charge_harm_and_fit_expected_errors() -> None:
    gt = torch.full((1, 1, H, W), 2.0)
    measured = gt + 0.01
    valid = torch.ones_like(gt, dtype=torch.bool)

    def parts(refined: torch.Tensor, scale: float) -> dict[str, torch.Tensor]:
        r = {
            "depth_refined": refined,
            "depth_warped": measured,
            "depth_classical": gt - 0.01,
            "errors": torch.full((1, 3, H, W), scale),
        }
        return guarded_losses(r, gt, valid, valid, lambda p, g, v: depth_loss(p, g, v, 0.0))

    # A refinement closer to the truth than the measurement does no harm; one further away
    # pays for every metre it adds.
    assert float(parts(gt + 0.005, 0.01)["harm"]) == 0.0
    assert float(parts(gt + 0.03, 0.01)["harm"]) == pytest.approx(0.02 * HARM_WEIGHT)
    # The likelihood is lowest when the maps predict each candidate's mean |error|.
    refined = gt + 0.01  # all three candidates are 0.01 m off
    best = [float(parts(refined, s)["error"]) for s in (0.003, 0.01, 0.03)]
    assert best[1] < best[0] and best[1] < best[2]


def test_guarded_refiner_warm_starts_from_the_shipped_hybrid_bundle() -> None:
    from dear_train.training.checkpoint import build_model, warm_start_refine
    from dear_train.training.config import get_profile

    bundle = Path(__file__).resolve().parents[2] / "models" / "edge"
    model = build_model(get_profile("cpu-guarded"))
    assert model.refine is not None
    head_bias_before = model.refine.backbone.head.bias.detach().clone()
    copied = warm_start_refine(model, bundle)
    assert "backbone.head.weight" in copied and "backbone.enc0.0.0.weight" in copied
    head = model.refine.backbone.head
    # The grown head keeps its three expected-error maps' initialisation.
    torch.testing.assert_close(head.bias.detach()[13:], head_bias_before[13:])
    assert not torch.equal(head.bias.detach()[:13], head_bias_before[:13])
    # A bundle whose refiner is not this network's is refused, naming the parameter.
    with pytest.raises(ValueError, match="backbone"):
        warm_start_refine(build_model(get_profile("cpu")), bundle)


def test_frame_level_context_starts_as_the_net_without_it() -> None:
    """Warm-starting a context net from a plain one changes nothing until training moves the
    branch's last convolution off zero; then a change far away reaches pixels that the plain
    net's receptive field does not."""
    plain = build_refine("edge", "guarded")
    ctx = build_refine("edge", "guarded", global_context=True)
    missing = ctx.load_state_dict(plain.state_dict(), strict=False).missing_keys
    assert missing and all(k.startswith("backbone.context.") for k in missing)
    torch.manual_seed(1)
    amp, depth = torch.rand(1, 1, 64, 192), 0.1 + 0.3 * torch.rand(1, 1, 64, 192)
    rgb, classical = torch.rand(1, 3, 64, 192), depth + 0.001

    def left_change(net: RefineNet) -> float:
        """How much the left sixth's maps move when the deepest features of the right third
        change (a random encoder barely passes input changes that deep, so they are set)."""

        def right_third(_m: torch.nn.Module, _i: object, e3: torch.Tensor) -> torch.Tensor:
            e3 = e3.clone()
            e3[..., :, 2 * e3.shape[-1] // 3 :] += 1.0
            return e3

        a = net.head_maps(amp, depth, rgb, classical)[..., :, :4]
        hook = net.backbone.enc3.register_forward_hook(right_third)
        b = net.head_maps(amp, depth, rgb, classical)[..., :, :4]
        hook.remove()
        return float((a - b).abs().max())

    with torch.no_grad():
        assert torch.equal(
            plain.head_maps(amp, depth, rgb, classical), ctx.head_maps(amp, depth, rgb, classical)
        )
        # A head that is not near zero (it starts at 1 %), the same in both nets.
        plain.backbone.head.weight.normal_(0, 0.3)
        ctx.backbone.head.weight.copy_(plain.backbone.head.weight)
        for p in ctx.backbone.context.parameters():
            p.normal_(0, 0.3)
        assert left_change(plain) < 1e-6
        assert left_change(ctx) > 1e-4
