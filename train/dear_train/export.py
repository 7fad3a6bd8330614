"""``dear-export``: write a model bundle (three ONNX graphs + ``model.json``) from a checkpoint.

Bundle layout::

    flow.onnx     rough flow      (rgb, amplitude)           → flow
    fuse.onnx     flow fusion     (flow_rough, flow_convt)   → flow_refined
    refine.onnx   depth refine    (amplitude, depth, rgb)    → depth_refined
    model.json    manifest: I/O contract, normalisation, recipe, metrics, SHA-256 of each file

The graphs hold only the networks: the warps, the least-squares calibration and the
normalisation run in the daemon (Rust), so no graph contains ``GridSample``. Each graph is
exported with the TorchScript-based exporter (``dynamo=False``, opset 17: every op tract
needs is stable there), self-contained (no external ``.onnx.data``), with dynamic ``N``, ``H``
and ``W``, and is checked against PyTorch with onnxruntime at two input sizes before the
manifest is written. See ``train/README.md``, "Graph I/O contract".
"""

from __future__ import annotations

import argparse
import hashlib
import json
import platform
from pathlib import Path

import numpy as np
import onnx
import torch
import torch.nn.functional as F
from torch import nn

import dear_train
from dear_train.data.dataset import normalize_amplitude
from dear_train.data.synthetic import render_scene
from dear_train.models import INPUT_SIZE_MULTIPLE, kpn, param_count
from dear_train.models.complexity import count_macs
from dear_train.models.dear import DEAR
from dear_train.models.flownetc import FlowNetC
from dear_train.models.fusion import FusionNet
from dear_train.models.kpn import RefineNet, uses_rgb
from dear_train.onnx_passes import subpixel_transposed_conv, subsample_strided_depthwise
from dear_train.training.checkpoint import load, load_model
from dear_train.training.config import Profile

FORMAT = "dear-model-bundle"
OPSET = 17
#: Largest allowed |ONNX − PyTorch| on the check inputs (flows in px, depths in m).
CHECK_ATOL = 1e-4
#: ``graphs.refine.apply.error_floor`` of a guarded bundle (the chain applies it; the depth is
#: unchanged): the expected error is raised to at least ``min(scale · m, cap_m)`` metres, ``m``
#: the mean |depth − classical| in the ``(2·radius + 1)²`` window. Chosen on validation draws
#: no RESULTS.md table scores (``dear-synth family --family heldout --seed 9300``, 4 draws of
#: 20 frames, and ``--family broad --seed 9100``, 8 of 10): docs/models.md, "Expected-error floor".
GUARDED_ERROR_FLOOR = {"scale": 1.0, "radius": 2, "cap_m": 0.16}


class FlowGraph(nn.Module):
    """``(rgb, amplitude)`` → full-resolution ``W_rough``."""

    def __init__(self, net: FlowNetC) -> None:
        super().__init__()
        self.net = net

    def forward(self, rgb: torch.Tensor, amplitude: torch.Tensor) -> torch.Tensor:
        return self.net(rgb, amplitude)[-1]


class FuseGraph(nn.Module):
    """``(flow_rough, flow_convt)`` → full-resolution ``W_refn``."""

    def __init__(self, net: FusionNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, flow_rough: torch.Tensor, flow_convt: torch.Tensor) -> torch.Tensor:
        return self.net(flow_rough, flow_convt)[-1]


class RefineGraph(nn.Module):
    """``(amplitude, depth[, rgb][, classical])`` → refined depth, depths in metres.

    The ``/ max_depth`` and ``× max_depth`` around the network are part of the graph, so the
    daemon passes and receives metres and cannot get the depth scaling wrong.

    For the ``gated`` and ``hybrid`` variants (format version 2) the graph ends at the head: it
    outputs the maps at 1/``stride`` resolution and the daemon upsamples and applies them
    (``pipeline/src/model/kernel_apply.rs``, described by ``graphs.refine.apply``): tract runs
    that full-resolution tail op by op at several times its arithmetic cost (its ``Softmax``
    alone took ~0.8 s per 640×480 frame).
    """

    def __init__(self, net: RefineNet, max_depth: float) -> None:
        super().__init__()
        self.net = net
        self.max_depth = max_depth

    def forward(
        self,
        amplitude: torch.Tensor,
        depth: torch.Tensor,
        rgb: torch.Tensor | None = None,
        classical: torch.Tensor | None = None,
    ) -> torch.Tensor:
        c = None if classical is None else classical / self.max_depth
        if kpn.applies_maps(self.net.variant):
            return self.net.head_maps(amplitude, depth / self.max_depth, rgb, c)
        return self.net(amplitude, depth / self.max_depth, rgb) * self.max_depth


