"""The Python reporting statistics against the hand-worked cases in ``fixtures/stats/``.

``stats/tests/fixture.rs`` checks the Rust crate ``dear-stats`` against the same file, so a
median or p95 printed by either language means the same thing (nearest rank).
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

import pytest

from dear_train.stats import (
    Summary,
    median,
    nearest_rank,
    percentile_nearest_rank,
    upper_median,
)

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "stats" / "percentiles.json"
CASES = json.loads(FIXTURE.read_text())["cases"]


@pytest.mark.parametrize("case", CASES, ids=[c["name"] for c in CASES])
def test_case(case: dict) -> None:
    values = case["values"]
    s = sorted(values)
    for q, want in zip(case["q"], case["percentiles"], strict=True):
        assert percentile_nearest_rank(s, q) == want, q
    assert median(values) == case["median"]
    assert upper_median(values) == case["upper_median"]
    got = Summary.of(values)
    want = case["summary"]
    assert got is not None
    assert (got.count, got.p50, got.p95, got.p99, got.max) == (
        want["count"],
        want["p50"],
        want["p95"],
        want["p99"],
        want["max"],
    )
    assert got.mean == pytest.approx(want["mean"], abs=1e-12)


def test_fixture_has_the_edge_cases() -> None:
    sizes = {len(c["values"]) for c in CASES}
    assert 1 in sizes and any(n % 2 == 0 for n in sizes)
    qs = {q for c in CASES for q in c["q"]}
    assert {0.0, 1.0} <= qs


def test_no_values() -> None:
    assert percentile_nearest_rank([], 0.5) is None
    assert median([]) is None
    assert upper_median([]) is None
    assert Summary.of([]) is None
    with pytest.raises(ValueError):
        nearest_rank(0, 0.5)


def test_clamped_and_not_the_mean_of_the_middle_two() -> None:
    assert nearest_rank(10, -1.0) == 1
    assert nearest_rank(10, 2.0) == 10
    assert nearest_rank(10, float("nan")) == 1
    assert median([1.0, 2.0]) == 1.0 != statistics.median([1.0, 2.0])
