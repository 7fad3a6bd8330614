"""The DEAR networks, by tier (``paper`` / ``edge``) and refinement variant.

- :mod:`.flownetc` — rough flow ``W_rough`` from RGB and amplitude;
- :mod:`.fusion` — fusion of ``W_rough`` and the calibration flow ``W_convt`` into ``W_refn``;
- :mod:`.kpn` — ToF-KPN depth refinement, ablation variants, DeepToF-style baseline;
- :mod:`.edge` — the compact real-time tier;
- :mod:`.dear` — the whole differentiable pipeline for end-to-end training;
- :mod:`.complexity` — parameter and MAC counts.
"""

from __future__ import annotations

from torch import nn

from dear_train.models.edge import edge_flow, edge_fusion, edge_refine
from dear_train.models.flownetc import FlowNetC, FlowNetCConfig
from dear_train.models.fusion import FusionConfig, FusionNet
from dear_train.models.kpn import VARIANTS, RefineNet, paper_refine, uses_rgb

TIERS = ("paper", "edge")

#: Inputs must be multiples of this (flows are predicted at 1/4, the cost volume at 1/8; deeper
#: levels crop their upsampled outputs, so no larger multiple is needed).
INPUT_SIZE_MULTIPLE = 8


def _check_tier(tier: str) -> None:
    if tier not in TIERS:
        raise ValueError(f"unknown tier {tier!r}; choose from {', '.join(TIERS)}")


def build_flow(tier: str) -> FlowNetC:
    """The rough-flow net of ``tier``."""
    _check_tier(tier)
    return FlowNetC(FlowNetCConfig()) if tier == "paper" else edge_flow()


def build_fusion(tier: str) -> FusionNet:
    """The fusion net of ``tier``."""
    _check_tier(tier)
    return FusionNet(FusionConfig()) if tier == "paper" else edge_fusion()


def build_refine(
    tier: str,
    variant: str = "kpn",
    global_context: bool = False,
    widths: tuple[int, int, int, int] | None = None,
) -> RefineNet:
    """The refinement net of ``tier`` and ``variant`` (``global_context``: the frame-level
    context branch; ``widths``: other channel widths per level; both edge tier only)."""
    _check_tier(tier)
    if tier == "paper":
        if global_context or widths is not None:
            raise ValueError("the context branch and other widths exist for the edge tier only")
        return paper_refine(variant)
    return edge_refine(variant, global_context, widths)


def param_count(model: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


__all__ = [
    "INPUT_SIZE_MULTIPLE",
    "TIERS",
    "VARIANTS",
    "FlowNetC",
    "FlowNetCConfig",
    "FusionConfig",
    "FusionNet",
    "RefineNet",
    "build_flow",
    "build_fusion",
    "build_refine",
    "param_count",
    "uses_rgb",
]
