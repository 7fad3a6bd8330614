"""Building blocks shared by the DEAR networks.

Every block here exports to plain ONNX operators (Conv, ConvTranspose, LeakyRelu, Pad, Slice,
Mul, ReduceMean, Concat) that the Rust side's tract can run fast; nothing samples an image at a
data-dependent position (no ``grid_sample``), and nothing exports to ``Resize`` (tract's is a
generic per-axis resampler: 22 % of the edge refiner's time at 640×480).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

#: FlowNet's feature activation. Never used on a flow or depth output (the authors' TF code put
#: a LeakyReLU on the flow predictions, which squashes negative flow by 10×).
LEAKY_SLOPE = 0.1


def scaled(channels: int, width: float, minimum: int = 8) -> int:
    """Channel count after a width multiplier, never below ``minimum`` (a multiple of 4)."""
    return max(minimum, round(channels * width / 4) * 4)


def conv(
    cin: int, cout: int, k: int = 3, stride: int = 1, separable: bool = False, act: bool = True
) -> nn.Module:
    """Conv (+ LeakyReLU). ``separable`` makes it depthwise k×k + pointwise 1×1, which costs
    ``k²·cin + cin·cout`` instead of ``k²·cin·cout`` MACs per pixel (the edge tier)."""
    pad = (k - 1) // 2
    if separable and k > 1:
        layers: list[nn.Module] = [
            nn.Conv2d(cin, cin, k, stride, pad, groups=cin, bias=False),
            nn.Conv2d(cin, cout, 1, 1, 0),
        ]
    else:
        layers = [nn.Conv2d(cin, cout, k, stride, pad)]
    if act:
        layers.append(nn.LeakyReLU(LEAKY_SLOPE, inplace=True))
    return nn.Sequential(*layers)


def deconv(cin: int, cout: int, k: int = 4) -> nn.Module:
    """2× transposed-conv upsampling + LeakyReLU (``k`` 4 as FlowNet, or 3 with output padding).

    The output is at least twice the input size; callers crop it to the skip connection with
    :func:`crop_like`, so inputs need not be a multiple of the network's total stride.
    """
    if k == 4:
        up = nn.ConvTranspose2d(cin, cout, 4, 2, 1)
    else:
        up = nn.ConvTranspose2d(cin, cout, 3, 2, 1, output_padding=1)
    return nn.Sequential(up, nn.LeakyReLU(LEAKY_SLOPE, inplace=True))


def predict_flow(cin: int) -> nn.Conv2d:
    """3×3 conv to a 2-channel flow, linear (no activation: flow is signed and unbounded)."""
    return nn.Conv2d(cin, 2, 3, 1, 1)


def upsample_flow() -> nn.ConvTranspose2d:
    """FlowNet's learned 2× upsampling of a coarse flow, linear."""
    return nn.ConvTranspose2d(2, 2, 4, 2, 1, bias=False)


def crop_like(x: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    """Crop ``x`` spatially to ``ref``'s size (top-left aligned, as strided convs are)."""
    return x[:, :, : ref.shape[2], : ref.shape[3]]


def bilinear_upsampling_weight(channels: int, scale: int) -> torch.Tensor:
    """Depthwise ``ConvTranspose`` weight ``(channels, 1, 2s, 2s)`` of bilinear ``s``× upsampling.

    With half-pixel centres, output pixel ``s·j + r`` samples input ``j + (2r + 1 − s)/(2s)``;
    the two taps' weights are the separable triangle ``1 − |m + 0.5 − s| / s``, ``m < 2s``.
    """
    m = torch.arange(2 * scale, dtype=torch.float32)
    taps = 1.0 - (m + 0.5 - scale).abs() / scale
    return (taps[:, None] * taps[None, :]).repeat(channels, 1, 1, 1)


def resize_like(x: torch.Tensor, ref: torch.Tensor, scale: int) -> torch.Tensor:
    """Bilinear ``scale``× upsampling then crop to ``ref`` (top-left aligned).

    The same arithmetic as ``F.interpolate(x, scale_factor=scale, mode="bilinear",
    align_corners=False)`` (half-pixel centres, edges clamped; ``test_models.py`` checks it),
    written as edge padding, a fixed depthwise transposed convolution and a slice so that the
    ONNX graph holds a ``ConvTranspose`` rather than a ``Resize`` (see the module docstring).
    ``scale`` must be 1 or even.
    """
    if scale == 1:
        return crop_like(x, ref)
    if scale % 2:
        raise ValueError(f"resize_like supports even scales, not {scale}")
    # The channel count is the architecture's (a Python int when traced for export), so the
    # weight is a constant of the graph.
    channels = int(x.shape[1])
    weight = bilinear_upsampling_weight(channels, scale).to(x)
    padded = F.pad(x, (1, 1, 1, 1), mode="replicate")
    up = F.conv_transpose2d(padded, weight, stride=scale, padding=scale // 2, groups=channels)
    # Padded input index j + 1 is input j: output s·j sits s further on.
    return up[:, :, scale : scale + ref.shape[2], scale : scale + ref.shape[3]]


class Correlation(nn.Module):
    """FlowNet's correlation cost volume between two feature maps.

    Channel ``k`` holds ``mean_c f1(p)·f2(p + d_k)`` for the displacements ``d_k`` on the grid
    ``{−D, −D+s, …, D}²`` (``D`` = ``max_displacement``, ``s`` = ``stride``), row-major with dy
    outer: ``(2·D/s + 1)²`` channels (441 for FlowNetC's D = 20, s = 2). Displacements reaching
    outside ``f2`` correlate with zero padding. Written as pad + slices so that it exports to
    plain ONNX ops; the per-displacement loop keeps peak memory at one feature map.
    """

    def __init__(self, max_displacement: int = 20, stride: int = 2) -> None:
        super().__init__()
        if max_displacement % stride:
            raise ValueError("max_displacement must be a multiple of stride")
        self.max_displacement = max_displacement
        self.stride = stride

    @property
    def out_channels(self) -> int:
        return (2 * (self.max_displacement // self.stride) + 1) ** 2

    def forward(self, f1: torch.Tensor, f2: torch.Tensor) -> torch.Tensor:
        d = self.max_displacement
        h, w = f1.shape[2], f1.shape[3]
        f2p = F.pad(f2, (d, d, d, d))
        out = []
        for dy in range(-d, d + 1, self.stride):
            rows = f2p[:, :, d + dy : d + dy + h, :]
            for dx in range(-d, d + 1, self.stride):
                out.append((f1 * rows[:, :, :, d + dx : d + dx + w]).mean(dim=1, keepdim=True))
        return torch.cat(out, dim=1)
