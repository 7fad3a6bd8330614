"""`dear-ros2` against an independent DDS implementation: Eclipse Cyclone DDS's Python package.

Defines the ROS 2 messages (`sensor_msgs/Image`, `CameraInfo`, `PointCloud2` with
`std_msgs/Header`, `builtin_interfaces/Time`, `PointField`) with `cyclonedds.idl` under their
ROS 2 DDS type names, subscribes to the bridge's topics (`rt/<ROS 2 topic>`) with the sensor-data
QoS, and checks, with `deard` replaying samples/demo in a loop and `dear-ros2` publishing it:

- the 16UC1 depth received equals, pixel for pixel, the depth PNG that `dear dump` writes for
  the same frame (the frame with the same capture stamp, received within a second of the
  publication time `dear dump` records: the replay's 2.8 s loop repeats stamps);
- CameraInfo carries the capture's K, which deard puts in every frame header (format 3) and the
  bridge takes from there, no --intrinsics given (and P = [K | 0], plumb_bob, D zero);
- PointCloud2 is organised (width × height points, x, y, z float32), z equals the depth image
  of the same frame (to the millimetre's rounding) where it is valid, x and y back-project
  with K, and x, y, z are NaN where the depth is invalid;
- a second bridge on the same service with --depth-encoding 32FC1 publishes metres (NaN where
  invalid) equal to the 16UC1 millimetres of the same frame, to the millimetre's rounding;
- the colour (rgb8) and confidence (mono8) images have the frame's size.

Discovery stays on this host and needs no multicast: Cyclone is configured for 127.0.0.1
unicast with itself as peer (CYCLONEDDS_URI), the bridge announces itself to localhost (RustDDS
does by default). A DDS domain of its own per run (from the process id) keeps runs apart.

Usage: ros2_bridge.py [--bin-dir target/debug] [--timeout 60]
Run by scripts/test.sh's tier "ROS 2 bridge"; needs the workspace's debug binaries and the
`cyclonedds` package (train's dev extras, scripts/setup.sh).
"""

# No `from __future__ import annotations`: cyclonedds reads the IDL structs' annotations as
# types, and cannot resolve them as strings.
import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from PIL import Image as PilImage

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "samples" / "demo"
# Unicast on the loopback only, the peer list being this host: no multicast needed.
CYCLONE_CONFIG = """<CycloneDDS><Domain id="any">
<General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>
<AllowMulticast>false</AllowMulticast></General>
<Discovery><Peers><Peer address="127.0.0.1"/></Peers>
<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>20</MaxAutoParticipantIndex>
</Discovery>
<Internal><SocketReceiveBufferSize min="default" max="4MB"/></Internal>
</Domain></CycloneDDS>"""


# The ROS 2 messages as Cyclone IDL structs under their ROS 2 DDS type names (module level:
# cyclonedds resolves the nested types by name in this module).


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header
    height: uint32
    width: uint32
    encoding: str
    is_bigendian: uint8
    step: uint32
    data: sequence[uint8]


@dataclass
class RegionOfInterest(IdlStruct, typename="sensor_msgs::msg::dds_::RegionOfInterest_"):
    x_offset: uint32
    y_offset: uint32
    height: uint32
    width: uint32
    do_rectify: bool


@dataclass
class CameraInfo(IdlStruct, typename="sensor_msgs::msg::dds_::CameraInfo_"):
    header: Header
    height: uint32
    width: uint32
    distortion_model: str
    d: sequence[float64]
    k: array[float64, 9]
    r: array[float64, 9]
    p: array[float64, 12]
    binning_x: uint32
    binning_y: uint32
    roi: RegionOfInterest


@dataclass
class PointField(IdlStruct, typename="sensor_msgs::msg::dds_::PointField_"):
    name: str
    offset: uint32
    datatype: uint8
    count: uint32


@dataclass
class PointCloud2(IdlStruct, typename="sensor_msgs::msg::dds_::PointCloud2_"):
    header: Header
    height: uint32
    width: uint32
    fields: sequence[PointField]
    is_bigendian: bool
    point_step: uint32
    row_step: uint32
    data: sequence[uint8]
    is_dense: bool


def stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def data_bytes(data: Any) -> bytes:
    return bytes(data) if not isinstance(data, bytes) else data


class Subscriber:
    """Cyclone DDS readers on the bridge's topics; keeps what arrives with its receive time."""

    def __init__(self, domain: int, namespace: str) -> None:
        types = {"Image": Image, "CameraInfo": CameraInfo, "PointCloud2": PointCloud2}
        # rmw_qos_profile_sensor_data, as the bridge offers it.
        self.qos = qos = Qos(
            Policy.Reliability.BestEffort,
            Policy.History.KeepLast(5),
            Policy.Durability.Volatile,
        )
        self.participant = DomainParticipant(domain)
        self.readers = {}
        for leaf, kind in [
            ("depth/image_raw", "Image"),
            ("color/image_raw", "Image"),
            ("confidence/image_raw", "Image"),
            ("depth/camera_info", "CameraInfo"),
            ("color/camera_info", "CameraInfo"),
            ("depth/points", "PointCloud2"),
        ]:
            topic = Topic(self.participant, f"rt{namespace}/{leaf}", types[kind])
            self.readers[leaf] = DataReader(self.participant, topic, qos=qos)
        self.received: dict[str, list[tuple[int, Any]]] = {leaf: [] for leaf in self.readers}

    def add(self, key: str, topic: str, kind: Any) -> None:
        """One more reader, of `topic` (a DDS topic name), kept under `key`."""
        self.readers[key] = DataReader(
            self.participant, Topic(self.participant, topic, kind), qos=self.qos
        )
        self.received[key] = []

    def poll(self) -> None:
        for leaf, reader in self.readers.items():
            for sample in reader.take(N=20):
                self.received[leaf].append((time.monotonic_ns(), sample))

    def counts(self) -> dict[str, int]:
        return {leaf: len(v) for leaf, v in self.received.items()}


def read_png16(path: Path) -> np.ndarray:
    with PilImage.open(path) as im:
        return (
            np.asarray(im, dtype=np.uint16) if im.mode == "I;16" else np.array(im).astype(np.uint16)
        )


def check_depth_against_dump(sub: Subscriber, dump: Path, width: int, height: int) -> int:
    manifest = json.loads((dump / "capture.json").read_text())
    published = manifest["source"]["published_frames"]
    depth_msgs = sub.received["depth/image_raw"]
    matched = 0
    for entry in published:
        stamp, publish = entry["capture_timestamp_ns"], entry["publish_timestamp_ns"]
        # The message of this frame: its stamp, received within a second of its publication
        # (the replay loop repeats stamps every 2.8 s).
        candidates = [m for t, m in depth_msgs if stamp_ns(m) == stamp and 0 <= t - publish < 1e9]
        if not candidates:
            continue
        assert len(candidates) == 1, f"{len(candidates)} depth messages of frame {entry}"
        msg = candidates[0]
        assert (msg.width, msg.height, msg.encoding) == (width, height, "16UC1"), msg.encoding
        assert msg.step == 2 * width and msg.is_bigendian == 0
        got = np.frombuffer(data_bytes(msg.data), dtype="<u2").reshape(height, width)
        want = read_png16(dump / "frames" / f"{entry['id']:06d}.depth.png")
        diff = int(np.count_nonzero(got != want))
        assert diff == 0, f"frame {entry['id']} (stamp {stamp}): {diff} depth pixels differ"
        assert (got > 0).mean() > 0.5, "the depth is mostly invalid: not a frame"
        matched += 1
    return matched


def check_camera_info(sub: Subscriber, k: list[float], width: int, height: int) -> None:
    fx, fy, cx, cy = (float(np.float32(v)) for v in k)
    for leaf in ("depth/camera_info", "color/camera_info"):
        assert sub.received[leaf], f"no {leaf}"
        info = sub.received[leaf][-1][1]
        assert (info.width, info.height) == (width, height)
        assert list(info.k) == [fx, 0, cx, 0, fy, cy, 0, 0, 1], f"{leaf} K = {info.k}"
        assert list(info.p) == [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], f"{leaf} P = {info.p}"
        assert list(info.r) == [1, 0, 0, 0, 1, 0, 0, 0, 1]
        assert info.distortion_model == "plumb_bob" and list(info.d) == [0.0] * 5


