"""Receive frames with an installed `dear` wheel and keep them for comparison.

Run by scripts/test-wheels.sh with the interpreter the wheel was installed for (a fresh venv on
x86-64, Debian's arm64 Python under qemu-user for aarch64), so it needs only the standard
library, numpy and `dear`. Two commands:

  receive SERVICE OUT --timeout-s S
      checks that `dear` is the installed wheel (not the checkout's package), that frames
      arrive with the documented shapes and dtypes, and the first frame's point cloud; saves
      each as OUT/RUNID-SEQ.npz; prints "receiving" once the first frame is in, so the caller
      can start `dear dump`, and stops after the frame that follows the caller's creating
      OUT/stop (when `dear dump` is done).
  compare OUT DUMP
      (the checkout's .venv: needs Pillow and dear_train, whose depth_to_u16 is the dump's
      depth conversion) every frame `dear dump` wrote into DUMP that the wheel
      also received must be equal plane for plane; at least two must match.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np


def receive(service: str, out: Path, timeout_s: float) -> None:
    import dear

    checkout = Path(__file__).resolve().parents[2]
    module = Path(dear.__file__).resolve()
    if checkout in module.parents:
        sys.exit(f"wheel_client: `dear` was imported from the checkout ({module}), not a wheel")
    print(f"dear from {module.parent} on {platform.machine()}", flush=True)
    out.mkdir(parents=True, exist_ok=True)
    deadline = time.monotonic() + timeout_s
    kept = 0
    stop = out / "stop"
    with dear.Subscriber(service) as sub:
        while not (kept > 0 and stop.exists()):
            left = deadline - time.monotonic()
            if left <= 0:
                sys.exit(f"wheel_client: {kept} frames from {service}, no {stop} in {timeout_s} s")
            frame = sub.wait(left)
            if frame is None:
                continue
            with frame:
                h = frame.header
                depth, rgb, confidence = frame.depth, frame.rgb, frame.confidence
                shape = (h.height, h.width)
                if depth.shape != shape or depth.dtype != np.float32:
                    sys.exit(f"wheel_client: depth {depth.shape} {depth.dtype}, header {shape}")
                if rgb.shape != (*shape, 3) or rgb.dtype != np.uint8:
                    sys.exit(f"wheel_client: rgb {rgb.shape} {rgb.dtype}, header {shape}")
                if confidence.shape != shape or confidence.dtype != np.uint8:
                    sys.exit(f"wheel_client: confidence {confidence.shape} {confidence.dtype}")
                if depth.flags.writeable:
                    sys.exit("wheel_client: the depth view is writeable, not read-only")
                if kept == 0:
                    check_point_cloud(frame, depth)
                np.savez(
                    out / f"{h.run_id:016x}-{h.sequence}.npz",
                    depth=depth,
                    rgb=rgb,
                    confidence=confidence,
                )
            if kept == 0:
                print("receiving", flush=True)
            kept += 1
    print(f"kept {kept} frames", flush=True)


def check_point_cloud(frame: object, depth: np.ndarray) -> None:
    """The wheel's point cloud (the Rust SDK's back-projection): organised, valid exactly where
    the depth is, z equal to the depth there, NaN elsewhere."""
    cloud = frame.point_cloud(colors=True)  # type: ignore[attr-defined]
    n = depth.size
    if cloud.points.shape != (n, 3) or cloud.valid.shape != (n,) or cloud.colors.shape != (n, 3):
        sys.exit(f"wheel_client: point cloud shapes {cloud.points.shape} {cloud.valid.shape}")
    flat = depth.reshape(-1)
    if not np.array_equal(cloud.valid, flat > 0) or not cloud.valid.any():
        sys.exit("wheel_client: the point cloud's valid mask is not the valid depth")
    if not np.array_equal(cloud.points[cloud.valid, 2], flat[cloud.valid]):
        sys.exit("wheel_client: a valid point's z is not its depth")
    if not np.isnan(cloud.points[~cloud.valid]).all():
        sys.exit("wheel_client: an invalid pixel has a point")
    print(f"point cloud: {int(cloud.valid.sum())} of {n} points valid", flush=True)


def compare(out: Path, dump: Path) -> None:
    from dear_train.data.capture import depth_to_u16
    from PIL import Image

    manifest = json.loads((dump / "capture.json").read_text())
    published = manifest["source"]["published_frames"]
    matched = 0
    for record in published:
        received = out / f"{int(record['run_id'], 16):016x}-{record['sequence']}.npz"
        if not received.is_file():
            continue
        planes = np.load(received)
        stem = dump / "frames" / f"{record['id']:06d}"
        np.testing.assert_array_equal(
            depth_to_u16(planes["depth"], manifest["depth_scale"]),
            np.asarray(Image.open(f"{stem}.depth.png")),
            err_msg=str(stem),
        )
        np.testing.assert_array_equal(
            planes["rgb"], np.asarray(Image.open(f"{stem}.rgb.png")), err_msg=str(stem)
        )
        amp = np.asarray(Image.open(f"{stem}.amp.png")).astype(np.uint32)
        np.testing.assert_array_equal(planes["confidence"].astype(np.uint32) * 257, amp)
        matched += 1
    if matched < 2:
        sys.exit(
            f"wheel_client: only {matched} of the {len(published)} frames dear dump wrote were"
            f" received by the wheel ({sorted(p.name for p in out.glob('*.npz'))})"
        )
    print(f"{matched} frames equal to dear dump's, plane for plane")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    r = commands.add_parser("receive")
    r.add_argument("service")
    r.add_argument("out", type=Path)
    r.add_argument("--timeout-s", type=float, default=120.0)
    c = commands.add_parser("compare")
    c.add_argument("out", type=Path)
    c.add_argument("dump", type=Path)
    args = parser.parse_args()
    if args.command == "receive":
        receive(args.service, args.out, args.timeout_s)
    else:
        compare(args.out, args.dump)


if __name__ == "__main__":
    main()
