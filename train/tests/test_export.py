"""ONNX export: graphs match PyTorch, are self-contained, and the manifest is honest."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from dear_train.export import export_bundle
from dear_train.training.checkpoint import build_model
from dear_train.training.config import get_profile


@pytest.mark.parametrize("variant", ["kpn", "norgb"])
def test_edge_bundle_round_trip(tmp_path: Path, variant: str) -> None:
    profile = get_profile("smoke", variant=variant)
    model = build_model(profile).eval()
    out = tmp_path / "bundle"
    manifest = export_bundle(model, profile, out, {"validation": {"x": 1.0}}, macs_at=None)
    assert sorted(p.name for p in out.iterdir()) == [
        "flow.onnx",
        "fuse.onnx",
        "model.json",
        "refine.onnx",
    ]  # one file per graph: no external .onnx.data
    on_disk = json.loads((out / "model.json").read_text())
    assert on_disk == json.loads(json.dumps(manifest))
    assert on_disk["format_version"] == 1 and on_disk["tier"] == "edge"
    assert on_disk["normalisation"]["max_depth_m"] == 10.0
    assert on_disk["validation"] == {"x": 1.0}
    for name, g in on_disk["graphs"].items():
        path = out / g["file"]
        assert hashlib.sha256(path.read_bytes()).hexdigest() == g["sha256"], name
        assert g["check"]["max_abs_diff"] <= 1e-4, name
        graph = onnx.load(str(path))
        assert "GridSample" not in {n.op_type for n in graph.graph.node}
        assert graph.opset_import[0].version == 17
        assert [i.name for i in graph.graph.input] == [i["name"] for i in g["inputs"]]
    refine_inputs = [i["name"] for i in on_disk["graphs"]["refine"]["inputs"]]
    with_rgb = variant != "norgb"
    assert refine_inputs == ["amplitude", "depth"] + (["rgb"] if with_rgb else [])

    # Independently of export_bundle's own check: refine.onnx takes and returns metres.
    sess = ort.InferenceSession(str(out / "refine.onnx"), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(5)
    amp = rng.random((1, 1, 40, 48), dtype=np.float32)
    depth = (1 + 3 * rng.random((1, 1, 40, 48))).astype(np.float32)
    rgb = rng.random((1, 3, 40, 48), dtype=np.float32)
    feed = {"amplitude": amp, "depth": depth} | ({"rgb": rgb} if with_rgb else {})
    (got,) = sess.run(None, feed)
    with torch.no_grad():
        args = [torch.from_numpy(x) for x in (amp, depth / 10)]
        want = model.refine(*args, torch.from_numpy(rgb) if with_rgb else None) * 10
    np.testing.assert_allclose(got, want.numpy(), atol=1e-4)
    assert abs(float(np.median(got)) - float(np.median(depth))) < 0.2  # near-identity at init
