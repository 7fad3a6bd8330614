"""The README's headline figures (issue 36): scripts/results.py writes them between two marker
comments from the eval.json files RESULTS.md is made of, and every number in that block must be
one RESULTS.md prints."""

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


def readme_with(results: types.ModuleType, block: str) -> str:
    begin, end = results.HEADLINE_BEGIN, results.HEADLINE_END
    return f"# Title\n\nbefore 1\n\n{begin}\n{block}\n{end}\n\nafter 2\n"


def test_every_readme_headline_figure_is_in_results_md(results: types.ModuleType) -> None:
    readme = (REPO / "README.md").read_text()
    missing = results.figures_not_in_results(readme, (REPO / "RESULTS.md").read_text())
    assert missing == [], f"README.md's headline figures not in RESULTS.md: {missing}"


def test_check_fails_on_a_figure_results_md_lacks(results: types.ModuleType) -> None:
    doc = "| edge | 8.34 | 1.62 |\n\n640×480: median 24.0 ms, p95 45.4"
    # Every figure present: nothing missing (numbers in link targets and in words are not figures).
    ok = "| What | `edge` 8.34, 640×480: 24.0 ms p95 | [s](RESULTS.md#tables-2-and-3) |"
    assert results.figures_not_in_results(readme_with(results, ok), doc) == []
    # A figure RESULTS.md does not print, a rounding of one it does, one a longer number contains.
    bad = "| What | `edge` 8.35, AEPE 1.6 px, 4.0 ms, 45 |"
    missing = results.figures_not_in_results(readme_with(results, bad), doc)
    assert missing == ["8.35", "1.6", "4.0", "45"]
    # Figures outside the block are not checked.
    assert results.figures_not_in_results(readme_with(results, ok) + "\n99.99\n", doc) == []


def test_a_readme_without_markers_is_refused_by_name(results: types.ModuleType) -> None:
    with pytest.raises(ValueError, match=r"NOREADME\.md.*headline figures"):
        results.figures_not_in_results("| a | 1.00 |\n", "1.00", Path("NOREADME.md"))
    swapped = f"{results.HEADLINE_END}\n| a |\n{results.HEADLINE_BEGIN}\n"
    with pytest.raises(ValueError, match="headline figures"):
        results.write_headline(swapped, ["| b |"], Path("README.md"))


def test_write_headline_replaces_only_the_block(results: types.ModuleType) -> None:
    readme = readme_with(results, "| old | 1.00 |")
    once = results.write_headline(readme, ["| new | 2.00 |"], Path("README.md"))
    assert "| old |" not in once and "| new | 2.00 |" in once
    assert once.startswith("# Title\n\nbefore 1\n\n") and once.endswith("\n\nafter 2\n")
    assert results.write_headline(once, ["| new | 2.00 |"], Path("README.md")) == once


def write_eval(root: Path, name: str, methods: list[dict]) -> None:
    (root / name).mkdir(parents=True)
    data = {"methods": methods, "frames_evaluated": 80, "figures": []}
    (root / name / "eval.json").write_text(json.dumps(data))


def test_headline_rows_come_from_eval_json_and_say_when_missing(
    results: types.ModuleType, tmp_path: Path
) -> None:
    rows = results.headline_table(tmp_path)
    assert len(rows) == 2 + 7
    # Nothing evaluated: every figure is "–", none invented.
    for row in rows[2:]:
        figure = row.split(" | ")[1]
        assert "–" in figure, row
        assert set(results.NUMBER.findall(figure)) <= {"640", "480", "320", "240"}, row

    def mae(method: str, cm: float) -> dict:
        return {"method": method, "mae_all_cm": cm, "mae_cm": [cm] * 4, "median_seconds": 0.01}

    write_eval(
        tmp_path,
        "clean",
        [
            {**mae("raw-tof", 1.994), "aepe_px": None},
            {**mae("static+classical-filter", 1.89), "aepe_px": 0.0},
            {**mae("edge aligned", 2.0), "aepe_px": 1.0864},
            {**mae("edge", 2.0), "aepe_px": 1.0864},
            {**mae("edge-without-gate aligned", 2.0), "aepe_px": 1.0864},
            mae("edge refine @ true calibration", 1.641),
            mae("edge-without-gate refine @ true calibration", 5.6649),
        ],
    )
    rows = results.headline_table(tmp_path)
    clean = next(r for r in rows if r.startswith("| Clean input"))
    assert "input 1.99 cm, `edge` 1.64, without its multi-path gate 5.66" in clean
    families = rows[-1]
    assert "`clean` 1.09" in families and "`aligned` –" in families and "`wide` –" in families
    # The same figures as RESULTS.md's family tables print them.
    results_md = "\n".join(results.table_families(tmp_path) + results.table_families_aepe(tmp_path))
    block = readme_with(results, "\n".join([clean, families]))
    assert results.figures_not_in_results(block, results_md) == []
