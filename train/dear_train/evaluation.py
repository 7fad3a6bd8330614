"""Evaluation: flow end-point errors and the paper's depth-error protocol.

One definition of the metrics for the whole project: this module mirrors
``pipeline/src/metrics.rs`` (what ``dear eval``, RESULTS.md and the daemon report), and both are
checked against the hand-computed cases in ``fixtures/metrics/`` (``train/tests/
test_metrics_fixture.py``, ``pipeline/tests/metrics_fixture.rs``).

Depth protocol (DEAR §5, Tables 2 and 3), **ranked per frame**:

- evaluated pixels of a frame: ground truth valid and in ``(0, 4 m]``, input depth finite and
  ``> 0``;
- within each frame they are ranked by the error of the *input* depth, ``|input − gt|``
  (float32, ties in row-major order), and the pixel of rank ``r`` among ``n`` goes to class
  ``min(floor(4r / n), 3)``: ``low`` (0–25 %), ``mid`` (25–50 %), ``high`` (50–75 %),
  ``outliers`` (the rest);
- the output's absolute errors are summed per class **over all frames** (pixels are never
  re-ranked over the set), so a class MAE is a pixel-weighted mean in which every frame
  contributes to every class in proportion to its size; ``all`` covers the four classes;
- an output that is not finite or ``<= 0`` is *missing*: it is in no MAE and lowers
  ``coverage`` instead.

AEPE: per frame, the mean end-point error over valid pixels (finite flows, ``|truth| < 1e9``);
over a set, the mean of the per-frame values.

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
from dear_train.models.dear import DEAR

#: Depth range of the paper's MAE, metres (``metrics::MAX_EVAL_DEPTH_M``).
MAE_RANGE_M = 4.0
#: Input-error classes, in the order of :attr:`DepthErrorSplit.sums` (``metrics::CLASSES``).
CLASSES = ("low", "mid", "high", "outliers")


def quantile_class(rank: np.ndarray, n: int) -> np.ndarray:
    """Class of the pixels at 0-based ``rank`` among ``n``: ``min(floor(4 · rank / n), 3)``."""
    return np.minimum((4 * np.asarray(rank, dtype=np.int64)) // max(n, 1), 3)


class DepthErrorSplit:
    """Per-class sums of absolute depth errors, accumulated over frames
    (``metrics::DepthErrorSplit``). Pixels are ranked *within each frame*."""

    def __init__(self) -> None:
        #: ``[low, mid, high, outliers]`` sums of ``|output − gt|`` in metres.
        self.sums = [0.0] * 4
        #: Pixels per class with a valid output.
        self.counts = [0] * 4
        #: Evaluated pixels whose output is invalid.
        self.missing = 0

    def add_errors(self, out_err: np.ndarray, in_err: np.ndarray) -> None:
        """Adds one frame's evaluated pixels, in row-major order: ``in_err = |input − gt|``
        ranks them; ``out_err = |output − gt|`` is accumulated, NaN for a missing output."""
        in_err = np.asarray(in_err, dtype=np.float32).ravel()
        out_err = np.asarray(out_err).ravel()
        order = np.argsort(in_err, kind="stable")
        cls = quantile_class(np.arange(order.size), order.size)
        err = out_err[order].astype(np.float64)
        ok = ~np.isnan(err)
        self.missing += int((~ok).sum())
        for k in range(4):
            m = ok & (cls == k)
            self.sums[k] += float(err[m].sum())
            self.counts[k] += int(m.sum())

    def add_frame(
        self,
        input_depth: np.ndarray,
        output: np.ndarray,
        gt: np.ndarray,
        valid: np.ndarray | None = None,
        max_depth: float = MAE_RANGE_M,
    ) -> None:
        """Adds one ``(H, W)`` frame (metres, 0 = invalid); ``valid`` is the ground-truth mask
        (``dear eval`` zeroes the ground truth outside it, which is the same)."""
        i = np.asarray(input_depth, dtype=np.float32)
        o = np.asarray(output, dtype=np.float32)
        g = np.asarray(gt, dtype=np.float32)
        sel = (g > 0) & (g <= np.float32(max_depth)) & (i > 0) & np.isfinite(i)
        if valid is not None:
            sel &= np.asarray(valid, dtype=bool)
        i, o, g = i[sel], o[sel], g[sel]  # row-major, like ndarray's Zip
        ok = (o > 0) & np.isfinite(o)
        out_err = np.where(ok, np.abs(o - g), np.float32(np.nan))
        self.add_errors(out_err, np.abs(i - g))

    def merge(self, other: DepthErrorSplit) -> None:
        for k in range(4):
            self.sums[k] += other.sums[k]
            self.counts[k] += other.counts[k]
        self.missing += other.missing

    def mae_cm(self, k: int) -> float | None:
        """MAE of class ``k`` in centimetres."""
        return 100.0 * self.sums[k] / self.counts[k] if self.counts[k] else None

    def mae_all_cm(self) -> float | None:
        """MAE over every evaluated pixel with a valid output, in centimetres."""
        n = sum(self.counts)
        return 100.0 * sum(self.sums) / n if n else None

    def coverage(self) -> float:
        """Fraction of evaluated pixels with a valid output."""
        n = sum(self.counts)
        return n / (n + self.missing) if n + self.missing else 0.0

    def result(self) -> dict[str, float]:
        """``{low, mid, high, outliers, all}`` MAE in cm (NaN when empty) and ``coverage``."""
        nan = float("nan")
        out = {c: self.mae_cm(k) for k, c in enumerate(CLASSES)}
        out["all"] = self.mae_all_cm()
        res = {k: nan if v is None else v for k, v in out.items()}
        res["coverage"] = self.coverage()
        return res


def depth_error_classes(pred_err: np.ndarray, input_err: np.ndarray) -> dict[str, float]:
    """MAE in cm per input-error class of **one frame's** evaluated pixels (row-major order).

    ``pred_err``: ``|output − gt|`` in metres, NaN where the output is missing; ``input_err``:
    ``|input − gt|``. Returns :meth:`DepthErrorSplit.result`. For a set of frames, use
    :class:`DepthErrorSplit` (or :class:`DepthAccumulator`): frames are ranked one by one, not
    pooled, so this must not be called on concatenated frames.
    """
    split = DepthErrorSplit()
    split.add_errors(pred_err, input_err)
    return split.result()


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


def aepe(estimate: np.ndarray, truth: np.ndarray, valid: np.ndarray) -> float | None:
    """AEPE (px) of one frame's ``(2, H, W)`` flow over ``valid`` pixels where both flows are
    finite and ``|truth| < 1e9`` (``metrics::aepe``); ``None`` when no pixel qualifies."""
    e = np.asarray(estimate, dtype=np.float32)
    t = np.asarray(truth, dtype=np.float32)
    ok = np.asarray(valid, dtype=bool) & np.isfinite(e).all(axis=0) & np.isfinite(t).all(axis=0)
    ok &= (np.abs(t) < 1e9).all(axis=0)
    if not ok.any():
        return None
    d = (e - t)[:, ok].astype(np.float64)
    return float(np.sqrt(d[0] ** 2 + d[1] ** 2).mean())


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
