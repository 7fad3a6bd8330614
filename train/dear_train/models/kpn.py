"""ToF-KPN (the depth refinement net), its ablation variants, and the DeepToF-style baseline.

A U-Net backbone looks at the aligned ToF amplitude and depth and the RGB image and predicts,
per pixel, a 3×3 kernel ``w`` and a bias ``b``. The refined depth is

    ``D_out(p) = ŵ_pᵀ · patch(D + b)(p)``,  ``ŵ_i = w_i / Σ_j (|w_j| + 1e-6)``

so the bias corrects the depth (MPI pushes concave regions too far) *before* the normalised
kernel smooths it, and the normalisation keeps the output a weighted mean of nearby corrected
depths instead of an arbitrary linear combination. The filtering (pad + 9 slices) is part of
the network and of the exported graph.

Depths inside the net are normalised: metres / ``max_depth``. Border pixels see a replicated
neighbourhood (``Pad`` mode ``edge``) rather than zeros, which would read as "no depth".

The ``gated`` variant (what the edge bundle ships, :class:`GatedKernelApply`) is built to be
*safe* off its training distribution: its weights are a convex combination over the valid
neighbours only, attenuated across depth discontinuities at full resolution, its bias is
bounded, and a predicted gate blends the result with the input depth. See that class.

The ``hybrid`` variant (:class:`HybridKernelApply`) also takes the classical refiner's output
(``pipeline/src/filter``, run by the daemon before the graph; precomputed for training by
``dear-synth classical``): it chooses per pixel between the measurement and the classical
estimate, then applies the gated kernel to that choice. Off its training distribution it can
fall back to either, so it inherits the classical filter's robustness where the network is
unsure and keeps the measurement where the measurement was already right.

The ``guarded`` variant (:class:`GuardedKernelApply`, issue 33) is the hybrid refiner with three
more maps: the expected absolute error of each candidate a pixel could publish — the hybrid
refinement, the measurement, the classical estimate — trained with a Laplace likelihood (the
proper scoring rule whose optimum is the conditional mean absolute error). Each pixel publishes
the candidate with the smallest expected error, and that error, so a correction the evidence
does not support falls back to the measurement (or the classical estimate), and the confidence
plane is a calibrated expected error rather than a heuristic.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import nn

from dear_train.models.layers import conv, crop_like, deconv, resize_like, scaled

#: Refinement variants by name. ``kpn`` is the paper's ToF-KPN; the others are its ablations
#: (``nograd`` is the same network trained without the gradient loss), plus ``deeptof``.
VARIANTS = (
    "kpn",
    "unet",
    "nograd",
    "nonorm",
    "aftbias",
    "nonormaftbias",
    "nonormnobias",
    "norgb",
    "deeptof",
    "gated",
    "hybrid",
    "guarded",
)

#: Epsilon of the kernel normalisation ``Σ(|w| + ε)``.
KERNEL_EPS = 1e-6


@dataclass(frozen=True)
class FilterMode:
    """How the predicted kernel and bias are applied."""

    normalize: bool = True
    #: ``"before"`` (paper): filter ``D + b``; ``"after"``: filter ``D`` then add ``b``;
    #: ``"none"``: no bias.
    bias: str = "before"


def filter_mode(variant: str) -> FilterMode | None:
    """The kernel application a variant uses; ``None`` for direct-regression variants."""
    return {
        "kpn": FilterMode(True, "before"),
        "nograd": FilterMode(True, "before"),
        "norgb": FilterMode(True, "before"),
        "nonorm": FilterMode(False, "before"),
        "aftbias": FilterMode(True, "after"),
        "nonormaftbias": FilterMode(False, "after"),
        "nonormnobias": FilterMode(False, "none"),
        "unet": None,
        "deeptof": None,
        "gated": None,
        "hybrid": None,
        "guarded": None,
    }[variant]


def head_channels(variant: str) -> int:
    """Output channels of a variant's backbone: gated maps, kernel + bias, or a depth."""
    if variant == "gated":
        return GATED_CHANNELS
    if variant == "hybrid":
        return HYBRID_CHANNELS
    if variant == "guarded":
        return GUARDED_CHANNELS
    return 10 if filter_mode(variant) is not None else 1


