"""The Python metrics against the hand-computed cases in ``fixtures/metrics/``.

``evaluate/tests/metrics_fixture.rs`` checks ``evaluate/src/metrics.rs`` against the same files,
so both languages compute one definition (per-frame ranking, see
:mod:`dear_train.evaluation`). The depth case is built so that ranking pooled over the set,
other quarter boundaries, other tie-breaking or counting invalid outputs all fail it; the
reliability case so that scaling predictions in float32, dropping a zero prediction or keeping a
non-finite one, an invalid output or ground truth beyond range fail it; the temporal case so
that ``<`` for ``<=`` or a float64 tolerance, another tolerance, invalid depths or the mean of
the pairs' means fail it (``fixtures/metrics/make_metrics.py``).
"""

from __future__ import annotations

import dataclasses
import json
import types
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch

from dear_train.evaluation import AepeAccumulator, DepthAccumulator
from dear_train.metrics import (
    CLASSES,
    MAE_RANGE_M,
    RELIABILITY_EDGES_CM,
    STATIC_TOLERANCE_M,
    DepthErrorSplit,
    Reliability,
    ReliabilityBin,
    TemporalChange,
    aepe,
    depth_error_classes,
)

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "metrics"
#: Every depth is a multiple of 1/64 m, so the float32 arithmetic is exact; this only absorbs
#: the order of the float64 sums.
TOL = 1e-9


def arr(spec: dict) -> np.ndarray:
    """An array of the fixture; non-finite values are the strings ``NaN``, ``inf``, ``-inf``."""
    dtype = {"f32": np.float32, "bool": np.bool_}[spec["dtype"]]
    data = [float(x) for x in spec["data"]]
    return np.array(data, dtype=np.float64).astype(dtype).reshape(spec["shape"])


def load(name: str) -> dict:
    return json.loads((FIXTURE / f"{name}.json").read_text())


def frames(doc: dict) -> list[dict[str, np.ndarray]]:
    return [{k: arr(v) for k, v in f.items()} for f in doc["inputs"]["frames"]]


def check_split(split: DepthErrorSplit, want: dict) -> None:
    assert split.counts == want["counts"]
    assert split.missing == want["missing"]
    np.testing.assert_allclose(split.sums, want["sums_m"], rtol=0, atol=TOL)


def test_depth_split_matches_the_fixture() -> None:
    doc = load("depth_error_split")
    assert doc["inputs"]["max_depth_m"] == MAE_RANGE_M
    out = doc["outputs"]
    total = DepthErrorSplit()
    for f, want in zip(frames(doc), out["per_frame"], strict=True):
        one = DepthErrorSplit()
        one.add_frame(f["input"], f["output"], f["gt"], f["valid"], doc["inputs"]["max_depth_m"])
        check_split(one, want)
        total.merge(one)
    check_split(total, out)
    for k, c in enumerate(CLASSES):
        assert total.mae_cm(k) == pytest.approx(out["mae_cm"][c], abs=TOL)
    assert total.mae_all_cm() == pytest.approx(out["mae_all_cm"], abs=TOL)
    assert total.coverage() == pytest.approx(out["coverage"], abs=1e-12)
    res = total.result()
    assert [res[c] for c in CLASSES] == pytest.approx([out["mae_cm"][c] for c in CLASSES])
    assert res["all"] == pytest.approx(out["mae_all_cm"])


def test_batched_accumulator_ranks_each_sample() -> None:
    """``evaluate``'s path: the three frames in one batch give the per-frame figures."""
    doc = load("depth_error_split")
    fs = frames(doc)

    def batch(key: str) -> torch.Tensor:
        return torch.from_numpy(np.stack([f[key] for f in fs]))[:, None]

    acc = DepthAccumulator()
    acc.add(batch("output"), batch("input"), batch("gt"), batch("valid"))
    assert acc.frames == 3
    check_split(acc.split, doc["outputs"])
    res = acc.result()
    assert res["low"] == pytest.approx(doc["outputs"]["mae_cm"]["low"], abs=TOL)
    assert res["coverage"] == pytest.approx(doc["outputs"]["coverage"])


