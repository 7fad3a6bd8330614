"""The ``edge`` tier: compact nets for real-time inference on a phone-class CPU.

Same architectures and I/O as the paper tier, so the daemon runs either bundle unchanged, but:

- every convolution after the first of a stage is depthwise-separable;
- channel widths are scaled down (flow ×1/4, fusion ×1/4, refinement 16/32/32/64);
- the flow net stops at 1/32 and searches ±4 px at 1/8 resolution with stride 1 (81 cost-volume
  channels instead of 441): the misalignment the daemon corrects is 5–20 px at full resolution,
  i.e. ≤ 2.5 px at 1/8, so ±4 (±32 px full-res) covers it. (A first version searched ±8 with
  stride 2 like the paper's ±20/2: its displacements were 16 full-res px apart, coarser than
  the whole misalignment, and it never learned; see ``models/edge/README.md``.)
- the flow net adds a parameter-free edge-matching prior (:mod:`.matching`) to its outputs and
  learns a correction to it: RGB and IR texture differ, and from scratch on a CPU budget the
  net did not learn to match them;
- the refinement backbone runs at 1/2 resolution (1/4 for the ``gated`` variant) and its
  kernels are upsampled and applied to the full-resolution depth, which keeps the
  edge-preserving filtering at full resolution.

``models/complexity.py`` measures what this buys (README, "Model sizes").
"""

from __future__ import annotations

from dataclasses import replace

from dear_train.models.flownetc import FlowNetC, FlowNetCConfig
from dear_train.models.fusion import FusionConfig, FusionNet
from dear_train.models.kpn import RefineNet, UNetConfig, applies_maps

EDGE_FLOW = FlowNetCConfig(
    width=0.25, max_displacement=4, stride=1, separable=True, levels=5, matching_prior=True
)
EDGE_FUSION = FusionConfig(width=0.25, separable=True)
EDGE_REFINE = UNetConfig(widths=(16, 32, 32, 64), separable=True, backbone_stride=2)
#: The gated refiner's backbone runs at 1/4 resolution: its output is a blend of full-resolution
#: neighbours whose weights are cut at depth edges at full resolution, so the backbone only has
#: to say *how much* to smooth and correct, which varies slowly (cost budget: ≤ 15 ms per
#: 640×480 frame on one core, shared with the real-time issue).
EDGE_GATED_REFINE = UNetConfig(widths=(16, 32, 32, 64), separable=True, backbone_stride=4)


def edge_flow() -> FlowNetC:
    """The edge-tier rough-flow net."""
    return FlowNetC(EDGE_FLOW)


def edge_fusion() -> FusionNet:
    """The edge-tier fusion net."""
    return FusionNet(EDGE_FUSION)


def edge_refine(
    variant: str = "kpn",
    global_context: bool = False,
    widths: tuple[int, int, int, int] | None = None,
) -> RefineNet:
    """The edge-tier refinement net (any variant of :mod:`dear_train.models.kpn`), optionally
    with the frame-level context branch (:class:`~dear_train.models.kpn.UNetConfig`) and other
    channel widths per level."""
    config = EDGE_GATED_REFINE if applies_maps(variant) else EDGE_REFINE
    config = replace(config, global_context=global_context)
    if widths is not None:
        config = replace(config, widths=tuple(widths))
    return RefineNet(variant, config)
