"""Type stubs of the `dear` package (the Rust extension `dear._dear`, client-py/src/lib.rs)."""

from collections.abc import Iterator
from types import TracebackType
from typing import Final, Literal, TypedDict

import numpy as np
import numpy.typing as npt

DEFAULT_SERVICE: Final[str]
"""`"dear/cam0/frames"`."""
MAX_BORROWED_FRAMES: Final[int]
"""Samples one subscriber may hold at once (2): frames not released plus their arrays' samples."""
FORMAT_VERSION: Final[int]
"""3: the header carries the RGB camera's intrinsics."""
CAMERA_MODEL_UNKNOWN: Final[int]
CAMERA_MODEL_PINHOLE: Final[int]
CAMERA_MODEL_BROWN_CONRADY: Final[int]
FLAG_ALIGNED: Final[int]
FLAG_REFINED_NETWORK: Final[int]
FLAG_REFINED_CLASSICAL: Final[int]
FLAG_CALIBRATION_ESTIMATED: Final[int]
FLAG_CALIBRATION_ONLINE: Final[int]
FLAG_NETWORK_OUTPUT_REJECTED: Final[int]
FLAG_CONFIDENCE_EXPECTED_ERROR: Final[int]
ERROR_CODE_UNIT_M: Final[float]
ERROR_CODE_STEPS_PER_DOUBLING: Final[float]

def expected_error_m(confidence: npt.ArrayLike) -> npt.NDArray[np.float32]: ...

class DearError(Exception):
    """Base class of the errors of the dear package."""

class ConnectError(DearError):
    """Subscribing failed; the message is the Rust error chain and names the service."""

class ReceiveError(DearError):
    """Receiving or waiting for a frame failed; the message is the Rust error chain."""

class PointCloudError(DearError):
    """The frame carries no (or unusable) intrinsics; the message names the header field."""

class Intrinsics(TypedDict):
    fx: float
    fy: float
    cx: float
    cy: float
    model: Literal["pinhole", "brown_conrady"]
    distortion: tuple[float, float, float, float, float] | None
    """(k1, k2, p1, p2, k3), OpenCV's order, with model "brown_conrady"."""

class PointCloud:
    """An organised point cloud: one entry per pixel, row-major (N = width·height)."""

    @property
    def points(self) -> npt.NDArray[np.float32]:
        """(N, 3) metres in the RGB camera's optical frame; NaN where not `valid`."""
    @property
    def valid(self) -> npt.NDArray[np.bool_]:
        """(N,): the pixel has valid depth. `points[valid]` is the measured cloud."""
    @property
    def colors(self) -> npt.NDArray[np.uint8] | None:
        """(N, 3) RGB of each point, with `point_cloud(colors=True)`."""
    @property
    def confidence(self) -> npt.NDArray[np.uint8] | None:
        """(N,) confidence byte of each point, with `point_cloud(confidence=True)`."""
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...

class Header:
    """A copy of the frame's 256-byte header (docs/protocol.md "Frame layout")."""

    @property
    def version(self) -> int: ...
    @property
    def frame_id(self) -> int: ...
    @property
    def capture_timestamp_ns(self) -> int: ...
    @property
    def publish_timestamp_ns(self) -> int:
        """`CLOCK_MONOTONIC` at publication: compare with `time.monotonic_ns()`."""
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def calib_tx(self) -> float: ...
    @property
    def calib_ty(self) -> float: ...
    @property
    def calib_cx(self) -> float: ...
    @property
    def calib_cy(self) -> float: ...
    @property
    def calib_residual_px(self) -> float: ...
    @property
    def calib_quality(self) -> float: ...
    @property
    def calib_age_frames(self) -> int: ...
    @property
    def calib_health(self) -> str:
        """`"unknown"`, `"good"`, `"can improve"` or `"needs recalibration"`."""
    @property
    def calib_health_code(self) -> int:
        """0 unknown, 1 good, 2 can improve, 3 needs recalibration."""
    @property
    def calib_constrained(self) -> int:
        """Directions of (t_x, t_y, c_x, c_y) the last measurement constrained, 0-4."""
    @property
    def flags(self) -> int:
        """`FLAG_*` bits."""
    @property
    def bundle(self) -> str: ...
    @property
    def stage_latency_us(self) -> dict[str, int]:
        """capture, preprocess, flow, fuse, warp, refine, publish, total (µs; 0 = not run)."""
    @property
    def frames_skipped(self) -> int: ...
    @property
    def frames_dropped(self) -> int: ...
    @property
    def run_id(self) -> int: ...
    @property
    def sequence(self) -> int: ...
    @property
    def depth_unit_m(self) -> float:
        """Metres per depth unit: 1.0."""
    @property
    def rgb_camera_model(self) -> int:
        """`CAMERA_MODEL_*`: 0 unknown, 1 pinhole, 2 Brown-Conrady."""
    @property
    def intrinsics(self) -> Intrinsics | None:
        """The RGB camera's intrinsics at the frame's size; None when unknown."""

class Frame:
    """One received frame. Arrays are read-only zero-copy views that keep the sample alive."""

    @property
    def header(self) -> Header: ...
    @property
    def depth(self) -> npt.NDArray[np.float32]:
        """(H, W) metres, 0 = invalid. Raises ValueError after `release()`."""
    @property
    def rgb(self) -> npt.NDArray[np.uint8]:
        """(H, W, 3). Raises ValueError after `release()`."""
    @property
    def confidence(self) -> npt.NDArray[np.uint8]:
        """(H, W), 0 = invalid, 255 = measured and kept. Raises ValueError after `release()`."""
    def point_cloud(self, *, colors: bool = False, confidence: bool = False) -> PointCloud:
        """The back-projected depth (the Rust SDK's math). Raises PointCloudError without
        intrinsics, ValueError after `release()`."""
    @property
    def shape(self) -> tuple[int, int]:
        """(height, width)."""
    @property
    def released(self) -> bool: ...
    def release(self) -> None:
        """Drops this frame's reference to its sample (arrays taken before keep theirs)."""
    def __enter__(self) -> Frame: ...
    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> Literal[False]: ...

class Subscriber:
    """A subscription to one deard frame service (root: `$DEAR_IOX2_ROOT`, else /dev/shm/dear).

    Not thread-safe: use it (and let its frames be freed) on the thread that made it.
    """

    def __init__(
        self, service: str = "dear/cam0/frames", *, reconnect: bool = False, stall_s: float = 3.0
    ) -> None:
        """Connects; raises ConnectError. With `reconnect=True` a corrupted channel, or one that
        delivered nothing for `stall_s` seconds (a service the daemon made again), is dropped and
        connected again; waits meanwhile time out as on an idle stream."""
    @property
    def service(self) -> str: ...
    @property
    def reconnects(self) -> int:
        """How many times the channel was connected again (0 without reconnect)."""
    def take_events(self) -> list[tuple[str, str]]:
        """("lost", reason) and ("connected", "") since the last call, oldest first."""
    @property
    def closed(self) -> bool: ...
    def wait(self, timeout_s: float) -> Frame | None:
        """Next frame within `timeout_s` seconds, else None. Releases the GIL while waiting."""
    def try_receive(self) -> Frame | None: ...
    def close(self) -> None: ...
    def __enter__(self) -> Subscriber: ...
    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> Literal[False]: ...
    def __iter__(self) -> Iterator[Frame]: ...
    def __next__(self) -> Frame: ...
