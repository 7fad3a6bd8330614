"""The reporting statistics' one definition, as ``stats/src/lib.rs`` (crate ``dear-stats``).

The ``q``-percentile (``q`` in [0, 1]) of ``n`` values is the value of 1-based rank
``ceil(q·n − 1e-9)``, clamped to ``[1, n]``, in ascending order: always a measured value, never
an interpolation. The median is the 0.5-percentile, the *lower* middle value for an even count
(``statistics.median`` would give the mean of the two, ``numpy.percentile``'s default
interpolates). The ``1e-9`` keeps a product that floating point puts just above an integer
(``0.07 · 100``) at the rank exact arithmetic gives.

``fixtures/stats/percentiles.json`` holds hand-worked cases that this module
(``train/tests/test_stats_fixture.py``) and the Rust crate (``stats/tests/fixture.rs``) are both
checked against. The amplitude normalisation's ``numpy.percentile`` (linear) is a different,
deliberate definition: part of the model bundle contract, not a reported figure.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass


def nearest_rank(n: int, q: float) -> int:
    """1-based nearest rank of the ``q``-percentile among ``n > 0`` values (``q`` clamped)."""
    if n <= 0:
        raise ValueError("nearest_rank of no values")
    x = q * n - 1e-9
    if math.isnan(x):
        return 1
    return min(max(math.ceil(x), 1), n)


def percentile_nearest_rank(sorted_values: list[float], q: float) -> float | None:
    """The nearest-rank ``q``-percentile of ascending ``sorted_values``; ``None`` when empty."""
    if not sorted_values:
        return None
    return sorted_values[nearest_rank(len(sorted_values), q) - 1]


def median(values: Iterable[float]) -> float | None:
    """The nearest-rank median (lower middle value for an even count); ``None`` when empty."""
    return percentile_nearest_rank(sorted(values), 0.5)


def upper_median(values: Iterable[float]) -> float | None:
    """The element of 0-based rank ``n // 2`` (for computations, not reports, as in Rust)."""
    v = sorted(values)
    return v[len(v) // 2] if v else None


@dataclass(frozen=True)
class Summary:
    """Nearest-rank p50 (the median), p95, p99, the maximum, the mean and the count."""

    count: int
    p50: float
    p95: float
    p99: float
    max: float
    mean: float

    @staticmethod
    def of(values: Iterable[float]) -> Summary | None:
        v = sorted(values)
        if not v:
            return None

        def at(q: float) -> float:
            return v[nearest_rank(len(v), q) - 1]

        return Summary(len(v), at(0.50), at(0.95), at(0.99), v[-1], math.fsum(v) / len(v))
