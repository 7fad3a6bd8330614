"""Parity of :mod:`dear_train.geometry` with ``dear-pipeline`` on the shared test vectors.

Every ``fixtures/geometry/*.json`` case written by the Rust side is checked; an unknown case
name fails (a new Rust case must get a Python check, not be ignored). The fixtures are committed,
so a missing or empty directory fails too: a skip would let the two ports drift unnoticed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from dear_train.geometry import (
    DEPTH_EDGE_ABS_M,
    DEPTH_EDGE_REL,
    SPLAT_MIN_COVERAGE,
    SPLAT_MIN_WEIGHT,
    Calibration,
    flow_from_depth,
    rms_residual,
    solve_calibration,
    solve_calibration_robust,
    synthesize_view,
    warp_bilinear,
    warp_depth,
)

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "geometry"
CASES = sorted(FIXTURES.glob("*.json")) if FIXTURES.is_dir() else []
#: How to regenerate the committed fixtures (fixtures/geometry/README.md).
REGENERATE = (
    "regenerate them from the repository root with "
    "`cargo run -p dear-pipeline --example write_geometry_fixtures` "
    "(or restore the committed files: `git checkout fixtures/geometry`)"
)
#: The Rust side's own tolerance for its committed files (relative to max(1, |x|)).
TOL = 1e-5


def arr(spec: dict) -> np.ndarray:
    dtype = {"f32": np.float32, "u8": np.uint8, "bool": np.bool_}[spec["dtype"]]
    data = np.array(spec["data"], dtype=np.float64)
    return data.astype(dtype).reshape(spec["shape"])


def close(got: np.ndarray, want: np.ndarray, what: str, tol: float = TOL) -> None:
    got = np.asarray(got, dtype=np.float64)
    want = np.asarray(want, dtype=np.float64)
    assert got.shape == want.shape, f"{what}: shape {got.shape} vs {want.shape}"
    err = np.abs(got - want) / np.maximum(1.0, np.abs(want))
    i = np.unravel_index(np.argmax(err), err.shape)
    assert err.max() <= tol, f"{what}: max rel err {err.max():.3g} at {i}: {got[i]} vs {want[i]}"


def t4(a: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(a))[None, None]


def flow_t(inputs: dict, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    return torch.from_numpy(np.stack([arr(inputs["flow_u"]), arr(inputs["flow_v"])]))[None].to(
        dtype
    )


def check_params(params: dict) -> None:
    """Thresholds the algorithm depends on must be the ones this port uses."""
    want = {
        "depth_edge_rel": DEPTH_EDGE_REL,
        "depth_edge_abs_m": DEPTH_EDGE_ABS_M,
        "min_weight": SPLAT_MIN_WEIGHT,
        "min_coverage": SPLAT_MIN_COVERAGE,
    }
    for k, v in params.items():
        assert k in want, f"unknown parameter {k} in fixture"
        assert np.float32(v) == np.float32(want[k]), f"{k}: fixture {v}, Python {want[k]}"


def case_warp_depth(inp: dict, out: dict) -> None:
    check_params(inp.get("params", {}))
    got, valid = warp_depth(t4(arr(inp["src"])), flow_t(inp))
    close(got[0, 0].numpy(), arr(out["out"]), "warp_depth.out")
    assert np.array_equal(valid[0, 0].numpy(), arr(out["out"]) > 0)


def case_warp_bilinear(inp: dict, out: dict) -> None:
    got, valid = warp_bilinear(t4(arr(inp["src"])), flow_t(inp))
    close(got[0, 0].numpy(), arr(out["out"]), "warp_bilinear.out")
    assert np.array_equal(valid[0, 0].numpy(), arr(out["valid"])), "warp_bilinear.valid"


def _calib_close(got: torch.Tensor, want: dict, what: str) -> None:
    close(got[0].numpy(), np.array([want["tx"], want["ty"], want["cx"], want["cy"]]), what)


def _lsq_inputs(inp: dict) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    flow = flow_t(inp, torch.float64)
    depth = t4(arr(inp["depth"])).to(torch.float64)
    w = t4(arr(inp["weights"])).to(torch.float64) if "weights" in inp else None
    return flow, depth, w


def case_lsq(inp: dict, out: dict) -> None:
    flow, depth, w = _lsq_inputs(inp)
    calib = solve_calibration(flow, depth, w)
    _calib_close(calib, out["calibration"], "lsq.calibration")
    rms, used = rms_residual(calib, flow, depth, w)
    close(rms.numpy(), np.array([out["rms_residual_px"]]), "lsq.rms_residual_px")
    assert int(used) == out["pixels_used"]


def case_lsq_robust(inp: dict, out: dict) -> None:
    flow, depth, w = _lsq_inputs(inp)
    opts = inp["options"]
    calib = solve_calibration_robust(
        flow, depth, w, huber_delta_px=opts["huber_delta_px"], iterations=opts["iterations"]
    )
    _calib_close(calib, out["calibration"], "lsq_robust.calibration")
    rms, used = rms_residual(calib, flow, depth, None)
    close(rms.numpy(), np.array([out["rms_residual_px"]]), "lsq_robust.rms_residual_px")
    assert int(used) == out["pixels_used"]
    # The robust fit must be closer to the truth than the plain one on this contaminated flow.
    truth = inp["true_calibration"]
    plain = solve_calibration(flow, depth, w)
    t = torch.tensor([[truth["tx"], truth["ty"], truth["cx"], truth["cy"]]], dtype=torch.float64)
    assert (calib - t).abs().sum() < (plain - t).abs().sum()


def case_flow_from_depth(inp: dict, out: dict) -> None:
    c = Calibration.from_dict(inp["calibration"])
    flow, valid = flow_from_depth(c.as_tensor()[None], t4(arr(inp["depth"])))
    close(flow[0, 0].numpy(), arr(out["flow_u"]), "flow_from_depth.flow_u")
    close(flow[0, 1].numpy(), arr(out["flow_v"]), "flow_from_depth.flow_v")
    assert np.array_equal(valid[0, 0].numpy(), arr(out["valid"]))
    u, v, ok = c.flow_at(arr(inp["depth"]))
    close(u, arr(out["flow_u"]), "Calibration.flow_at u")
    close(v, arr(out["flow_v"]), "Calibration.flow_at v")
    assert np.array_equal(ok, arr(out["valid"]))


def case_synthesize_view(inp: dict, out: dict) -> None:
    check_params(inp.get("params", {}))
    view = synthesize_view(
        arr(inp["rgb"]), arr(inp["depth"]), Calibration.from_dict(inp["perturbation"])
    )
    assert np.array_equal(view.valid, arr(out["valid"])), "synthesize_view.valid"
    close(view.depth, arr(out["depth"]), "synthesize_view.depth")
    close(view.flow_u, arr(out["flow_u"]), "synthesize_view.flow_u")
    close(view.flow_v, arr(out["flow_v"]), "synthesize_view.flow_v")
    diff = np.abs(view.rgb.astype(int) - arr(out["rgb"]).astype(int))
    # Colours are rounded from f32 sums; allow one level where a sum lands on .5.
    assert diff.max() <= 1 and (diff > 0).mean() < 0.01, "synthesize_view.rgb"


CHECKS = {
    "warp_depth": case_warp_depth,
    "warp_bilinear": case_warp_bilinear,
    "lsq": case_lsq,
    "lsq_robust": case_lsq_robust,
    "flow_from_depth": case_flow_from_depth,
    "synthesize_view": case_synthesize_view,
}


@pytest.mark.parametrize("path", CASES, ids=[p.stem for p in CASES])
def test_rust_fixture(path: Path) -> None:
    case = json.loads(path.read_text())
    assert case["name"] in CHECKS, f"{path.name}: no Python check for case {case['name']!r}"
    CHECKS[case["name"]](case["inputs"], case["outputs"])


def test_every_documented_case_is_present() -> None:
    """All six documented cases must be committed; with none, the parametrised test above would
    have nothing to check, so their absence is a failure that says how to get them back."""
    assert CASES, f"no Rust geometry fixtures in {FIXTURES}: {REGENERATE}"
    names = {json.loads(p.read_text())["name"] for p in CASES}
    missing = sorted(set(CHECKS) - names)
    assert not missing, f"missing cases {missing} in {FIXTURES}: {REGENERATE}"
