"""The outside aligner: an RGB↔ToF calibration per frame from OpenCV alone, scored as `dear eval`.

A baseline for issue 32 ("the bar, not a tool to ship"): what a user with OpenCV and an afternoon
would build. Per frame:

1. gradient-magnitude images (Sobel after a Gaussian blur of `--blur` px) of the RGB luma and of
   the log ToF amplitude, each scaled to 8 bits by its 99th percentile;
2. DIS optical flow (`cv2.DISOpticalFlow`, preset `--preset`) both ways between them: ToF → RGB
   `f(q)` and RGB → ToF `b(p)`; a ToF pixel is kept where the two agree,
   `|f(q) + b(q + f(q))| < --fb` px, its depth is valid and its amplitude gradient is in the
   frame's top half (DIS interpolates over flat regions);
3. the project's flow model, `W(p) = (t_x / z + c_x, t_y / z + c_y)` (capture/src/calibration.rs
   `flow_formula`; train/dear_train/geometry.py `Calibration.flow_at`): a ToF pixel `q` at depth
   `z(q)` is seen by RGB pixel `q − W(z(q))`, so `−f(q) = t / z(q) + c`. RANSAC (two-point
   samples, inliers within `--ransac` px end-point error), then Huber IRLS (δ = half the RANSAC
   threshold) on the points within twice it. Too few inliers: the capture's static calibration.

The fitted calibration is then scored exactly as `dear eval` scores a calibration method
(evaluate/src/methods.rs): the ToF depth is splatted to the RGB grid through it
(`StaticAligner::align_into`, pipeline/src/align.rs and geometry/splat.rs, reproduced here in
float32 with the same summation order), the flow is `W(aligned depth)` (the flow of the median
valid depth where nothing landed), and the AEPE is `dear_train.metrics.aepe` (the mirror of
evaluate/src/metrics.rs) against the ground-truth flow (`.flo`, else the frame's perturbation at
the ground-truth depth) over the ground-truth mask, averaged over frames.

Checks (run both before trusting a figure):

- `--check`: numpy only, no capture, no OpenCV: the AEPE against fixtures/metrics/aepe.json, the
  flow model against fixtures/geometry/flow_from_depth.json and the splat against
  fixtures/geometry/synthesize_view.json (the Rust-written shared cases);
- `--check-static EVAL_JSON`: the static calibration scored by this script must equal the
  `static-calibration` row of that `dear eval` output on the same capture to 1e-9 px.

Run (OpenCV in its own venv, as scripts/opencv_baselines.py, whose capture reader is used):

    python3 -m venv out/opencv-venv
    out/opencv-venv/bin/pip install opencv-contrib-python-headless numpy pillow
    out/opencv-venv/bin/python scripts/outside_aligner.py --check
    out/opencv-venv/bin/python scripts/outside_aligner.py CAPTURE [--json OUT] \
        [--check-static DEAR_EVAL_OUT/eval.json] [--tune]

`--tune` scores a grid of the four parameters on CAPTURE (tune on a set that is not reported).
The defaults are the grid's best on a set no table reports: `dear-synth generate --count 40
--seed 1234 --width 320 --height 240`, then `perturb --sigma 2 --seed 11` (σ = 4 px of 640×480,
the RGB view rendered from the RGB camera): 3.15 px there, against 6.32 px static (blur 0, the
best on the earlier splatted views whose black disocclusions marked every occluding contour:
3.76 px).
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]
# The metric (numpy only): train/dear_train/metrics.py, usable without the training venv's torch.
sys.path.insert(0, str(ROOT / "train"))
from dear_train.metrics import aepe  # noqa: E402

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]

# pipeline/src/geometry/splat.rs and surface.rs.
SPLAT_MIN_WEIGHT = np.float32(1e-3)
SPLAT_MIN_COVERAGE = np.float32(0.5)
DEPTH_EDGE_REL = np.float32(0.03)
DEPTH_EDGE_ABS_M = np.float32(0.01)
F32_MIN_POSITIVE = np.finfo(np.float32).tiny
# Fixed parts of the aligner (not tuned).
RANSAC_ITERATIONS = 400
RANSAC_POINTS = 6000  # points the RANSAC scores on (a random subset)
MIN_INLIERS = 200
IRLS_ITERATIONS = 10
PRESETS = {"ultrafast": 0, "fast": 1, "medium": 2}


@dataclass(frozen=True)
class Calibration:
    """The weak calibration `W(p) = (tx / z + cx, ty / z + cy)` (px·m, px·m, px, px)."""

    tx: float = 0.0
    ty: float = 0.0
    cx: float = 0.0
    cy: float = 0.0

    @staticmethod
    def of(d: dict[str, float] | None) -> Calibration:
        return Calibration() if d is None else Calibration(d["tx"], d["ty"], d["cx"], d["cy"])

    def formula(self, z: F32) -> tuple[F32, F32]:
        """`flow_formula` in float32 (infinite or NaN where `z` is not a valid depth)."""
        f = np.float32
        with np.errstate(divide="ignore", invalid="ignore"):
            return f(self.tx) / z + f(self.cx), f(self.ty) / z + f(self.cy)


@dataclass(frozen=True)
class Params:
    """The aligner's tuned parameters."""

    preset: str = "medium"
    blur: float = 1.0  # Gaussian σ (px) before the gradients
    fb: float = 2.0  # forward-backward threshold (px)
    ransac: float = 1.0  # RANSAC inlier threshold (px)


