"""What `dear view` costs while browsers look: its CPU (and deard's) with no viewer and with N
emulated viewers, each fetching the three pictures every 100 ms as the page does, and the time
to answer each picture (docs/view.md's figures).

Starts `deard --replay CAPTURE --loop --refine none` and `dear view` on a private service, reads
CPU times from /proc, prints one line per measurement. Not a test: the numbers depend on the
machine and its load.

Usage: .venv/bin/python scripts/view_cost.py CAPTURE [--bin-dir target/release]
       [--seconds 15] [--viewers 1]
A 640×480 capture: `dear-synth generate --count 8 --out /tmp/vga --spp 1 --indirect-spp 0
--bounces 1` (30 fps timestamps).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
PICTURES = ("depth", "blend", "confidence")
TICK = os.sysconf("SC_CLK_TCK")


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def fetch(url: str) -> tuple[float, int]:
    start = time.perf_counter()
    with urllib.request.urlopen(url, timeout=10) as response:
        size = len(response.read())
    return time.perf_counter() - start, size


def status(base: str) -> dict[str, Any]:
    with urllib.request.urlopen(base + "/status.json", timeout=10) as response:
        return json.loads(response.read())


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("capture", type=Path)
    parser.add_argument("--bin-dir", type=Path, default=ROOT / "target" / "release")
    parser.add_argument("--seconds", type=float, default=15.0)
    parser.add_argument("--viewers", type=int, default=1)
    args = parser.parse_args()

    service = f"dear-cost/{os.getpid()}/view/frames"
    deard_args = ["--service", service, "--refine", "none", "--loop", "--replay", args.capture]
    deard = subprocess.Popen(
        [args.bin_dir / "deard", *deard_args],
        stderr=subprocess.DEVNULL,
    )
    view = subprocess.Popen(
        [args.bin_dir / "dear", "view", "--bind", "127.0.0.1:0", "--service", service],
        stdout=subprocess.PIPE,
    )
    try:
        assert view.stdout is not None
        line = view.stdout.readline().decode()
        base = next(w for w in line.split() if w.startswith("http://")).rstrip("/")
        deadline = time.monotonic() + 60
        while status(base)["snapshot"] == 0:
            assert time.monotonic() < deadline, "no frame in 60 s"
            time.sleep(0.1)
        time.sleep(2)

        def window() -> tuple[float, float, dict[str, Any], dict[str, Any]]:
            v0, d0, s0 = cpu_s(view.pid), cpu_s(deard.pid), status(base)
            time.sleep(args.seconds)
            v1, d1, s1 = cpu_s(view.pid), cpu_s(deard.pid), status(base)
            return (v1 - v0) / args.seconds, (d1 - d0) / args.seconds, s0, s1

        def report(what: str, w: tuple[float, float, dict[str, Any], dict[str, Any]]) -> None:
            view_cpu, deard_cpu, s0, s1 = w
            frame = s1["frame"]
            print(
                f"{what}: dear view {view_cpu:.1%} of a core, deard {deard_cpu:.1%}; stream "
                f"{frame['width']}x{frame['height']} at {s1['fps']:.1f} fps, "
                f"{s1['lost'] - s0['lost']} missed by the viewer"
            )

        report("no viewer", window())
        times: dict[str, list[float]] = {p: [] for p in PICTURES}
        sizes: dict[str, list[int]] = {p: [] for p in PICTURES}
        stop = threading.Event()

        def viewer() -> None:
            while not stop.is_set():
                for p in PICTURES:
                    seconds, size = fetch(f"{base}/{p}.jpg")
                    times[p].append(seconds)
                    sizes[p].append(size)
                stop.wait(0.1)

        threads = [threading.Thread(target=viewer) for _ in range(args.viewers)]
        for t in threads:
            t.start()
        busy = window()
        stop.set()
        for t in threads:
            t.join()
        served = sum(len(v) for v in times.values()) / args.seconds
        report(f"{args.viewers} viewer(s), {served:.1f} pictures/s served", busy)
        for p in PICTURES:
            ms = sorted(1e3 * t for t in times[p])
            print(
                f"  /{p}.jpg: answer median {statistics.median(ms):.1f} ms, "
                f"p95 {ms[int(0.95 * (len(ms) - 1))]:.1f} ms, max {ms[-1]:.1f} ms, "
                f"{statistics.median(sizes[p]) / 1e3:.0f} kB"
            )
        print(f"  transport latency {busy[3]['frame']['transport_latency_ms']:.2f} ms")
    finally:
        view.send_signal(signal.SIGINT)
        try:
            view.wait(10)
        except subprocess.TimeoutExpired:
            view.kill()
        deard.kill()
        deard.wait()


if __name__ == "__main__":
    main()
