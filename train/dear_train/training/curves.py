"""Loss curves to PNG (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def plot_history(history: list[dict], path: Path) -> None:
    """Training loss per epoch (one line per stage) and validation metrics, to ``path``.

    ``history`` entries: ``{"stage", "epoch", "train_loss", "val": {metric: value}}``; the x
    axis is the global epoch index so consecutive stages follow each other.
    """
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    stages: dict[str, list[tuple[int, float]]] = {}
    vals: dict[str, list[tuple[int, float]]] = {}
    for i, h in enumerate(history):
        stages.setdefault(h["stage"], []).append((i, h["train_loss"]))
        for k, v in h.get("val", {}).items():
            if k.startswith("aepe") or k.endswith(".all"):
                vals.setdefault(k, []).append((i, v))
    for name, pts in stages.items():
        axes[0].plot(*zip(*pts, strict=True), marker="o", label=name)
    axes[0].set_title("training loss")
    axes[0].set_xlabel("epoch (all stages)")
    axes[0].set_yscale("log")
    axes[0].legend()
    for name, pts in vals.items():
        axes[1].plot(*zip(*pts, strict=True), marker="o", label=name)
    axes[1].set_title("validation (AEPE px, MAE cm)")
    axes[1].set_xlabel("epoch (all stages)")
    if vals:
        axes[1].legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
