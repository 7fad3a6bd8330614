"""dear_train.onnx_passes: the strided-depthwise rewrite keeps every output value, the
sub-pixel rewrite of transposed convolutions every value up to float summation order."""

from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch
from torch import nn

from dear_train.onnx_passes import subpixel_transposed_conv, subsample_strided_depthwise


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
    assert [n.op_type for n in model.graph.node].count("MaxPool") == 1
    _assert_same_outputs(before, after)


def _assert_same_outputs(before: Path, after: Path) -> None:
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


def test_the_earlier_reshape_and_slice_subsampling_becomes_the_pool(tmp_path: Path) -> None:
    """A graph the pass rewrote in its earlier form (pad to even, reshape to pairs, slice,
    reshape back; the fixture is ``_Net`` as that form of the pass, at f24063a, left it) gets
    the max pool, with none of the old nodes or constants left and every output the same."""
    before = Path(__file__).parents[2] / "fixtures/onnx_passes/reshape-subsample.onnx"
    model = onnx.load(str(before))
    assert any(n.op_type == "Slice" for n in model.graph.node)
    assert subsample_strided_depthwise(model) == 1
    ops = [n.op_type for n in model.graph.node]
    assert ops.count("MaxPool") == 1
    assert not {"Slice", "Pad", "Reshape", "Shape", "Gather", "Mod"} & set(ops)
    assert not [i.name for i in model.graph.initializer if "/subsample" in i.name]
    after = tmp_path / "after.onnx"
    onnx.save(model, str(after))
    _assert_same_outputs(before, after)
    assert subsample_strided_depthwise(model) == 0


def test_a_graph_without_strided_depthwise_convolutions_is_left_alone(tmp_path: Path) -> None:
    model = _export(tmp_path / "m.onnx")
    subsample_strided_depthwise(model)
    nodes = len(model.graph.node)
    assert subsample_strided_depthwise(model) == 0
    assert len(model.graph.node) == nodes


class _Decoder(nn.Module):
    """The decoders' transposed convolutions (refine: k3 p1 output padding 1; flow and
    fusion: k4 p1, no bias) and one the pass must leave alone (grouped)."""

    def __init__(self) -> None:
        super().__init__()
        torch.manual_seed(1)
        self.up3 = nn.ConvTranspose2d(6, 5, 3, stride=2, padding=1, output_padding=1)
        self.up4 = nn.ConvTranspose2d(5, 4, 4, stride=2, padding=1, bias=False)
        self.grouped = nn.ConvTranspose2d(4, 4, 4, stride=2, padding=1, groups=2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.grouped(torch.relu(self.up4(torch.relu(self.up3(x)))))


def test_transposed_convolutions_become_phase_convolutions_with_the_same_outputs(
    tmp_path: Path,
) -> None:
    before = tmp_path / "before.onnx"
    torch.onnx.export(
        _Decoder().eval(),
        (torch.rand(1, 6, 8, 12),),
        str(before),
        input_names=["x"],
        output_names=["y"],
        dynamic_axes={"x": {2: "H", 3: "W"}, "y": {2: "h", 3: "w"}},
        opset_version=17,
        dynamo=False,
    )
    model = onnx.load(str(before))
    assert subpixel_transposed_conv(model) == 2  # not the grouped one
    assert [n.op_type for n in model.graph.node].count("ConvTranspose") == 1
    assert [n.op_type for n in model.graph.node].count("DepthToSpace") == 2
    # The replaced weights are gone, so the file does not carry both.
    names = {i.name for i in model.graph.initializer}
    assert not any(n.startswith(("up3.", "up4.")) for n in names), names
    after = tmp_path / "after.onnx"
    onnx.save(model, str(after))
    a = ort.InferenceSession(str(before), providers=["CPUExecutionProvider"])
    b = ort.InferenceSession(str(after), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(5)
    for h, w in [(8, 12), (7, 9), (1, 1), (16, 5)]:
        x = rng.standard_normal((1, 6, h, w), dtype=np.float32)
        (want,) = a.run(None, {"x": x})
        (got,) = b.run(None, {"x": x})
        assert got.shape == want.shape == (1, 4, 8 * h, 8 * w)
        # Same products summed in another order: float rounding only.
        assert np.abs(got - want).max() <= 1e-5 * max(1.0, np.abs(want).max()), (h, w)
    assert subpixel_transposed_conv(model) == 0