def uses_rgb(variant: str) -> bool:
    """Whether the variant's network takes the RGB image (all but ``norgb`` and ``deeptof``)."""
    return variant not in ("norgb", "deeptof")


def uses_classical(variant: str) -> bool:
    """Whether the variant takes the classical refiner's output as an input (``hybrid``,
    ``guarded``)."""
    return variant in ("hybrid", "guarded")


def applies_maps(variant: str) -> bool:
    """Whether the variant's graph ends at its head maps, applied by the daemon in Rust."""
    return variant in ("gated", "hybrid", "guarded")


def neighbourhood(x: torch.Tensor) -> torch.Tensor:
    """The 3×3 neighbourhood of each pixel of ``(N, 1, H, W)`` as ``(N, 9, H, W)``.

    Channel ``3·(dy+1) + (dx+1)`` holds ``x(p + (dy, dx))``, row-major like the kernel;
    edges are replicated.
    """
    h, w = x.shape[2], x.shape[3]
    xp = F.pad(x, (1, 1, 1, 1), mode="replicate")
    return torch.cat(
        [xp[:, :, dy : dy + h, dx : dx + w] for dy in range(3) for dx in range(3)], dim=1
    )


#: Largest depth correction the ``gated`` variant can make, in normalised depth (× max_depth =
#: 0.5 m at 10 m): multi-path errors of indoor scenes stay below it, and a bounded bias cannot
#: throw a pixel arbitrarily far when the input is unlike anything seen in training.
GATED_MAX_BIAS = 0.05
#: Scale of the depth-range attenuation of the ``gated`` kernels: a neighbour ``Δ`` away
#: (normalised depth) loses ``exp(−GATED_RANGE_SCALE · e^s · |Δ|)`` of its weight, ``s`` the
#: predicted log-sharpness (0 at initialisation: 1 cm costs a factor e^-0.1, 10 cm e^-1).
GATED_RANGE_SCALE = 100.0
#: Logit weight that removes an invalid (zero-depth) neighbour from the softmax.
_INVALID_LOGIT = 1e4
#: Channels of the ``gated`` head: 9 kernel logits, bias, gate, range log-sharpness.
GATED_CHANNELS = 12
#: Initial gate logit: sigmoid(−2) ≈ 0.12, so training starts close to "output = input".
GATED_GATE_INIT = -2.0


class GatedKernelApply(nn.Module):
    """The ``gated`` refinement: ``out = D + g · (Σ ŵ_i · D_i + b − D)`` on valid pixels.

    From the head's 12 maps (already at full resolution): 9 kernel logits ``a_i``, a bias ``b``
    (``GATED_MAX_BIAS · tanh``), a gate ``g`` (sigmoid) and a log-sharpness ``s``. The weights

        ``ŵ = softmax_i(a_i − GATED_RANGE_SCALE · e^s · |D_i − D| − 1e4 · [D_i invalid])``

    are convex over the *valid* neighbours only, so a hole never pulls depth towards 0 (the
    paper's Σ|w| normalisation mixes zeros in), and they are cut across depth discontinuities
    at full resolution even though the backbone predicts them at 1/4 resolution, so the filter
    cannot blur a sharp edge into flying pixels. The output stays within the neighbours' range
    plus a bounded bias, scaled by a gate that falls back to the input where the network is
    unsure. Invalid input pixels stay invalid (0).
    """

    def forward(self, depth: torch.Tensor, maps: torch.Tensor) -> torch.Tensor:
        logits = maps[:, :9]
        bias = GATED_MAX_BIAS * torch.tanh(maps[:, 9:10])
        gate = torch.sigmoid(maps[:, 10:11])
        sharp = GATED_RANGE_SCALE * torch.exp(maps[:, 11:12])
        nb = neighbourhood(depth)
        valid_nb = (nb > 0).to(depth.dtype)
        a = logits - sharp * (nb - depth).abs() - _INVALID_LOGIT * (1.0 - valid_nb)
        w = torch.softmax(a, dim=1)
        filtered = (w * nb).sum(dim=1, keepdim=True)
        out = depth + gate * (filtered + bias - depth)
        return out * (depth > 0).to(depth.dtype)


