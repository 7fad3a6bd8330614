"""RESULTS.md's reliability score (scripts/results.py, issue 33): one number per family for how
far a row's expected errors are from the errors measured."""

from __future__ import annotations

import json
import math
import types
from collections.abc import Callable
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def results(fixture_maker: Callable[[Path], types.ModuleType]) -> types.ModuleType:
    return fixture_maker(REPO / "scripts" / "results.py")


def bin_(pixels: int, predicted: float, measured: float) -> dict:
    return {
        "predicted_lo_cm": 0.0,
        "predicted_hi_cm": 1.0,
        "pixels": pixels,
        "mean_predicted_cm": predicted,
        "mean_measured_cm": measured,
    }


def test_the_score_weighs_each_bins_log_ratio_by_its_pixels(results: types.ModuleType) -> None:
    assert results.reliability_score([bin_(10, 1.0, 1.0), bin_(5, 3.0, 3.0)]) == 0.0
    # 2× too small and 2× too large count alike.
    assert results.reliability_score([bin_(1, 1.0, 2.0)]) == pytest.approx(math.log(2))
    assert results.reliability_score([bin_(1, 2.0, 1.0)]) == pytest.approx(math.log(2))
    # Weighted by pixels: 3 pixels right, 1 pixel 4× off.
    score = results.reliability_score([bin_(3, 1.0, 1.0), bin_(1, 1.0, 4.0)])
    assert score == pytest.approx(math.log(4) / 4)
    # Nothing to score.
    assert results.reliability_score([]) is None
    assert results.reliability_score([bin_(0, 1.0, 1.0)]) is None


def test_the_table_has_a_column_per_family_with_an_eval(
    results: types.ModuleType, tmp_path: Path
) -> None:
    method = "edge-guarded refine @ true calibration"
    for name, ratio in [("heldout", 3.0), ("clean", 0.5)]:
        (tmp_path / name).mkdir()
        row = {"method": method, "reliability": [bin_(4, 1.0, ratio)]}
        plain = {"method": "raw-tof", "reliability": []}
        doc = {"capture": name, "frames_evaluated": 1, "methods": [plain, row]}
        (tmp_path / name / "eval.json").write_text(json.dumps(doc))
    lines = results.table_reliability_scores(tmp_path)
    assert lines[0] == "| Method | `heldout` | `clean` |"
    assert lines[2] == f"| `{method}` | {math.log(3):.2f} | {math.log(2):.2f} |"
    assert len(lines) == 3