def valid_depth(z: F32) -> NDArray[np.bool_]:
    """`is_valid_depth`: positive and finite."""
    return (z > 0) & (z < np.inf)


# ---------------------------------------------------------------- dear eval's scoring path


def splat_sums(depth: F32, calib: Calibration) -> tuple[F32, F32, F32]:
    """Passes 1 and 2 of the forward splat (geometry/splat.rs): per target pixel the front
    surface's weight, every surface's weight, and the front surface's weighted depth sum, in
    float32 and in the serial scatter's order (source pixels row-major, taps (0,0), (0,1),
    (1,0), (1,1)) so that the sums are bit-identical to Rust's."""
    h, w = depth.shape
    f = np.float32
    z = depth.astype(np.float32).ravel()
    ys, xs = np.divmod(np.arange(h * w), w)
    fu, fv = calib.formula(z)
    with np.errstate(invalid="ignore"):
        tx, ty = xs.astype(np.float32) - fu, ys.astype(np.float32) - fv
        ok = valid_depth(z) & (np.abs(tx) < 1e9) & (np.abs(ty) < 1e9)
    tx, ty, zs = tx[ok], ty[ok], z[ok]
    x0, y0 = np.floor(tx), np.floor(ty)
    fx, fy = tx - x0, ty - y0
    one = f(1.0)
    wts = np.stack([(one - fx) * (one - fy), fx * (one - fy), (one - fx) * fy, fx * fy], axis=1)
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    tap_x = x0[:, None] + np.array([0, 1, 0, 1])
    tap_y = y0[:, None] + np.array([0, 0, 1, 1])
    keep = (wts > SPLAT_MIN_WEIGHT) & (tap_x >= 0) & (tap_y >= 0) & (tap_x < w) & (tap_y < h)
    target = (tap_y * w + tap_x)[keep]  # row-major over (source, tap): the serial order
    wt = wts[keep]
    zt = np.broadcast_to(zs[:, None], wts.shape)[keep]
    zbuf = np.full(h * w, np.inf, np.float32)
    np.minimum.at(zbuf, target, zt)
    front_z = zbuf[target]
    same = np.abs(zt - front_z) <= np.maximum(DEPTH_EDGE_REL * front_z, DEPTH_EDGE_ABS_M)
    front = np.where(same, wt, f(0.0))
    any_w = np.zeros(h * w, np.float32)
    ws = np.zeros(h * w, np.float32)
    zsum = np.zeros(h * w, np.float32)
    np.add.at(any_w, target, wt)
    np.add.at(ws, target, front)
    np.add.at(zsum, target, front * zt)
    return ws.reshape(h, w), any_w.reshape(h, w), zsum.reshape(h, w)


