"""``fixtures/kernel_apply/{gated,hybrid,hybrid_replaced}.json`` still are what the Python
definitions compute.

The Rust tail of format-2 bundles is checked against that file
(``pipeline/tests/kernel_apply_parity.rs``); this test fails when the PyTorch definition or the
constants of the gated refiner change without the fixture being regenerated.
"""

from __future__ import annotations

import json
import types
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from dear_train.export import refine_apply_spec
from dear_train.models import build_refine

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "kernel_apply"


def _plane(doc: dict, key: str) -> np.ndarray:
    return np.array(doc[key]["data"], np.float32).reshape(doc[key]["shape"])


def _fixture(
    fixture_maker: Callable[[Path], types.ModuleType], name: str, case: str
) -> tuple[types.ModuleType, dict, dict[str, np.ndarray]]:
    """``make_gated.py``, the fixture ``name`` and the case it was made from (``make.<case>()``),
    whose every input plane the fixture still holds."""
    doc = json.loads((FIXTURE / name).read_text())
    make = fixture_maker(FIXTURE / "make_gated.py")
    c = getattr(make, case)()
    for k, v in c.items():
        np.testing.assert_array_equal(np.array(doc[k]["data"], np.float32), v.ravel())
    return make, doc, c


def test_fixture_matches_the_python_definition(
    fixture_maker: Callable[[Path], types.ModuleType],
) -> None:
    make, doc, c = _fixture(fixture_maker, "gated.json", "case")
    np.testing.assert_allclose(make.expected(c["depth"], c["maps"]), _plane(doc, "out"), atol=1e-6)


def test_fixture_constants_are_the_exported_ones() -> None:
    apply = refine_apply_spec(build_refine("edge", "gated"))
    assert apply is not None
    doc = json.loads((FIXTURE / "gated.json").read_text())
    assert apply["stride"] == doc["stride"]
    # The Rust test hard-codes these two; the exporter writes them into model.json.
    assert (apply["max_bias"], apply["range_scale"]) == (0.05, 100.0)


def test_hybrid_fixture_matches_the_python_definition(
    fixture_maker: Callable[[Path], types.ModuleType],
) -> None:
    make, doc, c = _fixture(fixture_maker, "hybrid.json", "hybrid_case")
    got = make.expected_hybrid(c["depth"], c["classical"], c["maps"])
    np.testing.assert_allclose(got, _plane(doc, "out"), atol=1e-6)
    apply = refine_apply_spec(build_refine("edge", "hybrid"))
    assert apply is not None
    # The Rust test hard-codes these; the exporter writes them into model.json.
    assert (apply["max_bias"], apply["range_scale"], apply["jump_scale"]) == (0.05, 100.0, 300.0)


def test_guarded_fixture_matches_the_python_definition(
    fixture_maker: Callable[[Path], types.ModuleType],
) -> None:
    make, doc, c = _fixture(fixture_maker, "guarded.json", "guarded_case")
    out, log_err = make.expected_guarded(c["depth"], c["classical"], c["maps"])
    np.testing.assert_allclose(out, _plane(doc, "out"), atol=1e-6)
    want_err = _plane(doc, "log_error")
    finite = want_err < 1e29
    assert np.all(np.isinf(log_err[~finite])) and np.any(~finite)
    np.testing.assert_allclose(log_err[finite], want_err[finite], atol=1e-6)
    apply = refine_apply_spec(build_refine("edge", "guarded"))
    assert apply is not None
    # The Rust test hard-codes these; the exporter writes them into model.json.
    assert (apply["jump_scale"], apply["error_unit"], apply["log_error_bound"]) == (
        300.0,
        1e-3,
        6.0,
    )
    assert apply["channels"] == 16 and apply["kind"] == "guarded-kernel"


def test_hybrid_replaced_fixture_matches_the_python_definition(
    fixture_maker: Callable[[Path], types.ModuleType],
) -> None:
    make, doc, c = _fixture(fixture_maker, "hybrid_replaced.json", "hybrid_replaced_case")
    want = _plane(doc, "out")
    got = make.expected_hybrid(c["depth"], c["classical"], c["maps"], c["classical_confidence"])
    np.testing.assert_allclose(got, want, atol=1e-6)
    # The restriction matters in this case: the jump everywhere gives another output.
    everywhere = make.expected_hybrid(c["depth"], c["classical"], c["maps"])
    assert (np.abs(everywhere - want) > 0.1).sum() > 5
    # The exporter writes the key the Rust tail reads, and refuses what it does not know.
    apply = refine_apply_spec(build_refine("edge", "hybrid"), "replaced")
    assert apply is not None and apply["jump_on"] == "replaced"
    with pytest.raises(ValueError, match="jump_on 'smoothed'"):
        refine_apply_spec(build_refine("edge", "hybrid"), "smoothed")
