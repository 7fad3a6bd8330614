"""``dear-gate``: train the multi-path gate and put it into a bundle's refine graph (issue 33).

::

    dear-gate train --data DATA/gate-train/shard-* --val DATA/gate-val/shard-* --out runs/gate
    dear-gate attach --bundle models/edge --gate runs/gate/gate.pt
    dear-gate attach --bundle runs/retrained-bundle --gate-from models/edge
    dear-gate score --gate runs/gate/gate.pt --data MY_RECORDING
    dear-gate detach --bundle models/edge --out edge-without-gate

``train`` fits :class:`~dear_train.models.multipath_gate.MultipathGate` to tell frames with
multi-path from frames without, on rendered family shards (``dear-synth family``): the label
of a shard is whether its simulation rendered indirect light (``max_bounces > 1`` in its
``capture.json``). ``attach`` appends the gate to the bundle's hybrid refine graph
(:func:`compose`), checks the result against onnxruntime and PyTorch, and records the gate in
``model.json``; the refiner's own weights are not touched. ``attach --gate-from`` takes the
gate out of another bundle's refine graph instead of a checkpoint (a retrained refiner keeps the
gate it shipped with).
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import onnx
import torch
import torch.nn.functional as F

from dear_train.augmentation import AugmentConfig, augment, draw_perturbation
from dear_train.data.capture import Capture, CaptureError, Frame
from dear_train.data.dataset import Normalisation, normalize_amplitude
from dear_train.export import CHECK_ATOL, OPSET, check_inputs, sha256
from dear_train.geometry import Calibration, warp_bilinear_np, warp_depth_np
from dear_train.models import param_count
from dear_train.models.multipath_gate import (
    BIAS_CHANNEL,
    GATE_CHANNEL,
    GRID,
    SMOOTHING_FLOOR,
    GateOnMaps,
    MultipathGate,
    pool_inputs,
)

#: Prefix of the gate's tensor names inside the composed refine graph.
PREFIX = "multipath_gate/"
#: The refiner's own maps inside the composed graph (the gate's input).
UNGATED = PREFIX + "ungated_maps"
#: What `attach` adds to the refine output's meaning in `model.json`.
MEANING_SUFFIX = (
    "; bias, gate and trust already scaled by the frame's multi-path probability "
    "(model.json multipath_gate)"
)


def shard_label(root: Path) -> float:
    """1 when the capture's simulation rendered indirect light (multi-path), else 0."""
    path = root / "capture.json"
    doc = json.loads(path.read_text())
    try:
        bounces = doc["source"]["details"]["params"]["sim"]["render"]["max_bounces"]
    except (KeyError, TypeError) as e:
        raise CaptureError(
            f"{path}: no source.details.params.sim.render.max_bounces: the gate trains on "
            "captures rendered by `dear-synth family` or `generate`, whose label it is"
        ) from e
    if not isinstance(bounces, int) or bounces < 1:
        raise CaptureError(f"{path}: max_bounces {bounces!r} is not a positive integer")
    return 1.0 if bounces > 1 else 0.0


def refine_inputs(frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """``(amplitude, depth)`` of ``frame`` as the refine graph gets them before the warp: the
    bundles' amplitude normalisation, depth in metres with masked pixels 0."""
    depth = frame.depth.copy()
    if frame.mask is not None:
        depth[~frame.mask] = 0.0
    amplitude = normalize_amplitude(frame.amplitude, depth, Normalisation().amplitude_percentile)
    return amplitude, depth


def warped_inputs(
    frame: Frame, amplitude: np.ndarray, depth: np.ndarray, view: Calibration, name: str
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`refine_inputs` warped into the RGB view of the misalignment ``view`` as the daemon
    warps them (depth discontinuity-aware, amplitude bilinear). ``frame`` (``name`` in errors)
    must be an aligned frame with ground-truth depth."""
    if frame.gt_depth is None or frame.perturbation != Calibration():
        raise CaptureError(
            f"{name}: a warped copy needs an aligned frame with ground-truth depth (a "
            "`dear-synth family` shard)"
        )
    synthesized = augment(frame.rgb, frame.gt_depth, view)
    # Zero flow where the view has no ground truth, as the refiner's training feeds it.
    u = np.where(synthesized.valid, synthesized.flow_u, 0.0)
    v = np.where(synthesized.valid, synthesized.flow_v, 0.0)
    return warp_bilinear_np(amplitude, u, v)[0], warp_depth_np(depth, u, v)


def on_grid(amplitude: np.ndarray, depth: np.ndarray) -> torch.Tensor:
    """Refine inputs on the gate's grid, ``(2, 60, 80)``."""
    t = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))[None, None]  # noqa: E731
    return pool_inputs(t(amplitude), t(depth))[0]


