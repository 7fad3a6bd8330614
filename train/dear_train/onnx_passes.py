"""Rewrites of exported ONNX graphs that keep every output value and run faster in tract.

``subsample_strided_depthwise``: tract 0.23 runs a depthwise convolution with stride 2 on a
generic path about 15x slower per output than its stride-1 kernel (``graph_profile``: the
refine graph's four strided depthwise layers took 3.9 of its 13-17 ms at 640x480). The pass
computes each such layer at stride 1 and keeps every second row and column. The subsampling is
written as pad-to-even, reshape ``[N, C, H/2, 2, W/2, 2]``, slice index 0 of both pair axes,
reshape back — a plain ``Slice`` with steps 2 would be folded straight back into the strided
convolution by tract's optimiser. Output ``y[i, j] = full[2i, 2j]`` is exactly the strided
convolution's (pads are the convolution's own, so the sampled positions are the same).

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


def subsample_strided_depthwise(model: onnx.ModelProto) -> int:
    """Rewrites every stride-2 depthwise ``Conv`` of ``model`` in place; returns how many."""
    graph = model.graph
    weights = {i.name: numpy_helper.to_array(i) for i in graph.initializer}
    nodes: list[onnx.NodeProto] = []
    count = 0
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

        def const(name: str, values: list[int]) -> str:
            graph.initializer.append(numpy_helper.from_array(np.array(values, np.int64), name))
            return name

        two = const(f"{p}/two", [2])
        hw = const(f"{p}/hw", [2, 3])
        shape = f"{p}/shape"
        nodes.append(helper.make_node("Shape", [full], [shape]))
        # pads = [0, 0, 0, 0, 0, 0, H mod 2, W mod 2]: an odd side gets one zero row/column,
        # which only ever lands in the dropped half of a pair.
        size = f"{p}/size"
        nodes.append(helper.make_node("Gather", [shape, hw], [size], axis=0))
        odd = f"{p}/odd"
        nodes.append(helper.make_node("Mod", [size, two], [odd]))
        zeros = const(f"{p}/zeros", [0] * 6)
        pads = f"{p}/pads"
        nodes.append(helper.make_node("Concat", [zeros, odd], [pads], axis=0))
        even = f"{p}/even"
        nodes.append(helper.make_node("Pad", [full, pads], [even], mode="constant"))
        half = f"{p}/half"
        padded = f"{p}/padded"
        nodes.append(helper.make_node("Add", [size, odd], [padded]))
        nodes.append(helper.make_node("Div", [padded, two], [half]))
        h2, w2 = f"{p}/h2", f"{p}/w2"
        nodes.append(helper.make_node("Gather", [half, const(f"{p}/i0", [0])], [h2], axis=0))
        nodes.append(helper.make_node("Gather", [half, const(f"{p}/i1", [1])], [w2], axis=0))
        keep = const(f"{p}/keep", [0, 0])
        six = f"{p}/six"
        nodes.append(helper.make_node("Concat", [keep, h2, two, w2, two], [six], axis=0))
        pairs = f"{p}/pairs"
        nodes.append(helper.make_node("Reshape", [even, six], [pairs]))
        picked = f"{p}/picked"
        nodes.append(
            helper.make_node(
                "Slice",
                [
                    pairs,
                    const(f"{p}/z2", [0, 0]),
                    const(f"{p}/o2", [1, 1]),
                    const(f"{p}/axes", [3, 5]),
                ],
                [picked],
            )
        )
        four = f"{p}/four"
        nodes.append(helper.make_node("Concat", [keep, h2, w2], [four], axis=0))
        nodes.append(helper.make_node("Reshape", [picked, four], [out]))
        count += 1
    del graph.node[:]
    graph.node.extend(nodes)
    if count:
        onnx.checker.check_model(model)
    return count


def rewrite_bundle(bundle: Path) -> dict[str, int]:
    """Applies the pass to every graph of ``bundle`` and updates ``model.json``'s ``bytes``
    and ``sha256``; returns the layers rewritten per graph."""
    from dear_train.export import sha256

    manifest_path = bundle / "model.json"
    manifest = json.loads(manifest_path.read_text())
    done = {}
    for role, graph in manifest["graphs"].items():
        path = bundle / graph["file"]
        model = onnx.load(str(path))
        n = subsample_strided_depthwise(model)
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
        print(f"{role}: {n} strided depthwise convolutions subsampled")


if __name__ == "__main__":
    main()