#: Channels of the ``hybrid`` head: the 12 gated maps, then the trust-in-classical logit.
HYBRID_CHANNELS = 13
#: Initial trust logit: sigmoid(2) ≈ 0.88, so training starts close to the classical filter.
HYBRID_TRUST_INIT = 2.0
#: Logit added per unit of normalised |classical − measurement| (× max_depth 10 m: +1 per
#: 3.3 cm): where the classical filter moved a pixel far (a flying pixel snapped onto a surface,
#: an outlier replaced), its estimate is trusted unless the network insists; small moves (noise
#: smoothing) are the network's call. Trained on every pixel; a bundle with ``apply.jump_on =
#: "replaced"`` applies it only where the classical filter replaced the measurement, so a far
#: smoothing move (across a depth step whose colours match) is the network's call as well.
HYBRID_JUMP_SCALE = 300.0


class HybridKernelApply(nn.Module):
    """The ``hybrid`` refinement: a per-pixel choice between the measurement ``D`` and the
    classical estimate ``C``, then the ``gated`` kernel on that choice.

    With ``t = sigmoid(m_12 + HYBRID_JUMP_SCALE · |C − D|)``::

        B = D + t · (C − D)   where both are valid,
            D                 where only D is,
            C                 where only C is (a hole the classical filter filled);
        out = GatedKernelApply(B, m_0..11)

    so the output lies between the measurement and the classical estimate plus the gated
    kernel's bounded, edge-cut correction.

    ``replaced`` (optional, bool like ``depth``) restricts the jump term to the pixels the
    classical filter did not measure itself (its confidence below 128: a flying pixel snapped,
    an outlier replaced): the bundle's ``apply.jump_on = "replaced"``. Without it the term
    applies everywhere, as the refiners were trained.
    """

    def __init__(self) -> None:
        super().__init__()
        self.gated = GatedKernelApply()

    def forward(
        self,
        depth: torch.Tensor,
        classical: torch.Tensor,
        maps: torch.Tensor,
        replaced: torch.Tensor | None = None,
    ) -> torch.Tensor:
        d_ok = depth > 0
        c_ok = classical > 0
        jump = HYBRID_JUMP_SCALE * (classical - depth).abs()
        if replaced is not None:
            jump = jump * replaced.to(jump.dtype)
        trust = torch.sigmoid(maps[:, 12:13] + jump)
        blended = depth + trust * (classical - depth)
        base = torch.where(d_ok & c_ok, blended, torch.where(d_ok, depth, classical))
        return self.gated(base, maps[:, :12])


#: Channels of the ``guarded`` head: the 13 hybrid maps, then the log expected absolute error of
#: the hybrid refinement, of the measurement and of the classical estimate.
GUARDED_CHANNELS = 16
#: Unit of the error maps: a map value ``m`` stands for the expected |error|
#: ``GUARDED_ERROR_UNIT · exp(clamp(m, ±GUARDED_LOG_ERROR_BOUND))`` in normalised depth
#: (× max_depth 10 m: 1 cm per unit).
GUARDED_ERROR_UNIT = 1e-3
#: Bound on the error maps' logits: expected errors from 0.025 mm to 4 m at max_depth 10 m.
GUARDED_LOG_ERROR_BOUND = 6.0
#: Candidates of a ``guarded`` pixel, in the order of their error maps (13, 14, 15).
GUARDED_CANDIDATES = ("refined", "measurement", "classical")


def guarded_errors(maps: torch.Tensor) -> torch.Tensor:
    """Expected absolute errors ``(N, 3, H, W)`` (normalised depth) of the three candidates."""
    log_err = maps[:, 13:16].clamp(-GUARDED_LOG_ERROR_BOUND, GUARDED_LOG_ERROR_BOUND)
    return GUARDED_ERROR_UNIT * torch.exp(log_err)


