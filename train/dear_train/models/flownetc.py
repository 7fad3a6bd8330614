"""FlowNetC: the rough-flow network ``W_rough = F(RGB, amplitude)`` of DEAR.

A Siamese tower (shared weights) encodes the RGB image and the ToF amplitude (repeated to three
channels so that one tower fits both) down to 1/8 resolution; a correlation cost volume between
the two 1/8 feature maps plus a 1×1 "redirect" of the RGB features feeds a FlowNet encoder down
to 1/64 and a U-Net decoder that predicts flow at 1/64 … 1/4. The 1/4 flow is upsampled
bilinearly to full resolution. All flow outputs are in *full-resolution pixels* on the RGB grid
(channel 0 = u along columns, 1 = v along rows) and have no activation.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from dear_train.models.layers import (
    Correlation,
    conv,
    crop_like,
    deconv,
    predict_flow,
    resize_like,
    scaled,
    upsample_flow,
)
from dear_train.models.matching import EdgeMatchingPrior


@dataclass(frozen=True)
class FlowNetCConfig:
    """Size of a FlowNetC. The defaults are the paper tier (≈ 39.2 M parameters)."""

    width: float = 1.0
    #: Largest displacement searched by the correlation, in 1/8-resolution pixels.
    max_displacement: int = 20
    #: Step between searched displacements (20 / 2 → 21² = 441 cost-volume channels).
    stride: int = 2
    #: Depthwise-separable convolutions after the first layer (edge tier).
    separable: bool = False
    #: Deepest encoder level: 6 → 1/64 (paper); 5 → 1/32 (edge).
    levels: int = 6
    #: The network predicts ``flow / flow_scale`` internally (FlowNet's ``div_flow``), keeping
    #: its activations O(1) for flows of tens of pixels; outputs are multiplied back.
    flow_scale: float = 20.0
    #: Add the parameter-free edge-matching prior (:mod:`.matching`) to every output, so the
    #: learned layers predict a correction to it (edge tier).
    matching_prior: bool = False

    def to_dict(self) -> dict:
        return asdict(self)


class FlowNetC(nn.Module):
    """FlowNetC with multi-scale outputs; see the module docstring.

    ``forward(rgb, amplitude)`` takes ``rgb`` ``(N, 3, H, W)`` in [0, 1] and the normalised
    amplitude ``(N, 1, H, W)`` in [0, 1]; ``H`` and ``W`` must be multiples of 8. It returns the
    list of flows coarse → fine (1/2^levels … 1/4) followed by the full-resolution flow.
    """

    def __init__(self, config: FlowNetCConfig | None = None) -> None:
        super().__init__()
        cfg = config or FlowNetCConfig()
        if cfg.levels not in (5, 6):
            raise ValueError("levels must be 5 or 6")
        self.config = cfg
        s = cfg.separable

        def c(n: int) -> int:
            return scaled(n, cfg.width)

        self.conv1 = conv(3, c(64), 7, 2)
        self.conv2 = conv(c(64), c(128), 5, 2, s)
        self.conv3 = conv(c(128), c(256), 5, 2, s)
        self.corr = Correlation(cfg.max_displacement, cfg.stride)
        self.corr_act = nn.LeakyReLU(0.1, inplace=True)
        self.conv_redir = conv(c(256), c(32), 1, 1)
        self.conv3_1 = conv(self.corr.out_channels + c(32), c(256), 3, 1, s)
        self.conv4 = conv(c(256), c(512), 3, 2, s)
        self.conv4_1 = conv(c(512), c(512), 3, 1, s)
        self.conv5 = conv(c(512), c(512), 3, 2, s)
        self.conv5_1 = conv(c(512), c(512), 3, 1, s)
        if cfg.levels == 6:
            self.conv6 = conv(c(512), c(1024), 3, 2, s)
            self.conv6_1 = conv(c(1024), c(1024), 3, 1, s)
            self.predict_flow6 = predict_flow(c(1024))
            self.deconv5 = deconv(c(1024), c(512))
            self.up6to5 = upsample_flow()
            cat5 = c(512) + c(512) + 2
        else:
            cat5 = c(512)
        self.predict_flow5 = predict_flow(cat5)
        self.deconv4 = deconv(cat5, c(256))
        self.up5to4 = upsample_flow()
        cat4 = c(512) + c(256) + 2
        self.predict_flow4 = predict_flow(cat4)
        self.deconv3 = deconv(cat4, c(128))
        self.up4to3 = upsample_flow()
        cat3 = c(256) + c(128) + 2
        self.predict_flow3 = predict_flow(cat3)
        self.deconv2 = deconv(cat3, c(64))
        self.up3to2 = upsample_flow()
        cat2 = c(128) + c(64) + 2
        self.predict_flow2 = predict_flow(cat2)
        self.prior = EdgeMatchingPrior() if cfg.matching_prior else None
        self._init_weights()

    def _init_weights(self) -> None:
        for m in self.modules():
            if isinstance(m, nn.Conv2d | nn.ConvTranspose2d):
                nn.init.kaiming_normal_(m.weight, a=0.1, nonlinearity="leaky_relu")
                if m.bias is not None:
                    nn.init.zeros_(m.bias)
        # Flow heads start small so the initial prediction is ≈ 0 px (not ± tens of px).
        for m in self.modules():
            if isinstance(m, nn.Conv2d) and m.out_channels == 2:
                m.weight.data.mul_(0.1)

    @staticmethod
    def _decode(
        feat: torch.Tensor,
        skip: torch.Tensor,
        flow: torch.Tensor,
        deconv_layer: nn.Module,
        up_layer: nn.Module,
    ) -> torch.Tensor:
        up_feat = crop_like(deconv_layer(feat), skip)
        up_flow = crop_like(up_layer(flow), skip)
        return torch.cat([skip, up_feat, up_flow], dim=1)

    def _prior_at(self, prior: torch.Tensor, out: torch.Tensor, stride: int) -> torch.Tensor:
        """The prior flow resampled to the grid of ``out``, an output at 1/``stride`` resolution.

        ``stride`` is a Python int known from the architecture (not read from tensor shapes), so
        the resize has a constant scale when the graph is traced for export.
        """
        assert self.prior is not None
        return resize_like(prior, out, self.prior.scale // stride)

    def forward(self, rgb: torch.Tensor, amplitude: torch.Tensor) -> list[torch.Tensor]:
        cfg = self.config
        n = rgb.shape[0]
        # Siamese tower: one pass over the batch of both images (amplitude repeated to 3 ch).
        both = torch.cat([rgb, amplitude.expand(-1, 3, -1, -1)], dim=0) - 0.5
        x2 = self.conv2(self.conv1(both))
        x3 = self.conv3(x2)
        conv2a, conv3a, conv3b = x2[:n], x3[:n], x3[n:]
        corr = self.corr_act(self.corr(conv3a, conv3b))
        conv3_1 = self.conv3_1(torch.cat([corr, self.conv_redir(conv3a)], dim=1))
        conv4_1 = self.conv4_1(self.conv4(conv3_1))
        conv5_1 = self.conv5_1(self.conv5(conv4_1))
        flows = []
        if cfg.levels == 6:
            conv6_1 = self.conv6_1(self.conv6(conv5_1))
            flow6 = self.predict_flow6(conv6_1)
            flows.append(flow6)
            cat5 = self._decode(conv6_1, conv5_1, flow6, self.deconv5, self.up6to5)
        else:
            cat5 = conv5_1
        flow5 = self.predict_flow5(cat5)
        cat4 = self._decode(cat5, conv4_1, flow5, self.deconv4, self.up5to4)
        flow4 = self.predict_flow4(cat4)
        cat3 = self._decode(cat4, conv3_1, flow4, self.deconv3, self.up4to3)
        flow3 = self.predict_flow3(cat3)
        cat2 = self._decode(cat3, conv2a, flow3, self.deconv2, self.up3to2)
        flow2 = self.predict_flow2(cat2)
        flows += [flow5, flow4, flow3, flow2]
        full = resize_like(flow2, rgb, 4)
        outs = [f * cfg.flow_scale for f in [*flows, full]]
        if self.prior is not None:
            prior = self.prior(rgb, amplitude)
            # Output strides, coarse to fine: flow6 (1/64, six levels only), flow5 … flow2
            # (1/32 … 1/4), and the full-resolution flow.
            strides = [64, 32, 16, 8, 4, 1][6 - cfg.levels :]
            outs = [o + self._prior_at(prior, o, k) for o, k in zip(outs, strides, strict=True)]
        return outs
