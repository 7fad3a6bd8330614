"""The project's metrics in Python, numpy only (so scripts outside the training venv, such as
``scripts/opencv_baselines.py``, use the same definitions): the mirror of
``pipeline/src/metrics.rs``, both checked against the hand-computed cases in
``fixtures/metrics/`` (``train/tests/test_metrics_fixture.py``,
``pipeline/tests/metrics_fixture.rs``).

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
"""

from __future__ import annotations

import numpy as np

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