class GuardedKernelApply(nn.Module):
    """The ``guarded`` refinement: the hybrid refinement ``R`` (:class:`HybridKernelApply`,
    maps 0–12), the measurement ``D`` and the classical estimate ``C`` are each given an
    expected absolute error ``e = GUARDED_ERROR_UNIT · exp(m)`` (maps 13, 14, 15); a pixel
    publishes the valid candidate with the smallest ``e`` (ties: the earlier of R, D, C) and
    that ``e`` as its expected error. No valid candidate: 0, error +inf.

    ``forward`` returns ``(published, expected_error, refined)``.
    """

    def __init__(self) -> None:
        super().__init__()
        self.hybrid = HybridKernelApply()

    def forward(
        self, depth: torch.Tensor, classical: torch.Tensor, maps: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        refined = self.hybrid(depth, classical, maps[:, :HYBRID_CHANNELS])
        err = guarded_errors(maps)
        cands = torch.cat([refined, depth, classical], dim=1)
        inf = torch.full_like(err, float("inf"))
        err = torch.where(cands > 0, err, inf)
        best_err, best = err.min(dim=1, keepdim=True)
        published = torch.gather(cands, 1, best)
        published = torch.where(torch.isfinite(best_err), published, torch.zeros_like(published))
        return published, best_err, refined


class KernelApply(nn.Module):
    """Applies per-pixel 3×3 kernels and a bias to a depth map (see the module docstring)."""

    def __init__(self, mode: FilterMode) -> None:
        super().__init__()
        if mode.bias not in ("before", "after", "none"):
            raise ValueError(f"bias must be before/after/none, not {mode.bias!r}")
        self.mode = mode

    def forward(
        self, depth: torch.Tensor, kernel: torch.Tensor, bias: torch.Tensor
    ) -> torch.Tensor:
        if self.mode.normalize:
            kernel = kernel / (kernel.abs() + KERNEL_EPS).sum(dim=1, keepdim=True)
        src = depth + bias if self.mode.bias == "before" else depth
        out = (kernel * neighbourhood(src)).sum(dim=1, keepdim=True)
        if self.mode.bias == "after":
            out = out + bias
        return out


@dataclass(frozen=True)
class UNetConfig:
    """The refinement U-Net: four levels of ``widths`` (full, 1/2, 1/4, 1/8 resolution)."""

    widths: tuple[int, int, int, int] = (64, 128, 128, 256)
    separable: bool = False
    #: Backbone runs at 1/``backbone_stride`` (1, 2 or 4) of the input (edge tier: 2; the
    #: gated edge refiner: 4); its kernel maps are upsampled bilinearly and applied at full
    #: resolution.
    backbone_stride: int = 1
    #: Frame-level context (issue 33): the deepest features' mean over the whole frame, through
    #: two 1×1 convolutions, is added back to every position. A 3×3 U-Net sees ~100 px; whether
    #: a frame has multi-path at all (rooms whose walls bulge, amplitude above what the
    #: geometry explains) is a property of the whole frame. The second convolution starts at
    #: zero, so a warm-started net begins exactly where it was.
    global_context: bool = False

    def to_dict(self) -> dict:
        d = asdict(self)
        d["widths"] = list(self.widths)
        return d


class UNet(nn.Module):
    """Encoder-decoder with skip connections; ``forward(x)`` → ``(N, out_channels, H, W)``."""

    def __init__(self, cin: int, cout: int, config: UNetConfig) -> None:
        super().__init__()
        w0, w1, w2, w3 = config.widths
        s = config.separable
        self.stride = config.backbone_stride
        if self.stride == 1:
            self.enc0 = nn.Sequential(conv(cin, w0, 3, 1), conv(w0, w0, 3, 1, s))
        elif self.stride == 2:
            self.enc0 = nn.Sequential(conv(cin, w0, 3, 2), conv(w0, w0, 3, 1, s))
        elif self.stride == 4:
            self.enc0 = nn.Sequential(conv(cin, w0, 3, 2), conv(w0, w0, 3, 2, s))
        else:
            raise ValueError("backbone_stride must be 1, 2 or 4")
        self.enc1 = nn.Sequential(conv(w0, w1, 3, 2, s), conv(w1, w1, 3, 1, s))
        self.enc2 = nn.Sequential(conv(w1, w2, 3, 2, s), conv(w2, w2, 3, 1, s))
        self.enc3 = nn.Sequential(conv(w2, w3, 3, 2, s), conv(w3, w3, 3, 1, s))
        self.up2 = deconv(w3, w2, k=3)
        self.dec2 = conv(2 * w2, w2, 3, 1, s)
        self.up1 = deconv(w2, w1, k=3)
        self.dec1 = conv(2 * w1, w1, 3, 1, s)
        self.up0 = deconv(w1, w0, k=3)
        self.dec0 = conv(2 * w0, w0, 3, 1, s)
        self.head = nn.Conv2d(w0, cout, 3, 1, 1)
        self.context: nn.Module | None = None
        if config.global_context:
            last = nn.Conv2d(w3, w3, 1)
            nn.init.zeros_(last.weight)
            nn.init.zeros_(last.bias)
            self.context = nn.Sequential(nn.Conv2d(w3, w3, 1), nn.ReLU(inplace=True), last)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.forward_lowres(x)
        if self.stride > 1:
            out = resize_like(out, x, self.stride)
        return out

    def forward_lowres(self, x: torch.Tensor) -> torch.Tensor:
        """The head's maps at the backbone's resolution (1/``backbone_stride``)."""
        e0 = self.enc0(x)
        e1 = self.enc1(e0)
        e2 = self.enc2(e1)
        e3 = self.enc3(e2)
        if self.context is not None:
            e3 = e3 + self.context(e3.mean(dim=(2, 3), keepdim=True))
        d2 = self.dec2(torch.cat([e2, crop_like(self.up2(e3), e2)], dim=1))
        d1 = self.dec1(torch.cat([e1, crop_like(self.up1(d2), e1)], dim=1))
        d0 = self.dec0(torch.cat([e0, crop_like(self.up0(d1), e0)], dim=1))
        return self.head(d0)


class RefineNet(nn.Module):
    """ToF-KPN and its variants: ``forward(amplitude, depth, rgb)`` → refined depth.

    Args of ``forward``: ``amplitude`` ``(N, 1, H, W)`` normalised, warped to the RGB grid;
    ``depth`` ``(N, 1, H, W)`` metres / ``max_depth``, warped, 0 = invalid; ``rgb``
    ``(N, 3, H, W)`` in [0, 1] (ignored by variants without RGB, see :func:`uses_rgb`).
    Returns the refined depth ``(N, 1, H, W)``, same units as ``depth``.
    """

    def __init__(self, variant: str = "kpn", config: UNetConfig | None = None) -> None:
        super().__init__()
        if variant not in VARIANTS:
            raise ValueError(f"unknown variant {variant!r}; choose from {', '.join(VARIANTS)}")
        self.variant = variant
        self.config = config or UNetConfig()
        self.mode = filter_mode(variant)
        cin = (5 if uses_rgb(variant) else 2) + (1 if uses_classical(variant) else 0)
        cout = head_channels(variant)
        self.backbone = UNet(cin, cout, self.config)
        self.apply_kernel = KernelApply(self.mode) if self.mode is not None else None
        self.apply_gated = GatedKernelApply() if variant == "gated" else None
        self.apply_hybrid = HybridKernelApply() if variant == "hybrid" else None
        self.apply_guarded = GuardedKernelApply() if variant == "guarded" else None
        head = self.backbone.head
        # Small head weights (not zero, so gradients still reach the backbone at step one) and,
        # for the kernel variants, a bias making the initial kernel the identity: training
        # starts from "output = input depth". The gated variant starts with uniform logits
        # (the range term keeps them off edges) behind a mostly closed gate.
        head.weight.data.mul_(0.01)
        nn.init.zeros_(head.bias)
        if self.mode is not None:
            head.bias.data[4] = 1.0
        if applies_maps(variant):
            head.bias.data[10] = GATED_GATE_INIT
        if variant in ("hybrid", "guarded"):
            head.bias.data[12] = HYBRID_TRUST_INIT
        if variant == "guarded":
            # Expected errors start at 5 units (5 cm at 10 m) for every candidate.
            head.bias.data[13:16] = math.log(5.0)

    def _inputs(
        self,
        amplitude: torch.Tensor,
        depth: torch.Tensor,
        rgb: torch.Tensor | None,
        classical: torch.Tensor | None,
    ) -> torch.Tensor:
        parts = [amplitude, depth]
        if uses_rgb(self.variant):
            if rgb is None:
                raise ValueError(f"variant {self.variant!r} needs the RGB image")
            parts.append(rgb)
        if uses_classical(self.variant):
            if classical is None:
                raise ValueError(
                    f"variant {self.variant!r} needs the classical refiner's output (training "
                    "captures get it from `dear-synth classical --capture DIR`)"
                )
            parts.append(classical)
        return torch.cat(parts, dim=1)

    def head_maps(
        self,
        amplitude: torch.Tensor,
        depth: torch.Tensor,
        rgb: torch.Tensor | None = None,
        classical: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """The ``gated``/``hybrid`` head maps at the backbone's resolution: what their exported
        graph outputs (the daemon upsamples and applies them, as :meth:`forward` does)."""
        if not applies_maps(self.variant):
            raise ValueError(f"variant {self.variant!r} has no head maps applied by the daemon")
        return self.backbone.forward_lowres(self._inputs(amplitude, depth, rgb, classical))

    def forward(
        self,
        amplitude: torch.Tensor,
        depth: torch.Tensor,
        rgb: torch.Tensor | None = None,
        classical: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Refined depth; ``classical`` (same units as ``depth``) only for ``hybrid`` and
        ``guarded`` (whose published depth this is: :meth:`forward_guarded` has the rest)."""
        if self.apply_guarded is not None:
            return self.forward_guarded(amplitude, depth, rgb, classical)["depth"]
        if applies_maps(self.variant):
            maps = self.head_maps(amplitude, depth, rgb, classical)
            full = resize_like(maps, depth, self.backbone.stride)
            if self.apply_hybrid is not None:
                assert classical is not None  # checked by head_maps
                return self.apply_hybrid(depth, classical, full)
            assert self.apply_gated is not None
            return self.apply_gated(depth, full)
        out = self.backbone(self._inputs(amplitude, depth, rgb, None))
        if self.apply_kernel is None:
            if self.variant == "deeptof":
                return depth + out
            return out
        return self.apply_kernel(depth, out[:, :9], out[:, 9:10])

    def forward_guarded(
        self,
        amplitude: torch.Tensor,
        depth: torch.Tensor,
        rgb: torch.Tensor | None,
        classical: torch.Tensor | None,
    ) -> dict[str, torch.Tensor]:
        """The ``guarded`` variant's outputs (normalised depth): ``depth`` (published),
        ``expected_error`` (of the published depth), ``refined`` (the hybrid candidate) and
        ``errors`` ``(N, 3, H, W)``, the expected errors of the three candidates."""
        if self.apply_guarded is None:
            raise ValueError(f"variant {self.variant!r} is not guarded")
        maps = self.head_maps(amplitude, depth, rgb, classical)
        full = resize_like(maps, depth, self.backbone.stride)
        assert classical is not None  # checked by head_maps
        published, err, refined = self.apply_guarded(depth, classical, full)
        return {
            "depth": published,
            "expected_error": err,
            "refined": refined,
            "errors": guarded_errors(full),
        }


def paper_refine(variant: str = "kpn") -> RefineNet:
    """The paper-tier refinement net (ToF-KPN widths 64/128/128/256, ≈ 2.6 M parameters).

    ``deeptof`` uses narrower widths (32/64/64/128): it stands for a network of the size of
    DeepToF's auto-encoder, not for ToF-KPN without its kernels.
    """
    if variant == "deeptof":
        return RefineNet(variant, UNetConfig(widths=(32, 64, 64, 128)))
    return RefineNet(variant, UNetConfig())


def scaled_unet(width: float, separable: bool, stride: int) -> UNetConfig:
    """A U-Net config with the paper widths scaled by ``width``."""
    return UNetConfig(
        widths=tuple(scaled(c, width) for c in (64, 128, 128, 256)),  # type: ignore[arg-type]
        separable=separable,
        backbone_stride=stride,
    )
