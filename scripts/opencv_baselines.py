"""OpenCV depth-refinement baselines on a dear capture, scored exactly like `dear eval`.

Reads a capture written by `dear-synth generate` (or any capture with ground truth:
capture.json + frames/NNNNNN.{rgb,depth,gt,mask}.png), runs OpenCV contrib filters on the
ToF depth guided by the RGB image, and prints the depth MAE (cm) per input-error class
(low / mid / high / all) in the format of `dear eval`'s table, with the project's definition
(`DepthErrorSplit` of train/dear_train/metrics.py, numpy only, which mirrors
evaluate/src/metrics.rs):

- evaluated pixels: ground truth in (0, 4 m] and inside the ground-truth mask, and a valid
  (> 0) input depth;
- per frame, pixels are ranked by the *input's* |depth - gt| (stable sort, row-major ties);
  the first quarter is "low", then "mid", "high", "outliers";
- a method's error is |output - gt| accumulated per class over all frames; pixels where the
  output is invalid (0) count as missing, not as error; "all" is over every valid output.

The first row ("ToF input") must reproduce `dear eval`'s "raw-tof" row to the printed
digit; check that before trusting the others.

Methods (each on the raw ToF depth, guide = the RGB image):
- fgs: cv2.ximgproc.fastGlobalSmootherFilter (Min et al. 2014) over a lambda × sigma_color
  grid, in a normalised form (filter depth·valid and valid, divide) so that invalid depth
  (0) is never averaged into valid pixels; `--fgs-plain` also runs it on the depth as is;
- jbf: cv2.ximgproc.jointBilateralFilter over a small grid, normalised the same way;
- median5: a 5 × 5 median over the valid pixels of each window.

Run (OpenCV lives in its own venv, not in the project's):

    python3 -m venv /tmp/cvenv
    /tmp/cvenv/bin/pip install opencv-contrib-python-headless numpy pillow
    /tmp/cvenv/bin/python scripts/opencv_baselines.py /work/data/results/aligned \
        [--json out.json] [--frames N] [--fgs-plain]

and compare with `target/release/dear eval --capture CAPTURE --baselines --out DIR`.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray
from PIL import Image

# The metric definitions (numpy only): train/dear_train/metrics.py, usable without the training
# venv's torch.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "train"))
from dear_train.metrics import DepthErrorSplit

CLASSES = ("low", "mid", "high", "outliers")

# Parameter grids; the best of each family (by MAE all) is reported.
FGS_LAMBDA = (1.0, 2.0, 4.0, 8.0, 16.0, 64.0, 256.0)
FGS_SIGMA_COLOUR = (2.0, 4.0, 8.0, 12.0, 16.0, 24.0)
JBF_DIAMETER = (5, 9, 15)
JBF_SIGMA_COLOUR = (8.0, 16.0, 32.0, 64.0)
JBF_SIGMA_SPACE = (2.0, 4.0, 8.0)

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]
Filter = Callable[[F32, U8], F32]


@dataclass
class Frame:
    """One frame of a capture, in metres (0 = invalid), as pipeline/src/capture reads it."""

    id: int
    rgb: U8  # (H, W, 3)
    depth: F32
    gt: F32  # already masked: 0 outside the ground-truth mask


def read_capture(root: Path, limit: int | None) -> Iterator[Frame]:
    """Frames of a capture (pipeline/src/capture/{layout,reader,png}.rs)."""
    manifest = json.loads((root / "capture.json").read_text())
    scale = np.float32(manifest["depth_scale"])
    frames = manifest["frames"] if limit is None else manifest["frames"][:limit]
    for entry in frames:
        fid = int(entry["id"])
        base = root / "frames" / f"{fid:06d}"

        def png(kind: str, base: Path = base) -> NDArray[np.generic]:
            return np.asarray(Image.open(f"{base}.{kind}.png"))

        rgb = png("rgb")[..., :3].astype(np.uint8)
        depth = png("depth").astype(np.float32) * scale
        gt = png("gt").astype(np.float32) * scale
        valid = (gt > 0) & np.isfinite(gt)
        if Path(f"{base}.mask.png").exists():
            valid &= png("mask") != 0
        if Path(f"{base}.flow.flo").exists():
            flow = read_flo(Path(f"{base}.flow.flo"))
            known = np.isfinite(flow).all(axis=2) & (np.abs(flow) < 1e9 / 10).all(axis=2)
            valid &= known
        yield Frame(fid, rgb, depth, np.where(valid, gt, np.float32(0)))


def read_flo(path: Path) -> F32:
    """Middlebury .flo: magic 202021.25, width, height, then (u, v) f32 pairs."""
    data = path.read_bytes()
    w, h = np.frombuffer(data, np.int32, 2, 4)
    return np.frombuffer(data, np.float32, int(w) * int(h) * 2, 12).reshape(int(h), int(w), 2)


def normalised(run: Callable[[F32], F32], depth: F32) -> F32:
    """Filter depth·valid and valid with the same linear filter, divide: holes get no weight."""
    valid = (depth > 0).astype(np.float32)
    num = run(depth * valid)
    den = run(valid)
    out = np.where(den > 1e-3, num / np.maximum(den, 1e-6), 0.0).astype(np.float32)
    return np.where(valid > 0, out, np.float32(0))  # evaluated only where the input is valid


def fgs(lam: float, sigma: float, plain: bool = False) -> Filter:
    def run(depth: F32, rgb: U8) -> F32:
        def f(src: F32) -> F32:
            out = cv2.ximgproc.fastGlobalSmootherFilter(rgb, src, lam, sigma)
            return np.asarray(out, np.float32)

        return f(depth) if plain else normalised(f, depth)

    return run


def jbf(d: int, sigma_colour: float, sigma_space: float) -> Filter:
    def run(depth: F32, rgb: U8) -> F32:
        guide = rgb.astype(np.float32)

        def f(src: F32) -> F32:
            out = cv2.ximgproc.jointBilateralFilter(guide, src, d, sigma_colour, sigma_space)
            return np.asarray(out, np.float32)

        return normalised(f, depth)

    return run


def median5(depth: F32, rgb: U8) -> F32:
    """5 × 5 median over the valid pixels of each window (invalid pixels stay 0)."""
    h, w = depth.shape
    pad = np.pad(np.where(depth > 0, depth, np.nan), 2, constant_values=np.nan)
    stack = np.stack([pad[dy : dy + h, dx : dx + w] for dy in range(5) for dx in range(5)])
    out = np.nanmedian(stack, axis=0).astype(np.float32)
    return np.where(depth > 0, out, np.float32(0))


def identity(depth: F32, rgb: U8) -> F32:
    return depth


def evaluate(
    frames: list[Frame], methods: dict[str, Filter]
) -> dict[str, tuple[DepthErrorSplit, float]]:
    results: dict[str, tuple[DepthErrorSplit, float]] = {}
    for name, method in methods.items():
        split, seconds = DepthErrorSplit(), 0.0
        for fr in frames:
            t0 = time.perf_counter()
            out = method(fr.depth, fr.rgb)
            seconds += time.perf_counter() - t0
            split.add_frame(fr.depth, out, fr.gt)
        results[name] = (split, 1e3 * seconds / max(len(frames), 1))
    return results


def row(name: str, split: DepthErrorSplit, ms: float) -> str:
    def fmt(v: float | None) -> str:
        return "–" if v is None else f"{v:.2f}"

    cells = [fmt(split.mae_cm(k)) for k in range(3)] + [fmt(split.mae_all_cm())]
    return f"| {name} | " + " | ".join(cells) + f" | {100 * split.coverage():.1f} % | {ms:.1f} |"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("--frames", type=int, default=None, help="only the first N frames")
    ap.add_argument("--json", type=Path, default=None, help="write every row here")
    ap.add_argument("--fgs-plain", action="store_true", help="also FGS on the depth with holes")
    args = ap.parse_args()

    frames = list(read_capture(args.capture, args.frames))
    methods: dict[str, Filter] = {"ToF input": identity}
    for lam, sigma in itertools.product(FGS_LAMBDA, FGS_SIGMA_COLOUR):
        methods[f"fgs lambda={lam:g} sigma_color={sigma:g}"] = fgs(lam, sigma)
        if args.fgs_plain:
            methods[f"fgs-plain lambda={lam:g} sigma_color={sigma:g}"] = fgs(lam, sigma, True)
    for d, sc, ss in itertools.product(JBF_DIAMETER, JBF_SIGMA_COLOUR, JBF_SIGMA_SPACE):
        methods[f"jbf d={d} sigma_color={sc:g} sigma_space={ss:g}"] = jbf(d, sc, ss)
    methods["median 5x5"] = median5
    results = evaluate(frames, methods)

    print(f"{args.capture}: {len(frames)} frames")
    print("| Method | MAE low (cm) | MAE mid (cm) | MAE high (cm) | MAE all (cm) | Coverage | ms |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, (split, ms) in results.items():
        print(row(name, split, ms))

    def best(prefix: str) -> str:
        names = [n for n in results if n.startswith(prefix + " ")]
        return min(names, key=lambda n: results[n][0].mae_all_cm() or float("inf"))

    print("\nBest per family (by MAE all):")
    for name in ("ToF input", best("fgs"), best("jbf"), "median 5x5"):
        print(row(name, *results[name]))
    if args.fgs_plain:
        print(row(best("fgs-plain"), *results[best("fgs-plain")]))
    if args.json is not None:
        rows = [
            {
                "method": name,
                "mae_cm": [split.mae_cm(k) for k in range(4)],
                "mae_all_cm": split.mae_all_cm(),
                "coverage": split.coverage(),
                "ms_per_frame": ms,
            }
            for name, (split, ms) in results.items()
        ]
        args.json.write_text(json.dumps({"capture": str(args.capture), "methods": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
