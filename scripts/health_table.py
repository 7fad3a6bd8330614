#!/usr/bin/env python3
"""The "Measured" table of docs/calibration-health.md, from `dear eval --online` runs.

For each `NAME=DIR` (DIR holds a `tracking.csv` written by `dear eval --capture SET --bundle
models/edge --online`), one row over the frames of the bundle's online method: the share of
frames reported *good*, the number of frames whose AEPE is above the threshold (2 px) and the
share of those reported *can improve* or *needs recalibration* (flagged):

    .venv/bin/python scripts/health_table.py aligned=out/health/aligned "σ = 2 px=out/health/sigma2"
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

GOOD = "good"
FLAGGED = ("can improve", "needs recalibration")


def row(name: str, tracking: Path, method: str, threshold_px: float) -> str:
    """One Markdown table row for the online method `method` in `tracking`."""
    with tracking.open(newline="") as f:
        frames = [r for r in csv.DictReader(f) if r["method"] == method]
    if not frames:
        raise SystemExit(f"{tracking}: no rows of method {method!r}")
    for r in frames:
        if r["health"] not in (GOOD, *FLAGGED):
            raise SystemExit(f"{tracking}: frame {r['frame']}: unknown health {r['health']!r}")
    good = sum(r["health"] == GOOD for r in frames) / len(frames)
    off = [r for r in frames if float(r["aepe_px"]) > threshold_px]
    flagged = f"{100 * sum(r['health'] in FLAGGED for r in off) / len(off):.1f} %" if off else "–"
    return f"| {name} | {100 * good:.1f} % | {len(off)} | {flagged} |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sets", nargs="+", help="NAME=DIR (DIR holds tracking.csv)")
    ap.add_argument("--method", default="edge online", help="the online row's method name")
    ap.add_argument("--threshold", type=float, default=2.0, help="AEPE threshold, px")
    a = ap.parse_args()
    print(f"| set | good | frames with AEPE > {a.threshold:g} px | flagged of those |")
    print("|---|---:|---:|---:|")
    for spec in a.sets:
        name, sep, d = spec.rpartition("=")
        if not sep:
            raise SystemExit(f"{spec!r}: expected NAME=DIR")
        print(row(name, Path(d) / "tracking.csv", a.method, a.threshold))


if __name__ == "__main__":
    main()