def format_version(variant: str) -> int:
    """Bundle format: 2 when the daemon applies the refiner's output (``gated``, ``hybrid``),
    else 1."""
    return 2 if kpn.applies_maps(variant) else 1


_GATED_DEFINITION = (
    "for the 3x3 neighbours b_i of b (edges replicated) w = softmax_i(maps[i] - range_scale * "
    "exp(maps[11]) * |b_i - b|) over neighbours with b_i > 0; out = b + sigmoid(maps[10]) * "
    "(sum w_i b_i + max_bias * tanh(maps[9]) - b), 0 where b = 0; metres = out * max_depth_m"
)


#: ``apply.jump_on`` values: the jump term on every pixel (as the refiners are trained), or only
#: on the pixels the classical filter replaced (``kpn.HybridKernelApply``'s ``replaced``).
JUMP_ON = ("every-pixel", "replaced")
#: The default: how the refiners are trained.
JUMP_ON_DEFAULT = JUMP_ON[0]


def refine_apply_spec(net: RefineNet, jump_on: str = JUMP_ON_DEFAULT) -> dict | None:
    """``graphs.refine.apply``: what the daemon does with a format-2 refine graph's maps."""
    if jump_on not in JUMP_ON:
        raise ValueError(f"jump_on {jump_on!r}: one of {', '.join(JUMP_ON)}")
    upsample = (
        "maps upsampled bilinearly (half-pixel centres, edges clamped) to the depth grid and "
        "cropped; "
    )
    if net.variant == "gated":
        kind, channels = "gated-kernel", kpn.GATED_CHANNELS
        definition = upsample + "b = depth / max_depth_m; " + _GATED_DEFINITION
    elif net.variant in ("hybrid", "guarded"):
        kind, channels = (
            ("hybrid-kernel", kpn.HYBRID_CHANNELS)
            if net.variant == "hybrid"
            else ("guarded-kernel", kpn.GUARDED_CHANNELS)
        )
        definition = (
            upsample
            + "d = depth / max_depth_m, c = classical / max_depth_m (the classical refiner's "
            "output on the warped depth); t = sigmoid(maps[12] + j * jump_scale * |c - d|), j = 1 "
            "(jump_on = every-pixel) or, with jump_on = replaced, 1 where the classical "
            "refiner's confidence is below 128 (it replaced the measurement) and 0 elsewhere; "
            "b = d + t * (c - d) where d > 0 and c > 0, d where only d > 0, c where only c > 0; "
            + _GATED_DEFINITION
        )
        if net.variant == "guarded":
            definition += (
                "; that is the refined candidate r. Expected absolute errors (metres) e_k = "
                "error_unit * max_depth_m * exp(clamp(maps[13 + k], -log_error_bound, "
                "log_error_bound)) for k = 0 (r), 1 (d), 2 (c); each pixel publishes the "
                "candidate with a positive depth and the smallest e_k (ties: r, then d, then c) "
                "and e_k as its expected error; none positive: 0; the published error is then "
                "raised to at least min(error_floor.scale * m, error_floor.cap_m) metres, m the "
                "mean of |depth - classical| over the pixels of the (2 * error_floor.radius + "
                "1)^2 window (clipped at the border) where both are positive (the depth is "
                "unchanged)"
            )
    else:
        return None
    spec = {
        "kind": kind,
        "stride": net.backbone.stride,
        "channels": channels,
        "max_bias": kpn.GATED_MAX_BIAS,
        "range_scale": kpn.GATED_RANGE_SCALE,
    }
    if net.variant in ("hybrid", "guarded"):
        spec["jump_scale"] = kpn.HYBRID_JUMP_SCALE
        spec["jump_on"] = jump_on
    if net.variant == "guarded":
        spec["error_unit"] = kpn.GUARDED_ERROR_UNIT
        spec["log_error_bound"] = kpn.GUARDED_LOG_ERROR_BOUND
        spec["error_floor"] = dict(GUARDED_ERROR_FLOOR)
    spec["definition"] = definition
    return spec


