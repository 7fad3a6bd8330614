"""Reader and writer of the capture-directory format (docs/capture-format.md).

```
capture.json             {"format": "dear-capture", "version": 1, "width", "height",
                          "intrinsics": {fx, fy, cx, cy}, "initial_calibration": {tx, ty, cx, cy},
                          "depth_scale", "modulation_frequencies_hz", "source", "frames": [...]}
frames/NNNNNN.rgb.png    8-bit RGB
frames/NNNNNN.amp.png    16-bit raw ToF amplitude
frames/NNNNNN.depth.png  16-bit ToF depth (× depth_scale → metres), 0 = invalid
frames/NNNNNN.gt.png     optional ground-truth depth in the RGB view
frames/NNNNNN.mask.png   optional 8-bit validity mask (non-zero = valid)
frames/NNNNNN.classical.png  optional 16-bit classical refiner output on the ToF grid
                         (× depth_scale → metres), written by `dear-synth classical` for
                         training refiners that take it
frames/NNNNNN.flow.flo   optional ground-truth RGB→ToF flow (Middlebury .flo)
```

Every problem is a :class:`CaptureError` whose message names the file and what is wrong (for
``capture.json``, the field), so a bad frame in a dataset of thousands can be found and fixed (or
skipped and counted).

The format is defined by the Rust crate ``dear-capture`` (``capture/``). ``capture.json`` is
validated against the JSON Schema generated from its types (:data:`SCHEMA_PATH`, the same bounds
the Rust reader enforces: no unknown keys, sides of 1..=8192, ids up to 999,999, positive focal
lengths, ...); what a schema cannot say (unique ids, timestamps in order) is checked here as the
Rust reader checks it. :func:`write_capture` writes what the Rust reader reads, with the Rust
writer's rounding. ``fixtures/capture/`` holds the tests both languages run.
"""

from __future__ import annotations

import functools
import json
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
from jsonschema.exceptions import ValidationError, best_match
from PIL import Image

from dear_train.geometry import Calibration

FORMAT_NAME = "dear-capture"
FORMAT_VERSION = 1
FLO_MAGIC = 202021.25
MANIFEST_FILE = "capture.json"
#: The JSON Schema of ``capture.json``, generated from the Rust types
#: (``cargo run -p dear-capture --example write_schema``) and read from the repository checkout
#: (``pip install -e train``, as ``scripts/setup.sh`` does).
SCHEMA_PATH = Path(__file__).resolve().parents[3] / "capture" / "schema" / "capture.schema.json"


class CaptureError(ValueError):
    """A capture file is missing or malformed; the message names the file."""


@dataclass(frozen=True)
class Intrinsics:
    fx: float
    fy: float
    cx: float
    cy: float


@dataclass(frozen=True)
class FrameEntry:
    id: int
    timestamp_ns: int
    perturbation: Calibration | None = None


@dataclass
class Frame:
    """One decoded frame; arrays are row-major ``(H, W[, C])``, depths in metres.

    ``timestamp_ns`` is the manifest's; a frame given to :func:`write_capture` is listed with it.
    """

    id: int
    rgb: np.ndarray  # (H, W, 3) uint8
    amplitude: np.ndarray  # (H, W) float32, raw sensor units
    depth: np.ndarray  # (H, W) float32 metres, 0 = invalid (ToF grid)
    gt_depth: np.ndarray | None = None  # (H, W) float32 metres (RGB view)
    mask: np.ndarray | None = None  # (H, W) bool
    flow: np.ndarray | None = None  # (2, H, W) float32 px, RGB → ToF
    perturbation: Calibration | None = None
    classical: np.ndarray | None = None  # (H, W) float32 metres, classical filter (ToF grid)
    timestamp_ns: int = 0


