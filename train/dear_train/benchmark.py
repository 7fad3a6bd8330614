"""Peer timing of a bundle's ONNX graphs in onnxruntime (`dear-bench-onnx`).

The daemon runs the same files through tract; this prints onnxruntime's time for each graph
at a frame size, so the Rust benchmark (`cargo bench -p dear-pipeline --bench dear_chain`)
has a reference on the same machine. Inputs are random values in the ranges the graphs see
(RGB and amplitude in [0, 1], depth in metres, flows of a few pixels).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from dear_train.stats import Summary


def _input(name: str, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    if name == "depth":
        return rng.uniform(0.5, 4.0, shape).astype(np.float32)
    if name.startswith("flow"):
        return rng.normal(0.0, 3.0, shape).astype(np.float32)
    return rng.uniform(0.0, 1.0, shape).astype(np.float32)


def time_graph(path: Path, inputs: dict[str, np.ndarray], threads: int, runs: int) -> list[float]:
    """Seconds per run of `path` after two warm-up runs."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    for _ in range(2):
        session.run(None, inputs)
    seconds = []
    for _ in range(runs):
        start = time.perf_counter()
        session.run(None, inputs)
        seconds.append(time.perf_counter() - start)
    return seconds


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="dear-bench-onnx", description=__doc__)
    parser.add_argument("--bundle", type=Path, default=Path("models/edge"))
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args(argv)

    manifest = json.loads((args.bundle / "model.json").read_text())
    rng = np.random.default_rng(0)
    print(f"onnxruntime, {args.bundle}, {args.width}×{args.height}, {args.runs} runs")
    print("graph    threads  median ms  p95 ms")
    rows = []
    for name, graph in manifest["graphs"].items():
        inputs = {
            i["name"]: _input(i["name"], (1, i["shape"][1], args.height, args.width), rng)
            for i in graph["inputs"]
        }
        for threads in args.threads:
            # Nearest rank, as the Rust figures (dear_train.stats, crate dear-stats).
            s = Summary.of(time_graph(args.bundle / graph["file"], inputs, threads, args.runs))
            assert s is not None, "--runs must be at least 1"
            median, p95 = s.p50, s.p95
            print(f"{name:8s} {threads:7d}  {1e3 * median:9.1f}  {1e3 * p95:6.1f}")
            rows.append({"graph": name, "threads": threads, "median_s": median, "p95_s": p95})
    if args.json:
        args.json.write_text(json.dumps({"width": args.width, "height": args.height, "runs": rows}))


if __name__ == "__main__":
    main()
