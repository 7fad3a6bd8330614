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

from dear_train.export import export_bundle, export_refine_into
from dear_train.training.checkpoint import build_model
from dear_train.training.config import Profile, get_profile


def random_refine_inputs(
    seed: int, h: int, w: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Random ``refine.onnx`` inputs of one ``h``×``w`` frame: amplitude, depth (1–4 m), RGB
    and a classical estimate 1 cm behind the depth."""
    rng = np.random.default_rng(seed)
    amp = rng.random((1, 1, h, w), dtype=np.float32)
    depth = (1 + 3 * rng.random((1, 1, h, w))).astype(np.float32)
    rgb = rng.random((1, 3, h, w), dtype=np.float32)
    return amp, depth, rgb, (depth + 0.01).astype(np.float32)


@pytest.mark.parametrize("variant", ["kpn", "norgb", "gated", "hybrid"])
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
    maps = variant in ("gated", "hybrid")
    assert on_disk["format_version"] == (2 if maps else 1)
    assert on_disk["tier"] == "edge"
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
    hybrid = variant == "hybrid"
    assert refine_inputs == ["amplitude", "depth"] + (["rgb"] if with_rgb else []) + (
        ["classical"] if hybrid else []
    )

    # Independently of export_bundle's own check: refine.onnx takes and returns metres.
    sess = ort.InferenceSession(str(out / "refine.onnx"), providers=["CPUExecutionProvider"])
    amp, depth, rgb, classical = random_refine_inputs(5, 40, 48)
    feed = (
        {"amplitude": amp, "depth": depth}
        | ({"rgb": rgb} if with_rgb else {})
        | ({"classical": classical} if hybrid else {})
    )
    (got,) = sess.run(None, feed)
    with torch.no_grad():
        args = [torch.from_numpy(x) for x in (amp, depth / 10)]
        rgb_t = torch.from_numpy(rgb) if with_rgb else None
        if maps:
            # Format 2: the graph outputs the head's maps at 1/4; the daemon applies them.
            apply = on_disk["graphs"]["refine"]["apply"]
            assert apply["kind"] == ("hybrid-kernel" if hybrid else "gated-kernel")
            assert apply["stride"] == 4
            assert ("jump_scale" in apply) == hybrid
            c_t = torch.from_numpy(classical / 10) if hybrid else None
            want = model.refine.head_maps(*args, rgb_t, c_t)
            assert got.shape == (1, 13 if hybrid else 12, 10, 12)
        else:
            assert "apply" not in on_disk["graphs"]["refine"]
            want = model.refine(*args, rgb_t) * 10
            assert abs(float(np.median(got)) - float(np.median(depth))) < 0.2  # near-identity
    np.testing.assert_allclose(got, want.numpy(), atol=1e-4)


def test_refine_only_export_replaces_just_the_refiner(tmp_path: Path) -> None:
    """A refine-only run goes into an existing bundle: flow graphs and their records stay."""
    base = get_profile("smoke")
    out = tmp_path / "bundle"
    export_bundle(build_model(base).eval(), base, out, {"validation": {"aepe": 2.0}}, macs_at=None)
    before = json.loads((out / "model.json").read_text())
    flow_bytes = (out / "flow.onnx").read_bytes()

    gated = get_profile("smoke", variant="gated")
    manifest = export_refine_into(
        build_model(gated).eval(), gated, out, {"validation": {"mae": 1.0}}, macs_at=None
    )
    on_disk = json.loads((out / "model.json").read_text())
    assert on_disk == json.loads(json.dumps(manifest))
    assert on_disk["variant"] == "gated"
    assert on_disk["graphs"]["flow"] == before["graphs"]["flow"]
    assert on_disk["graphs"]["fuse"] == before["graphs"]["fuse"]
    assert (out / "flow.onnx").read_bytes() == flow_bytes
    refine = on_disk["graphs"]["refine"]
    assert refine["sha256"] == hashlib.sha256((out / "refine.onnx").read_bytes()).hexdigest()
    assert refine["sha256"] != before["graphs"]["refine"]["sha256"]
    assert on_disk["validation"]["aepe"] == 2.0 and on_disk["validation"]["refine"] == {"mae": 1.0}
    assert on_disk["training"]["refine"]["profile"]["variant"] == "gated"


def test_refine_only_export_refuses_another_normalisation(tmp_path: Path) -> None:
    base = get_profile("smoke")
    out = tmp_path / "bundle"
    export_bundle(build_model(base).eval(), base, out, macs_at=None, check=False)
    from dear_train.data.dataset import Normalisation

    other = get_profile("smoke", variant="gated", norm=Normalisation(max_depth=8.0))
    with pytest.raises(ValueError, match="normalisation"):
        export_refine_into(build_model(other).eval(), other, out, check=False, macs_at=None)


def test_recipe_record_says_how_far_a_stopped_run_got() -> None:
    from dear_train.export import recipe_record

    history = [{"epoch": e, "val": {"mae": 10.0 - e}} for e in range(3)]
    stopped = recipe_record({"data": ["d"], "history": history})
    assert stopped["training"]["epochs_trained"] == 3
    assert stopped["training"]["from"].startswith("last.pt")
    assert stopped["validation"] == {"mae": 8.0}
    final = recipe_record({"data": ["d"], "frames": {"train": 9}, "metrics": {"mae": 1.0}})
    assert final["training"] == {
        "data": ["d"],
        "frames": {"train": 9},
        "epochs_trained": 0,
        "from": "final.pt",
    }
    assert final["validation"] == {"mae": 1.0}


def test_refiner_with_frame_level_context_exports_and_matches_onnxruntime(tmp_path: Path) -> None:
    """The context branch (a mean over the whole frame) exports to plain ONNX ops the daemon's
    runtime takes, and the graph agrees with PyTorch at another size than the export's."""
    profile = get_profile("smoke", variant="guarded", refine_context=True)
    model = build_model(profile).eval()
    assert model.refine is not None
    context = model.refine.backbone.context
    assert context is not None
    with torch.no_grad():  # a branch that does something (it starts at zero)
        for p in context.parameters():
            p.normal_(0, 0.3)
    out = tmp_path / "bundle"
    export_bundle(model, profile, out, {}, macs_at=None)
    ops = {n.op_type for n in onnx.load(str(out / "refine.onnx")).graph.node}
    assert "ReduceMean" in ops or "GlobalAveragePool" in ops
    sess = ort.InferenceSession(str(out / "refine.onnx"), providers=["CPUExecutionProvider"])
    amp, depth, rgb, classical = random_refine_inputs(9, 56, 72)
    (got,) = sess.run(None, {"amplitude": amp, "depth": depth, "rgb": rgb, "classical": classical})
    with torch.no_grad():
        want = model.refine.head_maps(
            torch.from_numpy(amp),
            torch.from_numpy(depth / 10),
            torch.from_numpy(rgb),
            torch.from_numpy(classical / 10),
        )
    np.testing.assert_allclose(got, want.numpy(), atol=1e-4)


def test_a_refiner_with_other_widths_is_rebuilt_from_its_recorded_profile(tmp_path: Path) -> None:
    """``refine_widths`` travels in the profile a checkpoint records, so an export rebuilds the
    same net, and the graph it writes carries those widths."""
    profile = get_profile("smoke", variant="hybrid", refine_widths=(8, 16, 24, 40))
    again = Profile.from_dict(json.loads(json.dumps(profile.to_dict())))
    assert again == profile
    model = build_model(again).eval()
    assert model.refine is not None
    state = model.refine.state_dict()
    assert tuple(state["backbone.enc3.0.1.weight"].shape) == (40, 24, 1, 1)
    assert (
        build_model(get_profile("smoke", variant="hybrid"))
        .refine.state_dict()["backbone.enc3.0.1.weight"]
        .shape
        != state["backbone.enc3.0.1.weight"].shape
    )
    out = tmp_path / "bundle"
    export_bundle(model, again, out, {}, macs_at=None)
    inits = {i.name: list(i.dims) for i in onnx.load(str(out / "refine.onnx")).graph.initializer}
    assert inits["net.backbone.enc3.0.1.weight"] == [40, 24, 1, 1]
    with pytest.raises(ValueError, match="edge tier only"):
        build_model(get_profile("smoke", tier="paper", refine_widths=(8, 16, 24, 40)))
