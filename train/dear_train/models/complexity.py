"""Parameter and multiply-accumulate (MAC) counts of the DEAR networks.

MACs are counted with forward hooks on the layers that do the arithmetic: convolutions and
transposed convolutions (``out_elements · cin/groups · kh · kw`` and ``in_elements ·
cout/groups · kh · kw``), the correlation (``channels · displacements`` per 1/8 pixel) and the
KPN filtering (9 per pixel). Element-wise ops, activations and resizes are left out: they are
memory-bound and a few percent at most. Run ``python -m dear_train.models.complexity`` for the
table in the README.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import nn

from dear_train.models import TIERS, build_flow, build_fusion, build_refine, param_count
from dear_train.models.kpn import KernelApply
from dear_train.models.layers import Correlation


@dataclass
class Complexity:
    """One model's size at one input resolution."""

    name: str
    params: int
    macs: int


def count_macs(model: nn.Module, run: Callable[[], object]) -> int:
    """MACs of one call of ``run()`` (which must call ``model``), via forward hooks."""
    total = 0

    def hook(module: nn.Module, inputs: tuple, output: torch.Tensor) -> None:
        nonlocal total
        if isinstance(module, nn.Conv2d):
            kh, kw = module.kernel_size
            total += (
                output.numel() // output.shape[0] * module.in_channels // module.groups * kh * kw
            )
        elif isinstance(module, nn.ConvTranspose2d):
            kh, kw = module.kernel_size
            x = inputs[0]
            total += x.numel() // x.shape[0] * module.out_channels // module.groups * kh * kw
        elif isinstance(module, Correlation):
            f1 = inputs[0]
            total += f1.numel() // f1.shape[0] * module.out_channels
        elif isinstance(module, KernelApply):
            total += output.numel() // output.shape[0] * 9

    handles = [
        m.register_forward_hook(hook)
        for m in model.modules()
        if isinstance(m, nn.Conv2d | nn.ConvTranspose2d | Correlation | KernelApply)
    ]
    try:
        with torch.no_grad():
            run()
    finally:
        for h in handles:
            h.remove()
    return total


def measure(
    tier: str, variant: str = "kpn", height: int = 480, width: int = 640
) -> list[Complexity]:
    """Params and MACs per image of the flow, fusion and refinement nets of ``tier``."""
    rgb = torch.zeros(1, 3, height, width)
    one = torch.zeros(1, 1, height, width)
    flow2 = torch.zeros(1, 2, height, width)
    flow, fusion, refine = build_flow(tier), build_fusion(tier), build_refine(tier, variant)
    for m in (flow, fusion, refine):
        m.eval()
    return [
        Complexity(f"{tier}/flow", param_count(flow), count_macs(flow, lambda: flow(rgb, one))),
        Complexity(
            f"{tier}/fusion", param_count(fusion), count_macs(fusion, lambda: fusion(flow2, flow2))
        ),
        Complexity(
            f"{tier}/refine[{variant}]",
            param_count(refine),
            count_macs(refine, lambda: refine(one, one, rgb)),
        ),
    ]


def main() -> None:
    """Print a Markdown table of params and GMACs for every tier."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--variant", default="kpn")
    a = p.parse_args()
    print(f"| model | params | GMAC at {a.width}×{a.height} |")
    print("| --- | ---: | ---: |")
    for tier in TIERS:
        for c in measure(tier, a.variant, a.height, a.width):
            print(f"| {c.name} | {c.params:,} | {c.macs / 1e9:.3f} |")


if __name__ == "__main__":
    main()
