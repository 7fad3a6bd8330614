"""Rewrites of exported ONNX graphs that keep their outputs and run faster in tract.

``subsample_strided_depthwise``: tract 0.23 runs a depthwise convolution with stride 2 on a
generic path about 15x slower per output than its stride-1 kernel (``graph_profile``: the
refine graph's four strided depthwise layers took 3.9 of its 13-17 ms at 640x480). The pass
computes each such layer at stride 1 and keeps every second row and column with a ``MaxPool``
over one element at stride 2 — a plain ``Slice`` with steps 2 would be folded straight back
into the strided convolution by tract's optimiser, and the pad / reshape / slice form this pass
wrote before ran on tract's generic slicing path (at 640x480 the first layer's took 0.50 ms,
the pool 0.15; graphs in that form are rewritten to the pool). Output ``y[i, j] = full[2i, 2j]``
is exactly the strided convolution's (pads are the convolution's own, so the sampled positions
are the same, and the pool's size ``floor((F − 1) / 2) + 1`` of a full side ``F`` is the
strided convolution's).

``subpixel_transposed_conv``: tract 0.23 runs a transposed convolution as a matrix product
followed by ``DeconvSum``, a scatter-add over the output that took 1.4 of the refine graph's
11 ms at 640x480 (``graph_profile``). A stride-2 transposed convolution whose output is exactly
twice its input (kernel k, pads p, output padding o with k + o - 2p = 2) is the same as a
stride-1 convolution that computes the four output phases as channels, followed by
``DepthToSpace``: output row 2m + a reads input rows m + d with kernel row a + p - 2d, so each
phase is a small convolution and the four share one kernel (zero where a phase has no tap).
Equal up to float summation order (max |diff| ~1e-5 on outputs of ~30).

Run on a bundle (rewrites its graphs and the manifest's sizes and checksums):

    python -m dear_train.onnx_passes models/edge
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import onnx
from onnx import helper, numpy_helper


def _attr(node: onnx.NodeProto, name: str, default: object = None) -> object:
    for a in node.attribute:
        if a.name == name:
            return helper.get_attribute_value(a)
    return default


def _is_strided_depthwise(node: onnx.NodeProto, weights: dict[str, np.ndarray]) -> bool:
    if node.op_type != "Conv" or list(_attr(node, "strides", [1, 1])) != [2, 2]:
        return False
    group = int(_attr(node, "group", 1))
    w = weights.get(node.input[1])
    # Depthwise: one input channel per group (weight [C_out, 1, kh, kw]), C_out = group.
    return group > 1 and w is not None and w.shape[1] == 1 and w.shape[0] == group


def _subsample(full: str, out: str, name: str) -> onnx.NodeProto:
    """``out[i, j] = full[2i, 2j]``: a max pool over one element with stride 2 (no padding),
    so each output is exactly one input value and the sizes are the strided convolution's."""
    return helper.make_node(
        "MaxPool", [full], [out], name=name, kernel_shape=[1, 1], strides=[2, 2]
    )


def subsample_strided_depthwise(model: onnx.ModelProto) -> int:
    """Rewrites every stride-2 depthwise ``Conv`` of ``model`` in place; returns how many.
    Graphs rewritten by the earlier reshape + slice form get the max pool instead
    (:func:`_replace_reshape_subsampling`, counted too)."""
    count = _replace_reshape_subsampling(model)
    graph = model.graph
    weights = {i.name: numpy_helper.to_array(i) for i in graph.initializer}
    nodes: list[onnx.NodeProto] = []
    for node in graph.node:
        if not _is_strided_depthwise(node, weights):
            nodes.append(node)
            continue
        p = f"{node.name or 'dwconv'}/subsample{count}"
        out = node.output[0]
        full = f"{p}/full"
        for a in node.attribute:
            if a.name == "strides":
                a.ints[:] = [1, 1]
        node.output[0] = full
        nodes.append(node)
        nodes.append(_subsample(full, out, f"{p}/picked"))
        count += 1
    del graph.node[:]
    graph.node.extend(nodes)
    if count:
        onnx.checker.check_model(model)
    return count


