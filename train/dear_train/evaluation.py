"""Evaluation of a checkpoint: flow end-point errors and the paper's depth-error protocol on
dataset samples, with the metric definitions of :mod:`dear_train.metrics` (the mirror of
``evaluate/src/metrics.rs``, so these are the quantities ``dear eval`` and RESULTS.md report).

``dear-evaluate --checkpoint RUN/final.pt --data CAPTURE_DIR`` prints the metrics as JSON.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch

from dear_train.geometry import warp_depth
from dear_train.metrics import DepthErrorSplit, aepe
from dear_train.models.dear import DEAR


class DepthAccumulator:
    """:class:`DepthErrorSplit` over batches of ``(B, 1, H, W)`` tensors, ranked per sample."""

    def __init__(self) -> None:
        self.split = DepthErrorSplit()
        #: Samples added.
        self.frames = 0

    def add(
        self, pred: torch.Tensor, input_depth: torch.Tensor, gt: torch.Tensor, valid: torch.Tensor
    ) -> None:
        # Pixels where the input has no measurement are left out (DepthErrorSplit.add_frame):
        # their "input error" would be the whole depth, and they are holes for every method.
        def planes(t: torch.Tensor) -> np.ndarray:
            return t.detach().float().cpu().reshape(t.shape[0], *t.shape[-2:]).numpy()

        for i, o, g, v in zip(
            planes(input_depth), planes(pred), planes(gt), planes(valid.bool()), strict=True
        ):
            self.split.add_frame(i, o, g, v.astype(bool))
            self.frames += 1

    def result(self) -> dict[str, float]:
        return self.split.result()


class AepeAccumulator:
    """Mean over samples of the per-sample :func:`aepe` (samples without a valid pixel skipped)."""

    def __init__(self) -> None:
        self.values: list[float] = []

    def add(self, pred: torch.Tensor, truth: torch.Tensor, valid: torch.Tensor) -> None:
        """``pred``, ``truth``: ``(B, 2, H, W)``; ``valid``: ``(B, 1, H, W)``."""
        p = pred.detach().float().cpu().numpy()
        t = truth.detach().float().cpu().numpy()
        v = valid.detach().bool().cpu().numpy()[:, 0]
        for pb, tb, vb in zip(p, t, v, strict=True):
            e = aepe(pb, tb, vb)
            if e is not None:
                self.values.append(e)

    def result(self) -> float | None:
        return float(np.mean(self.values)) if self.values else None


@torch.no_grad()
def evaluate(
    model: DEAR,
    batches: Iterable[dict[str, torch.Tensor]],
    device: torch.device | str = "cpu",
    max_batches: int | None = None,
    align: bool = True,
) -> dict[str, float]:
    """Every metric the model's parts allow, over ``batches`` of dataset samples.

    ``align=False`` leaves out the flow and whole-pipeline metrics (for refine-only runs).

    - ``aepe_rough`` / ``aepe_refined``: AEPE (px) of ``W_rough`` / ``W_refn``, the mean over
      samples of each sample's AEPE (:func:`aepe`);
    - ``mae_input_misaligned``: the ToF depth as is (no alignment) against the RGB-view truth;
    - ``mae_input_aligned``: the ToF depth warped with the ground-truth flow;
    - ``mae_refined_gtflow``: the refinement net on ground-truth-aligned inputs (ToF-KPN
      evaluated alone, as in the paper's refinement table);
    - ``mae_pipeline``: the whole pipeline (flow → fusion → warp → refinement);
    each depth figure as ``{low, mid, high, outliers, all}`` in cm (ranked per sample by the
    error of the ToF depth warped with the ground-truth flow, the module's protocol) and its
    ``coverage``, flattened to ``name.class`` keys.
    """
    was_training = model.training
    model.eval()
    flows = {"aepe_rough": AepeAccumulator(), "aepe_refined": AepeAccumulator()}
    acc = {
        k: DepthAccumulator()
        for k in ("mae_input_misaligned", "mae_input_aligned", "mae_refined_gtflow", "mae_pipeline")
    }
    for i, batch in enumerate(batches):
        if max_batches is not None and i >= max_batches:
            break
        b = {k: v.to(device) for k, v in batch.items()}
        rgb, amp, tof, gt = b["rgb"], b["amplitude"], b["tof_depth"], b["gt_depth"]
        valid = b["flow_valid"]
        aligned, _ = warp_depth(tof, b["flow"])
        acc["mae_input_misaligned"].add(tof, aligned, gt, valid)
        acc["mae_input_aligned"].add(aligned, aligned, gt, valid)
        if model.refine is not None:
            r = model.refine_depth(rgb, amp, tof, b["flow"], b.get("tof_classical"))
            acc["mae_refined_gtflow"].add(r["depth"], aligned, gt, valid)
        if align and model.flow is not None:
            out = model.align(rgb, amp, tof)
            flows["aepe_rough"].add(out["flow_rough"], b["flow"], valid)
            if "flow_refn" in out:
                flows["aepe_refined"].add(out["flow_refn"], b["flow"], valid)
            if model.refine is not None:
                final = out.get("flow_refn", out["flow_rough"])
                r = model.refine_depth(
                    rgb,
                    amp,
                    tof,
                    final,  # type: ignore[arg-type]
                    b.get("tof_classical"),
                )
                acc["mae_pipeline"].add(r["depth"], aligned, gt, valid)
    model.train(was_training)
    metrics: dict[str, float] = {}
    for key, f in flows.items():
        value = f.result()
        if value is not None:
            metrics[key] = value
    for name, a in acc.items():
        if a.frames:
            for cls, val in a.result().items():
                metrics[f"{name}.{cls}"] = val
    return metrics


def main(argv: list[str] | None = None) -> None:
    from torch.utils.data import DataLoader

    from dear_train.data.dataset import DearDataset
    from dear_train.models.kpn import uses_classical
    from dear_train.training.checkpoint import load_model

    p = argparse.ArgumentParser(description="Evaluate a trained DEAR checkpoint on captures.")
    p.add_argument("--checkpoint", type=Path, required=True, help="final.pt of a training run")
    p.add_argument("--data", type=Path, nargs="+", required=True, help="capture directories")
    p.add_argument("--max-frames", type=int, default=None)
    p.add_argument("--seed", type=int, default=1234, help="seed of the synthetic misalignments")
    p.add_argument("--out", type=Path, default=None, help="also write the metrics JSON here")
    a = p.parse_args(argv)
    model, profile = load_model(a.checkpoint)
    ds = DearDataset(
        a.data,
        crop=None,
        augment=profile.augment,
        norm=profile.norm,
        seed=a.seed,
        classical=uses_classical(profile.variant),
    )
    loader = DataLoader(ds, batch_size=1, shuffle=False)
    metrics = evaluate(model, loader, "cpu", a.max_frames)
    metrics["frames_skipped"] = ds.skipped
    text = json.dumps(metrics, indent=2)
    print(text)
    if a.out:
        a.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
