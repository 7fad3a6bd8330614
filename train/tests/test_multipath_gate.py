"""The multi-path gate (issue 33): its scaling of the hybrid maps, its composition into a
bundle's refine graph, its labels and a training run."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import onnxruntime as ort
import pytest
import torch

from dear_train import gate as cli
from dear_train.data.capture import Capture, CaptureError
from dear_train.data.synthetic import write_synthetic_capture
from dear_train.export import export_bundle
from dear_train.geometry import Calibration
from dear_train.models.multipath_gate import (
    BIAS_CHANNEL,
    EPS,
    GATE_CHANNEL,
    SMOOTHING_FLOOR,
    TRUST_CHANNEL,
    MultipathGate,
    gate_maps,
)
from dear_train.training.checkpoint import build_model
from dear_train.training.config import get_profile


def test_an_open_gate_keeps_the_maps_and_a_closed_one_stops_the_correction() -> None:
    maps = torch.randn(2, 13, 6, 8) * 2
    opened = gate_maps(maps, torch.ones(2, 1, 1, 1))
    # What the daemon's tail computes from the maps is unchanged (the logits themselves are
    # not, where tanh saturates in float32).
    for channel, f in ((BIAS_CHANNEL, torch.tanh), (GATE_CHANNEL, torch.sigmoid)):
        assert torch.allclose(f(opened[:, channel]), f(maps[:, channel]), atol=2e-6)
    assert torch.equal(opened[:, TRUST_CHANNEL], maps[:, TRUST_CHANNEL])
    closed = gate_maps(maps, torch.zeros(2, 1, 1, 1))
    # No bias, a little of the smoothing, and the classical estimate only where it finds a
    # jump.
    assert torch.tanh(closed[:, BIAS_CHANNEL]).abs().max() <= 2 * EPS
    assert torch.allclose(
        torch.sigmoid(closed[:, GATE_CHANNEL]),
        SMOOTHING_FLOOR * torch.sigmoid(maps[:, GATE_CHANNEL]),
        atol=1e-5,
    )
    shift = closed[:, TRUST_CHANNEL] - maps[:, TRUST_CHANNEL]
    assert torch.allclose(shift, torch.full_like(shift, 2 * float(np.log(EPS))), atol=1e-4)
    untouched = [c for c in range(13) if c not in (BIAS_CHANNEL, GATE_CHANNEL, TRUST_CHANNEL)]
    assert torch.equal(closed[:, untouched], maps[:, untouched])
    # In between: the bias scales with p, the smoothing from its floor up.
    half = gate_maps(maps, torch.full((2, 1, 1, 1), 0.5))
    assert torch.allclose(
        torch.tanh(half[:, BIAS_CHANNEL]), 0.5 * torch.tanh(maps[:, BIAS_CHANNEL]), atol=1e-5
    )
    assert torch.allclose(
        torch.sigmoid(half[:, GATE_CHANNEL]),
        (SMOOTHING_FLOOR + 0.5 * (1 - SMOOTHING_FLOOR)) * torch.sigmoid(maps[:, GATE_CHANNEL]),
        atol=1e-5,
    )


def fails(capsys: pytest.CaptureFixture[str], argv: list[str], message: str) -> None:
    """`dear-gate argv` exits with status 2 and an error naming `message`, no traceback."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        cli.main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("dear-gate: error: ") and message in err, err


def hybrid_bundle(tmp_path: Path, variant: str = "hybrid") -> Path:
    profile = get_profile("smoke", variant=variant)
    out = tmp_path / f"bundle-{variant}"
    export_bundle(build_model(profile).eval(), profile, out, macs_at=None)
    return out


def saved_gate(tmp_path: Path) -> tuple[Path, MultipathGate]:
    torch.manual_seed(1)
    gate = MultipathGate(width=8)
    # Not the identity: random batch-norm statistics, so that p differs between frames.
    for m in gate.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
    path = tmp_path / "run" / "gate.pt"
    path.parent.mkdir()
    torch.save({"width": 8, "state": gate.state_dict(), "history": []}, path)
    return path, gate.eval()


def refine_feed(seed: int) -> dict[str, np.ndarray]:
    """Random inputs of a hybrid refine graph at 64 × 96, the classical plane 1 cm off."""
    rng = np.random.default_rng(seed)
    feed = {
        "amplitude": rng.random((1, 1, 64, 96), dtype=np.float32),
        "depth": (1 + 3 * rng.random((1, 1, 64, 96))).astype(np.float32),
        "rgb": rng.random((1, 3, 64, 96), dtype=np.float32),
    }
    feed["classical"] = feed["depth"] + np.float32(0.01)
    return feed