def check_point_clouds(sub: Subscriber, k: list[float], width: int, height: int) -> int:
    """The clouds (published with --cloud-rgb) against the depth and colour images."""
    fx, fy, cx, cy = k
    depth_by_stamp = {stamp_ns(m): m for _, m in sub.received["depth/image_raw"]}
    rgb_by_stamp = {stamp_ns(m): m for _, m in sub.received["color/image_raw"]}
    checked = 0
    for _, cloud in sub.received["depth/points"]:
        assert (cloud.width, cloud.height) == (width, height)
        names = [(f.name, f.offset, f.datatype, f.count) for f in cloud.fields]
        want = [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("rgb", 12, 7, 1)]
        assert names == want, names
        assert cloud.point_step == 16 and cloud.row_step == 16 * width
        assert not cloud.is_bigendian and not cloud.is_dense
        points = np.frombuffer(data_bytes(cloud.data), dtype=np.uint8).reshape(height, width, 16)
        xyz = points[..., :12].copy().view("<f4")
        depth_msg = depth_by_stamp.get(stamp_ns(cloud))
        rgb_msg = rgb_by_stamp.get(stamp_ns(cloud))
        if depth_msg is None or rgb_msg is None:
            continue
        mm = np.frombuffer(data_bytes(depth_msg.data), dtype="<u2").reshape(height, width)
        valid = mm > 0
        finite = np.isfinite(xyz).all(axis=2)
        assert (finite == valid).all(), "finite points differ from the valid depth pixels"
        assert np.isnan(xyz[~valid]).all()
        z = xyz[..., 2][valid]
        assert np.abs(z * 1000 - mm[valid]).max() <= 0.5 + 1e-3, "z differs from the depth"
        v, u = np.nonzero(valid)
        np.testing.assert_allclose(xyz[..., 0][valid], (u - cx) * z / fx, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(xyz[..., 1][valid], (v - cy) * z / fy, rtol=1e-5, atol=1e-6)
        # PCL's packed colour: a float32 whose little-endian bytes are B, G, R, 0.
        rgb = np.frombuffer(data_bytes(rgb_msg.data), dtype=np.uint8).reshape(height, width, 3)
        assert (points[..., 12:15] == rgb[..., ::-1]).all() and (points[..., 15] == 0).all()
        checked += 1
    return checked


class Run:
    """deard replaying a capture in a loop, `dear-ros2` publishing it in a DDS domain of this
    run's own, and a Cyclone DDS subscriber on every topic."""

    def __init__(
        self, bin_dir: Path, capture: Path, tmp: Path, bridge_args: list[str], refine: str
    ) -> None:
        manifest = json.loads((capture / "capture.json").read_text())
        self.width, self.height = manifest["width"], manifest["height"]
        intr = manifest["intrinsics"]
        self.k = [intr["fx"], intr["fy"], intr["cx"], intr["cy"]]
        pid = os.getpid()
        self.service = f"dear-test/{pid}/ros2/frames"
        self.namespace = namespace = f"/dear_test/_{pid}/ros2"
        self.domain = domain = 1 + pid % 200  # domains 1..200; 0 is every ROS 2 system's default
        config = tmp / "cyclonedds.xml"
        config.write_text(CYCLONE_CONFIG)
        os.environ["CYCLONEDDS_URI"] = f"file://{config}"
        self.tmp = tmp
        self.processes: list[subprocess.Popen[bytes]] = []
        self.logs = {name: tmp / f"{name}.log" for name in ("deard", "bridge")}
        with open(self.logs["deard"], "wb") as log:
            deard = [bin_dir / "deard", "--service", self.service, "--loop", "--replay", capture]
            self.processes.append(
                subprocess.Popen(
                    [*deard, "--refine", refine], stdout=subprocess.DEVNULL, stderr=log
                )
            )
        # No --intrinsics: CameraInfo and the point cloud take the frame headers' (format 3).
        with open(self.logs["bridge"], "wb") as log:
            self.bridge = subprocess.Popen(
                [
                    *[bin_dir / "dear-ros2", "--service", self.service],
                    *["--domain-id", str(domain)],
                    *["--interface", "127.0.0.1", "--stats", *bridge_args],
                ],
                stdout=subprocess.PIPE,
                stderr=log,
            )
        self.processes.append(self.bridge)
        self.sub = Subscriber(domain, namespace)

    def poll(self, what: str, timeout: float, done: Any) -> None:
        """Takes what arrives until `done()`; fails after `timeout` seconds."""
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out waiting for {what}: {self.sub.counts()}")
            assert self.bridge.poll() is None, "dear-ros2 exited"
            self.sub.poll()
            time.sleep(0.005)

    def stop_bridge(self) -> dict[str, Any]:
        """Stops the bridge with Ctrl-C; its figures (--stats)."""
        self.bridge.send_signal(signal.SIGINT)
        out, _ = self.bridge.communicate(timeout=10)
        assert self.bridge.returncode == 0, "dear-ros2 did not stop cleanly on Ctrl-C"
        return json.loads(out.decode().strip().splitlines()[-1])

    def print_logs(self) -> None:
        for name, path in self.logs.items():
            lines = path.read_text(errors="replace").splitlines() if path.exists() else []
            print(f"{name} log (tail):\n" + "\n".join(lines[-20:]), file=sys.stderr)

    def close(self) -> None:
        for p in self.processes:
            if p.poll() is None:
                p.kill()
            p.wait()


def check_metres(sub: Subscriber, width: int, height: int) -> int:
    """The second bridge's 32FC1 depth (metres, NaN invalid) against the 16UC1 one's."""
    mm_msgs = sub.received["depth/image_raw"]
    checked = 0
    for t, msg in sub.received["32FC1"]:
        assert (msg.width, msg.height, msg.encoding) == (width, height, "32FC1"), msg.encoding
        assert msg.step == 4 * width and msg.is_bigendian == 0
        same = [m for u, m in mm_msgs if stamp_ns(m) == stamp_ns(msg) and abs(u - t) < 1e9]
        if len(same) != 1:
            continue
        m = np.frombuffer(data_bytes(msg.data), dtype="<f4").reshape(height, width)
        mm = np.frombuffer(data_bytes(same[0].data), dtype="<u2").reshape(height, width)
        valid = mm > 0
        assert (np.isfinite(m) == valid).all(), "32FC1's valid pixels differ from 16UC1's"
        assert np.abs(m[valid] * 1000 - mm[valid]).max() <= 0.5 + 1e-3, "32FC1 != 16UC1"
        checked += 1
    return checked


def check(run: Run, bin_dir: Path, timeout: float) -> None:
    started = time.monotonic()
    width, height, k = run.width, run.height, run.k
    # A second bridge on the same service: depth in metres (32FC1), images only.
    metres_ns = f"{run.namespace}_m"
    run.logs["bridge32"] = run.tmp / "bridge32.log"
    with open(run.logs["bridge32"], "wb") as log:
        run.processes.append(
            subprocess.Popen(
                [
                    *[bin_dir / "dear-ros2", "--service", run.service],
                    *["--domain-id", str(run.domain), "--namespace", metres_ns],
                    *["--depth-encoding", "32FC1", "--interface", "127.0.0.1"],
                ],
                stdout=subprocess.DEVNULL,
                stderr=log,
            )
        )
    run.sub.add("32FC1", f"rt{metres_ns}/depth/image_raw", Image)
    run.poll("a message on every topic", timeout, lambda: all(run.sub.counts().values()))
    print(f"ros2_bridge: every topic received after {time.monotonic() - started:.1f} s")
    dump = run.tmp / "dump"
    dumper = subprocess.Popen(
        [bin_dir / "dear", "dump", "--count", "10", "--out", dump, "--service", run.service],
        stdout=subprocess.DEVNULL,
    )
    run.processes.append(dumper)
    run.poll("dear dump", timeout, lambda: dumper.poll() is not None)
    assert dumper.returncode == 0, f"dear dump failed ({dumper.returncode})"
    # The last dumped frames' messages may still be on their way.
    end = time.monotonic() + 1.0
    run.poll("the last messages", timeout, lambda: time.monotonic() > end)
    print(f"ros2_bridge: received {run.sub.counts()}")

    matched = check_depth_against_dump(run.sub, dump, width, height)
    assert matched >= 5, f"only {matched} of the 10 dumped frames arrived over DDS"
    print(f"ros2_bridge: depth equals dear dump's in {matched} of 10 frames")
    metres = check_metres(run.sub, width, height)
    assert metres >= 3, f"only {metres} 32FC1 depth images had their 16UC1 one"
    print(f"ros2_bridge: 32FC1 depth (second bridge) equals the 16UC1 in {metres} frames")
    check_camera_info(run.sub, k, width, height)
    print(f"ros2_bridge: CameraInfo K = {k} (float32)")
    clouds = check_point_clouds(run.sub, k, width, height)
    assert clouds >= 3, f"only {clouds} point clouds had their depth image"
    print(f"ros2_bridge: {clouds} point clouds match their depth and colour images")
    for leaf, encoding, channels in [
        ("color/image_raw", "rgb8", 3),
        ("confidence/image_raw", "mono8", 1),
    ]:
        msg = run.sub.received[leaf][-1][1]
        assert (msg.width, msg.height, msg.encoding) == (width, height, encoding)
        assert len(data_bytes(msg.data)) == width * height * channels
    frame_ids = {m.header.frame_id for v in run.sub.received.values() for _, m in v}
    # Both bridges: the camera's name from the service, as the optical frame.
    assert frame_ids == {"ros2_optical_frame"}, frame_ids
    print(f"ros2_bridge: bridge figures {json.dumps(run.stop_bridge())}")
    print(f"ros2_bridge: ok ({time.monotonic() - started:.1f} s)")


def measure(run: Run, frames: int, timeout: float, no_cloud: bool) -> None:
    """Subscribes to every topic for `frames` frames and prints the bridge's figures."""
    started = time.monotonic()
    leaves = [leaf for leaf in run.sub.readers if leaf != "depth/points" or not no_cloud]
    run.poll("a message on every topic", timeout, lambda: all(run.sub.received[x] for x in leaves))
    print(f"ros2_bridge: every topic received after {time.monotonic() - started:.1f} s")
    run.sub.received = {leaf: [] for leaf in run.sub.readers}
    run.poll(
        f"{frames} depth images",
        timeout + frames,
        lambda: len(run.sub.received["depth/image_raw"]) >= frames,
    )
    print(f"ros2_bridge: {run.width}x{run.height}, received {run.sub.counts()}")
    print(f"ros2_bridge: bridge figures {json.dumps(run.stop_bridge())}")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--bin-dir", type=Path, default=ROOT / "target" / "debug")
    parser.add_argument("--timeout", type=float, default=60.0)
    parser.add_argument(
        "--measure",
        type=Path,
        metavar="CAPTURE",
        help="instead of the checks, replay CAPTURE and print the bridge's latency and CPU",
    )
    parser.add_argument("--frames", type=int, default=200, help="frames to measure")
    parser.add_argument("bridge_args", nargs="*", help="more dear-ros2 options (after --)")
    args = parser.parse_args()
    for binary in ("deard", "dear", "dear-ros2"):
        if not (args.bin_dir / binary).is_file():
            sys.exit(f"{args.bin_dir / binary} not found: build the workspace (cargo build)")
    with tempfile.TemporaryDirectory() as tmp_dir:
        if args.measure:
            # No refinement: the bridge's figures do not depend on it, and deard leaves the
            # CPU to the bridge.
            run = Run(args.bin_dir, args.measure, Path(tmp_dir), args.bridge_args, "none")
        else:
            bridge_args = ["--cloud-rgb", *args.bridge_args]
            run = Run(args.bin_dir, SAMPLE, Path(tmp_dir), bridge_args, "classical")
        try:
            if args.measure:
                measure(run, args.frames, args.timeout, "--no-cloud" in args.bridge_args)
            else:
                check(run, args.bin_dir, args.timeout)
        except BaseException:
            run.print_logs()
            raise
        finally:
            run.close()


if __name__ == "__main__":
    main()
