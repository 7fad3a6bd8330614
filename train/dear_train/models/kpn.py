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
"""

from __future__ import annotations

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
    }[variant]


def uses_rgb(variant: str) -> bool:
    """Whether the variant's network takes the RGB image (all but ``norgb`` and ``deeptof``)."""
    return variant not in ("norgb", "deeptof")


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
    #: Backbone runs at 1/``backbone_stride`` of the input (edge tier: 2); its kernel maps are
    #: upsampled bilinearly and applied at full resolution.
    backbone_stride: int = 1

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
        else:
            raise ValueError("backbone_stride must be 1 or 2")
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

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        e0 = self.enc0(x)
        e1 = self.enc1(e0)
        e2 = self.enc2(e1)
        e3 = self.enc3(e2)
        d2 = self.dec2(torch.cat([e2, crop_like(self.up2(e3), e2)], dim=1))
        d1 = self.dec1(torch.cat([e1, crop_like(self.up1(d2), e1)], dim=1))
        d0 = self.dec0(torch.cat([e0, crop_like(self.up0(d1), e0)], dim=1))
        out = self.head(d0)
        if self.stride > 1:
            out = resize_like(out, x, self.stride)
        return out


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
        cin = 5 if uses_rgb(variant) else 2
        cout = 10 if self.mode is not None else 1
        self.backbone = UNet(cin, cout, self.config)
        self.apply_kernel = KernelApply(self.mode) if self.mode is not None else None
        head = self.backbone.head
        # Small head weights (not zero, so gradients still reach the backbone at step one) and,
        # for the kernel variants, a bias making the initial kernel the identity: training
        # starts from "output = input depth".
        head.weight.data.mul_(0.01)
        nn.init.zeros_(head.bias)
        if self.mode is not None:
            head.bias.data[4] = 1.0

    def forward(
        self, amplitude: torch.Tensor, depth: torch.Tensor, rgb: torch.Tensor | None = None
    ) -> torch.Tensor:
        parts = [amplitude, depth]
        if uses_rgb(self.variant):
            if rgb is None:
                raise ValueError(f"variant {self.variant!r} needs the RGB image")
            parts.append(rgb)
        out = self.backbone(torch.cat(parts, dim=1))
        if self.apply_kernel is None:
            if self.variant == "deeptof":
                return depth + out
            return out
        return self.apply_kernel(depth, out[:, :9], out[:, 9:10])


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
