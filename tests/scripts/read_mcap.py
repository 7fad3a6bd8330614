"""Reads a `dear record --mcap` file with the `mcap` package and checks what it holds.

Used by `tests/tests/record_mcap.rs`; prints what it compares and exits non-zero (an
AssertionError) on the first mismatch.

Usage: read_mcap.py FILE --prefix /dear/cam0 --capture samples/demo/capture.json
       [--frames N | --at-least N] [--depth-encoding 16UC1|32FC1] [--size 320x240]
       [--intrinsics FX,FY,CX,CY]

The calibration channel must carry the replayed capture's intrinsics (deard puts them in every
frame header, format 3), or the ones given with --intrinsics (what `dear record --intrinsics`
was given).
"""

from __future__ import annotations

import argparse
import itertools
import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

IMAGE_TOPICS = ("depth", "rgb", "confidence")
#: The calibration health channel's states, by code (docs/calibration-health.md).
HEALTH_STATES = ("unknown", "good", "can improve", "needs recalibration")


def stamp_ns(msg: Any) -> int:
    return int(msg.timestamp.seconds) * 1_000_000_000 + int(msg.timestamp.nanos)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("file", type=Path)
    parser.add_argument("--prefix", required=True)
    parser.add_argument("--capture", type=Path, required=True)
    parser.add_argument("--frames", type=int)
    parser.add_argument("--at-least", type=int)
    parser.add_argument("--depth-encoding", default="16UC1")
    parser.add_argument("--size", default="320x240")
    parser.add_argument("--intrinsics")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    capture_stamps = {f["timestamp_ns"] for f in json.loads(args.capture.read_text())["frames"]}

    topics = {leaf: f"{args.prefix}/{leaf}" for leaf in (*IMAGE_TOPICS, "calibration")}
    health_topic = f"{args.prefix}/calibration_health"
    by_topic: dict[str, list[tuple[Any, Any]]] = defaultdict(list)
    with args.file.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None, "no summary section: the file was not finished"
        schemas = {s.name for s in summary.schemas.values()}
        print(f"schemas: {sorted(schemas)}")
        assert schemas == {
            "foxglove.RawImage",
            "foxglove.CameraCalibration",
            "dear.CalibrationHealth",
        }, schemas
        channel_topics = {
            c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()
        }
        print(f"channels: {channel_topics}")
        assert set(channel_topics) == {*topics.values(), health_topic}, channel_topics
        assert channel_topics[topics["calibration"]] == "foxglove.CameraCalibration"
        assert channel_topics[health_topic] == "dear.CalibrationHealth"
        # The health channel is JSON, the others protobuf: decode each by its encoding.
        factory = DecoderFactory()
        decoders: dict[int, Any] = {}
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding == "json":
                decoded = json.loads(message.data)
            else:
                if channel.id not in decoders:
                    decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema)
                decoded = decoders[channel.id](message.data)
            by_topic[channel.topic].append((message, decoded))
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    print(f"metadata dear.record: {metadata.get('dear.record')}")
    assert "dear.record" in metadata, metadata

    counts = {leaf: len(by_topic[t]) for leaf, t in topics.items()}
    print(f"messages per topic: {counts}")
    n = counts["depth"]
    assert all(c == n for c in counts.values()), counts
    if args.frames is not None:
        assert n == args.frames, (n, args.frames)
    if args.at_least is not None:
        assert n >= args.at_least, (n, args.at_least)
    assert metadata["dear.record"]["frames"] == str(n), metadata

    for leaf, topic in topics.items():
        messages = by_topic[topic]
        log_times = [m.log_time for m, _ in messages]
        assert all(a < b for a, b in itertools.pairwise(log_times)), (
            f"{leaf}: log times not strictly increasing: {log_times}"
        )
        stamps = [stamp_ns(d) for _, d in messages]
        assert set(stamps) <= capture_stamps, f"{leaf}: stamps not in the capture: {stamps}"
        # Log time = capture time; where the replay looped (capture time went back) the
        # recorder moves the log time on by a constant offset, so the offset only changes there.
        offsets = [lt - st for lt, st in zip(log_times, stamps, strict=True)]
        assert offsets[0] == 0, f"{leaf}: first log time {log_times[0]} != capture {stamps[0]}"
        for i in range(1, len(stamps)):
            if offsets[i] != offsets[i - 1]:
                assert stamps[i] <= stamps[i - 1], (leaf, i, stamps, offsets)
        publish = [m.publish_time for m, _ in messages]
        assert all(a < b for a, b in itertools.pairwise(publish)), publish
        sequences = [m.sequence for m, _ in messages]
        assert all(a < b for a, b in itertools.pairwise(sequences)), sequences
        assert all(d.frame_id for _, d in messages)
        if leaf == "depth":
            print(f"log times (ns): {log_times}")
            print(f"capture stamps (ns): {stamps}")
            print(f"offsets (ns): {offsets}")

    expected_encoding = {"depth": args.depth_encoding, "rgb": "rgb8", "confidence": "mono8"}
    bytes_per_pixel = {"16UC1": 2, "32FC1": 4, "rgb8": 3, "mono8": 1}
    for leaf in IMAGE_TOPICS:
        for _, image in by_topic[topics[leaf]]:
            assert (image.width, image.height) == (width, height), (leaf, image.width)
            assert image.encoding == expected_encoding[leaf], (leaf, image.encoding)
            assert image.step == width * bytes_per_pixel[image.encoding], (leaf, image.step)
            assert len(image.data) == image.step * height, (leaf, len(image.data))
    print(f"images: {width}x{height}, encodings {expected_encoding}")

    health = by_topic[health_topic]
    assert len(health) == n, (len(health), n)
    for (hm, h), (dm, _) in zip(health, by_topic[topics["depth"]], strict=True):
        assert hm.sequence == dm.sequence and hm.log_time == dm.log_time
        assert h["health"] == HEALTH_STATES[h["health_code"]], h
        assert 0 <= h["constrained_directions"] <= 4, h
        assert h["frame_id"], h
        stamp = h["timestamp"]["sec"] * 1_000_000_000 + h["timestamp"]["nsec"]
        assert stamp in capture_stamps, h
    print(f"calibration health: {sorted({h['health'] for _, h in health})}")

    if args.intrinsics:
        fx, fy, cx, cy = (float(v) for v in args.intrinsics.split(","))
    else:
        k = json.loads(args.capture.read_text())["intrinsics"]
        fx, fy, cx, cy = k["fx"], k["fy"], k["cx"], k["cy"]
    want_k = [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]
    want_p = [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    for _, calibration in by_topic[topics["calibration"]]:
        assert (calibration.width, calibration.height) == (width, height)
        np.testing.assert_allclose(list(calibration.K), want_k, rtol=1e-6)
        np.testing.assert_allclose(list(calibration.P), want_p, rtol=1e-6)
        np.testing.assert_array_equal(list(calibration.R), [1, 0, 0, 0, 1, 0, 0, 0, 1])
        assert calibration.distortion_model == "plumb_bob", calibration.distortion_model
        assert list(calibration.D) == [0.0] * 5, list(calibration.D)
    print(f"calibration: K = {want_k} (plumb_bob, D zero)")

    # deard: confidence is 0 exactly where depth is 0, so the frame's valid depth pixels are
    # its non-zero confidence pixels; the decoded depth image must have the same number.
    dtype = np.dtype("<u2") if args.depth_encoding == "16UC1" else np.dtype("<f4")
    pairs = zip(by_topic[topics["depth"]], by_topic[topics["confidence"]], strict=True)
    for i, ((dm, depth_msg), (cm, conf_msg)) in enumerate(pairs):
        assert dm.sequence == cm.sequence and dm.log_time == cm.log_time
        depth = np.frombuffer(depth_msg.data, dtype=dtype).reshape(height, width)
        confidence = np.frombuffer(conf_msg.data, dtype=np.uint8).reshape(height, width)
        valid_depth = int(np.count_nonzero(depth))
        valid_confidence = int(np.count_nonzero(confidence))
        valid = depth[depth > 0]
        print(
            f"frame {i} (sequence {dm.sequence}): valid depth pixels {valid_depth}, "
            f"non-zero confidence {valid_confidence}, depth range "
            f"{valid.min() if valid.size else '-'}..{valid.max() if valid.size else '-'}"
        )
        assert valid_depth > 0
        assert valid_depth == valid_confidence, (i, valid_depth, valid_confidence)
        assert np.all(np.isfinite(depth)) and np.all(depth >= 0)
    print("ok")


if __name__ == "__main__":
    main()