def upper_median_valid(depth: F32) -> float:
    """`median_valid_depth` of align.rs: every 7th pixel (row-major), the valid ones, the element
    of rank ⌊n/2⌋; 1.0 without any."""
    v = depth.ravel()[::7]
    v = np.sort(v[valid_depth(v)])
    return float(v[v.size // 2]) if v.size else 1.0


def align(depth: F32, calib: Calibration) -> tuple[F32, F32, F32]:
    """`StaticAligner::align_into`: the ToF depth on the RGB grid (0 where no surface lands) and
    the RGB→ToF flow `(u, v)` it aligned with."""
    ws, any_w, zsum = splat_sums(depth, calib)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = zsum / np.maximum(ws, F32_MIN_POSITIVE)
    ok = (ws > 0) & (any_w >= SPLAT_MIN_COVERAGE) & valid_depth(z)
    out = np.where(ok, z, np.float32(0.0))
    fallback = calib.formula(np.float32(upper_median_valid(depth)))
    fu, fv = calib.formula(out)
    u = np.where(ok, fu, fallback[0]).astype(np.float32)
    v = np.where(ok, fv, fallback[1]).astype(np.float32)
    return out, u, v


def truth_flow(gt: F32, perturbation: Calibration | None, flo: F32 | None) -> F32 | None:
    """`evaluate::ground_truth_flow`: the `.flo` file, else the perturbation at the ground-truth
    depth (NaN where it is invalid), as `(2, H, W)`."""
    if flo is not None:
        return np.moveaxis(flo, 2, 0)
    if perturbation is None:
        return None
    u, v = perturbation.formula(gt)
    ok = valid_depth(gt)
    return np.stack([np.where(ok, u, np.nan), np.where(ok, v, np.nan)]).astype(np.float32)


def score(depth: F32, calib: Calibration, truth: F32, mask: NDArray[np.bool_]) -> float | None:
    """One frame's AEPE of `calib` as `dear eval` computes it for a calibration method."""
    _, u, v = align(depth, calib)
    return aepe(np.stack([u, v]), truth, mask)


# ---------------------------------------------------------------- reading a capture


@dataclass
class Sample:
    id: int
    rgb: U8
    amplitude: F32
    depth: F32
    truth: F32 | None  # (2, H, W) ground-truth RGB→ToF flow
    mask: NDArray[np.bool_]  # `evaluate::ground_truth_mask`


def read_samples(root: Path, limit: int | None) -> Iterator[Sample]:
    """The frames of a capture with what `dear eval` reads of them; depth, RGB, ground truth and
    mask through scripts/opencv_baselines.py's reader (which needs OpenCV's venv)."""
    sys.path.insert(0, str(ROOT / "scripts"))
    from opencv_baselines import read_capture, read_flo
    from PIL import Image

    manifest = json.loads((root / "capture.json").read_text())
    entries = {int(e["id"]): e for e in manifest["frames"]}
    for fr in read_capture(root, limit):
        base = root / "frames" / f"{fr.id:06d}"
        amplitude = np.asarray(Image.open(f"{base}.amp.png")).astype(np.float32)
        flo_path = Path(f"{base}.flow.flo")
        flo = read_flo(flo_path) if flo_path.exists() else None
        p = entries[fr.id].get("perturbation")
        # read_capture zeroes gt outside the mask and unknown flow: gt > 0 is the eval mask.
        truth = truth_flow(fr.gt, None if p is None else Calibration.of(p), flo)
        yield Sample(fr.id, fr.rgb, amplitude, fr.depth, truth, fr.gt > 0)


def static_calibration(root: Path) -> Calibration:
    return Calibration.of(
        json.loads((root / "capture.json").read_text()).get("initial_calibration")
    )


# ---------------------------------------------------------------- the aligner


def gradient_image(img: F32, blur: float) -> U8:
    import cv2

    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3)
    mag = np.sqrt(gx * gx + gy * gy)
    scale = float(np.percentile(mag, 99)) or 1.0
    return np.clip(255.0 * mag / scale, 0, 255).astype(np.uint8)


def fit_lsq(s: F32, y: F32, w: F32) -> NDArray[np.float64] | None:
    """Weighted least squares of `y = t·s + c` for both components: `((tx, cx), (ty, cy))`."""
    sw, sws, swss = w.sum(), (w * s).sum(), (w * s * s).sum()
    det = sw * swss - sws * sws
    if sw <= 0 or det <= 1e-12 * max(sw * swss, 1e-30):
        return None
    out = np.empty((2, 2))
    for k in range(2):
        swy, swsy = (w * y[k]).sum(), (w * s * y[k]).sum()
        out[k] = ((sw * swsy - sws * swy) / det, (swss * swy - sws * swsy) / det)
    return out


@dataclass
class Flows:
    """Steps 1–2 of one frame: the ToF→RGB flow, its forward-backward error, the edge pixels."""

    fwd: F32  # (H, W, 2): ToF q ↔ RGB q + fwd(q)
    fb_err: F32
    edge: NDArray[np.bool_]


def dis_flows(sample: Sample, preset: str, blur: float) -> Flows:
    import cv2

    luma = cv2.cvtColor(sample.rgb, cv2.COLOR_RGB2GRAY).astype(np.float32)
    amp = np.log1p(np.maximum(sample.amplitude, 0)).astype(np.float32)
    g_rgb, g_tof = gradient_image(luma, blur), gradient_image(amp, blur)
    dis = cv2.DISOpticalFlow_create(PRESETS[preset])
    fwd = dis.calc(g_tof, g_rgb, None)
    bwd = dis.calc(g_rgb, g_tof, None)  # RGB p ↔ ToF p + bwd(p)
    h, w = g_tof.shape
    gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
    back = cv2.remap(bwd, gx + fwd[..., 0], gy + fwd[..., 1], cv2.INTER_LINEAR, borderValue=np.nan)
    fb_err = np.hypot(fwd[..., 0] + back[..., 0], fwd[..., 1] + back[..., 1])
    return Flows(fwd, fb_err, g_tof >= np.percentile(g_tof, 50))


def estimate(
    sample: Sample,
    params: Params,
    fallback: Calibration,
    seed: int = 0,
    flows: Flows | None = None,
) -> Calibration:
    """The outside aligner's calibration for one frame (see the module docs); `flows`, when
    given, are this frame's `dis_flows` for `params`' preset and blur."""
    fl = dis_flows(sample, params.preset, params.blur) if flows is None else flows
    fwd, fb_err, edge = fl.fwd, fl.fb_err, fl.edge
    z = sample.depth
    with np.errstate(invalid="ignore"):
        sel = valid_depth(z) & (fb_err < params.fb) & edge
    if sel.sum() < MIN_INLIERS:
        return fallback
    s = (1.0 / z[sel]).astype(np.float64)
    y = -np.stack([fwd[..., 0][sel], fwd[..., 1][sel]]).astype(np.float64)

    # RANSAC over two-point samples, scored on a subset.
    rng = np.random.default_rng(seed)
    sub = rng.choice(s.size, min(s.size, RANSAC_POINTS), replace=False)
    ss, ys = s[sub], y[:, sub]
    i, j = rng.integers(0, ss.size, (2, RANSAC_ITERATIONS))
    ds = ss[i] - ss[j]
    good = np.abs(ds) > 1e-3
    i, j, ds = i[good], j[good], ds[good]
    t = (ys[:, i] - ys[:, j]) / ds  # (2, K)
    c = ys[:, i] - t * ss[i]
    res = np.hypot(
        ys[0][None] - (t[0][:, None] * ss[None] + c[0][:, None]),
        ys[1][None] - (t[1][:, None] * ss[None] + c[1][:, None]),
    )
    if res.shape[0] == 0:
        return fallback
    best = int(np.argmax((res < params.ransac).sum(axis=1)))
    model = np.array([[t[0, best], c[0, best]], [t[1, best], c[1, best]]])

    def residual(m: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.hypot(y[0] - (m[0, 0] * s + m[0, 1]), y[1] - (m[1, 0] * s + m[1, 1]))

    r = residual(model)
    if (r < params.ransac).sum() < MIN_INLIERS:
        return fallback
    delta = 0.5 * params.ransac
    use = r < 2 * params.ransac
    for _ in range(IRLS_ITERATIONS):
        wts = np.where(r[use] <= delta, 1.0, delta / np.maximum(r[use], 1e-12))
        fitted = fit_lsq(s[use], y[:, use], wts)
        if fitted is None:
            break
        model = fitted
        r = residual(model)
    return Calibration(
        float(model[0, 0]), float(model[1, 0]), float(model[0, 1]), float(model[1, 1])
    )


# ---------------------------------------------------------------- evaluation


@dataclass
class Run:
    aepe_px: float | None  # mean over frames, as dear eval
    frames: int
    per_frame: list[float | None]
    ms_per_frame: float


def mean(values: list[float | None]) -> float | None:
    got = [v for v in values if v is not None]
    return float(np.mean(got)) if got else None


def evaluate(
    samples: list[Sample],
    static: Calibration,
    params: Params | None,
    cache: dict[int, tuple[tuple[str, float], Flows]] | None = None,
) -> Run:
    """AEPE of the static calibration (`params` None) or of the aligner with `params`; `cache`
    keeps each frame's DIS flows for the last preset and blur (tuning runs share them)."""
    per_frame: list[float | None] = []
    seconds = 0.0
    for sm in samples:
        t0 = time.perf_counter()
        flows = None
        if params is not None and cache is not None:
            key = (params.preset, params.blur)
            if sm.id not in cache or cache[sm.id][0] != key:
                cache[sm.id] = (key, dis_flows(sm, params.preset, params.blur))
            flows = cache[sm.id][1]
        calib = static if params is None else estimate(sm, params, static, sm.id, flows)
        seconds += time.perf_counter() - t0
        per_frame.append(None if sm.truth is None else score(sm.depth, calib, sm.truth, sm.mask))
    return Run(mean(per_frame), len(samples), per_frame, 1e3 * seconds / max(len(samples), 1))


def check_static(run: Run, eval_json: Path) -> bool:
    """The static row must reproduce `dear eval`'s (whose per-frame sum is in f64, as here)."""
    doc = json.loads(eval_json.read_text())
    row = next(m for m in doc["methods"] if m["method"] == "static-calibration")
    ok = row["frames"] == run.frames and run.aepe_px is not None
    diff = abs(run.aepe_px - row["aepe_px"]) if ok and run.aepe_px is not None else float("inf")
    print(
        f"static calibration: this script {run.aepe_px!r} px, dear eval {row['aepe_px']!r} px "
        f"({eval_json}), |difference| {diff:.3g} px over {run.frames} frames"
    )
    return ok and diff <= 1e-9


# ---------------------------------------------------------------- the fixture checks


def fixture_array(spec: dict[str, Any]) -> NDArray[Any]:
    dtype = {"f32": np.float32, "bool": np.bool_, "u8": np.uint8}[spec["dtype"]]
    return np.array(spec["data"], dtype=np.float64).astype(dtype).reshape(spec["shape"])


def check_fixtures() -> bool:
    """The scoring path against the shared, Rust-checked cases under fixtures/ (numpy only)."""
    ok = True

    def report(name: str, good: bool, detail: str) -> None:
        nonlocal ok
        ok &= good
        print(f"{'ok  ' if good else 'FAIL'} {name}: {detail}")

    doc = json.loads((ROOT / "fixtures/metrics/aepe.json").read_text())
    got = []
    for fr in doc["inputs"]["frames"]:
        a = {k: fixture_array(v) for k, v in fr.items()}
        got.append(
            aepe(
                np.stack([a["estimate_u"], a["estimate_v"]]),
                np.stack([a["truth_u"], a["truth_v"]]),
                a["valid"],
            )
        )
    want = doc["outputs"]
    per_frame_ok = all(
        (g is None and w is None) or (g is not None and w is not None and abs(g - w) < 1e-9)
        for g, w in zip(got, want["per_frame"], strict=True)
    )
    m = mean(got)
    report(
        "aepe.json",
        per_frame_ok and m is not None and abs(m - want["mean_over_frames"]) < 1e-9,
        f"per frame {got}, mean over frames {m}",
    )

    doc = json.loads((ROOT / "fixtures/geometry/flow_from_depth.json").read_text())
    depth = fixture_array(doc["inputs"]["depth"])
    u, v = Calibration.of(doc["inputs"]["calibration"]).formula(depth)
    valid = valid_depth(depth)
    exp = {k: fixture_array(doc["outputs"][k]) for k in ("flow_u", "flow_v", "valid")}
    err = max(
        float(np.abs(np.where(valid, u, 0) - exp["flow_u"]).max()),
        float(np.abs(np.where(valid, v, 0) - exp["flow_v"]).max()),
    )
    report(
        "flow_from_depth.json",
        bool((valid == exp["valid"]).all()) and err <= 1e-6,
        f"max |Δflow| {err:.2g} px",
    )

    # The splat's passes 1–2 with synthesize_view's pass 3 (front weight ≥ 0.5).
    doc = json.loads((ROOT / "fixtures/geometry/synthesize_view.json").read_text())
    params = doc["inputs"]["params"]
    same_constants = (
        np.float32(params["min_weight"]) == SPLAT_MIN_WEIGHT
        and np.float32(params["min_coverage"]) == SPLAT_MIN_COVERAGE
        and np.float32(params["depth_edge_rel"]) == DEPTH_EDGE_REL
        and np.float32(params["depth_edge_abs_m"]) == DEPTH_EDGE_ABS_M
    )
    depth = fixture_array(doc["inputs"]["depth"])
    p = Calibration.of(doc["inputs"]["perturbation"])
    ws, _, zsum = splat_sums(depth, p)
    keep = ws >= SPLAT_MIN_COVERAGE
    out = np.where(keep, zsum / np.maximum(ws, F32_MIN_POSITIVE), 0).astype(np.float32)
    fu, fv = p.formula(out)
    exp = {k: fixture_array(doc["outputs"][k]) for k in ("depth", "flow_u", "flow_v", "valid")}
    err = max(
        float(np.abs(out - exp["depth"]).max()),
        float(np.abs(np.where(keep, fu, 0) - exp["flow_u"]).max()),
        float(np.abs(np.where(keep, fv, 0) - exp["flow_v"]).max()),
    )
    report(
        "synthesize_view.json",
        same_constants and bool((keep == exp["valid"]).all()) and err <= 1e-6,
        f"{int(keep.sum())} valid pixels, max |Δdepth|, |Δflow| {err:.2g}",
    )
    return ok


# ---------------------------------------------------------------- main

TUNE_GRID = {
    "preset": ("fast", "medium"),
    "blur": (0.0, 1.0, 2.0),
    "fb": (0.5, 1.0, 2.0),
    "ransac": (0.5, 1.0, 2.0),
}


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("capture", type=Path, nargs="?")
    ap.add_argument("--frames", type=int, default=None, help="only the first N frames")
    ap.add_argument("--json", type=Path, default=None, help="write the results here")
    ap.add_argument("--check", action="store_true", help="check the scoring against fixtures/")
    ap.add_argument(
        "--check-static",
        type=Path,
        default=None,
        metavar="EVAL_JSON",
        help="fail unless the static row equals this dear eval output's (same capture)",
    )
    ap.add_argument("--tune", action="store_true", help="score the parameter grid instead")
    for name, default in asdict(Params()).items():
        ap.add_argument(f"--{name}", type=type(default), default=default)
    args = ap.parse_args()

    if args.check and not check_fixtures():
        return 1
    if args.capture is None:
        if not args.check:
            ap.error("give a capture, or --check")
        return 0
    params = Params(args.preset, args.blur, args.fb, args.ransac)
    if params.preset not in PRESETS:
        ap.error(f"--preset: one of {', '.join(PRESETS)}")
    static = static_calibration(args.capture)
    samples = list(read_samples(args.capture, args.frames))
    static_run = evaluate(samples, static, None)
    print(f"{args.capture}: {len(samples)} frames; static calibration {static_run.aepe_px} px")
    if args.check_static is not None and not check_static(static_run, args.check_static):
        print("the static row does not reproduce dear eval's: the scoring differs")
        return 1
    if args.tune:
        rows = []
        cache: dict[int, tuple[tuple[str, float], Flows]] = {}
        for values in itertools.product(*TUNE_GRID.values()):
            p = Params(*values)  # type: ignore[arg-type]
            run = evaluate(samples, static, p, cache)
            rows.append((run.aepe_px or float("inf"), p, run.ms_per_frame))
            print(f"{p}: AEPE {run.aepe_px:.4f} px, {run.ms_per_frame:.0f} ms/frame", flush=True)
        rows.sort(key=lambda r: r[0])
        print("best:", rows[0][1], f"{rows[0][0]:.4f} px")
        if args.json is not None:
            tuned = [{"params": asdict(p), "aepe_px": a, "ms": ms} for a, p, ms in rows]
            args.json.write_text(
                json.dumps({"capture": str(args.capture), "grid": tuned}, indent=1)
            )
        return 0
    run = evaluate(samples, static, params)
    print(f"outside aligner {params}: AEPE {run.aepe_px} px, {run.ms_per_frame:.0f} ms/frame")
    if args.json is not None:
        doc = {
            "capture": str(args.capture),
            "method": "outside-aligner",
            "params": asdict(params),
            "frames": run.frames,
            "aepe_px": run.aepe_px,
            "aepe_per_frame_px": run.per_frame,
            "ms_per_frame": run.ms_per_frame,
            "static_aepe_px": static_run.aepe_px,
            "static_checked_against": None if args.check_static is None else str(args.check_static),
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