def session(path: Path) -> ort.InferenceSession:
    return ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])


def test_attach_puts_the_gate_into_the_refine_graph(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bundle = hybrid_bundle(tmp_path)
    before = json.loads((bundle / "model.json").read_text())
    original = tmp_path / "refine-before.onnx"
    shutil.copy(bundle / "refine.onnx", original)
    path, gate = saved_gate(tmp_path)
    cli.main(["attach", "--bundle", str(bundle), "--gate", str(path)])
    after = json.loads((bundle / "model.json").read_text())
    entry = after["graphs"]["refine"]
    assert entry["sha256"] == cli.sha256(bundle / "refine.onnx")
    assert entry["sha256"] != before["graphs"]["refine"]["sha256"]
    assert entry["inputs"] == before["graphs"]["refine"]["inputs"]
    assert after["multipath_gate"]["params"] == sum(p.numel() for p in gate.parameters())
    assert after["graphs"]["flow"] == before["graphs"]["flow"]
    # The composed graph: the same inputs and output names, the maps gated by the frame's p.
    feed = refine_feed(5)
    composed = session(bundle / "refine.onnx")
    assert [o.name for o in composed.get_outputs()] == [
        o["name"] for o in before["graphs"]["refine"]["outputs"]
    ]
    (maps,) = session(original).run(None, feed)
    (got,) = composed.run(None, feed)
    with torch.no_grad():
        p = gate(torch.from_numpy(feed["amplitude"]), torch.from_numpy(feed["depth"]))
        want = gate_maps(torch.from_numpy(maps), p).numpy()
    assert 0.0 < float(p) < 1.0
    assert np.abs(got - want).max() < 1e-4
    assert np.abs(got - maps).max() > 1e-3, "the gate changed nothing"
    fails(
        capsys,
        ["attach", "--bundle", str(bundle), "--gate", str(path)],
        "already has a multi-path gate",
    )
    # Taken out again: the refiner's own maps, bit for bit, and the manifest says so.
    without = tmp_path / "without"
    cli.main(["detach", "--bundle", str(bundle), "--out", str(without)])
    (back,) = session(without / "refine.onnx").run(None, feed)
    assert np.array_equal(back, maps)
    detached = json.loads((without / "model.json").read_text())
    assert "multipath_gate" not in detached
    assert detached["graphs"]["refine"]["params"] == before["graphs"]["refine"]["params"]
    assert detached["graphs"]["refine"]["outputs"] == before["graphs"]["refine"]["outputs"]
    assert detached["graphs"]["refine"]["sha256"] == cli.sha256(without / "refine.onnx")
    fails(
        capsys,
        ["detach", "--bundle", str(without), "--out", str(tmp_path / "again")],
        "no multi-path gate",
    )


def test_a_retrained_refiner_takes_the_gate_another_bundle_ships_with(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    donor = hybrid_bundle(tmp_path)
    path, gate = saved_gate(tmp_path)
    cli.main(["attach", "--bundle", str(donor), "--gate", str(path)])
    (tmp_path / "retrained").mkdir()
    torch.manual_seed(7)  # other refiner weights than the donor's
    bundle = hybrid_bundle(tmp_path / "retrained")
    original = tmp_path / "retrained-ungated.onnx"
    shutil.copy(bundle / "refine.onnx", original)
    cli.main(["attach", "--bundle", str(bundle), "--gate-from", str(donor)])
    manifest = json.loads((bundle / "model.json").read_text())
    donor_manifest = json.loads((donor / "model.json").read_text())
    assert manifest["multipath_gate"]["copied_from"] == str(donor)
    assert manifest["multipath_gate"]["params"] == donor_manifest["multipath_gate"]["params"]
    assert manifest["graphs"]["refine"]["sha256"] == cli.sha256(bundle / "refine.onnx")
    # The retrained refiner's own maps, gated by the donor's gate as PyTorch computes it.
    feed = refine_feed(6)
    (maps,) = session(original).run(None, feed)
    (donor_maps,) = session(donor / "refine.onnx").run(None, feed)
    (got,) = session(bundle / "refine.onnx").run(None, feed)
    with torch.no_grad():
        p = gate(torch.from_numpy(feed["amplitude"]), torch.from_numpy(feed["depth"]))
        want = gate_maps(torch.from_numpy(maps), p).numpy()
    assert np.abs(got - want).max() < 1e-4
    assert np.abs(got - donor_maps).max() > 1e-3, "the donor's refiner came along"
    # Taken out again: the retrained refiner, bit for bit.
    cli.main(["detach", "--bundle", str(bundle), "--out", str(tmp_path / "again")])
    (back,) = session(tmp_path / "again" / "refine.onnx").run(None, feed)
    assert np.array_equal(back, maps)
    # A donor without a gate, and a bundle that already has one, are named.
    fails(
        capsys,
        ["attach", "--bundle", str(tmp_path / "again"), "--gate-from", str(tmp_path / "again")],
        "no multi-path gate to copy",
    )
    fails(
        capsys,
        ["attach", "--bundle", str(bundle), "--gate-from", str(donor)],
        "already has a multi-path gate",
    )


def test_attach_refuses_a_refiner_without_a_bias_map(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bundle = hybrid_bundle(tmp_path, variant="kpn")
    path, _ = saved_gate(tmp_path)
    fails(capsys, ["attach", "--bundle", str(bundle), "--gate", str(path)], "hybrid")
    hybrid = hybrid_bundle(tmp_path)
    missing = str(tmp_path / "none.pt")
    fails(capsys, ["attach", "--bundle", str(hybrid), "--gate", missing], "none.pt")


def labelled_capture(root: Path, bounces: int | None, seed: int) -> Path:
    """Aligned frames, as `dear-synth family` renders them, labelled as its shards are."""
    write_synthetic_capture(root, frames=4, seed=seed, misaligned_fraction=0.0)
    path = root / "capture.json"
    doc = json.loads(path.read_text())
    if bounces is not None:
        doc["source"]["details"] = {"params": {"sim": {"render": {"max_bounces": bounces}}}}
    path.write_text(json.dumps(doc))
    return root


def test_labels_come_from_the_simulation_and_a_capture_without_one_is_named(
    tmp_path: Path,
) -> None:
    assert cli.shard_label(labelled_capture(tmp_path / "a", 3, 1)) == 1.0
    assert cli.shard_label(labelled_capture(tmp_path / "b", 1, 2)) == 0.0
    unknown = labelled_capture(tmp_path / "c", None, 3)
    with pytest.raises(CaptureError, match=str(unknown / "capture.json")):
        cli.shard_label(unknown)


def test_training_writes_a_gate_that_attach_and_score_take(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = [
        labelled_capture(tmp_path / "mpi", 3, 1),
        labelled_capture(tmp_path / "clean", 1, 2),
    ]
    out = tmp_path / "run"
    train = ["train", "--data", *map(str, data), "--val", str(data[0]), "--out", str(out)]
    cli.main([*train, "--epochs", "2", "--batch", "4", "--width", "8"])
    ckpt = torch.load(out / "gate.pt", weights_only=True)
    assert len(ckpt["history"]) == 2 and "val_accuracy" in ckpt["history"][0]
    assert ckpt["recipe"]["data"] == {"captures": 2, "directories": [tmp_path.name]}
    cli.main(["score", "--gate", str(out / "gate.pt"), "--data", str(data[1])])
    assert "4 frames" in capsys.readouterr().out
    bundle = hybrid_bundle(tmp_path)
    cli.main(["attach", "--bundle", str(bundle), "--gate", str(out / "gate.pt")])
    assert (
        json.loads((bundle / "model.json").read_text())["multipath_gate"]["recipe"]["epochs"] == 2
    )


def test_warped_copies_move_the_frame_into_an_rgb_view_and_need_aligned_frames(
    tmp_path: Path,
) -> None:
    root = labelled_capture(tmp_path / "aligned", 3, 4)
    aligned = cli.capture_grids(root)
    grids = cli.capture_grids(root, 2, np.random.default_rng(0))
    # Every frame as it is, then two warped copies of each.
    assert grids.shape == (3 * len(aligned), *aligned.shape[1:])
    assert torch.equal(grids[: len(aligned)], aligned)
    capture = Capture(root)
    # The identity view is the frame itself; a view drawn by the augmentation moves it.
    frame = capture.load(0)
    identity = cli.warped_inputs(frame, *cli.refine_inputs(frame), Calibration(), "frame 0")
    assert torch.allclose(cli.on_grid(*identity), aligned[0], atol=1e-6)
    for copy in grids[len(aligned) :: len(aligned)]:
        assert (copy - aligned[0]).abs().max() > 1e-3
    misaligned = tmp_path / "misaligned"
    write_synthetic_capture(misaligned, frames=2, seed=5, misaligned_fraction=1.0)
    with pytest.raises(CaptureError, match=f"{misaligned}: frame 0: a warped copy needs"):
        cli.capture_grids(misaligned, 1, np.random.default_rng(0))
