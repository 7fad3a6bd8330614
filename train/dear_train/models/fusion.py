"""The flow-fusion U-Net: ``W_refn = G(W_rough, W_convt)``.

``W_rough`` is the network's flow, detailed but noisy; ``W_convt`` is the flow the least-squares
calibration predicts from the warped depth, smooth and globally consistent but wrong where the
depth is wrong (flying pixels, holes). The fusion net combines the two (paper appendix: conv0
4→64 …, multi-scale outputs at 1/4, 1/2 and full resolution).

The net predicts a *correction* of ``W_rough`` at each scale rather than the flow itself: at
initialisation it returns ``W_rough`` unchanged, so the staged schedule starts from the rough
flow's accuracy instead of from zero, and the net only has to learn where to trust ``W_convt``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import nn

from dear_train.models.layers import conv, crop_like, deconv, predict_flow, scaled, upsample_flow


@dataclass(frozen=True)
class FusionConfig:
    """Size of the fusion net; the defaults are the paper tier (≈ 1.0 M parameters)."""

    width: float = 1.0
    separable: bool = False
    flow_scale: float = 20.0

    def to_dict(self) -> dict:
        return asdict(self)


class FusionNet(nn.Module):
    """``forward(flow_rough, flow_convt)`` → ``[W_refn at 1/4, 1/2, 1]``, full-resolution pixels.

    Inputs are ``(N, 2, H, W)`` flows in pixels on the RGB grid, ``H``, ``W`` multiples of 4.
    """

    def __init__(self, config: FusionConfig | None = None) -> None:
        super().__init__()
        cfg = config or FusionConfig()
        self.config = cfg
        s = cfg.separable

        def c(n: int) -> int:
            return scaled(n, cfg.width)

        self.conv0 = conv(4, c(64), 3, 1)
        self.conv1 = conv(c(64), c(64), 3, 2, s)
        self.conv1_1 = conv(c(64), c(128), 3, 1, s)
        self.conv2 = conv(c(128), c(192), 3, 2, s)
        self.conv2_1 = conv(c(192), c(192), 3, 1, s)
        self.predict2 = predict_flow(c(192))
        self.deconv1 = deconv(c(192), c(64))
        self.up2to1 = upsample_flow()
        self.predict1 = predict_flow(c(128) + c(64) + 2)
        self.iconv1 = conv(c(128) + c(64) + 2, c(64), 3, 1, s)
        self.deconv0 = deconv(c(64), c(32))
        self.up1to0 = upsample_flow()
        self.iconv0 = conv(c(64) + c(32) + 2, c(32), 3, 1, s)
        self.predict0 = predict_flow(c(32))
        for m in self.modules():
            if isinstance(m, nn.Conv2d) and m.out_channels == 2:
                m.weight.data.mul_(0.1)
                nn.init.zeros_(m.bias)

    def forward(self, flow_rough: torch.Tensor, flow_convt: torch.Tensor) -> list[torch.Tensor]:
        k = 1.0 / self.config.flow_scale
        x0 = self.conv0(torch.cat([flow_rough, flow_convt], dim=1) * k)
        x1 = self.conv1_1(self.conv1(x0))
        x2 = self.conv2_1(self.conv2(x1))
        base2 = F.avg_pool2d(flow_rough, 4) * k
        base1 = F.avg_pool2d(flow_rough, 2) * k
        d2 = self.predict2(x2)
        cat1 = torch.cat(
            [x1, crop_like(self.deconv1(x2), x1), crop_like(self.up2to1(d2), x1)], dim=1
        )
        d1 = self.predict1(cat1)
        y1 = self.iconv1(cat1)
        cat0 = torch.cat(
            [x0, crop_like(self.deconv0(y1), x0), crop_like(self.up1to0(d1), x0)], dim=1
        )
        d0 = self.predict0(self.iconv0(cat0))
        scale = self.config.flow_scale
        return [(base2 + d2) * scale, (base1 + d1) * scale, flow_rough + d0 * scale]
