"""Evaluation: flow end-point errors and the paper's depth-error protocol.

Depth protocol (DEAR §5): mean absolute error in centimetres over pixels whose ground truth is
within 4 m; the pixels are ranked by the error of the *input* depth and split into quantile
classes — low (0–25 %), mid (25–50 %), high (50–75 %); the remaining 25 % are outliers, which
count only in ``all``. Pixels are pooled over the whole set before ranking.

``dear-evaluate --checkpoint RUN/final.pt --data CAPTURE_DIR`` prints the metrics as JSON.
"""

from __future__ import annotations

import argparse
import itertools
import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch

from dear_train.geometry import warp_depth
from dear_train.losses import epe
from dear_train.models.dear import DEAR

#: Depth range of the paper's MAE, metres.
MAE_RANGE_M = 4.0


def depth_error_classes(pred_err: np.ndarray, input_err: np.ndarray) -> dict[str, float]:
    """MAE in cm of ``pred_err`` (metres, absolute) per class of ``input_err`` quantiles."""
    if pred_err.size == 0:
        return {"low": float("nan"), "mid": float("nan"), "high": float("nan"), "all": float("nan")}
    order = np.argsort(input_err, kind="stable")
    n = order.size
    q = [0, n // 4, n // 2, (3 * n) // 4]
    out = {}
    for name, (a, b) in zip(("low", "mid", "high"), itertools.pairwise(q), strict=True):
        sel = order[a:b]
        out[name] = float(pred_err[sel].mean() * 100) if sel.size else float("nan")
    out["all"] = float(pred_err.mean() * 100)
    return out


class DepthAccumulator:
    """Pools per-pixel errors over a dataset for :func:`depth_error_classes`."""

    def __init__(self) -> None:
        self.pred: list[np.ndarray] = []
        self.inp: list[np.ndarray] = []

    def add(
        self, pred: torch.Tensor, input_depth: torch.Tensor, gt: torch.Tensor, valid: torch.Tensor
    ) -> None:
        # Pixels where the aligned input has no measurement are left out: their "input error"
        # would be the whole depth, and they are holes for every method alike.
        m = valid & (gt > 0) & (gt <= MAE_RANGE_M) & (input_depth > 0)
        self.pred.append((pred - gt).abs()[m].detach().cpu().numpy())
        self.inp.append((input_depth - gt).abs()[m].detach().cpu().numpy())

    def result(self) -> dict[str, float]:
        if not self.pred:
            return depth_error_classes(np.zeros(0), np.zeros(0))
        return depth_error_classes(np.concatenate(self.pred), np.concatenate(self.inp))


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

    - ``aepe_rough`` / ``aepe_refined``: mean EPE (px) of ``W_rough`` / ``W_refn``;
    - ``mae_input_misaligned``: the ToF depth as is (no alignment) against the RGB-view truth;
    - ``mae_input_aligned``: the ToF depth warped with the ground-truth flow;
    - ``mae_refined_gtflow``: the refinement net on ground-truth-aligned inputs (ToF-KPN
      evaluated alone, as in the paper's refinement table);
    - ``mae_pipeline``: the whole pipeline (flow → fusion → warp → refinement);
    each depth figure as ``{low, mid, high, all}`` in cm, flattened to ``name.class`` keys.
    """
    was_training = model.training
    model.eval()
    flows: dict[str, list[float]] = {"aepe_rough": [], "aepe_refined": []}
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
            flows["aepe_rough"].append(float(epe(out["flow_rough"], b["flow"], valid)))
            if "flow_refn" in out:
                flows["aepe_refined"].append(float(epe(out["flow_refn"], b["flow"], valid)))
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
    metrics: dict[str, float] = {k: float(np.mean(v)) for k, v in flows.items() if v}
    for name, a in acc.items():
        if a.pred:
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