def capture_grids(
    root: Path, warped: int = 0, rng: np.random.Generator | None = None
) -> torch.Tensor:
    """Every frame of the capture ``root`` on the gate's grid, then ``warped`` copies of each
    in views drawn by the refiner's augmentation (:func:`draw_perturbation`) from ``rng``:
    ``((1 + warped)·frames, 2, 60, 80)``. The daemon refines depth warped into the RGB view,
    and a gate that saw only aligned frames gives warped multi-path frames a lower ``p``.
    Each frame is read once; with copies, the frames are kept until they are made."""
    capture = Capture(root)
    if len(capture) == 0:
        raise ValueError(f"{root}: no frames")
    if warped and rng is None:
        raise ValueError("warped copies need a random generator")
    grids, kept = [], []
    for i in range(len(capture)):
        frame = capture.load(i)
        inputs = refine_inputs(frame)
        grids.append(on_grid(*inputs))
        if warped:
            kept.append((frame, inputs))
    h, w = capture.size
    for _ in range(warped):
        assert rng is not None
        for i, (frame, inputs) in enumerate(kept):
            view = draw_perturbation(rng, h, w, AugmentConfig())
            grids.append(on_grid(*warped_inputs(frame, *inputs, view, f"{root}: frame {i}")))
    return torch.stack(grids)


def load_grids(
    roots: list[Path], warped: int = 0, seed: int = 0
) -> tuple[torch.Tensor, torch.Tensor]:
    """Every frame of ``roots`` on the gate's grid (with ``warped`` warped copies each, drawn
    from ``seed``), and its label."""
    if not roots:
        raise ValueError("no captures given")
    rng = np.random.default_rng(seed)
    labels = [shard_label(root) for root in roots]
    grids = [capture_grids(root, warped, rng) for root in roots]
    per_frame = [torch.full((len(g),), label) for g, label in zip(grids, labels, strict=True)]
    return torch.cat(grids), torch.cat(per_frame)


def probabilities(gate: MultipathGate, grids: torch.Tensor) -> torch.Tensor:
    """The gate's ``p`` for every frame of ``grids``, in evaluation mode, 64 frames at a time."""
    was_training = gate.training
    gate.eval()
    with torch.no_grad():
        p = torch.cat(
            [torch.sigmoid(gate.logit(grids[i : i + 64])) for i in range(0, len(grids), 64)]
        )
    gate.train(was_training)
    return p


def accuracy(gate: MultipathGate, grids: torch.Tensor, labels: torch.Tensor) -> float:
    p = probabilities(gate, grids)
    return float(((p > 0.5).float() == labels).float().mean())


