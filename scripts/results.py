"""Assembles RESULTS.md from the `dear eval` outputs written by scripts/results.sh.

Reads OUT/<set>/eval.json for the sets aligned, sigma2, sigma4, sigma6; lays the numbers out
in the shape of the paper's tables; computes the relative improvements the paper reports and
sets ours beside them; copies the figures. Every number in RESULTS.md comes from eval.json.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
from pathlib import Path
from typing import Any

from dear_train.stats import Summary

SIGMAS = (2, 4, 6)
#: Misalignments beyond the paper's (issue 32: a dropped phone, a re-seated module).
LARGE_SIGMAS = (8, 12)
#: Families no training run samples, misaligned at σ = 4 px (sets "NAME-sigma4").
NEW_FAMILIES = ("clean", "empty", "wide", "dual-low")

# The paper's relative improvements (Qiu et al., ICCV 2019).
PAPER_AEPE_CHANGE = -0.12  # Table 1: refined flow vs rough flow
PAPER_KPN_VS_UNET = -0.16  # Table 2: ToF-KPN vs U-Net, MAE all
# Whole pipeline: input, modules trained separately, joint fine-tune (cm).
PAPER_WHOLE = (14.61, 2.90, 2.81)
# Table 1: rough and refined flow AEPE (px) per σ.
PAPER_AEPE = {2: (1.52, 1.34), 4: (2.10, 1.87), 6: (2.70, 2.45)}

Report = dict[str, Any]


#: The outside aligner's row (scripts/outside_aligner.py, written beside eval.json by results.sh).
OUTSIDE = "outside-aligner"
OUTSIDE_LABEL = "outside aligner (OpenCV DIS + RANSAC)"


def load(eval_dir: Path, name: str) -> dict[str, Report]:
    path = eval_dir / name / "eval.json"
    data = json.loads(path.read_text())
    report = {m["method"]: m for m in data["methods"]} | {"__file__": data}
    outside = eval_dir / name / "outside_aligner.json"
    if outside.is_file():
        report[OUTSIDE] = json.loads(outside.read_text())
    return report


def missing(eval_dir: Path, names: list[str]) -> str:
    """The line a section gets in place of its table when its sets were not evaluated."""
    files = ", ".join(f"`{eval_dir / n / 'eval.json'}`" for n in names)
    return f"– (not evaluated: no {files})"


def load_optional(eval_dir: Path, name: str) -> dict[str, Report] | None:
    """`load`, or None when the set has no eval.json (its figures are then written as –)."""
    return load(eval_dir, name) if (eval_dir / name / "eval.json").is_file() else None


def fmt(v: float | None, digits: int = 2) -> str:
    return "–" if v is None else f"{v:.{digits}f}"


def pct(new: float | None, old: float | None) -> str:
    if new is None or old is None or old == 0:
        return "–"
    return f"{100.0 * (new - old) / old:+.0f} %"


def bundles(report: dict[str, Report]) -> list[str]:
    """Bundle names: rows that have an '<name> aligned' companion."""
    return [m[: -len(" aligned")] for m in report if m.endswith(" aligned")]


#: The comparison bundle `scripts/results.sh` makes with `dear-gate detach`: the shipped
#: bundle's refiner without its multi-path gate (the row a learned component must beat).
WITHOUT_GATE = "-without-gate"


def variant_of(report: dict[str, Report], bundle: str) -> str:
    """The refinement variant of a bundle row, from the bundle's model.json."""
    if bundle.endswith(WITHOUT_GATE):
        base = variant_of(report, bundle.removesuffix(WITHOUT_GATE))
        return f"{base} without the multi-path gate"
    manifest = Path("models") / bundle / "model.json"
    if not manifest.is_file():
        return "?"
    variant = json.loads(manifest.read_text()).get("variant", "?")
    return {
        "kpn": "ToF-KPN",
        "gated": "gated KPN",
        "hybrid": "hybrid (gated KPN on the classical filter)",
        "guarded": "guarded (hybrid + expected-error fallback)",
        "unet": "U-Net, paper Table 2",
        "nonormaftbias": "vanilla KPN, paper Table 3",
        "norgb": "ToF-KPN without RGB, paper Table 3",
        "deeptof": "DeepToF, paper Table 2",
    }.get(variant, variant)


def sigma_columns(
    sets: dict[int, dict[str, Report]], sigmas: tuple[int, ...] = SIGMAS
) -> list[tuple[str, dict[str, Report]]]:
    """The σ sets as labelled columns of [`table_alignment`]."""
    return [(f"σ = {s} px", sets[s]) for s in sigmas]


def table_alignment(columns: list[tuple[str, dict[str, Report]]]) -> list[str]:
    """AEPE of every alignment method, one column per (label, set)."""
    lines = [
        "| Method | " + " | ".join(label for label, _ in columns) + " |",
        "|---|" + "---:|" * len(columns),
    ]

    def row(label: str, method: str, key: str) -> None:
        cells = [fmt(report.get(method, {}).get(key)) for _, report in columns]
        if any(c != "–" for c in cells):
            lines.append(f"| {label} | " + " | ".join(cells) + " |")

    row("static calibration (factory)", "static-calibration", "aepe_px")
    row("classical edge matching + LS", "edge-matching", "aepe_px")
    row("direct fit of (t, c) to all edges", "direct-fit", "aepe_px")
    row(OUTSIDE_LABEL, OUTSIDE, "aepe_px")
    for b in bundles(columns[0][1]):
        row(f"{b}: rough flow W_rough", b, "aepe_rough_px")
        row(f"{b}: final flow (direct fit from W_rough's calibration)", b, "aepe_px")
    row("true calibration (bound)", "oracle-calibration", "aepe_px")
    return lines


