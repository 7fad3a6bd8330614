"""Capture-directory reading (validation errors name the file), normalisation, samples."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from dear_train.augmentation import AugmentConfig
from dear_train.data.capture import Capture, CaptureError, frame_path, read_flo, write_flo
from dear_train.data.dataset import DearDataset, normalize_amplitude, split_items


def _copy(src: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "cap"
    shutil.copytree(src, dst)
    return dst


def test_round_trip_of_a_synthetic_capture(capture_dir: Path) -> None:
    cap = Capture(capture_dir)
    assert len(cap) == 6 and cap.size == (96, 128)
    f = cap.load(0)
    assert f.rgb.shape == (96, 128, 3) and f.rgb.dtype == np.uint8
    assert f.depth.dtype == np.float32 and 0.5 < np.median(f.depth) < 7
    assert f.flow is not None and f.flow.shape == (2, 96, 128)
    assert f.perturbation is not None and f.perturbation.tx != 0
    assert cap.load(5).flow is None  # aligned frame


def test_errors_name_the_file(capture_dir: Path, tmp_path: Path) -> None:
    root = _copy(capture_dir, tmp_path)
    cap = Capture(root)
    depth = frame_path(root, 1, "depth.png")
    Image.fromarray(np.zeros((10, 10), dtype=np.uint16)).save(depth)
    with pytest.raises(CaptureError, match=r"000001\.depth\.png.*size 10×10"):
        cap.load(1)
    rgb = frame_path(root, 2, "rgb.png")
    rgb.write_bytes(b"not a png")
    with pytest.raises(CaptureError, match=r"000002\.rgb\.png.*not a readable PNG"):
        cap.load(2)
    Image.fromarray(np.zeros((96, 128), dtype=np.uint8)).save(frame_path(root, 3, "amp.png"))
    with pytest.raises(CaptureError, match=r"000003\.amp\.png.*expected 16-bit"):
        cap.load(3)
    frame_path(root, 4, "rgb.png").unlink()
    with pytest.raises(CaptureError, match=r"000004\.rgb\.png: missing"):
        cap.load(4)


def test_manifest_validation(capture_dir: Path, tmp_path: Path) -> None:
    root = _copy(capture_dir, tmp_path)
    manifest = root / "capture.json"
    good = json.loads(manifest.read_text())
    for bad, msg in [
        ({**good, "format": "other"}, "format"),
        ({**good, "version": 2}, "version"),
        ({**good, "depth_scale": 0}, "depth_scale"),
        ({k: v for k, v in good.items() if k != "frames"}, "frames"),
        ({**good, "frames": [good["frames"][1], good["frames"][0]]}, "monotonic"),
        (
            {**good, "frames": [{**good["frames"][0], "perturbation": {"tx": 1}}]},
            "perturbation",
        ),
    ]:
        manifest.write_text(json.dumps(bad))
        with pytest.raises(CaptureError, match=rf"capture\.json.*{msg}"):
            Capture(root)
    manifest.write_text("{")
    with pytest.raises(CaptureError, match="invalid JSON"):
        Capture(root)


def test_flo_round_trip_and_corruption(tmp_path: Path) -> None:
    flow = np.random.default_rng(0).normal(size=(2, 5, 7)).astype(np.float32)
    path = tmp_path / "a.flo"
    write_flo(path, flow)
    assert np.array_equal(read_flo(path), flow)
    path.write_bytes(path.read_bytes()[:-4])
    with pytest.raises(CaptureError, match=r"a\.flo.*bytes"):
        read_flo(path)


def test_amplitude_normalisation() -> None:
    depth = np.full((10, 10), 2.0, dtype=np.float32)
    depth[0, 0] = 0.0
    amp = np.arange(100, dtype=np.float32).reshape(10, 10) + 1
    out = normalize_amplitude(amp, depth, 90.0)
    i = amp * 4
    p90 = np.percentile(i[depth > 0], 90)
    assert out.dtype == np.float32 and out.min() >= 0 and out.max() == 1.0
    assert out[0, 0] == 0.0  # invalid depth: I·D² = 0
    assert np.isclose(out[1, 0], i[1, 0] / p90)


def test_dataset_samples_and_skips(capture_dir: Path, tmp_path: Path) -> None:
    root = _copy(capture_dir, tmp_path)
    manifest = json.loads((root / "capture.json").read_text())
    del manifest["frames"][0]["perturbation"]  # unknown misalignment → not usable
    (root / "capture.json").write_text(json.dumps(manifest))
    ds = DearDataset([root], crop=(64, 96), augment=AugmentConfig(), seed=1)
    assert ds.skipped == 1 and len(ds) == 5
    s = ds[0]
    assert s["rgb"].shape == (3, 64, 96) and s["flow"].shape == (2, 64, 96)
    assert s["flow_valid"].dtype.is_floating_point is False
    assert float(s["amplitude"].min()) >= 0 and float(s["amplitude"].max()) <= 1
    # Augmented (aligned) frames draw a new misalignment each epoch.
    aligned = ds.items.index((0, 5))
    a = ds[aligned]["flow"].clone()
    ds.set_epoch(1)
    assert not np.allclose(a.numpy(), ds[aligned]["flow"].numpy())
    train, val = split_items(ds, 0.2, 0)
    assert len(val) == 1 and len(train) == 4 and not set(train) & set(val)
    with pytest.raises(ValueError, match="multiples of 8"):
        DearDataset([root], crop=(60, 96))
