"""Reader and writer of the capture-directory format (docs/design.md, "Capture directory format").

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

Every problem is a :class:`CaptureError` whose message names the file and what is wrong, so a
bad frame in a dataset of thousands can be found and fixed (or skipped and counted).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image

from dear_train.geometry import Calibration

FORMAT_NAME = "dear-capture"
FORMAT_VERSION = 1
FLO_MAGIC = 202021.25


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
    """One decoded frame; arrays are row-major ``(H, W[, C])``, depths in metres."""

    id: int
    rgb: np.ndarray  # (H, W, 3) uint8
    amplitude: np.ndarray  # (H, W) float32, raw sensor units
    depth: np.ndarray  # (H, W) float32 metres, 0 = invalid (ToF grid)
    gt_depth: np.ndarray | None = None  # (H, W) float32 metres (RGB view)
    mask: np.ndarray | None = None  # (H, W) bool
    flow: np.ndarray | None = None  # (2, H, W) float32 px, RGB → ToF
    perturbation: Calibration | None = None
    classical: np.ndarray | None = None  # (H, W) float32 metres, classical filter (ToF grid)


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
            "initial_calibration": self.initial_calibration.to_dict(),
            "depth_scale": self.depth_scale,
            "modulation_frequencies_hz": self.modulation_frequencies_hz,
            "frames": frames,
        }
        if self.source is not None:
            d["source"] = self.source
        return d


def frame_path(root: Path, frame_id: int, kind: str) -> Path:
    """``root/frames/{id:06}.{kind}``, e.g. ``kind = "rgb.png"``."""
    return Path(root) / "frames" / f"{frame_id:06d}.{kind}"


def _calibration(obj: object, path: Path, what: str) -> Calibration:
    if not isinstance(obj, dict) or set(obj) != {"tx", "ty", "cx", "cy"}:
        raise CaptureError(f"{path}: {what} must be an object with exactly tx, ty, cx, cy")
    try:
        c = Calibration.from_dict(obj)
    except (TypeError, ValueError) as e:
        raise CaptureError(f"{path}: {what}: {e}") from e
    if not all(np.isfinite([c.tx, c.ty, c.cx, c.cy])):
        raise CaptureError(f"{path}: {what} has a non-finite value")
    return c


def read_manifest(root: Path) -> Manifest:
    """Parse and validate ``root/capture.json``."""
    path = Path(root) / "capture.json"
    try:
        d = json.loads(path.read_text())
    except FileNotFoundError as e:
        raise CaptureError(f"{path}: missing (not a capture directory)") from e
    except json.JSONDecodeError as e:
        raise CaptureError(f"{path}: invalid JSON: {e}") from e
    if not isinstance(d, dict):
        raise CaptureError(f"{path}: top level must be an object")
    if d.get("format") != FORMAT_NAME:
        raise CaptureError(f"{path}: format is {d.get('format')!r}, expected {FORMAT_NAME!r}")
    if d.get("version") != FORMAT_VERSION:
        raise CaptureError(f"{path}: unsupported version {d.get('version')!r}")
    for key in ("width", "height", "intrinsics", "depth_scale", "frames"):
        if key not in d:
            raise CaptureError(f"{path}: missing field {key!r}")
    w, h = d["width"], d["height"]
    if not (isinstance(w, int) and isinstance(h, int) and w > 0 and h > 0):
        raise CaptureError(f"{path}: width/height must be positive integers, got {w!r}×{h!r}")
    intr = d["intrinsics"]
    if not isinstance(intr, dict) or set(intr) != {"fx", "fy", "cx", "cy"}:
        raise CaptureError(f"{path}: intrinsics must have exactly fx, fy, cx, cy")
    scale = d["depth_scale"]
    if not isinstance(scale, int | float) or not scale > 0:
        raise CaptureError(f"{path}: depth_scale must be positive, got {scale!r}")
    init = d.get("initial_calibration", {"tx": 0.0, "ty": 0.0, "cx": 0.0, "cy": 0.0})
    frames = []
    seen: set[int] = set()
    last_ts = -1
    if not isinstance(d["frames"], list):
        raise CaptureError(f"{path}: frames must be a list")
    for i, e in enumerate(d["frames"]):
        if not isinstance(e, dict) or "id" not in e or "timestamp_ns" not in e:
            raise CaptureError(f"{path}: frames[{i}] needs id and timestamp_ns")
        fid, ts = e["id"], e["timestamp_ns"]
        if not isinstance(fid, int) or fid < 0 or fid in seen:
            raise CaptureError(f"{path}: frames[{i}].id {fid!r} is not a new non-negative integer")
        if not isinstance(ts, int) or ts < last_ts:
            raise CaptureError(f"{path}: frames[{i}].timestamp_ns {ts!r} is not monotonic")
        seen.add(fid)
        last_ts = ts
        pert = e.get("perturbation")
        frames.append(
            FrameEntry(
                fid,
                ts,
                None if pert is None else _calibration(pert, path, f"frames[{i}].perturbation"),
            )
        )
    return Manifest(
        width=w,
        height=h,
        intrinsics=Intrinsics(**{k: float(v) for k, v in intr.items()}),
        initial_calibration=_calibration(init, path, "initial_calibration"),
        depth_scale=float(scale),
        modulation_frequencies_hz=[float(f) for f in d.get("modulation_frequencies_hz", [])],
        source=d.get("source"),
        frames=frames,
    )


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
    data = np.frombuffer(raw[12:], "<f4").reshape(h, w, 2)
    return _check_size(path, data, size).transpose(2, 0, 1).astype(np.float32)


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
            flow = read_flo(path("flow.flo"), size)
            if not np.isfinite(flow).all():
                raise CaptureError(f"{path('flow.flo')}: non-finite flow values")
            frame.flow = flow
        return frame


def _write_u16(path: Path, arr: np.ndarray) -> None:
    Image.fromarray(np.ascontiguousarray(arr, dtype=np.uint16)).save(path)


def depth_to_u16(depth: np.ndarray, scale: float) -> np.ndarray:
    """Metres → 16-bit units of ``scale`` metres (rounded; invalid and out-of-range → 0)."""
    units = np.where(np.isfinite(depth) & (depth > 0), np.round(depth / scale), 0)
    return np.where(units > 65535, 0, units).astype(np.uint16)


def write_frame(root: Path, frame: Frame, scale: float) -> None:
    """Write one frame's files (the manifest is written separately)."""
    (Path(root) / "frames").mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.ascontiguousarray(frame.rgb, dtype=np.uint8), "RGB").save(
        frame_path(root, frame.id, "rgb.png")
    )
    amp = np.clip(np.round(frame.amplitude), 0, 65535)
    _write_u16(frame_path(root, frame.id, "amp.png"), amp)
    _write_u16(frame_path(root, frame.id, "depth.png"), depth_to_u16(frame.depth, scale))
    if frame.gt_depth is not None:
        _write_u16(frame_path(root, frame.id, "gt.png"), depth_to_u16(frame.gt_depth, scale))
    if frame.mask is not None:
        Image.fromarray(frame.mask.astype(np.uint8) * 255, "L").save(
            frame_path(root, frame.id, "mask.png")
        )
    if frame.flow is not None:
        write_flo(frame_path(root, frame.id, "flow.flo"), frame.flow)


def write_manifest(root: Path, manifest: Manifest) -> None:
    Path(root).mkdir(parents=True, exist_ok=True)
    (Path(root) / "capture.json").write_text(json.dumps(manifest.to_json(), indent=2) + "\n")