def families_section(columns: list[tuple[str, dict[str, Report]]]) -> list[str]:
    """Alignment at σ = 4 px on the families no training run sampled (issue 32)."""
    lines = [
        "## Alignment on families no training run sampled (σ = 4 px, issue 32)",
        "",
        (
            "The aligned sets of the refinement families below (`clean`: bright, single "
            "bounce; `empty`: near-empty rooms; `wide`: a 100° module with a large illuminator "
            "offset; `dual-low`: a dual-frequency 20 + 16 MHz module), misaligned at σ = 4 px "
            "(`dear-synth perturb --sigma 2 --seed 4`, RGB views rendered from the RGB camera). "
            "Only the shipped bundle runs: every bundle shares its flow graphs."
        ),
        "",
        *table_alignment(columns),
        "",
    ]
    ratios = []
    for label, report in columns:
        ours = report.get("edge", {}).get("aepe_px")
        outside = report.get(OUTSIDE, {}).get("aepe_px")
        alone = report.get("direct-fit", {}).get("aepe_px")
        if ours is not None and outside:
            ratio = f"{label} {ours / outside:.2f}×"
            if alone:
                ratio += f" ({pct(ours, alone)} against the direct fit without the network)"
            ratios.append(ratio)
    if ratios:
        lines += ["`edge`'s final AEPE over the outside aligner's: " + "; ".join(ratios) + ".", ""]
    return lines


def table_large(sets: dict[int, dict[str, Report]]) -> list[str]:
    """Large misalignments: AEPE, then the whole pipeline's MAE, per σ."""
    lines = [*table_alignment(sigma_columns(sets, LARGE_SIGMAS)), ""]
    heads = " | ".join(f"σ = {s} px" for s in LARGE_SIGMAS)
    lines += [
        f"| Whole pipeline, MAE all (cm) | {heads} |",
        "|---|" + "---:|" * len(LARGE_SIGMAS),
    ]
    rows = [("misaligned input", "raw-tof"), ("direct fit, no refinement", "direct-fit")]
    rows += [(f"`{b}`", b) for b in bundles(sets[LARGE_SIGMAS[0]])]
    for label, method in rows:
        cells = [fmt(sets[s].get(method, {}).get("mae_all_cm")) for s in LARGE_SIGMAS]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return lines


def large_paragraph(sets: dict[int, dict[str, Report]]) -> str:
    parts = []
    for s in LARGE_SIGMAS:
        r = sets[s]
        static = r.get("static-calibration", {}).get("aepe_px")
        finals = [r[b]["aepe_px"] for b in bundles(r) if r[b].get("aepe_px") is not None]
        outside = r.get(OUTSIDE, {}).get("aepe_px")
        if static is None or not finals:
            continue
        parts.append(
            f"σ = {s} px: {fmt(static)} → {fmt(min(finals))} px"
            + (f" (outside aligner {fmt(outside)})" if outside is not None else "")
        )
    return (
        "One frame does not bring these back to the aligned figures: "
        + "; ".join(parts)
        + ". The online estimator over a sequence, and the calibration health in every frame "
        "header (docs/calibration-health.md), are what tell a user that it has not converged."
    )


def table_refinement(aligned: dict[str, Report]) -> list[str]:
    lines = [
        "| Method | MAE low (cm) | MAE mid (cm) | MAE high (cm) | MAE all (cm) | ms / frame |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    rows = [
        ("ToF input", "raw-tof"),
        ("classical edge-aware filter", "static+classical-filter"),
    ]
    rows += [
        (
            f"`{b}` refinement ({variant_of(aligned, b)})",
            f"{b} refine @ true calibration",
        )
        for b in bundles(aligned)
    ]
    for label, method in rows:
        r = aligned.get(method)
        if r is None:
            continue
        cells = [fmt(v) for v in r["mae_cm"][:3]] + [fmt(r["mae_all_cm"])]
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {1e3 * r['median_seconds']:.1f} |")
    return lines


def table_whole(report: dict[str, Report]) -> list[str]:
    lines = [
        "| Method | AEPE (px) | MAE all (cm) | vs input | ms / frame |",
        "|---|---:|---:|---:|---:|",
    ]
    raw = report["raw-tof"]["mae_all_cm"]
    rows = [
        ("ToF input, unaligned", "raw-tof"),
        ("static calibration", "static-calibration"),
        ("static calibration + classical filter", "static+classical-filter"),
        ("edge matching + LS + classical filter", "edge-matching+classical-filter"),
        ("direct fit + classical filter", "direct-fit+classical-filter"),
    ]
    for b in bundles(report):
        rows += [
            (f"{b}: aligned (before refinement)", f"{b} aligned"),
            (f"{b}: whole pipeline", b),
            (
                f"{b}: refinement at the true calibration",
                f"{b} refine @ true calibration",
            ),
        ]
    for label, method in rows:
        r = report.get(method)
        if r is None:
            continue
        lines.append(
            f"| {label} | {fmt(r.get('aepe_px'))} | {fmt(r['mae_all_cm'])} | "
            f"{pct(r['mae_all_cm'], raw)} | {1e3 * r['median_seconds']:.1f} |"
        )
    return lines