@dataclass
class Manifest:
    width: int
    height: int
    intrinsics: Intrinsics
    initial_calibration: Calibration
    depth_scale: float
    modulation_frequencies_hz: list[float]
    source: dict | None
    frames: list[FrameEntry] = field(default_factory=list)
    #: The RGB camera's Brown-Conrady distortion [k1, k2, p1, p2, k3] (OpenCV's order); None:
    #: none (a pinhole). deard publishes it with the intrinsics in every frame header.
    distortion: list[float] | None = None

    def to_json(self) -> dict:
        frames = []
        for f in self.frames:
            e: dict = {"id": f.id, "timestamp_ns": f.timestamp_ns}
            if f.perturbation is not None:
                e["perturbation"] = f.perturbation.to_dict()
            frames.append(e)
        d: dict = {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "width": self.width,
            "height": self.height,
            "intrinsics": vars(self.intrinsics),
        }
        if self.distortion is not None:
            d["distortion"] = [float(k) for k in self.distortion]
        d |= {
            "initial_calibration": self.initial_calibration.to_dict(),
            "depth_scale": self.depth_scale,
            "modulation_frequencies_hz": self.modulation_frequencies_hz,
            "frames": frames,
        }
        if self.source is not None:
            d["source"] = self.source
        return d

    @staticmethod
    def from_json(d: dict) -> Manifest:
        """From a parsed ``capture.json`` that :func:`validate_manifest` accepted."""

        def calibration(obj: dict | None) -> Calibration | None:
            return None if obj is None else Calibration.from_dict(obj)

        return Manifest(
            width=d["width"],
            height=d["height"],
            intrinsics=Intrinsics(**{k: float(v) for k, v in d["intrinsics"].items()}),
            initial_calibration=calibration(d.get("initial_calibration")) or Calibration(),
            depth_scale=float(d["depth_scale"]),
            modulation_frequencies_hz=[float(f) for f in d.get("modulation_frequencies_hz", [])],
            source=d.get("source"),
            distortion=(
                None if d.get("distortion") is None else [float(k) for k in d["distortion"]]
            ),
            frames=[
                FrameEntry(e["id"], e["timestamp_ns"], calibration(e.get("perturbation")))
                for e in d["frames"]
            ],
        )


def frame_path(root: Path, frame_id: int, kind: str) -> Path:
    """``root/frames/{id:06}.{kind}``, e.g. ``kind = "rgb.png"``."""
    return Path(root) / "frames" / f"{frame_id:06d}.{kind}"


def _is_integer(_checker: object, instance: object) -> bool:
    # JSON Schema counts 1.0 as an integer; serde, and so the Rust reader, does not.
    return isinstance(instance, int) and not isinstance(instance, bool)


@functools.cache
def _validator() -> jsonschema.protocols.Validator:
    try:
        schema = json.loads(SCHEMA_PATH.read_text())
    except FileNotFoundError as e:
        raise CaptureError(
            f"{SCHEMA_PATH}: missing: the capture.json schema is read from the repository "
            "checkout (install train with `pip install -e train`)"
        ) from e
    base = jsonschema.validators.validator_for(schema)
    base.check_schema(schema)
    strict = jsonschema.validators.extend(
        base, type_checker=base.TYPE_CHECKER.redefine("integer", _is_integer)
    )
    return strict(schema)


def _field_name(path: Iterable[str | int]) -> str:
    """``["frames", 3, "id"]`` → ``frames[3].id``, as the Rust reader names fields."""
    name = ""
    for part in path:
        name += f"[{part}]" if isinstance(part, int) else (f".{part}" if name else part)
    return name


def _most_specific(error: ValidationError) -> ValidationError:
    """The error inside an ``anyOf``: for ``perturbation`` (a calibration or null) what is wrong
    with the calibration, not that it is not null."""
    while error.context:
        inner = [e for e in error.context if (e.validator, e.validator_value) != ("type", "null")]
        error = best_match(inner or error.context)
    return error


def validate_manifest(doc: Any, path: Path) -> None:
    """Check a parsed ``capture.json`` as the Rust reader does; raise :class:`CaptureError`
    naming ``path`` and the field.

    The schema (:data:`SCHEMA_PATH`) carries every rule it can express; the order of the frame
    list, which it cannot, is checked here with the Rust reader's wording.
    """
    error = best_match(_validator().iter_errors(doc))
    if error is not None:
        error = _most_specific(error)
        field = _field_name(error.absolute_path)
        raise CaptureError(
            f"{path}: field `{field}`: {error.message}" if field else f"{path}: {error.message}"
        )
    seen: set[int] = set()
    last_ts = 0
    for i, e in enumerate(doc["frames"]):
        if e["id"] in seen:
            raise CaptureError(f"{path}: field `frames[{i}].id` is {e['id']}, which appears twice")
        seen.add(e["id"])
        if e["timestamp_ns"] < last_ts:
            raise CaptureError(
                f"{path}: field `frames[{i}].timestamp_ns` is {e['timestamp_ns']}, before the "
                f"previous frame's {last_ts} (timestamps must be monotonic)"
            )
        last_ts = e["timestamp_ns"]