def train(args: argparse.Namespace) -> None:
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    t0 = time.time()
    grids, labels = load_grids(args.data, args.warped, args.seed)
    # Validation frames are warped too, from their own fixed generator.
    val = load_grids(args.val, args.warped, args.seed + 1) if args.val else None
    n_val = 0 if val is None else len(val[0])
    print(
        f"dear-gate: {len(grids)} training frames ({labels.mean():.0%} with multi-path), "
        f"{n_val} validation frames, loaded in {time.time() - t0:.0f} s",
        flush=True,
    )
    gate = MultipathGate(width=args.width)
    opt = torch.optim.Adam(gate.parameters(), args.lr)
    steps = args.epochs * ((len(grids) + args.batch - 1) // args.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, args.lr, total_steps=steps)
    history = []
    for epoch in range(args.epochs):
        t0 = time.time()
        order = rng.permutation(len(grids))
        total = 0.0
        for i in range(0, len(order), args.batch):
            idx = torch.from_numpy(order[i : i + args.batch])
            x = grids[idx]
            # Mirror images have the same multi-path.
            if rng.random() < 0.5:
                x = x.flip(-1)
            loss = F.binary_cross_entropy_with_logits(gate.logit(x), labels[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item() * len(idx)
        record = {"epoch": epoch, "loss": total / len(grids), "seconds": time.time() - t0}
        if val is not None:
            record["val_accuracy"] = accuracy(gate, *val)
        history.append(record)
        print("dear-gate: " + json.dumps(record), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    torch.save(
        {
            "width": args.width,
            "state": gate.state_dict(),
            "recipe": {
                "data": captures_summary(args.data),
                "val": captures_summary(args.val or []),
                "frames": len(grids),
                "warped_copies": args.warped,
                "multipath_fraction": float(labels.mean()),
                "epochs": args.epochs,
                "batch": args.batch,
                "lr": args.lr,
                "seed": args.seed,
            },
            "history": history,
        },
        args.out / "gate.pt",
    )
    print(f"dear-gate: wrote {args.out / 'gate.pt'}")


def captures_summary(roots: list[Path]) -> dict:
    """How many captures, from which directories (their names, not the machine's paths)."""
    return {"captures": len(roots), "directories": sorted({p.parent.name for p in roots})}


def load_gate(path: Path) -> tuple[MultipathGate, dict]:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no gate checkpoint there (`dear-gate train` writes one)")
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    gate = MultipathGate(width=ckpt["width"])
    gate.load_state_dict(ckpt["state"])
    return gate.eval(), ckpt


def compose(refine: onnx.ModelProto, gate_graph: onnx.ModelProto) -> onnx.ModelProto:
    """``refine`` followed by ``gate_graph`` (inputs ``amplitude, depth, maps``; one output):
    the refine graph's output feeds the gate's ``maps``, the two share the other inputs, and
    the composed graph keeps the refine graph's inputs and output name. Every other tensor of
    the gate is renamed under :data:`PREFIX`."""
    (out,) = refine.graph.output
    for node in refine.graph.node:
        node.output[:] = [UNGATED if o == out.name else o for o in node.output]
    shared = {"amplitude", "depth"}
    gate_in = [i.name for i in gate_graph.graph.input]
    if gate_in != ["amplitude", "depth", "maps"]:
        raise ValueError(f"gate graph inputs {gate_in}: want amplitude, depth, maps")
    (gate_out,) = gate_graph.graph.output

    def rename(name: str) -> str:
        if name in shared or name == "":
            return name
        if name == gate_in[2]:
            return UNGATED
        if name == gate_out.name:
            return out.name
        return PREFIX + name

    for init in gate_graph.graph.initializer:
        init.name = rename(init.name)
        refine.graph.initializer.append(init)
    for node in gate_graph.graph.node:
        node.name = PREFIX + node.name
        node.input[:] = [rename(i) for i in node.input]
        node.output[:] = [rename(o) for o in node.output]
        refine.graph.node.append(node)
    onnx.checker.check_model(refine)
    return refine


def export_gate_graph(gate: MultipathGate, channels: int, path: Path) -> None:
    """:class:`GateOnMaps` as an ONNX graph (opset as every bundle graph, dynamic N/H/W)."""
    module = GateOnMaps(gate).eval()
    h, w = 96, 128
    inputs = (
        torch.rand(1, 1, h, w),
        torch.rand(1, 1, h, w) * 4,
        torch.randn(1, channels, h // 4, w // 4),
    )
    names = ["amplitude", "depth", "maps"]
    dyn = {n: {0: "N", 2: "H", 3: "W"} for n in names}
    dyn["maps"] = {0: "N", 2: "h", 3: "w"}
    dyn["gated_maps"] = {0: "N", 2: "h", 3: "w"}
    with torch.no_grad():
        torch.onnx.export(
            module,
            inputs,
            str(path),
            input_names=names,
            output_names=["gated_maps"],
            dynamic_axes=dyn,
            opset_version=OPSET,
            do_constant_folding=True,
            dynamo=False,
        )


def as_applied(maps: np.ndarray) -> np.ndarray:
    """``maps`` with the bias and smoothing-gate logits as the daemon's tail uses them
    (``tanh``, ``sigmoid``). Those logits are rebuilt from ``p · tanh`` and ``p · sigmoid``:
    where ``p`` rounds to 1 and the map saturates, one ulp of ``tanh`` moves the logit by
    0.01 and more, and the output not at all, so the check compares what is applied."""
    out = maps.astype(np.float64)
    out[:, BIAS_CHANNEL] = np.tanh(out[:, BIAS_CHANNEL])
    out[:, GATE_CHANNEL] = 1.0 / (1.0 + np.exp(-out[:, GATE_CHANNEL]))
    return out


#: What a composed graph is checked against: ``(amplitude, depth, maps)`` → the gated maps.
GateReference = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def torch_reference(gate: MultipathGate) -> GateReference:
    """The gate as trained: :class:`GateOnMaps` in PyTorch."""

    def run(amplitude: np.ndarray, depth: np.ndarray, maps: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return GateOnMaps(gate)(
                *(torch.from_numpy(x) for x in (amplitude, depth, maps))
            ).numpy()

    return run


def onnx_reference(gate_graph: onnx.ModelProto) -> GateReference:
    """A gate graph taken out of another bundle (:func:`gate_graph_of`), run on its own."""
    import onnxruntime as ort

    session = ort.InferenceSession(
        gate_graph.SerializeToString(), providers=["CPUExecutionProvider"]
    )

    def run(amplitude: np.ndarray, depth: np.ndarray, maps: np.ndarray) -> np.ndarray:
        (out,) = session.run(None, {"amplitude": amplitude, "depth": depth, "maps": maps})
        return out

    return run


def check_composed(
    original: Path, composed: Path, reference: GateReference, feeds: list[dict[str, np.ndarray]]
) -> float:
    """Max |composed − (original maps gated by ``reference``)| over the refine graph's
    ``feeds``, compared :func:`as_applied`."""
    import onnxruntime as ort

    before = ort.InferenceSession(str(original), providers=["CPUExecutionProvider"])
    after = ort.InferenceSession(str(composed), providers=["CPUExecutionProvider"])
    worst = 0.0
    for feed in feeds:
        (maps,) = before.run(None, feed)
        (got,) = after.run(None, feed)
        want = reference(feed["amplitude"], feed["depth"], maps)
        worst = max(worst, float(np.abs(as_applied(got) - as_applied(want)).max()))
    if not worst <= CHECK_ATOL:
        raise RuntimeError(f"{composed}: differs from the gated maps by {worst:.3g} > {CHECK_ATOL}")
    return worst


def refine_feeds(manifest: dict, sizes: list[tuple[int, int]]) -> list[dict[str, np.ndarray]]:
    """The refine graph's check inputs at each ``(h, w)`` of ``sizes`` (``export.check_inputs``,
    a rendered scene under the bundle's normalisation), by input name."""
    norm = manifest["normalisation"]
    names = [i["name"] for i in manifest["graphs"]["refine"]["inputs"]]
    feeds = []
    for h, w in sizes:
        inputs = check_inputs(
            manifest["variant"], norm["max_depth_m"], norm["amplitude_percentile"], h, w
        )["refine"]
        feeds.append({n: x.numpy() for n, x in zip(names, inputs, strict=True)})
    return feeds


def attach(args: argparse.Namespace) -> None:
    bundle: Path = args.bundle
    manifest_path = bundle / "model.json"
    manifest = json.loads(manifest_path.read_text())
    entry = manifest["graphs"]["refine"]
    apply = entry.get("apply", {})
    if apply.get("kind") != "hybrid-kernel":
        raise ValueError(
            f"{manifest_path}: refine apply kind {apply.get('kind')!r}: the gate scales the bias "
            "map of a hybrid refiner (hybrid-kernel)"
        )
    if "multipath_gate" in manifest:
        raise ValueError(f"{manifest_path}: the refine graph already has a multi-path gate")
    if args.gate is not None:
        gate, ckpt = load_gate(args.gate)
        history = ckpt.get("history", [])
        record = {
            "what": "a frame-level CNN (train/dear_train/models/multipath_gate.py) inside "
            f"refine.onnx: the refine inputs averaged onto a {GRID[0]}x{GRID[1]} grid give p, "
            "the probability that the frame has multi-path; the maps are then scaled by p: "
            f"tanh(maps[9]) becomes p times itself, sigmoid(maps[10]) ({SMOOTHING_FLOOR} + "
            f"{1 - SMOOTHING_FLOOR} p) times itself, maps[12] becomes maps[12] + 2 log(p) "
            "(gate_maps in that file)",
            "params": param_count(gate),
            "recipe": ckpt.get("recipe", {}),
            "last_epoch": history[-1] if history else None,
        }
        with tempfile.TemporaryDirectory() as tmp:
            gate_path = Path(tmp) / "gate-on-maps.onnx"
            export_gate_graph(gate, apply["channels"], gate_path)
            gate_graph = onnx.load(str(gate_path))
        reference = torch_reference(gate)
    else:
        gate_graph, donor = gate_graph_of(args.gate_from)
        if donor["graphs"]["refine"]["apply"].get("channels") != apply["channels"]:
            raise ValueError(
                f"{args.gate_from / 'model.json'}: its gate scales "
                f"{donor['graphs']['refine']['apply'].get('channels')} maps, "
                f"{manifest_path}'s refiner has {apply['channels']}"
            )
        record = dict(donor["multipath_gate"], copied_from=str(args.gate_from))
        reference = onnx_reference(gate_graph)
    path = bundle / entry["file"]
    with tempfile.TemporaryDirectory() as tmp:
        original = Path(tmp) / "refine-ungated.onnx"
        original.write_bytes(path.read_bytes())
        composed = compose(onnx.load(str(path)), gate_graph)
        onnx.save(composed, str(path))
        try:
            feeds = refine_feeds(manifest, [(96, 128), (64, 80), (240, 320)])
            diff = check_composed(original, path, reference, feeds)
        except Exception:
            # Never leave a bundle whose graph and manifest disagree.
            path.write_bytes(original.read_bytes())
            raise
    entry["params"] = int(entry["params"]) + int(record["params"])
    entry["bytes"] = path.stat().st_size
    entry["sha256"] = sha256(path)
    entry.setdefault("check", {})["gate_max_abs_diff"] = diff
    entry["outputs"][0]["meaning"] += MEANING_SUFFIX
    manifest["multipath_gate"] = record
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")
    print(f"dear-gate: {path} gated ({record['params']} parameters, max |diff| {diff:.2g})")


def split_gate(
    graph: onnx.GraphProto,
) -> tuple[
    list[onnx.NodeProto], list[onnx.NodeProto], list[onnx.TensorProto], list[onnx.TensorProto]
]:
    """A composed refine graph's nodes and initializers as (the refiner's nodes, the gate's
    nodes, the refiner's initializers, the gate's initializers): :func:`compose` names
    everything of the gate under :data:`PREFIX`."""
    nodes = [n for n in graph.node if not n.name.startswith(PREFIX)]
    gate_nodes = [n for n in graph.node if n.name.startswith(PREFIX)]
    inits = [i for i in graph.initializer if not i.name.startswith(PREFIX)]
    gate_inits = [i for i in graph.initializer if i.name.startswith(PREFIX)]
    return nodes, gate_nodes, inits, gate_inits


def gate_graph_of(bundle: Path) -> tuple[onnx.ModelProto, dict]:
    """The multi-path gate inside ``bundle``'s refine graph as a graph of its own (inputs
    ``amplitude, depth, maps``, output ``gated_maps``, as :func:`export_gate_graph` writes),
    and ``bundle``'s manifest: so that a retrained refiner can take the gate a bundle ships
    with (``dear-gate attach --gate-from``) without the gate's checkpoint."""
    manifest_path = bundle / "model.json"
    manifest = json.loads(manifest_path.read_text())
    if "multipath_gate" not in manifest:
        raise ValueError(f"{manifest_path}: the refine graph has no multi-path gate to copy")
    model = onnx.load(str(bundle / manifest["graphs"]["refine"]["file"]))
    (out,) = model.graph.output

    def own(name: str) -> str:
        if name == UNGATED:
            return "maps"
        if name == out.name:
            return "gated_maps"
        return name.removeprefix(PREFIX)

    # The model was loaded for this alone: its gate's protos are renamed where they stand.
    _, nodes, _, inits = split_gate(model.graph)
    for node in nodes:
        node.name = own(node.name)
        node.input[:] = [own(i) for i in node.input]
        node.output[:] = [own(o) for o in node.output]
    for init in inits:
        init.name = own(init.name)
    if not nodes or not any("maps" in n.input for n in nodes):
        raise ValueError(f"{bundle}: its refine graph has no {PREFIX} nodes reading the maps")
    channels = manifest["graphs"]["refine"]["apply"]["channels"]
    f32 = onnx.TensorProto.FLOAT
    graph = onnx.helper.make_graph(
        nodes,
        "multipath_gate",
        [
            onnx.helper.make_tensor_value_info("amplitude", f32, ["N", 1, "H", "W"]),
            onnx.helper.make_tensor_value_info("depth", f32, ["N", 1, "H", "W"]),
            onnx.helper.make_tensor_value_info("maps", f32, ["N", channels, "h", "w"]),
        ],
        [onnx.helper.make_tensor_value_info("gated_maps", f32, ["N", channels, "h", "w"])],
        inits,
    )
    gate_graph = onnx.helper.make_model(graph, opset_imports=list(model.opset_import))
    gate_graph.ir_version = model.ir_version
    onnx.checker.check_model(gate_graph)
    return gate_graph, manifest


def detach(args: argparse.Namespace) -> None:
    """A copy of ``--bundle`` at ``--out`` whose refine graph is the refiner alone (the gate's
    nodes removed, its manifest record dropped): the row *without* the gate in
    ``scripts/results.sh``. The refiner's nodes and weights are the attached graph's own."""
    src: Path = args.bundle
    manifest = json.loads((src / "model.json").read_text())
    record = manifest.pop("multipath_gate", None)
    if record is None:
        raise ValueError(f"{src / 'model.json'}: the refine graph has no multi-path gate")
    if args.out.exists():
        raise FileExistsError(f"{args.out}: exists; detach writes a new bundle directory")
    shutil.copytree(src, args.out)
    entry = manifest["graphs"]["refine"]
    path = args.out / entry["file"]
    model = onnx.load(str(path))
    (out,) = model.graph.output
    kept, _, inits, _ = split_gate(model.graph)
    for node in kept:
        node.output[:] = [out.name if o == UNGATED else o for o in node.output]
    del model.graph.node[:]
    model.graph.node.extend(kept)
    del model.graph.initializer[:]
    model.graph.initializer.extend(inits)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    entry["params"] = int(entry["params"]) - int(record["params"])
    entry["bytes"] = path.stat().st_size
    entry["sha256"] = sha256(path)
    entry.get("check", {}).pop("gate_max_abs_diff", None)
    entry["outputs"][0]["meaning"] = entry["outputs"][0]["meaning"].removesuffix(MEANING_SUFFIX)
    (args.out / "model.json").write_text(json.dumps(manifest, indent=2) + "\n")
    print(f"dear-gate: {args.out}: {src}'s refiner without its multi-path gate")


def score(args: argparse.Namespace) -> None:
    """Per capture: the gate's mean ``p`` and the range of its frames, beside the label when
    the capture records one (how a user checks the gate on their own recordings)."""
    gate, _ = load_gate(args.gate)
    for root in args.data:
        p = probabilities(gate, capture_grids(root))
        try:
            label = f"multi-path {'yes' if shard_label(root) else 'no'}"
        except CaptureError:
            label = "multi-path unknown"
        print(
            f"{root}: {len(p)} frames, p mean {p.mean():.3f}, min {p.min():.3f}, "
            f"max {p.max():.3f} ({label})"
        )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="dear-gate", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train", help="train the gate on rendered family shards")
    t.add_argument("--data", type=Path, nargs="+", required=True, help="training captures")
    t.add_argument("--val", type=Path, nargs="*", help="validation captures (other seeds)")
    t.add_argument("--out", type=Path, required=True, help="run directory (gate.pt)")
    t.add_argument("--epochs", type=int, default=20)
    t.add_argument("--batch", type=int, default=32)
    t.add_argument("--lr", type=float, default=1e-3)
    t.add_argument("--width", type=int, default=16)
    t.add_argument("--seed", type=int, default=0)
    t.add_argument(
        "--warped",
        type=int,
        default=1,
        help="warped copies of every frame, in random views as the refiner trains (default 1)",
    )
    a = sub.add_parser("attach", help="append a trained gate to a bundle's refine graph")
    a.add_argument("--bundle", type=Path, required=True, help="bundle directory (edited)")
    source = a.add_mutually_exclusive_group(required=True)
    source.add_argument("--gate", type=Path, help="gate.pt from `dear-gate train`")
    source.add_argument(
        "--gate-from",
        type=Path,
        help="a gated bundle whose gate is copied (e.g. a retrained refiner keeps models/edge's)",
    )
    d = sub.add_parser("detach", help="copy a bundle with the gate taken out (for comparison)")
    d.add_argument("--bundle", type=Path, required=True, help="bundle with a gate")
    d.add_argument("--out", type=Path, required=True, help="new bundle directory")
    c = sub.add_parser("score", help="the gate's p on captures (e.g. your own recordings)")
    c.add_argument("--gate", type=Path, required=True, help="gate.pt from `dear-gate train`")
    c.add_argument("--data", type=Path, nargs="+", required=True, help="captures")
    args = parser.parse_args(argv)
    commands = {"train": train, "attach": attach, "detach": detach, "score": score}
    try:
        commands[args.command](args)
    except (CaptureError, ValueError, OSError) as e:
        # A bad input (a capture, a bundle, a path): its message names it; no traceback.
        parser.exit(2, f"dear-gate: error: {e}\n")


if __name__ == "__main__":
    main()
