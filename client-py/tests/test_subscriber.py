"""The `dear` Python package against a real daemon.

Starts `target/debug/deard` (built by `cargo test --workspace` / `cargo build -p deard`)
replaying samples/demo with `--refine none` on a service of its own, under a private iceoryx2
root (`DEAR_IOX2_ROOT` in a temporary directory), and checks what the package promises: header
fields, shapes and dtypes, zero-copy read-only views that keep their sample alive, the borrow
limit, errors, and that the depth is what `dear dump` (the Rust SDK) writes for the same frame.
"""

from __future__ import annotations

import gc
import itertools
import json
import os
import shutil
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import dear
import numpy as np
import pytest
from dear_train.data.capture import depth_to_u16
from PIL import Image

REPO = Path(__file__).resolve().parents[2]
DEARD = REPO / "target" / "debug" / "deard"
DEAR = REPO / "target" / "debug" / "dear"
DEMO = REPO / "samples" / "demo"
WIDTH, HEIGHT = 320, 240
# Long enough for a debug deard on a loaded 2-core machine to start and publish.
FIRST_FRAME_S = 30.0


def require_binary(path: Path) -> None:
    if not path.is_file():
        pytest.fail(
            f"{path} is missing: build it first (`cargo build -p deard -p dear-cli`; "
            "scripts/test.sh builds it with `cargo test --workspace`)"
        )