def table_tracking(
    report: dict[str, Report], untracked: dict[str, Report] | None = None
) -> list[str]:
    lines = [
        "| Calibration | AEPE (px) | MAE all (cm) | flicker (cm) | flow network on | ms / frame |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    frames = report["__file__"]["frames_evaluated"]
    network = dict(report["__file__"].get("online_network_frames", []))
    rows = [
        ("(c) static (factory) calibration", "static-calibration", "–"),
        ("classical edge matching + LS, every frame", "edge-matching", "–"),
        ("direct fit of (t, c) to all edges, every frame", "direct-fit", "–"),
    ]
    for b in bundles(report):
        rows += [
            (f"(a) `{b}`: per-frame estimation (the paper)", b, f"{frames} / {frames}"),
            (
                f"(b) `{b}`: online filter",
                f"{b} online",
                f"{network.get(b, '?')} / {frames}",
            ),
        ]
    rows.insert(0, ("ToF input (as measured)", "raw-tof", "–"))
    picked = [(label, report.get(method), runs) for label, method, runs in rows]
    if untracked is not None:
        network_u = dict(untracked["__file__"].get("online_network_frames", []))
        for b in bundles(untracked):
            picked.append(
                (
                    f"(b′) `{b}`: online filter without edge tracking",
                    untracked.get(f"{b} online"),
                    f"{network_u.get(b, '?')} / {frames}",
                )
            )
    for label, r, runs in picked:
        if r is None:
            continue
        lines.append(
            f"| {label} | {fmt(r.get('aepe_px'))} | {fmt(r['mae_all_cm'])} | "
            f"{fmt(r.get('temporal_change_cm'))} | {runs} | {1e3 * r['median_seconds']:.1f} |"
        )
    return lines


#: Refinement sets of the family table (issue 33): name, what it is.
FAMILIES = [
    ("aligned", "default simulator settings (seed 9001)"),
    ("heldout", "outside every training range"),
    ("clean", "bright, single bounce, no multi-path"),
    ("empty", "near-empty rooms (0–2 objects)"),
    ("wide", "wide-angle module, 30–45 mm illuminator offset (never trained on)"),
    ("dual-low", "dual-frequency 20 + 16 MHz module (never trained on)"),
]


def opencv_best(eval_dir: Path, name: str) -> dict | None:
    """The best OpenCV filter (by MAE all) of scripts/opencv_baselines.py on a set, tuned on
    that very set (generous to OpenCV); None when it was not run."""
    path = eval_dir / name / "opencv.json"
    if not path.is_file():
        return None
    rows = json.loads(path.read_text())["methods"]
    filters = [r for r in rows if r["method"] != "ToF input" and r["mae_all_cm"] is not None]
    return min(filters, key=lambda r: r["mae_all_cm"]) if filters else None


def table_families(eval_dir: Path) -> list[str]:
    """Refinement at the true calibration on every family: MAE all (low quarter) in cm."""
    sets = [(n, d) for n, d in FAMILIES if (eval_dir / n / "eval.json").is_file()]
    reports = {n: load(eval_dir, n) for n, _ in sets}
    names = bundles(reports[sets[0][0]]) if sets else []
    header = ["Set", "ToF input", "classical filter", "best tuned OpenCV filter"]
    header += [f"`{b}`" for b in names]
    lines = ["| " + " | ".join(header) + " |", "|---" + "|---:" * (len(header) - 1) + "|"]

    def cell(r: dict | None) -> str:
        return "–" if r is None else f"{fmt(r['mae_all_cm'])} ({fmt(r['mae_cm'][0])})"

    for name, description in sets:
        r = reports[name]
        cells = [cell(r.get("raw-tof")), cell(r.get("static+classical-filter"))]
        cv = opencv_best(eval_dir, name)
        cells.append("–" if cv is None else f"{cell(cv)} {cv['method'].split()[0]}")
        cells += [cell(r.get(f"{b} refine @ true calibration")) for b in names]
        lines.append(f"| `{name}`: {description} | " + " | ".join(cells) + " |")
    return lines


def table_families_aepe(eval_dir: Path) -> list[str]:
    """Alignment on the same sets (aligned frames, a correct factory calibration): AEPE in px of
    every alignment method, the chain's final flow for each bundle."""
    sets = [n for n, _ in FAMILIES if (eval_dir / n / "eval.json").is_file()]
    reports = {n: load(eval_dir, n) for n in sets}
    names = bundles(reports[sets[0]]) if sets else []
    columns = [
        ("static calibration (factory)", "static-calibration"),
        ("classical edge matching + LS", "edge-matching"),
        ("direct fit", "direct-fit"),
    ]
    columns += [(f"`{b}` final flow", b) for b in names]
    header = ["Set", *(label for label, _ in columns)]
    lines = ["| " + " | ".join(header) + " |", "|---" + "|---:" * (len(header) - 1) + "|"]
    for name in sets:
        cells = [fmt(reports[name].get(m, {}).get("aepe_px")) for _, m in columns]
        lines.append(f"| `{name}` | " + " | ".join(cells) + " |")
    return lines


def table_reliability(report: dict[str, Report]) -> list[str]:
    """Predicted against measured error of every row with an expected-error confidence."""
    lines: list[str] = []
    for method, r in report.items():
        if method == "__file__" or not r.get("reliability"):
            continue
        lines += [
            f"`{method}`:",
            "",
            "| predicted error (cm) | pixels | mean predicted (cm) | mean measured (cm) |",
            "|---|---:|---:|---:|",
        ]
        for b in r["reliability"]:
            lo, hi = b["predicted_lo_cm"], b["predicted_hi_cm"]
            span = f"{lo:g}–{hi:g}" if hi is not None else f"≥ {lo:g}"
            lines.append(
                f"| {span} | {b['pixels']} | {fmt(b['mean_predicted_cm'])} | "
                f"{fmt(b['mean_measured_cm'])} |"
            )
        lines.append("")
    return lines


def reliability_score(bins: list[dict]) -> float | None:
    """How far a row's expected errors are from the errors measured: the pixel-weighted mean of
    |ln(mean measured / mean predicted)| over its reliability bins (0 when every bin's mean
    prediction is its mean error, ln 2 = 0.69 when they are 2× apart); None without bins."""
    used = [
        b
        for b in bins
        if b["pixels"] > 0 and b["mean_predicted_cm"] > 0 and b["mean_measured_cm"] > 0
    ]
    pixels = sum(b["pixels"] for b in used)
    if pixels == 0:
        return None
    return (
        sum(
            b["pixels"] * abs(math.log(b["mean_measured_cm"] / b["mean_predicted_cm"]))
            for b in used
        )
        / pixels
    )


def table_reliability_scores(eval_dir: Path) -> list[str]:
    """The reliability score of every expected-error row at the true calibration, per family."""
    sets = [n for n, _ in FAMILIES if (eval_dir / n / "eval.json").is_file()]
    reports = {n: load(eval_dir, n) for n in sets}
    methods = sorted(
        {
            m
            for r in reports.values()
            for m, row in r.items()
            if m != "__file__" and m.endswith("@ true calibration") and row.get("reliability")
        }
    )
    if not methods:
        return []
    lines = [
        "| Method | " + " | ".join(f"`{n}`" for n in sets) + " |",
        "|---" + "|---:" * len(sets) + "|",
    ]
    for m in methods:
        cells = [
            fmt(reliability_score(reports[n].get(m, {}).get("reliability") or [])) for n in sets
        ]
        lines.append(f"| `{m}` | " + " | ".join(cells) + " |")
    return lines


def criterion_seconds(root: Path, name: str) -> tuple[float, float] | None:
    """Median and p95 seconds per iteration of a criterion benchmark, from its samples."""
    path = root / name / "new" / "sample.json"
    if not path.is_file():
        return None
    sample = json.loads(path.read_text())
    # Nearest rank, the one definition of a reported percentile (dear_train.stats, dear-stats).
    s = Summary.of(t / n * 1e-9 for t, n in zip(sample["times"], sample["iters"], strict=True))
    return None if s is None else (s.p50, s.p95)


def table_latency(criterion: Path, onnxruntime: Path, interval: int) -> list[str]:
    lines = [
        (
            "| What | tract median (ms) | tract p95 (ms) | onnxruntime 1 thread (ms) | "
            "onnxruntime 2 threads (ms) | tract / onnxruntime, 1 thread |"
        ),
        "|---|---:|---:|---:|---:|---:|",
    ]
    ort: dict[tuple[str, int], float] = {}
    if onnxruntime.is_file():
        for r in json.loads(onnxruntime.read_text())["runs"]:
            ort[(r["graph"], r["threads"])] = r["median_s"]
    rows = [
        ("rough-flow network", "flow_net", "flow"),
        ("fusion network", "fuse_net", "fuse"),
        (
            # Format-2 bundles: tract runs the graph up to its head maps and the Rust tail (and
            # nothing of the classical filter) is included; onnxruntime runs the graph alone,
            # so the ratio compares unlike work for them.
            "refinement (graph; + Rust tail for format 2)",
            "refine_net",
            "refine",
        ),
        ("frame, rough flow every frame (the paper)", "frame_full", None),
        ("frame, online steady state (cached calibration)", "frame_cached_skip", None),
    ]
    times = {}
    for label, bench, graph in rows:
        t = criterion_seconds(criterion, bench)
        if t is None:
            continue
        times[bench] = t
        o1, o2 = (ort.get((graph, k)) if graph else None for k in (1, 2))
        cells = [f"{1e3 * t[0]:.1f}", f"{1e3 * t[1]:.1f}"]
        cells += ["–" if o is None else f"{1e3 * o:.1f}" for o in (o1, o2)]
        cells.append("–" if o1 is None else f"{t[0] / o1:.2f}×")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    if "frame_full" in times and "frame_cached_skip" in times:
        full, cached = times["frame_full"][0], times["frame_cached_skip"][0]
        mean = ((interval - 1) * cached + full) / interval
        lines.append(
            f"| frame, online with the network every {interval} frames (mean) | "
            f"{1e3 * mean:.1f} | – | – | – | – |"
        )
    return lines


def bench_threads(bench: dict) -> str:
    """Where a `deard-bench --json` run's threads ran: placed by the scheduler, pinned one per
    CPU (`--pin-threads`), or all on one CPU (`--pin-cpu`)."""
    if bench.get("pinned_cpu") is not None:
        return f"all on CPU {bench['pinned_cpu']}"
    pinned = bench.get("pinned_threads")
    if pinned:
        return "pinned, one per CPU " + ", ".join(str(cpu) for cpu in pinned)
    return f"{bench['threads_available']} CPUs, placed by the scheduler"


def table_daemon(benches: list[Path]) -> list[str]:
    """Rows of `deard-bench --json` files: time per frame and latency of the daemon's processing."""
    lines = [
        (
            "| Frame size | Threads | Calibration | frames with the flow network | "
            "frames overlapped | median (ms) | p95 (ms) | mean (ms) | latency median (ms) | "
            "stage medians (ms) |"
        ),
        "|---|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for path in benches:
        if not path.is_file():
            continue
        bench = json.loads(path.read_text())
        size = f"{bench['width']}×{bench['height']}"
        threads = bench_threads(bench)
        for m in bench["modes"]:
            runs = m["with_network"]["count"] if m["with_network"] else 0
            stages = ", ".join(f"{k} {v:.1f}" for k, v in m["stage_median_ms"] if v > 0)
            rows = [("all frames", m["all"])]
            if m["mode"] == "online" and m["without_network"]:
                rows.insert(0, ("steady state (no network)", m["without_network"]))
            # Files from before frames overlapped have neither figure.
            overlapped = m.get("overlapped_frames", 0)
            latency = m.get("latency", m["all"])["median_ms"]
            for what, t in rows:
                lines.append(
                    f"| {size} | {threads} | {m['mode']}, {what} | {runs} / {m['all']['count']} | "
                    f"{overlapped} | {t['median_ms']:.1f} | {t['p95_ms']:.1f} | "
                    f"{t['mean_ms']:.1f} | {latency:.1f} | {stages} |"
                )
    return lines


#: Work per pixel of each online steady-state stage at 640×480, counted from the code (not
#: measured): bytes read plus written once each (a pixel's neighbours read again from cache
#: are not counted) and f32 operations. The refine graph's FLOPs are its 0.1945 GMAC at
#: 640×480 (models/edge/model.json) × 2 / 307,200 px; its bytes are its six input planes
#: and its 1/2- and 1/4-resolution activations. An estimate of the order of magnitude: it
#: says which limit a stage is far from, not a precise fraction.
STAGE_WORK: dict[str, tuple[str, float, float]] = {
    "preprocess": ("RGB planes, amplitude normalisation and its percentile", 31, 8),
    "flow": (
        "splat (cells computed once, two scatter passes over 4 taps), flow from depth, fallback",
        130,
        55,
    ),
    "warp": ("depth and amplitude backward warps", 56, 40),
    "refine": (
        "classical filter (six stages) + refine graph + Rust tail + confidence + edge check",
        300,
        1860,
    ),
}


def table_limits(bench_path: Path) -> list[str]:
    """The physical-limit table: each stage's estimated work over its measured time, as a
    fraction of this machine's measured copy bandwidth and FMA peak (`deard-bench --machine`)."""
    if not bench_path.is_file():
        return []
    bench = json.loads(bench_path.read_text())
    machine = bench.get("machine")
    online = next((m for m in bench["modes"] if m["mode"] == "online"), None)
    if not machine or not online:
        return []
    pixels = bench["width"] * bench["height"]
    medians = dict(online["stage_median_ms"])
    threads = machine["threads"]
    lines = [
        (
            f"This machine (`deard-bench --machine`): copy bandwidth "
            f"{machine['bandwidth_gbs_one']:.1f} GB/s on one thread, "
            f"{machine['bandwidth_gbs_all']:.1f} GB/s on {threads}; f32 FMA "
            f"{machine['fma_gflops_one']:.1f} GFLOP/s on one thread, "
            f"{machine['fma_gflops_all']:.1f} GFLOP/s on {threads}. Work per pixel is "
            "counted from the code (`STAGE_WORK` in `scripts/results.py`), not measured; "
            "fractions are of the all-thread limits. In online mode a frame's first stages "
            "run beside the previous frame's refinement (overlapped frames), so their times "
            "are of about one thread's share of the machine."
        ),
        "",
        (
            "| Stage (640×480, online steady state) | what | bytes / px | FLOP / px | "
            "median (ms) | GB/s | GFLOP/s | of bandwidth | of FMA peak |"
        ),
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for stage, (what, bytes_px, flop_px) in STAGE_WORK.items():
        ms = medians.get(stage)
        if not ms:
            continue
        gbs = bytes_px * pixels / (ms * 1e-3) / 1e9
        gflops = flop_px * pixels / (ms * 1e-3) / 1e9
        lines.append(
            f"| {stage} | {what} | {bytes_px:.0f} | {flop_px:.0f} | {ms:.1f} | {gbs:.2f} | "
            f"{gflops:.2f} | {100 * gbs / machine['bandwidth_gbs_all']:.0f} % | "
            f"{100 * gflops / machine['fma_gflops_all']:.0f} % |"
        )
    return lines


def alignment_paragraph(sets: dict[int, dict[str, Report]]) -> str:
    parts = []
    for b in bundles(sets[SIGMAS[0]]):
        changes = []
        for s in SIGMAS:
            r = sets[s].get(b, {})
            changes.append(f"{pct(r.get('aepe_px'), r.get('aepe_rough_px'))} at σ = {s}")
        parts.append(f"`{b}`: final vs rough flow AEPE " + ", ".join(changes))
    return (
        f"The paper's flow fusion lowers the AEPE of the rough flow by about "
        f"{-100 * PAPER_AEPE_CHANGE:.0f} % (Table 1: "
        + ", ".join(f"{a} → {b} px at σ = {s}" for s, (a, b) in PAPER_AEPE.items())
        + "). Ours goes further from the rough flow because the chain's final flow is not the "
        "fusion network's: the direct fit to the frame's edges, started from the least-squares "
        "calibration of the rough flow, aligns the frame when it is confident (the fusion "
        'network runs only where it is not; docs/daemon.md, "Chain modes"). '
        + "; ".join(parts)
        + "."
    )


def refinement_paragraph(aligned: dict[str, Report]) -> str:
    raw = aligned["raw-tof"]["mae_all_cm"]
    classical = aligned.get("static+classical-filter", {}).get("mae_all_cm")
    parts = [f"the classical filter {pct(classical, raw)}"]
    for b in bundles(aligned):
        r = aligned.get(f"{b} refine @ true calibration", {})
        parts.append(
            f"`{b}` {pct(r.get('mae_all_cm'), raw)} vs the input and "
            f"{pct(r.get('mae_all_cm'), classical)} vs the classical filter"
        )
    return (
        f"The paper's ToF-KPN improves on its U-Net by {-100 * PAPER_KPN_VS_UNET:.0f} % MAE "
        f"(Table 2). On aligned input, MAE all relative to the ToF input: " + "; ".join(parts) + "."
    )


def whole_paragraph(report: dict[str, Report]) -> str:
    raw_paper, out_paper, oracle_paper = PAPER_WHOLE
    parts = []
    raw = report["raw-tof"]["mae_all_cm"]
    for b in bundles(report):
        out = report.get(b, {}).get("mae_all_cm")
        oracle = report.get(f"{b} refine @ true calibration", {}).get("mae_all_cm")
        parts.append(
            f"`{b}` {fmt(raw)} → {fmt(out)} cm ({pct(out, raw)}), "
            f"{fmt(oracle)} cm at the true calibration"
        )
    return (
        f"The paper's whole pipeline takes misaligned ToF depth from {raw_paper} to "
        f"{out_paper} cm ({pct(out_paper, raw_paper)}) with its modules trained separately, "
        f"{oracle_paper} cm after a joint fine-tune. Ours at σ = 4 px: " + "; ".join(parts) + "."
    )


#: The README's headline table lies between these lines; `write_headline` replaces what is
#: between them and nothing else.
HEADLINE_BEGIN = "<!-- headline figures: written by scripts/results.py -->"
HEADLINE_END = "<!-- end headline figures -->"
#: The bundle the README's headline figures are of (the daemon's default).
HEADLINE_BUNDLE = "edge"
#: RESULTS.md sections the headline rows link to (GitHub's anchors of their headings).
SECTION = {
    "refinement": "refinement-on-aligned-input-mae-within-4-m-paper-tables-2-and-3",
    "heldout": "held-out-family-sensors-and-scenes-no-training-run-sampled",
    "whole": "whole-pipeline-on-misaligned-input-σ--4-px",
    "online": "online-recalibration-on-a-drifting-calibration-beyond-the-paper",
    "daemon": "the-daemons-time-per-frame",
    "families": "refinement-on-every-family-does-it-leave-good-depth-alone-issue-33",
}


def field(report: dict[str, Report] | None, method: str, key: str) -> float | None:
    """One figure of one row of a set's eval.json; None when the set or the row has none."""
    return None if report is None else report.get(method, {}).get(key)


def daemon_online(bench_path: Path) -> dict | None:
    """The all-frames timing of a `deard-bench --json` file's online mode (its row "online,
    all frames" in the daemon's table); None when the file or the mode is missing."""
    if not bench_path.is_file():
        return None
    modes = json.loads(bench_path.read_text())["modes"]
    return next((m["all"] for m in modes if m["mode"] == "online"), None)


def headline_table(eval_dir: Path) -> list[str]:
    """The README's headline figures: each one the figure RESULTS.md prints (the same rows of
    the same eval.json files, formatted by `fmt` / `pct`), "–" where an input is missing."""
    b = HEADLINE_BUNDLE
    refine = f"{b} refine @ true calibration"
    aligned = load_optional(eval_dir, "aligned")
    heldout = load_optional(eval_dir, "heldout")
    sigma4 = load_optional(eval_dir, "sigma4")
    sequence = load_optional(eval_dir, "sequence")
    clean = load_optional(eval_dir, "clean")

    def mae(report: dict[str, Report] | None, method: str) -> str:
        return fmt(field(report, method, "mae_all_cm"))

    def ms(report: dict[str, Report] | None, method: str) -> str:
        seconds = field(report, method, "median_seconds")
        return fmt(None if seconds is None else 1e3 * seconds, 1)

    raw4, out4 = field(sigma4, "raw-tof", "mae_all_cm"), field(sigma4, b, "mae_all_cm")
    whole = (
        f"AEPE {fmt(field(sigma4, 'static-calibration', 'aepe_px'))} → "
        f"{fmt(field(sigma4, b, 'aepe_px'))} px; MAE {fmt(raw4)} → {fmt(out4)} cm "
        f"({pct(out4, raw4)})"
    )
    sequence_frames = "–"
    if sequence is None:
        online = "– (no sequence evaluation)"
    else:
        sequence_frames = sequence["__file__"]["frames_evaluated"]
        network = dict(sequence["__file__"].get("online_network_frames", []))
        online = (
            f"{fmt(field(sequence, f'{b} online', 'aepe_px'))} px, "
            f"{mae(sequence, f'{b} online')} cm, {ms(sequence, f'{b} online')} ms a frame, "
            f"network on {network.get(b, '?')} of {sequence_frames} frames (per-frame estimation: "
            f"{fmt(field(sequence, b, 'aepe_px'))} px, {mae(sequence, b)} cm, "
            f"{ms(sequence, b)} ms)"
        )
    vga = daemon_online(eval_dir / "deard-bench-vga.json")
    vga_pinned = daemon_online(eval_dir / "deard-bench-vga-pinned.json")
    qvga = daemon_online(eval_dir / "deard-bench-qvga.json")

    def bench(timing: dict | None, key: str) -> str:
        return fmt(None if timing is None else timing[key], 1)

    daemon = (
        f"640×480: median {bench(vga, 'median_ms')} ms, p95 {bench(vga, 'p95_ms')} "
        f"(threads pinned: {bench(vga_pinned, 'median_ms')}, p95 "
        f"{bench(vga_pinned, 'p95_ms')}); 320×240: {bench(qvga, 'median_ms')} ms"
    )
    families = ", ".join(
        f"`{name}` {fmt(field(load_optional(eval_dir, name), b, 'aepe_px'))}"
        for name, _ in FAMILIES
    )

    def link(text: str, section: str) -> str:
        return f"[{text}](RESULTS.md#{SECTION[section]})"

    rows = [
        (
            "Refinement at the true calibration, MAE all",
            f"ToF input {mae(aligned, 'raw-tof')} cm, classical filter "
            f"{mae(aligned, 'static+classical-filter')}, `{b}` {mae(aligned, refine)}",
            link("aligned input", "refinement"),
        ),
        (
            "Same, sensors and scenes outside every training range",
            f"input {mae(heldout, 'raw-tof')} cm, classical "
            f"{mae(heldout, 'static+classical-filter')}, `{b}` {mae(heldout, refine)}",
            link("held-out family", "heldout"),
        ),
        ("Whole pipeline at σ = 4 px misalignment", whole, link("whole pipeline", "whole")),
        (
            f"Online recalibration, {sequence_frames}-frame drifting sequence",
            online,
            link("online recalibration", "online"),
        ),
        (
            "`deard` time per frame, online (`deard-bench`)",
            daemon,
            link("daemon's time per frame", "daemon"),
        ),
        (
            "Clean input (bright, single bounce): the refiner leaves it alone",
            f"input {mae(clean, 'raw-tof')} cm, `{b}` {mae(clean, refine)}, "
            f"without its multi-path gate "
            f"{mae(clean, f'{b}{WITHOUT_GATE} refine @ true calibration')}",
            link("every family", "families"),
        ),
        (
            f"Aligned frames (a correct factory calibration), final AEPE of `{b}` per family (px)",
            families,
            link("every family", "families"),
        ),
    ]
    return [
        "| What | Figure | RESULTS.md section |",
        "|---|---|---|",
        *(f"| {what} | {figure} | {section} |" for what, figure, section in rows),
    ]


def headline_block(text: str, path: Path) -> tuple[int, int]:
    """Where the headline block's content lies in a README's text: (start, end), between the
    two marker lines; ValueError naming the file when a marker is missing or out of order."""
    begin, end = text.find(HEADLINE_BEGIN), text.find(HEADLINE_END)
    if begin < 0 or end < 0 or end < begin:
        raise ValueError(
            f"{path}: the headline figures must lie between a line {HEADLINE_BEGIN!r} and a "
            f"later line {HEADLINE_END!r}"
        )
    return begin + len(HEADLINE_BEGIN), end


def write_headline(readme: str, table: list[str], path: Path) -> str:
    """The README's text with the headline block replaced by `table`, the rest unchanged."""
    start, end = headline_block(readme, path)
    return readme[:start] + "\n\n" + "\n".join(table) + "\n\n" + readme[end:]


#: A number as the documents write it: digits with an optional decimal part, not part of a
#: word ("p95", "x86") nor of a longer number.
NUMBER = re.compile(r"(?<![\w.])\d+(?:\.\d+)?(?![\w]|\.\d)")


def figures_not_in_results(
    readme: str, results: str, readme_path: Path = Path("README.md")
) -> list[str]:
    """The numbers of the README's headline block (link targets left out) that RESULTS.md does
    not contain as a number written the same way; empty when every figure is backed."""
    start, end = headline_block(readme, readme_path)
    block = re.sub(r"\]\([^)]*\)", "]", readme[start:end])
    known = set(NUMBER.findall(results))
    return [n for n in NUMBER.findall(block) if n not in known]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--eval", type=Path, required=True, help="dear eval outputs per set")
    parser.add_argument("--out", type=Path, required=True, help="RESULTS.md to write")
    parser.add_argument("--figures", type=Path, required=True, help="where figures go")
    parser.add_argument(
        "--commentary",
        type=Path,
        default=Path(__file__).with_name("results_commentary.md"),
        help="hand-written discussion appended after the tables",
    )
    parser.add_argument(
        "--readme",
        type=Path,
        default=Path(__file__).resolve().parents[1] / "README.md",
        help="README whose headline block (between its marker comments) is rewritten "
        "(default: the repository's README.md)",
    )
    args = parser.parse_args()
    # Refuse a README without the markers before anything is written.
    readme = write_headline(args.readme.read_text(), headline_table(args.eval), args.readme)

    aligned = load(args.eval, "aligned")
    sets = {s: load(args.eval, f"sigma{s}") for s in SIGMAS}
    heldout = load(args.eval, "heldout")
    heldout_sigma4 = load(args.eval, "heldout-sigma4")
    family_sets = {f: load_optional(args.eval, f"{f}-sigma4") for f in NEW_FAMILIES}
    families_sigma4 = [(f"`{f}`", r) for f, r in family_sets.items() if r is not None]
    large_sets = {s: load_optional(args.eval, f"sigma{s}") for s in LARGE_SIGMAS}
    large = {s: r for s, r in large_sets.items() if r is not None}
    frames = aligned["__file__"]["frames_evaluated"]
    sequence = load_optional(args.eval, "sequence")
    # Frames from a network frame to the delivery of its measurement (eval.json of dear eval
    # --online; 0: measured on the frame itself).
    delay = "–" if sequence is None else sequence["__file__"].get("online_delay_frames", 0)
    untracked_path = args.eval / "sequence-untracked" / "eval.json"
    untracked = load(args.eval, "sequence-untracked") if untracked_path.is_file() else None

    if args.figures.exists():
        shutil.rmtree(args.figures)
    args.figures.mkdir(parents=True)
    figure_lines = []
    for name in ("aligned", "sigma4", "heldout"):
        data = load(args.eval, name)["__file__"]
        for f in data["figures"]:
            target = args.figures / f"{name}-{Path(f).name}"
            shutil.copyfile(args.eval / name / f, target)
            figure_lines.append(f"![{name}: {Path(f).name}]({target.as_posix()})")

    doc = [
        "# Results",
        "",
        (
            "Regenerate with `scripts/results.sh` (fixed-seed test sets from `dear-synth`, then "
            "`dear eval` on each; the numbers below are copied from its `eval.json` files by "
            "`scripts/results.py`). Test sets: "
            f"{frames} frames at 320×240 rendered with seed 9001, and misaligned copies at "
            "the paper's σ = 2, 4, 6 px (pixels of a 640×480 image; rendered as σ = 1, 2, 3 px "
            "at 320×240, seed 4) whose RGB views are rendered from the RGB camera of each "
            "frame's calibration, as a camera sees them (no black disocclusions; "
            'synth/README.md, "Misalignment"). Every method runs through `dear-pipeline`, '
            "the code the daemon runs; times are medians on the 2-core development machine, "
            "tract on one "
            "thread."
        ),
        "",
        "## Alignment: AEPE of the flow (paper Table 1)",
        "",
        *table_alignment(sigma_columns(sets)),
        "",
        alignment_paragraph(sets),
        "",
        "## Refinement on aligned input: MAE within 4 m (paper Tables 2 and 3)",
        "",
        (
            "Pixels are ranked by the *input's* error: low 0–25 %, mid 25–50 %, high 50–75 %; "
            "all includes the worst quarter."
        ),
        "",
        *table_refinement(aligned),
        "",
        refinement_paragraph(aligned),
        "",
        "## Whole pipeline on misaligned input (σ = 4 px)",
        "",
        *table_whole(sets[4]),
        "",
        whole_paragraph(sets[4]),
        "",
        "## Large misalignment (σ = 8 and 12 px, issue 32)",
        "",
        (
            "The aligned set misaligned further (rendered as σ = 4 and 6 px at 320×240, seed 4): "
            "a dropped phone or a re-seated module."
        ),
        "",
        *(
            [*table_large(large), "", large_paragraph(large)]
            if len(large) == len(LARGE_SIGMAS)
            else [missing(args.eval, [f"sigma{s}" for s in LARGE_SIGMAS])]
        ),
        "",
        "## Held-out family: sensors and scenes no training run sampled",
        "",
        (
            f"{heldout['__file__']['frames_evaluated']} frames of the `heldout` family of "
            "`dear-synth family` (synth/src/family.rs; seed 9002): horizontal field of view "
            "48–58°, 2,000–5,000 electrons per unit signal, 25–40 e⁻ read noise, more ambient "
            "light, 13–15.5 MHz modulation, an 18–25 mm illuminator offset and 30–40 objects — "
            "every one outside the range the `train` family samples. Aligned input, then the "
            "same frames misaligned at σ = 4 px (seed 4)."
        ),
        "",
        *table_refinement(heldout),
        "",
        refinement_paragraph(heldout),
        "",
        "Whole pipeline at σ = 4 px, held-out family:",
        "",
        *table_alignment([("AEPE (px)", heldout_sigma4)]),
        "",
        *table_whole(heldout_sigma4),
        "",
        *(families_section(families_sigma4) if families_sigma4 else []),
        "## Refinement on every family: does it leave good depth alone? (issue 33)",
        "",
        (
            "Refinement at the true calibration, MAE all within 4 m in cm with the low-error "
            "quarter (the pixels the sensor already got right) in parentheses; 80 frames per "
            "set (`dear-synth family --family NAME --seed 9003…9006`). OpenCV's fast global "
            "smoother, joint bilateral and 5×5 median filters (`scripts/opencv_baselines.py`) are "
            "each tuned on the very set they are scored on, which favours them. `broad`, the "
            "guarded refiner's training family, spans bright single-bounce scenes and near-empty "
            "rooms; `wide` and `dual-low` are modules no training family samples."
        ),
        "",
        *table_families(args.eval),
        "",
        (
            "Alignment on the same sets: the frames are aligned and the factory calibration is "
            "correct, so the chain should leave it alone; AEPE of the flow each method aligned "
            "with (px)."
        ),
        "",
        *table_families_aepe(args.eval),
        "",
        "Reliability of the expected-error confidence on the held-out family (refinement at the "
        "true calibration; `dear_proto::confidence`): per bin of the predicted error, the "
        "error measured against the ground truth.",
        "",
        *table_reliability(
            {k: v for k, v in heldout.items() if k == "__file__" or k.endswith("calibration")}
        ),
        "The same on every family, as one number: the pixel-weighted mean of |ln(measured / "
        "predicted)| over the bins (0 when every bin's prediction holds, 0.69 when they are 2× "
        'apart; docs/models.md, "Expected-error floor").',
        "",
        *table_reliability_scores(args.eval),
        "",
        "## Online recalibration on a drifting calibration (beyond the paper)",
        "",
        (
            f"{'–' if sequence is None else sequence['__file__']['frames_evaluated']} frames of "
            "a moving scene whose "
            "principal point drifts (sinusoids, 4 px peak; `dear-synth sequence --seed 77`). "
            "AEPE is the error of the flow each frame was aligned with; the per-frame error "
            "over time is in `out/results/sequence/tracking.csv`; flicker is the mean "
            "frame-to-frame change of the published depth on static surfaces (pixels whose "
            "ground truth did not change). The online filter is deard's per-frame engine "
            "(`dear_pipeline::engine`) with its background measurement made deterministic: each "
            f"network measurement reaches the estimator {delay} frames after the frame that "
            "asked for it (deard's typical latency at this size and 30 fps; "
            '`--online-delay-frames`), so "flow network on" counts the frames measured off '
            "the frame path and ms / frame is the frame path's. ms / frame includes the "
            "alignment check (the online trigger's residual), which runs beside the refinement "
            "on the second core."
        ),
        "",
        *(
            table_tracking(sequence, untracked)
            if sequence is not None
            else [missing(args.eval, ["sequence"])]
        ),
        "",
    ]
    doc += [
        "## Cost at 640×480",
        "",
        (
            "`cargo bench -p dear-pipeline --bench dear_chain` with `models/edge` (tract on one "
            "thread, as the daemon runs it) and `dear-bench-onnx --bundle models/edge` "
            "(onnxruntime, the same ONNX files). Frame rows include preprocessing, the "
            "geometry, the warps and the confidence map."
        ),
        "",
        *table_latency(Path("target/criterion/dear_chain_vga"), args.eval / "onnxruntime.json", 30),
        "",
        "## The daemon's time per frame",
        "",
        (
            "`deard-bench` runs deard's own processing (`Processor`, default configuration, "
            "mimalloc, tract on one thread, online mode's network frames on the background "
            "worker) over a capture in order, frames back to back, and times every frame; "
            "as in deard, a frame is prepared (aligned, warped, classically filtered) beside "
            "the previous frame's refine graph when it is already waiting, which back to back "
            "it always is in online mode, so the time per frame is the interval between "
            "publications and the latency (first stage to publication) is about two of them; "
            "640×480: a 60-frame drifting sequence (`dear-synth sequence --seed 5`), 320×240: "
            "the tracking sequence above. Online mode's steady state is the frames between "
            'rough-flow runs; "all frames" includes the network frames. Stage medians are '
            'over the steady-state frames (online) or all frames (every-frame); "flow" '
            "includes the calibration (least squares, or the splat with a known calibration), "
            '"refine" the confidence map and the edge check.'
        ),
        "",
        *table_daemon(
            [
                args.eval / "deard-bench-vga.json",
                args.eval / "deard-bench-vga-pinned.json",
                args.eval / "deard-bench-qvga.json",
            ]
        ),
        "",
        "## Physical limits",
        "",
        *table_limits(args.eval / "deard-bench-vga.json"),
        "",
    ]
    if args.commentary.is_file():
        doc += [args.commentary.read_text().rstrip(), ""]
    doc += [
        "## Figures",
        "",
        (
            "Panels: RGB | amplitude | ToF depth | result | ground truth | |error| (0–20 cm). "
            "Blends: depth over RGB before | after alignment. "
            "Scan lines: ToF (grey), result (red), "
            "ground truth (green) along one row."
        ),
        "",
        *figure_lines,
        "",
    ]
    args.out.write_text("\n".join(doc))
    args.readme.write_text(readme)


if __name__ == "__main__":
    main()