def _replace_reshape_subsampling(model: onnx.ModelProto) -> int:
    """Replaces each subsampling this pass used to write (pad to even, reshape to pairs, slice
    index 0 of both pair axes, reshape back: ``{p}/full`` → … → ``{p}/picked`` → the layer's
    output) with :func:`_subsample`'s max pool, which takes the same values: tract ran that
    ``Slice`` on its generic path (0.5 of the refine graph's ~12 ms at 640x480 for the first
    layer alone, ``graph_profile``), the pool in a quarter of that. Returns how many."""
    graph = model.graph

    def ended_by(node: onnx.NodeProto) -> str | None:
        """The block ``p`` whose last node (``Reshape`` of ``{p}/picked``) ``node`` is."""
        if node.op_type != "Reshape" or not node.input[0].endswith("/picked"):
            return None
        return node.input[0].removesuffix("/picked")

    produced = {o for n in graph.node for o in n.output}
    blocks = {p for n in graph.node if (p := ended_by(n)) and f"{p}/full" in produced}
    if not blocks:
        return 0

    def block_of(name: str) -> str | None:
        return next((p for p in blocks if name.startswith(f"{p}/")), None)

    nodes: list[onnx.NodeProto] = []
    for node in graph.node:
        if (p := ended_by(node)) in blocks:
            nodes.append(_subsample(f"{p}/full", node.output[0], f"{p}/picked"))
            continue
        p = block_of(node.output[0]) if node.output else None
        if p is None or node.output[0] == f"{p}/full":
            nodes.append(node)
    del graph.node[:]
    graph.node.extend(nodes)
    unused = [i for i in graph.initializer if block_of(i.name) is not None]
    for init in unused:
        graph.initializer.remove(init)
    onnx.checker.check_model(model)
    return len(blocks)


def _transposed_phases(node: onnx.NodeProto, weights: dict[str, np.ndarray]) -> tuple | None:
    """``(kernel, pad)`` of a transposed convolution :func:`subpixel_transposed_conv` can
    rewrite: weights (and bias) constant, group 1, stride 2, no dilation, square
    kernel and symmetric pads with output exactly twice the input; ``None`` otherwise."""
    if node.op_type != "ConvTranspose" or any(i not in weights for i in node.input[1:] if i):
        return None
    if list(_attr(node, "strides", [1, 1])) != [2, 2] or int(_attr(node, "group", 1)) != 1:
        return None
    if list(_attr(node, "dilations", [1, 1])) != [1, 1] or _attr(node, "output_shape"):
        return None
    k = list(_attr(node, "kernel_shape", weights[node.input[1]].shape[2:]))
    pads = list(_attr(node, "pads", [0, 0, 0, 0]))
    out_pad = list(_attr(node, "output_padding", [0, 0]))
    if len(k) != 2 or k[0] != k[1] or len(set(pads)) != 1 or out_pad[0] != out_pad[1]:
        return None
    if _attr(node, "auto_pad", b"NOTSET") not in (b"NOTSET", "NOTSET"):
        return None
    if k[0] + out_pad[0] - 2 * pads[0] != 2:
        return None
    return k[0], pads[0]


def _phase_kernel(w: np.ndarray, k: int, pad: int) -> tuple[np.ndarray, int, int]:
    """The stride-1 kernel ``[4 C_out, C_in, n, n]`` (phase-major channels, DepthToSpace's DCR
    order) of a stride-2 transposed kernel ``w`` ``[C_in, C_out, k, k]``, with the input
    offsets it covers: ``(kernel, first offset, last offset)``."""
    # Output 2m + a reads input m + d through kernel tap a + pad - 2d.
    taps = {
        (a, d): a + pad - 2 * d
        for a in (0, 1)
        for d in range(-k, k + 1)
        if 0 <= a + pad - 2 * d < k
    }
    lo = min(d for _, d in taps)
    hi = max(d for _, d in taps)
    n = hi - lo + 1
    c_in, c_out = w.shape[:2]
    kernel = np.zeros((4 * c_out, c_in, n, n), np.float32)
    for (a, dy), ky in taps.items():
        for (b, dx), kx in taps.items():
            phase = 2 * a + b
            kernel[phase * c_out : (phase + 1) * c_out, :, dy - lo, dx - lo] = w[:, :, ky, kx].T
    return kernel, lo, hi


