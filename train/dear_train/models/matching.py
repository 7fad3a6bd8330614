"""A parameter-free cross-modal matching prior for the rough-flow net (edge tier).

Why: RGB and ToF amplitude do not share texture (IR reflectance is not visible colour), so a
small FlowNetC trained from scratch on a CPU budget never learned to match them: on our
simulator data it stayed at the zero-flow error (AEPE 6.1 px → 6.0 px after 1 440 steps, see
``models/edge/README.md``). What the two images *do* share is where edges are. This module
matches edge maps directly:

1. Sobel gradient magnitude of the RGB luminance and of the amplitude;
2. 4×4 average pooling, each map divided by its mean (contrast-invariant), local mean
   removed (9×9 at 1/4 resolution);
3. a correlation cost volume at 1/4 resolution over displacements ``±max_displacement`` (in
   1/4-resolution pixels, stride 1);
4. costs averaged over ``block × block`` cells (one edge rarely decides a displacement; a
   block of them does), standardised per cell, and turned into a flow by a soft-argmax
   ``Σ_k softmax(β·c)_k · d_k`` (β learnable, everything else fixed).

The result is a coarse flow (one vector per ``4·block`` pixels) that the learned network
corrects; it costs one single-channel correlation at 1/4 resolution. Every op exports to plain
ONNX (Conv, AveragePool, Pad, Slice, Mul, ReduceMean, Softmax).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from dear_train.losses import SOBEL_X, SOBEL_Y
from dear_train.models.layers import Correlation

#: Pooling from full resolution to the matching resolution.
MATCH_POOL = 4


class EdgeMatchingPrior(nn.Module):
    """``forward(rgb, amplitude)`` → flow ``(N, 2, ⌈H/4/block⌉, ⌈W/4/block⌉)`` in full-res px."""

    def __init__(self, max_displacement: int = 4, block: int = 16, beta: float = 3.0) -> None:
        super().__init__()
        self.block = block
        self.corr = Correlation(max_displacement, 1)
        self.beta = nn.Parameter(torch.tensor(float(beta)))
        self.register_buffer("sobel", torch.stack([SOBEL_X, SOBEL_Y])[:, None].clone())
        d = torch.arange(-max_displacement, max_displacement + 1, dtype=torch.float32)
        dy, dx = torch.meshgrid(d, d, indexing="ij")
        # Row-major with dy outer, as the correlation's channels.
        disp = torch.stack([dx.reshape(-1), dy.reshape(-1)]) * MATCH_POOL
        self.register_buffer("displacements", disp[:, :, None, None].clone())

    @property
    def scale(self) -> int:
        """Full-resolution pixels per output cell."""
        return MATCH_POOL * self.block

    def _edges(self, x: torch.Tensor) -> torch.Tensor:
        g = F.conv2d(F.pad(x, (1, 1, 1, 1), mode="replicate"), self.sobel)
        mag = torch.sqrt((g * g).sum(dim=1, keepdim=True) + 1e-12)
        e = F.avg_pool2d(mag, MATCH_POOL)
        e = e / (e.mean(dim=(2, 3), keepdim=True) + 1e-6)
        return e - F.avg_pool2d(e, 9, 1, 4, count_include_pad=False)

    def forward(self, rgb: torch.Tensor, amplitude: torch.Tensor) -> torch.Tensor:
        c = self.corr(self._edges(rgb.mean(dim=1, keepdim=True)), self._edges(amplitude))
        c = F.avg_pool2d(c, self.block, self.block, ceil_mode=True)
        c = (c - c.mean(dim=1, keepdim=True)) / (c.std(dim=1, keepdim=True) + 1e-6)
        p = torch.softmax(self.beta * c, dim=1)
        return F.conv2d(p, self.displacements)
