"""The Python capture writer (``write_capture``): it writes only what the Rust reader reads, with
the Rust writer's rounding, and refuses bad input naming the file and the field."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from dear_train.data import capture as cap
from dear_train.data.capture import Capture, CaptureError, Frame, Intrinsics, Manifest
from dear_train.geometry import Calibration

H, W = 2, 3


def manifest(**changes: object) -> Manifest:
    m = Manifest(W, H, Intrinsics(2.0, 2.0, 1.0, 0.5), Calibration(), 0.001, [20e6], None)
    for key, value in changes.items():
        setattr(m, key, value)
    return m


def frame(frame_id: int, timestamp_ns: int, **planes: np.ndarray) -> Frame:
    ones = np.ones((H, W), np.float32)
    return Frame(
        id=frame_id,
        rgb=planes.get("rgb", np.zeros((H, W, 3), np.uint8)),
        amplitude=planes.get("amplitude", ones),
        depth=planes.get("depth", ones),
        timestamp_ns=timestamp_ns,
    )


def test_a_written_capture_reads_back(tmp_path: Path) -> None:
    depth = np.array([[0.0, 1.0, 2.5], [np.nan, -1.0, 70.0]], np.float32)
    root = cap.write_capture(
        tmp_path / "c", manifest(), [frame(4, 123, depth=depth), frame(9, 123)]
    )
    c = Capture(root)
    assert [e.id for e in c.manifest.frames] == [4, 9]
    f = c.load(0)
    assert f.timestamp_ns == 123 and f.perturbation is None
    # Invalid depths are stored as 0; beyond 65535 units the value saturates, as in Rust.
    np.testing.assert_array_equal(
        f.depth, np.array([[0, 1000, 2500], [0, 0, 65535]], np.float32) * np.float32(0.001)
    )
    assert not (root / "capture.json.tmp").exists()


def test_writer_rounding_is_the_rust_writers() -> None:
    """Hand-checked ties of ``f32::round`` (half away from zero) where NumPy's ``round``
    (half to even) differs; ``rounding`` in ``fixtures/capture/python_written.json`` has more,
    which the Rust test runs through the Rust writer's functions."""
    amplitude = np.array([0.5, 1.5, 2.5, -2.5, 0.49999997, 65535.5, np.nan, np.inf], np.float32)
    np.testing.assert_array_equal(cap.amplitude_to_u16(amplitude), [1, 2, 3, 0, 0, 65535, 0, 0])
    depth = np.array([0.625, 70.0, -1.0, np.nan, np.inf, 0.0], np.float32)
    np.testing.assert_array_equal(cap.depth_to_u16(depth, 0.25), [3, 280, 0, 0, 0, 0])
    np.testing.assert_array_equal(cap.depth_to_u16(np.array([70.0], np.float32), 0.001), [65535])


def test_writer_refuses_a_directory_with_files(tmp_path: Path) -> None:
    (tmp_path / "old.txt").write_text("x")
    with pytest.raises(CaptureError, match=rf"{tmp_path}: expected a new or empty directory"):
        cap.write_capture(tmp_path, manifest(), [frame(0, 0)])


def test_writer_refuses_frames_out_of_order(tmp_path: Path) -> None:
    for frames in ([frame(3, 10), frame(3, 20)], [frame(3, 10), frame(4, 9)]):
        root = tmp_path / f"c{len(list(tmp_path.iterdir()))}"
        with pytest.raises(CaptureError, match=r"000003\.depth\.png|000004\.depth\.png"):
            cap.write_capture(root, manifest(), frames)
        assert not (root / "capture.json").exists(), "an incomplete capture has no manifest"


def test_writer_refuses_a_plane_of_another_size(tmp_path: Path) -> None:
    with pytest.raises(CaptureError, match=r"000000\.amp\.png: size \(3, 3\)"):
        cap.write_capture(tmp_path / "c", manifest(), [frame(0, 0, amplitude=np.ones((3, 3)))])


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"width": 9000}, "width"),
        ({"depth_scale": 0.0}, "depth_scale"),
        ({"intrinsics": Intrinsics(float("nan"), 2.0, 1.0, 0.5)}, "intrinsics.fx"),
        ({"modulation_frequencies_hz": [float("inf")]}, "modulation_frequencies_hz[0]"),
    ],
)
def test_writer_refuses_a_manifest_the_readers_would(
    changes: dict, field: str, tmp_path: Path
) -> None:
    with pytest.raises(CaptureError, match=rf"capture\.json: field `{re.escape(field)}`"):
        cap.write_capture(tmp_path / "c", manifest(**changes), [])
    assert not (tmp_path / "c" / "capture.json").exists()


def test_writer_refuses_a_frame_id_past_the_file_names(tmp_path: Path) -> None:
    with pytest.raises(CaptureError, match=r"field `frames\[0\]\.id`: 1000000 is greater"):
        cap.write_capture(tmp_path / "c", manifest(), [frame(1_000_000, 0)])


def test_reader_refuses_a_non_finite_flow_naming_file_and_pixel(tmp_path: Path) -> None:
    path = tmp_path / "000000.flow.flo"
    flow = np.zeros((2, 2, 3), np.float32)
    flow[0, 0, 2] = 1e10  # Middlebury's "unknown": a value
    cap.write_flo(path, flow)
    np.testing.assert_array_equal(cap.read_flo(path, (2, 3)), flow)
    flow[1, 1, 1] = np.nan
    cap.write_flo(path, flow)
    with pytest.raises(CaptureError, match=r"000000\.flow\.flo: .*nan at row 1, column 1"):
        cap.read_flo(path, (2, 3))


def test_manifest_errors_name_file_and_field(tmp_path: Path) -> None:
    root = cap.write_capture(tmp_path / "c", manifest(), [frame(0, 0)])
    path = root / "capture.json"
    good = json.loads(path.read_text())
    good["frames"][0]["perturbation"] = {"tx": 1.0, "ty": 0.0, "cx": 0.0}
    path.write_text(json.dumps(good))
    # Inside the anyOf (a calibration or null): what is wrong with the calibration.
    with pytest.raises(
        CaptureError, match=r"capture\.json: field `frames\[0\]\.perturbation`: 'cy' is a required"
    ):
        Capture(root)