def start_deard(name: str, log_path: Path) -> subprocess.Popen[bytes]:
    """`deard` replaying samples/demo in a loop on service `name`, alignment only, logging to
    `log_path`, under this process's `DEAR_IOX2_ROOT`."""
    with log_path.open("w") as log:
        return subprocess.Popen(
            [DEARD, "--replay", DEMO, "--loop", "--refine", "none", "--service", name],
            stdout=log,
            stderr=subprocess.STDOUT,
        )


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A running deard on a unique service, under a private iceoryx2 root."""
    require_binary(DEARD)
    tmp = tmp_path_factory.mktemp("dear-py")
    name = f"test/py{os.getpid()}/frames"
    with pytest.MonkeyPatch.context() as mp:
        # Read by every connect in this process, and inherited by the daemon and `dear dump`.
        mp.setenv("DEAR_IOX2_ROOT", str(tmp / "iox2"))
        log_path = tmp / "deard.log"
        daemon = start_deard(name, log_path)
        try:
            with dear.Subscriber(name) as sub:
                first = sub.wait(FIRST_FRAME_S)
            if first is None:
                pytest.fail(f"deard sent no frame in {FIRST_FRAME_S} s: {log_path.read_text()}")
            first.release()
            yield name
            assert daemon.poll() is None, f"deard exited: {log_path.read_text()}"
        finally:
            daemon.terminate()
            daemon.wait(timeout=30)


def receive(sub: dear.Subscriber) -> dear.Frame:
    frame = sub.wait(10.0)
    assert frame is not None, f"no frame from {sub.service} in 10 s"
    return frame


def test_point_cloud_of_a_real_frame(service: str) -> None:
    """Format 3: the header carries the replayed capture's intrinsics, and `point_cloud` (the
    Rust SDK's back-projection) gives each pixel's ((u-cx)z/fx, (v-cy)z/fy, z), checked here
    in float64 numpy, with invalid depth masked and NaN, never a point at the origin."""
    k = json.loads((DEMO / "capture.json").read_text())["intrinsics"]
    with dear.Subscriber(service) as sub, receive(sub) as frame:
        h = frame.header
        assert h.rgb_camera_model == dear.CAMERA_MODEL_PINHOLE
        got = h.intrinsics
        assert got is not None and got["model"] == "pinhole" and got["distortion"] is None
        for name in ("fx", "fy", "cx", "cy"):
            assert got[name] == pytest.approx(k[name], abs=1e-4), name
        depth = np.array(frame.depth, dtype=np.float64)
        rgb, conf = np.array(frame.rgb), np.array(frame.confidence)
        bare = frame.point_cloud()
        assert bare.colors is None and bare.confidence is None
        cloud = frame.point_cloud(colors=True, confidence=True)
        assert "valid points, colors, confidence" in repr(cloud)
    n = WIDTH * HEIGHT
    assert (cloud.width, cloud.height) == (WIDTH, HEIGHT)
    assert cloud.points.shape == (n, 3) and cloud.points.dtype == np.float32
    assert cloud.valid.shape == (n,) and cloud.valid.dtype == np.bool_
    np.testing.assert_array_equal(bare.points, cloud.points)
    valid = (depth > 0).ravel()
    np.testing.assert_array_equal(cloud.valid, valid)
    assert 0 < valid.sum() < n, "both valid and invalid pixels are checked"
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH]
    z = depth.ravel()
    want = np.stack(
        [
            (u.ravel() - got["cx"]) * z / got["fx"],
            (v.ravel() - got["cy"]) * z / got["fy"],
            z,
        ],
        axis=1,
    )
    np.testing.assert_allclose(cloud.points[valid], want[valid], rtol=1e-5, atol=1e-6)
    assert np.isnan(cloud.points[~valid]).all()
    np.testing.assert_array_equal(cloud.colors, rgb.reshape(n, 3))
    np.testing.assert_array_equal(cloud.confidence, conf.ravel())
    with pytest.raises(TypeError):
        frame.point_cloud(True)  # type: ignore[misc]
    # After release the planes are gone, and so is the cloud.
    with pytest.raises(ValueError, match="released"):
        frame.point_cloud()


def test_frames_header_shapes_and_views(service: str) -> None:
    sequences: list[int] = []
    run_ids: set[int] = set()
    with dear.Subscriber(service) as sub:
        assert sub.service == service and not sub.closed
        for _ in range(5):
            with receive(sub) as frame:
                h = frame.header
                assert (h.width, h.height) == (WIDTH, HEIGHT)
                assert frame.shape == (HEIGHT, WIDTH)
                assert h.version == dear.FORMAT_VERSION == 3
                assert h.depth_unit_m == 1.0
                assert 0 <= h.frame_id < 42  # samples/demo has 42 frames
                # --refine none: aligned with the static calibration, no network, no bundle.
                assert h.flags & dear.FLAG_ALIGNED
                assert not h.flags & (dear.FLAG_REFINED_NETWORK | dear.FLAG_REFINED_CLASSICAL)
                assert h.bundle == ""
                assert h.calib_quality == 0.0 and np.isnan(h.calib_residual_px)
                # Static calibration: the health is not assessed.
                assert (h.calib_health, h.calib_health_code, h.calib_constrained) == (
                    "unknown",
                    0,
                    0,
                )
                assert 0 < h.publish_timestamp_ns <= time.monotonic_ns()
                assert list(h.stage_latency_us) == [
                    "capture",
                    "preprocess",
                    "flow",
                    "fuse",
                    "warp",
                    "refine",
                    "publish",
                    "total",
                ]
                assert h.stage_latency_us["total"] > 0
                sequences.append(h.sequence)
                run_ids.add(h.run_id)

                depth, rgb, conf = frame.depth, frame.rgb, frame.confidence
                assert depth.shape == (HEIGHT, WIDTH) and depth.dtype == np.float32
                assert rgb.shape == (HEIGHT, WIDTH, 3) and rgb.dtype == np.uint8
                assert conf.shape == (HEIGHT, WIDTH) and conf.dtype == np.uint8
                for array in (depth, rgb, conf):
                    # Views of the sample: numpy owns no data, and nobody may write into it.
                    assert array.flags.owndata is False
                    assert array.flags.writeable is False
                    assert array.flags.c_contiguous
                    assert type(array.base).__name__ == "_Sample"
                    with pytest.raises(ValueError):
                        array.setflags(write=True)
                with pytest.raises(ValueError):
                    depth[0, 0] = 1.0
                # One sample behind all three planes; each access is a new view of it.
                assert depth.base is rgb.base is conf.base
                valid = depth > 0
                assert 0.5 < valid.mean() <= 1.0
                assert np.isfinite(depth).all() and (depth >= 0).all()
                # --refine none: confidence 255 where depth is valid, else 0.
                np.testing.assert_array_equal(conf, np.where(valid, 255, 0))
    assert sub.closed
    assert len(run_ids) == 1 and 0 not in run_ids
    assert all(b > a for a, b in itertools.pairwise(sequences)), sequences


def test_arrays_outlive_frame_and_subscriber(service: str) -> None:
    sub = dear.Subscriber(service)
    frame = receive(sub)
    depth, rgb, conf = frame.depth, frame.rgb, frame.confidence
    copies = (depth.copy(), rgb.copy(), conf.copy())
    frame.release()
    assert frame.released
    assert frame.header.width == WIDTH  # the header is a copy: still there
    with pytest.raises(ValueError, match="released"):
        _ = frame.depth
    frame.release()  # idempotent
    del frame, sub
    gc.collect()
    # The arrays still hold the sample: same memory, same values, after frame and subscriber.
    for array, copy in zip((depth, rgb, conf), copies, strict=True):
        np.testing.assert_array_equal(array, copy)
    assert float(depth.sum()) > 0


def test_borrow_limit(service: str) -> None:
    """A subscriber holds at most MAX_BORROWED_FRAMES samples: frames and arrays alike."""
    assert dear.MAX_BORROWED_FRAMES == 2
    with dear.Subscriber(service) as sub:
        held = [receive(sub), receive(sub)]
        with pytest.raises(dear.ReceiveError, match="at most 2 frames"):
            sub.wait(10.0)
        # Released frames whose arrays are alive still hold their samples.
        arrays = [frame.depth for frame in held]
        for frame in held:
            frame.release()
        with pytest.raises(dear.ReceiveError, match="at most 2 frames"):
            sub.wait(10.0)
        del arrays, held
        gc.collect()
        # Every sample given back: frames flow again, as long as each one is released.
        for _ in range(2 * dear.MAX_BORROWED_FRAMES + 1):
            receive(sub).release()


def test_iteration_and_threads(service: str) -> None:
    with dear.Subscriber(service) as sub:
        frames = []
        for frame in sub:
            frames.append(frame)
            if len(frames) == 2:
                break
        # A frame and its arrays may be read on another thread.
        seen: list[tuple[int, float]] = []
        worker = threading.Thread(
            target=lambda: seen.append((frames[1].header.sequence, float(frames[1].depth.max())))
        )
        worker.start()
        worker.join()
        assert seen == [(frames[1].header.sequence, float(frames[1].depth.max()))]
        assert frames[1].header.sequence > frames[0].header.sequence
        for frame in frames:
            frame.release()
        sub.close()
        assert list(sub) == []  # a closed subscriber ends iteration
        with pytest.raises(ValueError, match="closed"):
            sub.wait(0.0)


def test_wait_times_out_without_publisher(service: str) -> None:
    # Under the same root, but nobody publishes this one.
    with dear.Subscriber(service.replace("/frames", "-silent/frames")) as sub:
        start = time.monotonic()
        assert sub.wait(0.3) is None
        assert 0.25 < time.monotonic() - start < 5.0
        assert sub.try_receive() is None
        with pytest.raises(ValueError, match="timeout_s"):
            sub.wait(-1.0)


def test_invalid_service_raises_connect_error(service: str) -> None:
    del service  # the private root only
    with pytest.raises(dear.ConnectError, match='cannot connect to "bad name!"') as info:
        dear.Subscriber("bad name!")
    assert isinstance(info.value, dear.DearError)
    # The Rust error chain: what was wrong with the name.
    assert "contains ' '" in str(info.value)


def test_depth_matches_dear_dump(service: str, tmp_path: Path) -> None:
    require_binary(DEAR)
    out = tmp_path / "dump"
    received: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    with dear.Subscriber(service) as sub:
        receive(sub).release()  # subscribed and receiving before dump starts
        dump = subprocess.Popen(
            [DEAR, "dump", "--count", "3", "--service", service, "--out", out],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        deadline = time.monotonic() + 60
        extra = 0
        while extra < 3 and time.monotonic() < deadline:
            with receive(sub) as frame:
                h = frame.header
                received[(h.run_id, h.sequence)] = (
                    frame.depth.copy(),
                    frame.rgb.copy(),
                    frame.confidence.copy(),
                )
            if dump.poll() is not None:
                extra += 1  # a few frames past dump's last
        output, _ = dump.communicate(timeout=60)
    assert dump.returncode == 0, output
    manifest = json.loads((out / "capture.json").read_text())
    published = manifest["source"]["published_frames"]
    assert len(published) == 3
    matched = 0
    for record in published:
        key = (int(record["run_id"], 16), record["sequence"])
        if key not in received:
            continue
        depth, rgb, conf = received[key]
        stem = out / "frames" / f"{record['id']:06d}"
        # The capture writer's depth conversion, whose Python twin is dear_train's.
        np.testing.assert_array_equal(
            depth_to_u16(depth, manifest["depth_scale"]),
            np.asarray(Image.open(f"{stem}.depth.png")),
        )
        np.testing.assert_array_equal(rgb, np.asarray(Image.open(f"{stem}.rgb.png")))
        # dump writes confidence × 257 as the amplitude plane.
        amp = np.asarray(Image.open(f"{stem}.amp.png")).astype(np.uint32)
        np.testing.assert_array_equal(conf.astype(np.uint32) * 257, amp)
        matched += 1
    assert matched >= 2, (sorted(received), published)


def test_reconnecting_subscriber_outlives_a_service_made_again(
    tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`reconnect=True`: when the daemon makes its service again (here its transport's files
    are deleted under it), the old channel delivers nothing more; the subscriber reports the
    loss and the new channel, and receives the same daemon's frames again."""
    require_binary(DEARD)
    # A short path: the listener's socket under the root must fit a Unix socket address.
    tmp_path = tmp_path_factory.mktemp("rc")
    root = tmp_path / "iox2"
    monkeypatch.setenv("DEAR_IOX2_ROOT", str(root))
    name = f"test/py{os.getpid()}/reconnect"
    log_path = tmp_path / "deard.log"
    daemon = start_deard(name, log_path)
    try:
        # Connect once it serves: a client making the root beside the starting daemon can fail.
        deadline = time.monotonic() + FIRST_FRAME_S
        while "serving" not in log_path.read_text():
            assert daemon.poll() is None and time.monotonic() < deadline, log_path.read_text()
            time.sleep(0.05)
        with pytest.raises(ValueError, match="stall_s"):
            dear.Subscriber(name, reconnect=True, stall_s=0.0)
        with dear.Subscriber(name, reconnect=True, stall_s=1.0) as sub:
            first = sub.wait(FIRST_FRAME_S)
            assert first is not None, f"no frame: {log_path.read_text()}"
            run_id = first.header.run_id
            first.release()
            assert sub.take_events() == [] and sub.reconnects == 0
            for entry in root.iterdir():
                if entry.is_dir():
                    shutil.rmtree(entry)
                else:
                    entry.unlink()
            events: list[tuple[str, str]] = []
            deadline = time.monotonic() + FIRST_FRAME_S
            while ("connected", "") not in events:
                assert time.monotonic() < deadline, f"{events}: {log_path.read_text()}"
                frame = sub.wait(0.2)
                if frame is not None:
                    frame.release()
                events += sub.take_events()
            assert events[0][0] == "lost" and "no frame" in events[0][1], events
            again = sub.wait(10.0)
            assert again is not None, f"no frame after reconnecting: {log_path.read_text()}"
            assert again.header.run_id == run_id
            again.release()
            assert sub.reconnects >= 1
        assert "made the transport's files again" in log_path.read_text()
    finally:
        daemon.terminate()
        daemon.wait(timeout=30)