def subpixel_transposed_conv(model: onnx.ModelProto) -> int:
    """Rewrites every qualifying stride-2 ``ConvTranspose`` of ``model`` in place as a
    ``Conv`` over the four output phases and a ``DepthToSpace``; returns how many. The
    transposed weights (and biases) it no longer needs are removed."""
    graph = model.graph
    weights = {i.name: numpy_helper.to_array(i) for i in graph.initializer}
    # The exporter shares equal initializers (e.g. zero biases) through Identity nodes.
    for node in graph.node:
        if node.op_type == "Identity" and node.input[0] in weights:
            weights[node.output[0]] = weights[node.input[0]]
    nodes: list[onnx.NodeProto] = []
    replaced: set[str] = set()
    count = 0
    for node in graph.node:
        shape = _transposed_phases(node, weights)
        if shape is None:
            nodes.append(node)
            continue
        k, pad = shape
        kernel, lo, hi = _phase_kernel(weights[node.input[1]], k, pad)
        p = f"{node.name or 'deconv'}/subpixel{count}"
        graph.initializer.append(numpy_helper.from_array(kernel, f"{p}/kernel"))
        inputs = [node.input[0], f"{p}/kernel"]
        replaced.add(node.input[1])
        if len(node.input) > 2 and node.input[2]:
            bias = np.tile(weights[node.input[2]], 4).astype(np.float32)
            graph.initializer.append(numpy_helper.from_array(bias, f"{p}/bias"))
            inputs.append(f"{p}/bias")
            replaced.add(node.input[2])
        phases = f"{p}/phases"
        n = hi - lo + 1
        nodes.append(
            helper.make_node(
                "Conv",
                inputs,
                [phases],
                name=f"{p}/conv",
                kernel_shape=[n, n],
                pads=[-lo, -lo, hi, hi],
                strides=[1, 1],
            )
        )
        nodes.append(
            helper.make_node(
                "DepthToSpace", [phases], [node.output[0]], name=f"{p}/interleave", blocksize=2
            )
        )
        count += 1
    del graph.node[:]
    graph.node.extend(nodes)
    if count:
        used = {i for n in graph.node for i in n.input}
        unused = [i for i in graph.initializer if i.name in replaced and i.name not in used]
        for init in unused:
            graph.initializer.remove(init)
        onnx.checker.check_model(model)
    return count


def rewrite_bundle(bundle: Path) -> dict[str, int]:
    """Applies both passes to every graph of ``bundle`` and updates ``model.json``'s ``bytes``
    and ``sha256``; returns the layers rewritten per graph."""
    from dear_train.export import sha256

    manifest_path = bundle / "model.json"
    manifest = json.loads(manifest_path.read_text())
    done = {}
    for role, graph in manifest["graphs"].items():
        path = bundle / graph["file"]
        model = onnx.load(str(path))
        n = subsample_strided_depthwise(model) + subpixel_transposed_conv(model)
        done[role] = n
        if n:
            onnx.save(model, str(path))
            graph["bytes"] = path.stat().st_size
            graph["sha256"] = sha256(path)
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")
    return done


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bundle", type=Path, help="bundle directory (model.json + graphs)")
    a = parser.parse_args(argv)
    for role, n in rewrite_bundle(a.bundle).items():
        print(f"{role}: {n} layers rewritten")


if __name__ == "__main__":
    main()
