"""The Python capture reader and writer against the fixtures both languages check
(``fixtures/capture/README.md``; the Rust side is ``capture/tests/cross_language.rs``): Python
reads ``samples/demo`` (written by the Rust simulator) as ``demo_digest.json`` says, writes
``python_written/`` byte for byte as committed (the Rust test reads it back), and refuses every
manifest of ``bad_manifests.json``, by the part of the reader the file names.
"""

from __future__ import annotations

import copy
import filecmp
import json
import types
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from dear_train.data import capture as cap
from dear_train.data.capture import Capture, CaptureError

REPO = Path(__file__).resolve().parents[2]
FIXTURES = REPO / "fixtures" / "capture"


@pytest.fixture(scope="module")
def maker(fixture_maker: Callable[[Path], types.ModuleType]) -> types.ModuleType:
    return fixture_maker(FIXTURES / "make_capture_fixtures.py")


def load(name: str) -> dict:
    return json.loads((FIXTURES / name).read_text())


def depth_units(depth: np.ndarray, scale: float) -> np.ndarray:
    """The stored units of a depth the reader gave in metres, which must be exactly
    ``units · depth_scale`` in float32 (the format's definition, the Rust reader's too)."""
    units = np.round(depth / np.float32(scale)).astype(np.int64)
    assert units.min() >= 0 and units.max() <= 65535
    np.testing.assert_array_equal(units.astype(np.float32) * np.float32(scale), depth)
    return units


def whole(values: np.ndarray) -> np.ndarray:
    assert np.all(values == np.round(values)), "not whole numbers"
    return values.astype(np.int64)


def stored_planes(f: cap.Frame, scale: float) -> dict[str, np.ndarray | None]:
    """The frame's planes as the integers stored, under the fixtures' names (None: no file)."""
    return {
        "rgb": f.rgb,
        "amplitude": whole(f.amplitude),
        "depth_units": depth_units(f.depth, scale),
        "gt_depth_units": None if f.gt_depth is None else depth_units(f.gt_depth, scale),
        "mask": f.mask,
    }


def check_entry(f: cap.Frame, want: dict) -> None:
    assert (f.id, f.timestamp_ns) == (want["id"], want["timestamp_ns"])
    assert (f.perturbation and f.perturbation.to_dict()) == want["perturbation"]


def check_manifest(m: cap.Manifest, want: dict) -> None:
    assert (m.width, m.height) == (want["width"], want["height"])
    assert vars(m.intrinsics) == want["intrinsics"]
    assert m.initial_calibration.to_dict() == want["initial_calibration"]
    assert m.depth_scale == want["depth_scale"]
    assert m.modulation_frequencies_hz == want["modulation_frequencies_hz"]


def test_the_committed_fixtures_are_what_the_generator_writes(
    maker: types.ModuleType, tmp_path: Path
) -> None:
    for name, doc in [
        ("demo_digest.json", maker.demo_digest()),
        ("python_written.json", maker.python_written_values()),
        ("bad_manifests.json", maker.bad_manifests()),
    ]:
        maker.write_json(tmp_path / name, doc)
        assert (tmp_path / name).read_bytes() == (FIXTURES / name).read_bytes(), (
            f"{name} differs: .venv/bin/python fixtures/capture/make_capture_fixtures.py"
        )


def test_python_writes_the_committed_capture_byte_for_byte(
    maker: types.ModuleType, tmp_path: Path
) -> None:
    written = maker.write_python_capture(tmp_path / "capture")
    committed = FIXTURES / "python_written"
    names = sorted(p.relative_to(committed) for p in committed.rglob("*") if p.is_file())
    assert sorted(p.relative_to(written) for p in written.rglob("*") if p.is_file()) == names
    for name in names:
        assert filecmp.cmp(written / name, committed / name, shallow=False), name


def test_python_reads_samples_demo_as_the_digest_says(maker: types.ModuleType) -> None:
    want = load("demo_digest.json")
    capture = Capture(REPO / "samples" / "demo")
    check_manifest(capture.manifest, want["manifest"])
    assert len(capture) == len(want["frames"])
    h, w = capture.size
    scale = capture.manifest.depth_scale
    for i, fw in enumerate(want["frames"]):
        f = capture.load(i)
        check_entry(f, fw)
        assert (f.flow is not None) == fw["has_flow"]
        assert f.rgb.shape == (h, w, 3) and f.depth.shape == (h, w)
        for name, plane in stored_planes(f, scale).items():
            digest = None if plane is None else maker.plane_digest(plane)
            assert digest == fw[name], f"frame {f.id}: {name}"


def test_python_reads_what_it_wrote_value_for_value() -> None:
    want = load("python_written.json")
    capture = Capture(FIXTURES / "python_written")
    check_manifest(capture.manifest, want["manifest"])
    assert capture.manifest.source == want["manifest"]["source"]
    scale = capture.manifest.depth_scale
    for i, fw in enumerate(want["frames"]):
        f = capture.load(i)
        check_entry(f, fw)
        got = {
            **stored_planes(f, scale),
            "flow_u": None if f.flow is None else f.flow[0],
            "flow_v": None if f.flow is None else f.flow[1],
        }
        for name, plane in got.items():
            flat = None if plane is None else np.asarray(plane).ravel().tolist()
            assert flat == fw[name], f"frame {f.id}: {name}"


def bad_manifest_text(base: str, case: dict) -> str:
    """``case``'s edit of ``base``, as the Rust test applies it."""
    if "text" in case:
        return case["text"]
    doc = json.loads(base)
    for pointer, value in case.get("set", {}).items():
        parent, key = pointer.rsplit("/", 1)
        target = doc
        for part in parent.split("/")[1:]:
            target = target[int(part) if isinstance(target, list) else part]
        target[int(key) if isinstance(target, list) else key] = copy.deepcopy(value)
    for pointer in case.get("remove", []):
        parent, key = pointer.rsplit("/", 1)
        target = doc
        for part in parent.split("/")[1:]:
            target = target[part]
        del target[key]
    return json.dumps(doc, indent=2)


BAD = load("bad_manifests.json")


@pytest.mark.parametrize("case", BAD["cases"], ids=[c["name"] for c in BAD["cases"]])
def test_python_refuses_the_bad_manifest_naming_the_field(case: dict, tmp_path: Path) -> None:
    base = (FIXTURES / BAD["base"]).read_text()
    text = bad_manifest_text(base, case)
    assert text.strip() != base.strip()
    (tmp_path / "capture.json").write_text(text)
    with pytest.raises(CaptureError) as refused:
        Capture(tmp_path)
    msg = str(refused.value)
    assert str(tmp_path / "capture.json") in msg
    for word in case["expect"]:
        assert word in msg, msg
    # The part of the reader the fixture names is the one that refuses it: the schema generated
    # from the Rust types carries the rule, or (only) the checks a schema cannot express do.
    if case["refused_by"] == "parser":
        return
    doc = json.loads(text)
    schema_errors = list(cap._validator().iter_errors(doc))
    assert bool(schema_errors) == (case["refused_by"] == "schema"), schema_errors
