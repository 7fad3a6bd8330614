"""RESULTS.md's table of the daemon's time per frame (scripts/results.py, issue 37): each row says
where the bench's threads ran, read from `deard-bench --json`."""

from __future__ import annotations

import json
import types
from collections.abc import Callable
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def results(fixture_maker: Callable[[Path], types.ModuleType]) -> types.ModuleType:
    return fixture_maker(REPO / "scripts" / "results.py")


def write_bench(path: Path, **threads: object) -> Path:
    timing = {"count": 120, "median_ms": 16.2, "p95_ms": 19.8, "mean_ms": 16.7}
    mode = {
        "mode": "online",
        "all": timing,
        "latency": timing,
        "overlapped_frames": 120,
        "without_network": timing,
        "with_network": None,
        "stage_median_ms": [["refine", 24.0]],
    }
    bench = {
        "width": 640,
        "height": 480,
        "threads_available": 2,
        "pinned_cpu": None,
        "hog_cpus": [],
        "modes": [mode],
        **threads,
    }
    path.write_text(json.dumps(bench))
    return path


def test_each_row_says_where_the_threads_ran(results: types.ModuleType, tmp_path: Path) -> None:
    placed = write_bench(tmp_path / "placed.json")
    pinned = write_bench(tmp_path / "pinned.json", pinned_threads=[0, 1])
    one = write_bench(tmp_path / "one.json", pinned_cpu=0)
    rows = results.table_daemon([placed, pinned, one, tmp_path / "missing.json"])
    body = rows[2:]
    # Two rows a file (steady state, all frames); the missing file adds none.
    assert len(body) == 6
    assert all("| 2 CPUs, placed by the scheduler |" in row for row in body[:2])
    assert all("| pinned, one per CPU 0, 1 |" in row for row in body[2:4])
    assert all("| all on CPU 0 |" in row for row in body[4:])
    # Every row has as many cells as the header.
    assert {row.count("|") for row in rows} == {rows[0].count("|")}