def test_pooled_ranking_would_fail_the_fixture() -> None:
    """The fixture tells the definitions apart: the frames stacked as one (= pooled over the
    set, the former Python protocol) rank differently."""
    doc = load("depth_error_split")
    fs = frames(doc)
    pooled = DepthErrorSplit()
    pooled.add_frame(
        *(np.concatenate([f[k] for f in fs]) for k in ("input", "output", "gt", "valid"))
    )
    want = doc["outputs"]
    assert pooled.mae_cm(0) == pytest.approx(want["pooled_ranking_low_mae_cm"], abs=TOL)
    assert abs(pooled.mae_cm(0) - want["mae_cm"]["low"]) > 0.1
    assert pooled.counts != want["counts"]


def test_depth_error_classes_is_one_frame() -> None:
    doc = load("depth_error_split")
    f = frames(doc)[0]
    want = doc["outputs"]["per_frame"][0]
    g, i, o = f["gt"], f["input"], f["output"]
    sel = f["valid"] & (g > 0) & (g <= MAE_RANGE_M) & (i > 0)
    out_err = np.where(o[sel] > 0, np.abs(o[sel] - g[sel]), np.nan)
    got = depth_error_classes(out_err, np.abs(i[sel] - g[sel]))
    for k, c in enumerate(CLASSES):
        assert got[c] == pytest.approx(100 * want["sums_m"][k] / want["counts"][k], abs=TOL)
    assert got["coverage"] == pytest.approx(9 / 10)


def test_empty_split() -> None:
    res = DepthErrorSplit().result()
    assert all(np.isnan(res[c]) for c in (*CLASSES, "all")) and res["coverage"] == 0.0


def test_aepe_matches_the_fixture() -> None:
    doc = load("aepe")
    fs = frames(doc)
    want = doc["outputs"]
    acc = AepeAccumulator()
    for f, w in zip(fs, want["per_frame"], strict=True):
        est = np.stack([f["estimate_u"], f["estimate_v"]])
        truth = np.stack([f["truth_u"], f["truth_v"]])
        got = aepe(est, truth, f["valid"])
        assert got == (None if w is None else pytest.approx(w, abs=1e-9))
        acc.add(
            torch.from_numpy(est)[None],
            torch.from_numpy(truth)[None],
            torch.from_numpy(f["valid"])[None, None],
        )
    assert acc.result() == pytest.approx(want["mean_over_frames"], abs=1e-9)
    # One batch of all frames: still the mean over samples.
    batched = AepeAccumulator()
    batched.add(
        torch.from_numpy(np.stack([np.stack([f["estimate_u"], f["estimate_v"]]) for f in fs])),
        torch.from_numpy(np.stack([np.stack([f["truth_u"], f["truth_v"]]) for f in fs])),
        torch.from_numpy(np.stack([f["valid"] for f in fs]))[:, None],
    )
    assert batched.result() == pytest.approx(want["mean_over_frames"], abs=1e-9)


def test_reliability_matches_the_fixture() -> None:
    doc = load("reliability")
    assert doc["inputs"]["max_depth_m"] == MAE_RANGE_M
    assert tuple(doc["inputs"]["edges_cm"]) == RELIABILITY_EDGES_CM
    fs = frames(doc)
    assert any(np.isnan(f["predicted"]).any() for f in fs)  # the non-finite cases are read
    want = doc["outputs"]
    rel = Reliability()
    for f in fs:
        rel.add_frame(
            f["output"], f["predicted"], f["gt"], f["valid"], doc["inputs"]["max_depth_m"]
        )
    assert rel.counts == want["counts"]
    np.testing.assert_allclose(rel.predicted, want["predicted_sums_m"], rtol=0, atol=TOL)
    np.testing.assert_allclose(rel.measured, want["measured_sums_m"], rtol=0, atol=TOL)
    got = rel.bins()
    assert [(b.predicted_lo_cm, b.predicted_hi_cm, b.pixels) for b in got] == [
        (w["predicted_lo_cm"], w["predicted_hi_cm"], w["pixels"]) for w in want["bins"]
    ]
    for b, w in zip(got, want["bins"], strict=True):
        assert b.mean_predicted_cm == pytest.approx(w["mean_predicted_cm"], abs=TOL)
        assert b.mean_measured_cm == pytest.approx(w["mean_measured_cm"], abs=TOL)
    assert isinstance(got[0], ReliabilityBin)
    assert set(dataclasses.asdict(got[0])) == set(want["bins"][0])  # eval.json's field names