def _tensor_io(name: str, channels: int, meaning: str) -> dict:
    return {
        "name": name,
        "shape": ["N", channels, "H", "W"],
        "dtype": "float32",
        "layout": "NCHW",
        "meaning": meaning,
    }


def graph_specs(variant: str) -> dict[str, dict]:
    """Names, shapes and meanings of every graph's inputs and outputs (the I/O contract)."""
    rgb = _tensor_io("rgb", 3, "RGB image on the RGB grid, R,G,B channels, value/255 in [0,1]")
    refine_inputs = [
        _tensor_io(
            "amplitude",
            1,
            "normalised ToF amplitude backward-warped to the RGB grid with flow_refined "
            "(bilinear; 0 outside the image)",
        ),
        _tensor_io(
            "depth",
            1,
            "ToF depth in metres backward-warped to the RGB grid with flow_refined "
            "(discontinuity-aware warp_depth); 0 = invalid",
        ),
    ]
    if uses_rgb(variant):
        refine_inputs.append(rgb)
    if kpn.uses_classical(variant):
        refine_inputs.append(
            _tensor_io(
                "classical",
                1,
                "the daemon's classical refiner (pipeline/src/filter) run on the warped depth, "
                "guided by the RGB image, metres; 0 = invalid",
            )
        )
    maps_channels = kpn.head_channels(variant)
    return {
        "flow": {
            "file": "flow.onnx",
            "inputs": [
                rgb,
                _tensor_io(
                    "amplitude",
                    1,
                    "normalised ToF amplitude on the ToF grid: clip(I_raw*D^2 / "
                    "percentile_p(I_raw*D^2 over valid D), 0, 1), D in metres",
                ),
            ],
            "outputs": [
                _tensor_io(
                    "flow",
                    2,
                    "W_rough in pixels on the RGB grid; channel 0 = u (columns), 1 = v (rows); "
                    "RGB pixel p sees ToF pixel p + W(p)",
                )
            ],
        },
        "fuse": {
            "file": "fuse.onnx",
            "inputs": [
                _tensor_io("flow_rough", 2, "W_rough from flow.onnx, pixels"),
                _tensor_io(
                    "flow_convt",
                    2,
                    "W_convt = (tx/D_rgb + cx, ty/D_rgb + cy) from the least-squares "
                    "calibration, D_rgb = warp_depth(D_tof, W_rough) in metres; where D_rgb is "
                    "invalid (0), W_rough instead",
                ),
            ],
            "outputs": [_tensor_io("flow_refined", 2, "W_refn in pixels, same convention")],
        },
        "refine": {
            "file": "refine.onnx",
            "inputs": refine_inputs,
            "outputs": [
                {
                    **_tensor_io(
                        "refine_maps",
                        maps_channels,
                        "kernel logits (9), bias, gate and range log-sharpness"
                        + (
                            ", trust in the classical estimate"
                            if variant in ("hybrid", "guarded")
                            else ""
                        )
                        + (
                            ", log expected error of the refined, measured and classical depth"
                            if variant == "guarded"
                            else ""
                        )
                        + " at 1/stride resolution; applied by the daemon as "
                        "graphs.refine.apply says",
                    ),
                    "shape": ["N", maps_channels, "H/4", "W/4"],
                }
                if kpn.applies_maps(variant)
                else _tensor_io("depth_refined", 1, "refined depth on the RGB grid, metres")
            ],
        },
    }


