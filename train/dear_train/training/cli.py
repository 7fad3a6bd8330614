"""``dear-train``: train the DEAR networks on capture directories.

Examples::

    dear-train --profile smoke --data CAPTURE --out runs/smoke
    dear-train --profile cpu --data DATASET/train --out runs/cpu           # edge tier, 2 cores
    torchrun --nproc_per_node=4 -m dear_train.training.cli --profile gpu --data D --out runs/gpu
    dear-train --profile cpu --data D --out runs/cpu --resume              # continue a run
    dear-train --profile smoke --synthetic --out runs/smoke                # no data needed
    dear-train --profile cpu-gated --variants kpn unet norgb --data D --out runs/variants
                                   # refinement variants on identical batches: OUT/VARIANT/
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from dear_train.models import TIERS, VARIANTS
from dear_train.training.config import PROFILES, get_profile
from dear_train.training.trainer import Trainer
from dear_train.training.variants import train_side_by_side


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        prog="dear-train",
        description=__doc__.splitlines()[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=__doc__.split("\n", 2)[2],
    )
    p.add_argument("--profile", choices=sorted(PROFILES), default="smoke")
    p.add_argument("--data", type=Path, nargs="+", help="capture directories")
    p.add_argument(
        "--synthetic",
        action="store_true",
        help="generate a tiny synthetic capture under OUT/synthetic and train on it",
    )
    p.add_argument("--out", type=Path, required=True, help="run directory")
    p.add_argument("--tier", choices=TIERS, default=None, help="override the profile's tier")
    p.add_argument("--variant", choices=VARIANTS, default=None, help="refinement variant")
    p.add_argument(
        "--variants",
        choices=VARIANTS,
        nargs="+",
        default=None,
        help="train these refinement variants side by side on identical batches "
        "(refine-only profiles; one run directory per variant under OUT)",
    )
    p.add_argument(
        "--refine-context",
        choices=("on", "off"),
        default=None,
        help="override the profile's frame-level context branch of the refiner (edge tier)",
    )
    p.add_argument(
        "--harm-weight",
        type=float,
        default=None,
        help="override the profile's weight of the harm term (the guarded refiner's, or the "
        "hybrid refiner's: 0 turns it off)",
    )
    p.add_argument("--device", default=None, help="cpu, cuda, cuda:1 (default: auto)")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoints/last.pt")
    p.add_argument(
        "--init-refine",
        type=Path,
        default=None,
        help="start the refinement net from this bundle's refine.onnx (a grown head keeps its "
        "extra maps' initialisation); ignored with --resume once a checkpoint exists",
    )
    a = p.parse_args(argv)
    if not a.data and not a.synthetic:
        p.error("give --data CAPTURE_DIR... or --synthetic")
    data = list(a.data or [])
    if a.synthetic:
        from dear_train.data.synthetic import write_synthetic_capture

        syn = a.out / "synthetic"
        if not (syn / "capture.json").exists():
            write_synthetic_capture(syn, frames=8)
        data.append(syn)
    overrides: dict[str, object] = {"tier": a.tier, "variant": a.variant}
    if a.refine_context is not None:
        overrides["refine_context"] = a.refine_context == "on"
    if a.harm_weight is not None:
        if not a.harm_weight >= 0:
            p.error(f"--harm-weight must be a non-negative number, not {a.harm_weight}")
        overrides["harm_weight"] = a.harm_weight
        overrides["hybrid_harm_weight"] = a.harm_weight
    profile = get_profile(a.profile, **overrides)
    if a.variants:
        if a.variant:
            p.error("--variants names the variants; it takes no --variant")
        finals = train_side_by_side(profile, a.variants, data, a.out, a.device, a.resume)
        print(json.dumps({"out": str(a.out), "final_validation": finals}, indent=2))
        return
    metrics = Trainer(profile, data, a.out, a.device, a.resume, a.init_refine).run()
    print(json.dumps({"out": str(a.out), "final_validation": metrics}, indent=2))


if __name__ == "__main__":
    main()
