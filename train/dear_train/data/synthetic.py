"""Tiny synthetic ToF RGB-D captures, rendered analytically with NumPy.

The real dataset comes from the simulator (``synth/``); this module exists so that the tests
and the ``smoke`` profile can run the whole training and export path without it. Scenes are a
tilted background plane and a few boxes (planes in 3-D have inverse depth affine in the pixel
coordinates, so each is exact), textured so that RGB and amplitude share structure the flow
net can match. The ToF depth gets what makes refinement necessary: noise proportional to
depth, an MPI-like positive bias on the far side of depth edges, and flying pixels on edges.

``python -m dear_train.data.synthetic OUT --frames 8`` writes one.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from dear_train.augmentation import AugmentConfig, draw_perturbation
from dear_train.data.capture import (
    Frame,
    FrameEntry,
    Intrinsics,
    Manifest,
    write_frame,
    write_manifest,
)
from dear_train.geometry import Calibration, synthesize_view

DEPTH_SCALE = 0.001


def _smooth_noise(rng: np.random.Generator, h: int, w: int, cells: int) -> np.ndarray:
    """Low-frequency noise in [0, 1]: a coarse random grid upsampled bilinearly."""
    g = rng.random((cells + 1, cells + 1))
    ys = np.linspace(0, cells, h)
    xs = np.linspace(0, cells, w)
    y0 = np.minimum(ys.astype(int), cells - 1)
    x0 = np.minimum(xs.astype(int), cells - 1)
    fy = (ys - y0)[:, None]
    fx = (xs - x0)[None, :]
    a = g[y0][:, x0]
    b = g[y0][:, x0 + 1]
    c = g[y0 + 1][:, x0]
    d = g[y0 + 1][:, x0 + 1]
    return (a * (1 - fx) * (1 - fy) + b * fx * (1 - fy) + c * (1 - fx) * fy + d * fx * fy).astype(
        np.float32
    )


def render_scene(rng: np.random.Generator, h: int, w: int) -> dict[str, np.ndarray]:
    """One aligned scene: ``rgb`` uint8, ``amplitude`` raw, ``gt_depth`` and ``tof_depth`` (m)."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    xn, yn = xs / w - 0.5, ys / h - 0.5
    # Background plane: inverse depth affine in the pixel coordinates.
    inv = 1.0 / rng.uniform(3.0, 6.0) + rng.uniform(-0.05, 0.05) * xn + rng.uniform(0.0, 0.08) * yn
    depth = (1.0 / inv).astype(np.float32)
    obj = np.zeros((h, w), dtype=np.int32)
    for k in range(1, int(rng.integers(2, 5))):
        bh, bw = int(rng.integers(h // 5, h // 2)), int(rng.integers(w // 6, w // 2))
        y0, x0 = int(rng.integers(0, h - bh)), int(rng.integers(0, w - bw))
        z = rng.uniform(0.8, 2.5)
        tilt = rng.uniform(-0.3, 0.3)
        box_inv = 1.0 / z + tilt * (xs - x0) / w
        region = np.zeros((h, w), dtype=bool)
        region[y0 : y0 + bh, x0 : x0 + bw] = True
        nearer = region & (1.0 / box_inv < depth)
        depth = np.where(nearer, 1.0 / box_inv, depth).astype(np.float32)
        obj[nearer] = k
    # Texture shared by RGB and IR (both see the same surface markings).
    pattern = np.zeros((h, w), dtype=np.float32)
    colours = rng.random((obj.max() + 1, 3)).astype(np.float32)
    albedo = rng.uniform(0.3, 1.0, obj.max() + 1).astype(np.float32)
    for k in range(obj.max() + 1):
        f = rng.uniform(4, 16, 2)
        ph = rng.uniform(0, 2 * np.pi, 2)
        stripes = 0.5 + 0.5 * np.sin(2 * np.pi * (f[0] * xn + f[1] * yn) + ph[0])
        checks = (np.sin(2 * np.pi * f[1] * xn + ph[1]) * np.sin(2 * np.pi * f[0] * yn)) > 0
        pattern = np.where(obj == k, 0.6 * stripes + 0.4 * checks, pattern)
    marks = _smooth_noise(rng, h, w, 8)
    tex = 0.5 * pattern + 0.5 * marks
    rgb = colours[obj] * (0.35 + 0.65 * tex[..., None]) + 0.03 * rng.standard_normal((h, w, 3))
    rgb = np.clip(rgb * 255, 0, 255).astype(np.uint8)
    ir = albedo[obj] * (0.3 + 0.7 * tex)
    amplitude = 4000.0 * ir / depth**2 * (1 + 0.02 * rng.standard_normal((h, w)))
    # ToF artefacts.
    edge = np.zeros((h, w), dtype=bool)
    edge[:, 1:] |= np.abs(np.diff(depth, axis=1)) > 0.1 * depth[:, 1:]
    edge[1:, :] |= np.abs(np.diff(depth, axis=0)) > 0.1 * depth[1:, :]
    near_edge = _dilate(edge, 3)
    far_side = near_edge & (depth > _local_min(depth, 3) * 1.1)
    tof = depth * (1 + 0.004 * rng.standard_normal((h, w)))
    tof = tof + np.where(far_side, rng.uniform(0.02, 0.06), 0.0)
    flying = edge & (rng.random((h, w)) < 0.5)
    tof = np.where(flying, 0.5 * (depth + _local_max(depth, 1)), tof)
    tof = np.where(rng.random((h, w)) < 0.005, 0.0, tof)  # dropouts
    return {
        "rgb": rgb,
        "amplitude": np.clip(amplitude, 0, 65535).astype(np.float32),
        "gt_depth": depth,
        "tof_depth": tof.astype(np.float32),
    }


def _shifted(a: np.ndarray, r: int, fn: object) -> np.ndarray:
    p = np.pad(a, r, mode="edge")
    h, w = a.shape
    out = a.copy()
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            out = fn(out, p[r + dy : r + dy + h, r + dx : r + dx + w])  # type: ignore[operator]
    return out


def _dilate(m: np.ndarray, r: int) -> np.ndarray:
    return _shifted(m, r, np.logical_or)


def _local_min(a: np.ndarray, r: int) -> np.ndarray:
    return _shifted(a, r, np.minimum)


def _local_max(a: np.ndarray, r: int) -> np.ndarray:
    return _shifted(a, r, np.maximum)


def write_synthetic_capture(
    root: str | Path,
    frames: int = 6,
    height: int = 96,
    width: int = 128,
    seed: int = 0,
    misaligned_fraction: float = 0.5,
    augment_cfg: AugmentConfig | None = None,
) -> Path:
    """Write a capture directory of ``frames`` synthetic frames; returns its path.

    A ``misaligned_fraction`` of the frames carries a random perturbation (RGB and ground
    truth re-rendered in the perturbed view, ``.flow.flo`` written); the others are aligned
    (perturbation zero), for on-the-fly augmentation.
    """
    root = Path(root)
    rng = np.random.default_rng(seed)
    cfg = augment_cfg or AugmentConfig()
    f = 0.5 * width / np.tan(np.deg2rad(35.0))
    manifest = Manifest(
        width=width,
        height=height,
        intrinsics=Intrinsics(float(f), float(f), width / 2 - 0.5, height / 2 - 0.5),
        initial_calibration=Calibration(),
        depth_scale=DEPTH_SCALE,
        modulation_frequencies_hz=[20e6, 100e6],
        source={"generator": "dear_train.data.synthetic", "seed": seed},
    )
    n_mis = round(frames * misaligned_fraction)
    for i in range(frames):
        scene = render_scene(rng, height, width)
        frame = Frame(
            id=i,
            rgb=scene["rgb"],
            amplitude=scene["amplitude"],
            depth=scene["tof_depth"],
            gt_depth=scene["gt_depth"],
            perturbation=Calibration(),
        )
        if i < n_mis:
            p = draw_perturbation(rng, height, width, cfg)
            view = synthesize_view(scene["rgb"], scene["gt_depth"], p)
            frame.rgb, frame.gt_depth, frame.perturbation = view.rgb, view.depth, p
            frame.flow = np.stack([view.flow_u, view.flow_v])
        write_frame(root, frame, DEPTH_SCALE)
        manifest.frames.append(FrameEntry(i, i * 33_333_333, frame.perturbation))
    write_manifest(root, manifest)
    return root


def main() -> None:
    p = argparse.ArgumentParser(description="Write a tiny synthetic DEAR capture directory.")
    p.add_argument("out", type=Path)
    p.add_argument("--frames", type=int, default=6)
    p.add_argument("--height", type=int, default=96)
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    print(write_synthetic_capture(a.out, a.frames, a.height, a.width, a.seed))


if __name__ == "__main__":
    main()