def _non_finite_field(value: Any, path: Sequence[str | int] = ()) -> str | None:
    """The first field of a JSON-to-be that holds NaN or ±inf (JSON has no such numbers, and
    the schema's bounds do not catch NaN: every comparison with it is false)."""
    if isinstance(value, float) and not math.isfinite(value):
        return _field_name(path) or "(top level)"
    items = (
        value.items()
        if isinstance(value, dict)
        else enumerate(value)
        if isinstance(value, list)
        else ()
    )
    for key, item in items:
        found = _non_finite_field(item, (*path, key))
        if found is not None:
            return found
    return None


def _parse_json(text: str, path: Path) -> Any:
    """JSON as serde_json reads it: no key twice in an object (Python's json would keep the
    last), no NaN or infinity (Python's json reads ``NaN`` and makes ``1e400`` infinite)."""

    def unique_keys(pairs: list[tuple[str, Any]]) -> dict:
        d: dict = {}
        for key, value in pairs:
            if key in d:
                raise CaptureError(f"{path}: invalid JSON: field `{key}` appears twice")
            d[key] = value
        return d

    try:
        doc = json.loads(text, object_pairs_hook=unique_keys)
    except json.JSONDecodeError as e:
        raise CaptureError(f"{path}: invalid JSON: {e}") from e
    bad = _non_finite_field(doc)
    if bad is not None:
        raise CaptureError(
            f"{path}: invalid JSON: field `{bad}` is not a finite number (NaN, Infinity or a "
            "number beyond float64 such as 1e400)"
        )
    return doc


def read_manifest(root: Path) -> Manifest:
    """Parse and validate ``root/capture.json``."""
    path = Path(root) / MANIFEST_FILE
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError as e:
        raise CaptureError(f"{path}: missing (not a capture directory)") from e
    except UnicodeDecodeError as e:
        raise CaptureError(f"{path}: not UTF-8 text: {e}") from e
    doc = _parse_json(text, path)
    validate_manifest(doc, path)
    return Manifest.from_json(doc)


def _open_png(path: Path) -> Image.Image:
    if not path.exists():
        raise CaptureError(f"{path}: missing")
    try:
        img = Image.open(path)
        img.load()
    except (OSError, SyntaxError) as e:
        raise CaptureError(f"{path}: not a readable PNG: {e}") from e
    if img.format != "PNG":
        raise CaptureError(f"{path}: is {img.format}, expected PNG")
    return img


def _check_size(path: Path, arr: np.ndarray, size: tuple[int, int] | None) -> np.ndarray:
    if size is not None and arr.shape[:2] != size:
        raise CaptureError(
            f"{path}: size {arr.shape[1]}×{arr.shape[0]}, expected {size[1]}×{size[0]}"
        )
    return arr


