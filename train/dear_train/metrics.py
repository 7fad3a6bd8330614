"""The project's metrics in Python, numpy only (so scripts outside the training venv, such as
``scripts/opencv_baselines.py``, use the same definitions): the mirror of
``evaluate/src/metrics.rs``, both checked against the hand-computed cases in
``fixtures/metrics/`` (``train/tests/test_metrics_fixture.py``,
``evaluate/tests/metrics_fixture.rs``).

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

Reliability of a predicted absolute error (:class:`Reliability`): evaluated pixels have valid
ground truth in ``(0, 4 m]``, a valid output and a finite prediction (0 included); the
prediction ``p`` (metres) goes to the bin ``[RELIABILITY_EDGES_CM[b − 1],
RELIABILITY_EDGES_CM[b])`` (0 and open above at the ends) counted as the edges ``<= 100 · p``
in float64, and the bins accumulate the predicted and the measured ``|output − gt|``.

Temporal change (:class:`TemporalChange`): over consecutive frames, the mean ``|a − b|`` of the
depth on static pixels: both ground truths valid, the previous one within range, ``|ga − gb| <=
STATIC_TOLERANCE_M`` (float32), both depths valid.

A valid depth is finite and ``> 0`` (``is_valid_depth``).
"""

from __future__ import annotations

from dataclasses import dataclass

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


def _valid_depth(z: np.ndarray) -> np.ndarray:
    """``is_valid_depth``: finite and ``> 0`` (NaN fails the comparison)."""
    return (z > 0) & np.isfinite(z)


#: Upper edges (cm) of the bins of predicted error :class:`Reliability` reports; the last bin is
#: open above (``metrics::RELIABILITY_EDGES_CM``).
RELIABILITY_EDGES_CM = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0)
_RELIABILITY_BINS = len(RELIABILITY_EDGES_CM) + 1


@dataclass(frozen=True)
class ReliabilityBin:
    """One bin of a :class:`Reliability`: predictions in ``[predicted_lo_cm, predicted_hi_cm)``
    (``metrics::ReliabilityBin``, a row of ``eval.json``'s reliability table)."""

    predicted_lo_cm: float
    #: ``None``: open above.
    predicted_hi_cm: float | None
    pixels: int
    mean_predicted_cm: float
    mean_measured_cm: float


class Reliability:
    """Predicted against measured absolute depth error, accumulated over frames per bin of the
    prediction (``metrics::Reliability``)."""

    def __init__(self) -> None:
        #: Pixels per bin.
        self.counts = [0] * _RELIABILITY_BINS
        #: Sums of the predicted errors per bin, metres.
        self.predicted = [0.0] * _RELIABILITY_BINS
        #: Sums of ``|output − gt|`` per bin, metres.
        self.measured = [0.0] * _RELIABILITY_BINS

    def add_frame(
        self,
        output: np.ndarray,
        predicted: np.ndarray,
        gt: np.ndarray,
        valid: np.ndarray | None = None,
        max_depth: float = MAE_RANGE_M,
    ) -> None:
        """Adds one ``(H, W)`` frame: ``predicted`` is each pixel's predicted absolute error in
        metres; ``valid`` the ground-truth mask (as zeroing the ground truth outside it).
        Evaluated pixels: ground truth valid and ``<= max_depth``, output valid, prediction
        finite."""
        o = np.asarray(output, dtype=np.float32)
        p = np.asarray(predicted, dtype=np.float32)
        g = np.asarray(gt, dtype=np.float32)
        sel = _valid_depth(g) & (g <= np.float32(max_depth)) & _valid_depth(o) & np.isfinite(p)
        if valid is not None:
            sel &= np.asarray(valid, dtype=bool)
        p64 = p[sel].astype(np.float64)
        # The number of edges <= the prediction in cm; 100 · p is exact in float64 (never
        # scaled in float32, which rounds the float32 just below an edge onto it).
        bins = np.searchsorted(np.asarray(RELIABILITY_EDGES_CM), 100.0 * p64, side="right")
        measured = np.abs(o[sel] - g[sel]).astype(np.float64)
        counts = np.bincount(bins, minlength=_RELIABILITY_BINS)
        pred_sums = np.bincount(bins, weights=p64, minlength=_RELIABILITY_BINS)
        meas_sums = np.bincount(bins, weights=measured, minlength=_RELIABILITY_BINS)
        for b in range(_RELIABILITY_BINS):
            self.counts[b] += int(counts[b])
            self.predicted[b] += float(pred_sums[b])
            self.measured[b] += float(meas_sums[b])

    def bins(self) -> list[ReliabilityBin]:
        """The bins that hold pixels, from the smallest prediction up."""
        edges = (0.0, *RELIABILITY_EDGES_CM, None)
        return [
            ReliabilityBin(
                predicted_lo_cm=float(edges[b]),
                predicted_hi_cm=edges[b + 1],
                pixels=n,
                mean_predicted_cm=100.0 * self.predicted[b] / n,
                mean_measured_cm=100.0 * self.measured[b] / n,
            )
            for b, n in enumerate(self.counts)
            if n > 0
        ]


#: Ground truths closer than this (metres) count as the same static surface; compared in
#: float32, so the bound is ``float32(1e-3)`` = 0.0010000000475 m (``metrics::STATIC_TOLERANCE_M``).
STATIC_TOLERANCE_M = np.float32(1e-3)


class TemporalChange:
    """Mean absolute change of the depth between consecutive frames over *static* pixels
    (``metrics::TemporalChange``): on a still scene, pure flicker."""

    def __init__(self) -> None:
        #: Sum of ``|a − b|`` over the counted pixels, metres.
        self.sum = 0.0
        #: Pixels counted.
        self.count = 0

    def add_pair(
        self,
        previous: tuple[np.ndarray, np.ndarray],
        current: tuple[np.ndarray, np.ndarray],
        max_depth: float = MAE_RANGE_M,
    ) -> None:
        """Adds the pair of consecutive frames, each ``(depth, gt)`` in metres (ground truth
        zeroed outside its mask). A pixel counts when both ground truths are valid, the
        previous one is ``<= max_depth``, they differ by at most :data:`STATIC_TOLERANCE_M`
        (float32) and both depths are valid."""
        a, ga = (np.asarray(x, dtype=np.float32) for x in previous)
        b, gb = (np.asarray(x, dtype=np.float32) for x in current)
        sel = _valid_depth(ga) & _valid_depth(gb) & (ga <= np.float32(max_depth))
        sel &= _valid_depth(a) & _valid_depth(b)
        a, ga, b, gb = a[sel], ga[sel], b[sel], gb[sel]  # finite: no warnings below
        still = np.abs(ga - gb) <= STATIC_TOLERANCE_M
        self.sum += float(np.abs(a[still] - b[still]).astype(np.float64).sum())
        self.count += int(still.sum())

    def mean_cm(self) -> float | None:
        """The mean change in centimetres; ``None`` before any static pixel."""
        return 100.0 * self.sum / self.count if self.count else None