def test_reliability_masks_like_zeroed_ground_truth() -> None:
    """``dear eval`` zeroes the ground truth outside its mask instead of passing one."""
    doc = load("reliability")
    rel = Reliability()
    for f in frames(doc):
        rel.add_frame(f["output"], f["predicted"], np.where(f["valid"], f["gt"], 0))
    assert rel.counts == doc["outputs"]["counts"]


def test_reliability_in_float32_would_fail_the_fixture() -> None:
    """The predictions just below an edge: scaled to cm in float32 they round onto the edge and
    move up a bin."""
    doc = load("reliability")
    fs = frames(doc)
    counts = np.zeros(len(RELIABILITY_EDGES_CM) + 1, dtype=np.int64)
    for f in fs:
        g, o, p = f["gt"], f["output"], f["predicted"]
        sel = f["valid"] & (g > 0) & (g <= MAE_RANGE_M) & (o > 0) & np.isfinite(o) & np.isfinite(p)
        cm32 = np.float32(100) * p[sel]
        assert cm32.dtype == np.float32
        edges = np.asarray(RELIABILITY_EDGES_CM, dtype=np.float32)
        counts += np.bincount(np.searchsorted(edges, cm32, side="right"), minlength=counts.size)
    assert counts.tolist() != doc["outputs"]["counts"]


def test_empty_reliability() -> None:
    rel = Reliability()
    rel.add_frame(np.ones((2, 2)), np.full((2, 2), np.nan), np.ones((2, 2)))
    assert rel.bins() == [] and sum(rel.counts) == 0


def test_temporal_change_matches_the_fixture() -> None:
    doc = load("temporal_change")
    assert doc["inputs"]["max_depth_m"] == MAE_RANGE_M
    assert np.float32(doc["inputs"]["static_tolerance_m"]) == STATIC_TOLERANCE_M
    fs = [(f["depth"], np.where(f["valid"], f["gt"], np.float32(0))) for f in frames(doc)]
    want = doc["outputs"]
    total = TemporalChange()
    assert total.mean_cm() is None
    pair_means = []
    for prev, cur, w in zip(fs[:-1], fs[1:], want["per_pair"], strict=True):
        one = TemporalChange()
        one.add_pair(prev, cur, doc["inputs"]["max_depth_m"])
        assert one.count == w["count"]
        assert one.sum == pytest.approx(w["sum_m"], abs=TOL)
        pair_means.append(one.mean_cm())
        total.add_pair(prev, cur)
    assert total.count == want["count"]
    assert total.sum == pytest.approx(want["sum_m"], abs=TOL)
    assert total.mean_cm() == pytest.approx(want["mean_cm"], abs=TOL)
    assert sum(pair_means) / 2 == pytest.approx(want["mean_of_pair_means_cm"], abs=TOL)
    assert abs(want["mean_of_pair_means_cm"] - want["mean_cm"]) > 0.1


def test_temporal_tolerance_in_float64_would_fail_the_fixture() -> None:
    """The ground truths 1 mm and 2 mm apart differ by exactly float32(1e-3), above 1e-3."""
    doc = load("temporal_change")
    f0, f1 = frames(doc)[:2]
    diff = np.abs(f0["gt"] - f1["gt"])
    assert (diff == STATIC_TOLERANCE_M).any()
    assert (diff.astype(np.float64) <= 1e-3).sum() < (diff <= STATIC_TOLERANCE_M).sum()


def test_committed_fixture_is_what_the_generator_writes(
    fixture_maker: Callable[[Path], types.ModuleType],
) -> None:
    make = fixture_maker(FIXTURE / "make_metrics.py")
    assert load("depth_error_split") == json.loads(json.dumps(make.depth_doc()))
    assert load("aepe") == json.loads(json.dumps(make.aepe_doc()))
    assert load("reliability") == json.loads(json.dumps(make.reliability_doc()))
    assert load("temporal_change") == json.loads(json.dumps(make.temporal_doc()))
    assert make.RELIABILITY_EDGES_CM == RELIABILITY_EDGES_CM
    assert np.float32(make.STATIC_TOLERANCE_M) == STATIC_TOLERANCE_M