def check_inputs(variant: str, max_depth: float, percentile: float, h: int, w: int) -> dict:
    """Deterministic, realistic inputs for each graph (a synthetic scene at ``h × w``)."""
    scene = render_scene(np.random.default_rng(7), h, w)
    rgb = torch.from_numpy(scene["rgb"].astype(np.float32) / 255).permute(2, 0, 1)[None]
    amp = torch.from_numpy(normalize_amplitude(scene["amplitude"], scene["tof_depth"], percentile))[
        None, None
    ]
    depth = torch.from_numpy(scene["tof_depth"])[None, None]
    yy, xx = torch.meshgrid(torch.arange(h) / h, torch.arange(w) / w, indexing="ij")
    flow = torch.stack([6 * torch.sin(3 * xx) - 2, 4 * torch.cos(2 * yy) + 1])[None]
    refine = (amp, depth, rgb) if uses_rgb(variant) else (amp, depth)
    if kpn.uses_classical(variant):
        # Any depth-like plane checks the graph; a smoothed depth with its holes filled by
        # neighbours stands for the classical filter's output.
        filled = torch.where(depth > 0, depth, F.max_pool2d(depth, 5, 1, 2))
        refine = (*refine, F.avg_pool2d(filled, 3, 1, 1, count_include_pad=False))
    return {"flow": (rgb, amp), "fuse": (flow, flow + 0.5 * torch.sin(7 * xx)), "refine": refine}


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def export_graph(module: nn.Module, inputs: tuple, spec: dict, path: Path) -> None:
    """Export one graph (TorchScript exporter, opset 17, dynamic N/H/W, one file)."""
    names_in = [i["name"] for i in spec["inputs"]]
    names_out = [o["name"] for o in spec["outputs"]]
    dyn = {n: {0: "N", 2: "H", 3: "W"} for n in names_in}
    dyn |= {
        o["name"]: {0: "N", 2: str(o["shape"][2]), 3: str(o["shape"][3])} for o in spec["outputs"]
    }
    module.eval()
    with torch.no_grad():
        torch.onnx.export(
            module,
            inputs,
            str(path),
            input_names=names_in,
            output_names=names_out,
            dynamic_axes=dyn,
            opset_version=OPSET,
            do_constant_folding=True,
            dynamo=False,
        )
    model = onnx.load(str(path), load_external_data=False)
    onnx.checker.check_model(model)
    # Same outputs, faster in tract (its strided depthwise and transposed convolutions are
    # slow): dear_train.onnx_passes.
    if subsample_strided_depthwise(model) + subpixel_transposed_conv(model):
        onnx.save(model, str(path))
    ops = {n.op_type for n in model.graph.node}
    if "GridSample" in ops:
        raise RuntimeError(f"{path}: graph contains GridSample; the daemon does the warping")
    for init in model.graph.initializer:
        if init.data_location == onnx.TensorProto.EXTERNAL:
            raise RuntimeError(f"{path}: initializer {init.name} is stored externally")


def verify_graph(module: nn.Module, inputs: tuple, path: Path, spec: dict) -> float:
    """Max |onnxruntime − PyTorch| on ``inputs``; raises above :data:`CHECK_ATOL`."""
    import onnxruntime as ort

    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    feed = {i["name"]: x.numpy() for i, x in zip(spec["inputs"], inputs, strict=True)}
    (got,) = sess.run(None, feed)
    with torch.no_grad():
        want = module(*inputs).numpy()
    if got.shape != want.shape:
        raise RuntimeError(f"{path}: ONNX output {got.shape} vs PyTorch {want.shape}")
    diff = float(np.abs(got - want).max())
    if not diff <= CHECK_ATOL:
        raise RuntimeError(f"{path}: ONNX differs from PyTorch by {diff:.3g} > {CHECK_ATOL}")
    return diff


