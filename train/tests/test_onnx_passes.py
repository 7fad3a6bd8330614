"""dear_train.onnx_passes: the strided-depthwise rewrite keeps every output value."""

from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch
from torch import nn

from dear_train.onnx_passes import subsample_strided_depthwise


class _Net(nn.Module):
    def __init__(self) -> None:
        super().__init__()
        torch.manual_seed(0)
        self.full = nn.Conv2d(3, 8, 3, stride=2, padding=1)
        self.dw = nn.Conv2d(8, 8, 3, stride=2, padding=1, groups=8, bias=False)
        self.pw = nn.Conv2d(8, 4, 1)
        self.grouped = nn.Conv2d(4, 4, 3, stride=2, padding=1, groups=2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.grouped(self.pw(self.dw(torch.relu(self.full(x)))))


def _export(path: Path) -> onnx.ModelProto:
    torch.onnx.export(
        _Net().eval(),
        (torch.rand(1, 3, 32, 48),),
        str(path),
        input_names=["x"],
        output_names=["y"],
        dynamic_axes={"x": {2: "H", 3: "W"}, "y": {2: "h", 3: "w"}},
        opset_version=17,
        dynamo=False,
    )
    return onnx.load(str(path))


def test_only_strided_depthwise_convolutions_are_rewritten_and_outputs_are_identical(
    tmp_path: Path,
) -> None:
    before = tmp_path / "before.onnx"
    model = _export(before)
    assert subsample_strided_depthwise(model) == 1  # not the full or the grouped conv
    after = tmp_path / "after.onnx"
    onnx.save(model, str(after))
    strided = [
        n
        for n in model.graph.node
        if n.op_type == "Conv"
        and any(a.name == "strides" and list(a.ints) == [2, 2] for a in n.attribute)
    ]
    assert len(strided) == 2
    a = ort.InferenceSession(str(before), providers=["CPUExecutionProvider"])
    b = ort.InferenceSession(str(after), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(3)
    # Even and odd intermediate sides: 32x48 -> 16x24 -> 8x12; 40x56 -> 20x28 -> 10x14;
    # 36x44 -> 18x22 -> 9x11; 30x26 -> 15x13 (odd before the depthwise layer).
    for h, w in [(32, 48), (40, 56), (36, 44), (30, 26)]:
        x = rng.random((1, 3, h, w), dtype=np.float32)
        (want,) = a.run(None, {"x": x})
        (got,) = b.run(None, {"x": x})
        assert got.shape == want.shape
        assert np.array_equal(got, want), (h, w, np.abs(got - want).max())


def test_a_graph_without_strided_depthwise_convolutions_is_left_alone(tmp_path: Path) -> None:
    model = _export(tmp_path / "m.onnx")
    subsample_strided_depthwise(model)
    nodes = len(model.graph.node)
    assert subsample_strided_depthwise(model) == 0
    assert len(model.graph.node) == nodes