def read_rgb(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """8-bit RGB PNG → ``(H, W, 3)`` uint8."""
    img = _open_png(path)
    if img.mode != "RGB":
        raise CaptureError(f"{path}: mode {img.mode}, expected 8-bit RGB")
    return _check_size(path, np.asarray(img, dtype=np.uint8), size)


def read_u16(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """16-bit greyscale PNG → ``(H, W)`` uint16."""
    img = _open_png(path)
    if img.mode not in ("I;16", "I;16B", "I"):
        raise CaptureError(f"{path}: mode {img.mode}, expected 16-bit greyscale")
    arr = np.asarray(img)
    if arr.dtype != np.uint16:
        if arr.min() < 0 or arr.max() > 65535:
            raise CaptureError(f"{path}: values outside the 16-bit range")
        arr = arr.astype(np.uint16)
    return _check_size(path, arr, size)


def read_mask(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """8-bit greyscale PNG → ``(H, W)`` bool (non-zero = valid)."""
    img = _open_png(path)
    if img.mode not in ("L", "1"):
        raise CaptureError(f"{path}: mode {img.mode}, expected 8-bit greyscale")
    return _check_size(path, np.asarray(img) > 0, size)


def read_flo(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """Middlebury ``.flo`` → ``(2, H, W)`` float32 (u, v)."""
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError as e:
        raise CaptureError(f"{path}: missing") from e
    if len(raw) < 12 or np.frombuffer(raw[:4], "<f4")[0] != np.float32(FLO_MAGIC):
        raise CaptureError(f"{path}: bad .flo magic number")
    w, h = (int(x) for x in np.frombuffer(raw[4:12], "<i4"))
    if w <= 0 or h <= 0 or len(raw) != 12 + 8 * w * h:
        raise CaptureError(f"{path}: header says {w}×{h} but the file has {len(raw)} bytes")
    data = _check_size(path, np.frombuffer(raw[12:], "<f4").reshape(h, w, 2), size)
    bad = np.argwhere(~np.isfinite(data))
    if len(bad):
        row, col, _ = bad[0]
        raise CaptureError(
            f"{path}: expected finite flow values (1e10 marks unknown), found "
            f"{data[tuple(bad[0])]} at row {row}, column {col}"
        )
    return data.transpose(2, 0, 1).astype(np.float32)


def write_flo(path: Path, flow: np.ndarray) -> None:
    """``(2, H, W)`` flow → Middlebury ``.flo``."""
    _, h, w = flow.shape
    header = np.array([FLO_MAGIC], "<f4").tobytes() + np.array([w, h], "<i4").tobytes()
    Path(path).write_bytes(header + flow.transpose(1, 2, 0).astype("<f4").tobytes())


class Capture:
    """A capture directory: its manifest and lazily decoded frames."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.manifest = read_manifest(self.root)

    def __len__(self) -> int:
        return len(self.manifest.frames)

    @property
    def size(self) -> tuple[int, int]:
        """``(height, width)``."""
        return self.manifest.height, self.manifest.width

    def load(self, index: int) -> Frame:
        """Decode frame ``index`` (position in the frame list), validating every file."""
        entry = self.manifest.frames[index]
        size = self.size
        scale = self.manifest.depth_scale

        def path(kind: str) -> Path:
            return frame_path(self.root, entry.id, kind)

        frame = Frame(
            id=entry.id,
            rgb=read_rgb(path("rgb.png"), size),
            amplitude=read_u16(path("amp.png"), size).astype(np.float32),
            depth=read_u16(path("depth.png"), size).astype(np.float32) * np.float32(scale),
            perturbation=entry.perturbation,
            timestamp_ns=entry.timestamp_ns,
        )
        if path("gt.png").exists():
            frame.gt_depth = read_u16(path("gt.png"), size).astype(np.float32) * np.float32(scale)
        if path("mask.png").exists():
            frame.mask = read_mask(path("mask.png"), size)
        if path("classical.png").exists():
            frame.classical = read_u16(path("classical.png"), size).astype(np.float32) * np.float32(
                scale
            )
        if path("flow.flo").exists():
            frame.flow = read_flo(path("flow.flo"), size)
        return frame


def _write_u16(path: Path, arr: np.ndarray) -> None:
    Image.fromarray(np.ascontiguousarray(arr, dtype=np.uint16)).save(path)


def _round_half_away(x: np.ndarray) -> np.ndarray:
    """Rust's ``f32::round`` (half away from zero; NumPy's rounds half to even). Not
    ``floor(x + 0.5)``: in float32, 0.49999997 + 0.5 rounds up to 1."""
    whole = np.trunc(x)
    with np.errstate(invalid="ignore"):  # inf - inf: an infinite x stays infinite
        return whole + np.where(np.abs(x - whole) >= 0.5, np.sign(x), 0).astype(x.dtype)


def depth_to_u16(depth: np.ndarray, scale: float) -> np.ndarray:
    """Metres → 16-bit units of ``scale`` metres, as the Rust writer stores them
    (``png::depth_to_u16``): ``z / scale`` in float32, rounded half away from zero, saturated at
    65535; an invalid depth (not positive and finite) → 0."""
    z = np.asarray(depth, dtype=np.float32)
    valid = np.isfinite(z) & (z > 0)
    with np.errstate(over="ignore"):  # beyond float32 → inf → saturates like Rust's
        units = _round_half_away(np.where(valid, z, np.float32(0)) / np.float32(scale))
    return np.where(valid, np.clip(units, 0, 65535), 0).astype(np.uint16)


def amplitude_to_u16(amplitude: np.ndarray) -> np.ndarray:
    """Raw amplitude → the 16-bit on-disk unit, as the Rust writer stores it
    (``png::amplitude_to_u16``): rounded half away from zero, clamped to 0..=65535, non-finite →
    0."""
    a = np.asarray(amplitude, dtype=np.float32)
    finite = np.isfinite(a)
    units = _round_half_away(np.where(finite, a, np.float32(0)))
    return np.where(finite, np.clip(units, 0, 65535), 0).astype(np.uint16)


def write_frame(root: Path, frame: Frame, scale: float) -> None:
    """Write one frame's files (the manifest is written separately)."""
    (Path(root) / "frames").mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.ascontiguousarray(frame.rgb, dtype=np.uint8), "RGB").save(
        frame_path(root, frame.id, "rgb.png")
    )
    _write_u16(frame_path(root, frame.id, "amp.png"), amplitude_to_u16(frame.amplitude))
    _write_u16(frame_path(root, frame.id, "depth.png"), depth_to_u16(frame.depth, scale))
    if frame.gt_depth is not None:
        _write_u16(frame_path(root, frame.id, "gt.png"), depth_to_u16(frame.gt_depth, scale))
    if frame.mask is not None:
        Image.fromarray(np.where(frame.mask, 255, 0).astype(np.uint8), "L").save(
            frame_path(root, frame.id, "mask.png")
        )
    if frame.classical is not None:
        _write_u16(
            frame_path(root, frame.id, "classical.png"), depth_to_u16(frame.classical, scale)
        )
    if frame.flow is not None:
        write_flo(frame_path(root, frame.id, "flow.flo"), frame.flow)


def write_manifest(root: Path, manifest: Manifest) -> None:
    """Validate ``manifest`` as a reader will and write ``root/capture.json`` (via a temporary
    file and a rename, as the Rust writer does, so a reader never sees half a file)."""
    path = Path(root) / MANIFEST_FILE
    doc = manifest.to_json()
    bad = _non_finite_field(doc)
    if bad is not None:
        raise CaptureError(f"{path}: field `{bad}` is not a finite number (JSON has none)")
    validate_manifest(doc, path)
    Path(root).mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{MANIFEST_FILE}.tmp")
    tmp.write_text(json.dumps(doc, indent=2) + "\n")
    os.replace(tmp, path)


def write_capture(root: str | Path, manifest: Manifest, frames: Iterable[Frame]) -> Path:
    """Write a new capture directory that ``deard``, ``dear eval`` and training read: e.g. to
    convert a dataset recorded elsewhere. The Python twin of the Rust ``CaptureWriter``.

    ``root`` must not exist or be empty. ``manifest`` gives the header (size, intrinsics,
    calibration, ``depth_scale``, ...); its frame list is replaced by ``frames``, listed with
    their ``id``, ``timestamp_ns`` and ``perturbation`` in the order given (ids increasing,
    timestamps not decreasing). Each plane must have the manifest's size. Depths are in metres and
    stored in units of ``depth_scale``, amplitude rounded to whole units, with the Rust writer's
    rounding (:func:`depth_to_u16`, :func:`amplitude_to_u16`). ``capture.json`` is written last
    and only when every frame was written, so a directory with one is complete.
    """
    root = Path(root)
    if root.exists() and any(root.iterdir()):
        raise CaptureError(f"{root}: expected a new or empty directory, found files in it")
    size = (manifest.height, manifest.width)
    entries: list[FrameEntry] = []
    for frame in frames:
        planes = {
            "rgb.png": frame.rgb,
            "amp.png": frame.amplitude,
            "depth.png": frame.depth,
            "gt.png": frame.gt_depth,
            "mask.png": frame.mask,
            "classical.png": frame.classical,
            "flow.flo": None if frame.flow is None else frame.flow[0],
        }
        for kind, plane in planes.items():
            if plane is not None and np.shape(plane)[:2] != size:
                raise CaptureError(
                    f"{frame_path(root, frame.id, kind)}: size {np.shape(plane)}, expected "
                    f"{manifest.height}×{manifest.width} (height × width)"
                )
        if entries and (
            frame.id <= entries[-1].id or frame.timestamp_ns < entries[-1].timestamp_ns
        ):
            raise CaptureError(
                f"{frame_path(root, frame.id, 'depth.png')}: expected a frame after id "
                f"{entries[-1].id} at {entries[-1].timestamp_ns} ns, found id {frame.id} at "
                f"{frame.timestamp_ns} ns"
            )
        write_frame(root, frame, manifest.depth_scale)
        entries.append(FrameEntry(frame.id, frame.timestamp_ns, frame.perturbation))
    root.mkdir(parents=True, exist_ok=True)
    write_manifest(root, replace(manifest, frames=entries))
    return root