def export_bundle(
    model: DEAR,
    profile: Profile,
    out: Path,
    extra: dict | None = None,
    check: bool = True,
    check_sizes: tuple[tuple[int, int], ...] = ((96, 128), (64, 80)),
    macs_at: tuple[int, int] | None = (480, 640),
    jump_on: str = JUMP_ON_DEFAULT,
) -> dict:
    """Export ``model`` to the bundle directory ``out``; returns the manifest it wrote.

    ``check`` compares every graph with PyTorch at each of ``check_sizes`` (two sizes, so the
    dynamic H/W axes are exercised); ``macs_at`` records each graph's MACs at that ``(H, W)``;
    ``jump_on`` is a hybrid or guarded refiner's ``apply.jump_on`` (:data:`JUMP_ON`).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    assert model.flow is not None and model.fusion is not None and model.refine is not None
    norm = profile.norm
    modules: dict[str, nn.Module] = {
        "flow": FlowGraph(model.flow).eval(),
        "fuse": FuseGraph(model.fusion).eval(),
        "refine": RefineGraph(model.refine, norm.max_depth).eval(),
    }
    specs = graph_specs(profile.variant)
    sizes = [
        check_inputs(profile.variant, norm.max_depth, norm.amplitude_percentile, h, w)
        for h, w in check_sizes
    ]
    graphs = {
        name: _export_entry(
            module,
            specs[name],
            [s[name] for s in sizes],
            out / specs[name]["file"],
            check_sizes if check else None,
            macs_at,
            refine_apply_spec(model.refine, jump_on) if name == "refine" else None,
        )
        for name, module in modules.items()
    }
    manifest = {
        "format": FORMAT,
        "format_version": format_version(profile.variant),
        "tier": profile.tier,
        "variant": profile.variant,
        "opset": OPSET,
        "input_size_multiple": INPUT_SIZE_MULTIPLE,
        "normalisation": {
            "max_depth_m": norm.max_depth,
            "amplitude_percentile": norm.amplitude_percentile,
            "amplitude": (
                "clip(I_raw * D^2 / percentile(I_raw * D^2 over pixels with valid D), 0, 1)"
            ),
            "rgb": "value / 255",
            "depth": "metres in and out of refine.onnx (the graph divides by max_depth_m itself)",
        },
        "graphs": graphs,
        "training": {"profile": profile.to_dict(), **(extra or {}).get("training", {})},
        "validation": (extra or {}).get("validation", {}),
        "software": {
            "dear_train": dear_train.__version__,
            "torch": torch.__version__,
            "onnx": onnx.__version__,
            "python": platform.python_version(),
        },
    }
    (out / "model.json").write_text(json.dumps(manifest, indent=2) + "\n")
    return manifest


def export_refine_into(
    model: DEAR,
    profile: Profile,
    bundle: Path,
    extra: dict | None = None,
    check: bool = True,
    check_sizes: tuple[tuple[int, int], ...] = ((96, 128), (64, 80)),
    macs_at: tuple[int, int] | None = (480, 640),
    jump_on: str = JUMP_ON_DEFAULT,
) -> dict:
    """Replace the refinement graph of the existing bundle ``bundle`` with ``model``'s.

    For a refinement net trained on its own (a profile whose only stage is ``refine``): the
    bundle keeps its flow and fusion graphs; ``refine.onnx``, its ``graphs.refine`` entry and
    the top-level ``variant`` are replaced, and the run's recipe and metrics are recorded under
    ``training.refine`` and ``validation.refine`` (the flow graphs' records stay as they were).
    The normalisation must match the bundle's: the daemon applies one to every graph.
    """
    bundle = Path(bundle)
    manifest_path = bundle / "model.json"
    manifest = json.loads(manifest_path.read_text())
    norm = profile.norm
    have = manifest["normalisation"]
    if (have["max_depth_m"], have["amplitude_percentile"]) != (
        norm.max_depth,
        norm.amplitude_percentile,
    ):
        raise ValueError(
            f"{manifest_path}: normalisation {have} differs from the checkpoint's {norm}"
        )
    assert model.refine is not None
    module = RefineGraph(model.refine, norm.max_depth).eval()
    spec = graph_specs(profile.variant)["refine"]
    sizes = [
        check_inputs(profile.variant, norm.max_depth, norm.amplitude_percentile, h, w)["refine"]
        for h, w in check_sizes
    ]
    manifest["graphs"]["refine"] = _export_entry(
        module,
        spec,
        sizes,
        bundle / spec["file"],
        check_sizes if check else None,
        macs_at,
        refine_apply_spec(model.refine, jump_on),
    )
    manifest["variant"] = profile.variant
    manifest["format_version"] = format_version(profile.variant)
    manifest.setdefault("training", {})["refine"] = {
        "profile": profile.to_dict(),
        **(extra or {}).get("training", {}),
    }
    manifest.setdefault("validation", {})["refine"] = (extra or {}).get("validation", {})
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")
    return manifest


def _export_entry(
    module: nn.Module,
    spec: dict,
    inputs: list[tuple],
    path: Path,
    check_sizes: tuple[tuple[int, int], ...] | None,
    macs_at: tuple[int, int] | None,
    apply: dict | None,
) -> dict:
    """Export one graph to ``path`` and return its manifest entry.

    ``inputs``: the graph's example inputs at each size (the first is traced; with
    ``check_sizes`` every one is compared with onnxruntime); ``macs_at``: ``(H, W)`` of the MAC
    count; ``apply``: the refine graph's format-2 ``apply`` record, if any.
    """
    export_graph(module, inputs[0], spec, path)
    entry = dict(spec)
    if check_sizes is not None:
        entry["check"] = {
            "runtime": "onnxruntime",
            "sizes": [list(s) for s in check_sizes],
            "max_abs_diff": max(verify_graph(module, x, path, spec) for x in inputs),
            "tolerance": CHECK_ATOL,
        }
    entry["params"] = param_count(module)
    if macs_at is not None:
        zeros = _zeros_at(inputs[0], macs_at)
        entry[f"gmac_at_{macs_at[1]}x{macs_at[0]}"] = round(
            count_macs(module, lambda: module(*zeros)) / 1e9, 4
        )
    entry["bytes"] = path.stat().st_size
    entry["sha256"] = sha256(path)
    if apply is not None:
        entry["apply"] = apply
    return entry


def _zeros_at(inputs: tuple, size: tuple[int, int]) -> tuple:
    """Zero inputs with the channels of ``inputs`` at ``size`` (for the MAC count)."""
    return tuple(torch.zeros(x.shape[0], x.shape[1], *size) for x in inputs)


def recipe_record(ckpt: dict) -> dict:
    """What ``model.json`` records of the run behind a checkpoint: data, frames, epochs trained,
    the bundle a warm-started run began from, and the last validation.

    ``final.pt`` carries its metrics; a ``last.pt`` (a run stopped early, e.g. for time) only
    its history, so the last epoch's validation is taken from there and ``epochs_trained``
    says how far the run got, instead of leaving the schedule in the profile to speak for it.
    """
    history = ckpt.get("history", [])
    training = {
        "data": ckpt.get("data", []),
        "frames": ckpt.get("frames", {}),
        "epochs_trained": len(history),
        "from": "final.pt" if "metrics" in ckpt else "last.pt (stopped before the schedule ended)",
    }
    if "warm_start" in ckpt:
        # The epochs above came after these (``dear-train --init-refine``).
        training["warm_start"] = ckpt["warm_start"]
    return {
        "training": training,
        "validation": ckpt.get("metrics", history[-1]["val"] if history else {}),
    }


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        prog="dear-export", description="Export a trained DEAR checkpoint to a model bundle."
    )
    p.add_argument(
        "--checkpoint", type=Path, required=True, help="final.pt (or last.pt) of a training run"
    )
    p.add_argument("--out", type=Path, required=True, help="bundle directory to write")
    p.add_argument("--no-check", action="store_true", help="skip the onnxruntime comparison")
    p.add_argument(
        "--refine-only",
        action="store_true",
        help="replace only refine.onnx of the existing bundle --out (a refine-only training run)",
    )
    p.add_argument(
        "--jump-on",
        choices=JUMP_ON,
        default=JUMP_ON_DEFAULT,
        help="hybrid and guarded refiners: the pixels the jump term applies to (apply.jump_on; "
        "replaced: only those the classical filter replaced, docs/models.md)",
    )
    a = p.parse_args(argv)
    model, profile = load_model(a.checkpoint)
    extra = recipe_record(load(a.checkpoint))
    check = not a.no_check
    if a.refine_only:
        manifest = export_refine_into(model, profile, a.out, extra, check=check, jump_on=a.jump_on)
    else:
        manifest = export_bundle(model, profile, a.out, extra, check=check, jump_on=a.jump_on)
    for _name, g in manifest["graphs"].items():
        chk = g.get("check", {}).get("max_abs_diff")
        print(
            f"{a.out / g['file']}: {g['bytes']} bytes, sha256 {g['sha256'][:12]}…, "
            f"max |onnx - torch| = {chk}"
        )
    print(a.out / "model.json")


if __name__ == "__main__":
    main()
