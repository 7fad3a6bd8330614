"""Python client of deard: receive aligned, refined ToF depth frames as zero-copy numpy arrays.

    import dear

    with dear.Subscriber("dear/cam0/frames") as sub:
        frame = sub.wait(1.0)
        if frame is not None:
            print(frame.header.frame_id, frame.depth.shape, frame.depth.max())

`Frame.depth`, `.rgb` and `.confidence` are read-only views of the daemon's shared memory:
each array keeps its sample alive (its `base` owns it). A subscriber holds at most
`MAX_BORROWED_FRAMES` (2) samples at once; `Frame.release()` (or `with frame:`) gives the
frame's own reference back, and the sample returns to the subscriber once no array over it
is left either. docs/clients.md, "Python", has the rules.
"""

import numpy as np
import numpy.typing as npt

from dear._dear import (
    CAMERA_MODEL_BROWN_CONRADY,
    CAMERA_MODEL_PINHOLE,
    CAMERA_MODEL_UNKNOWN,
    DEFAULT_SERVICE,
    ERROR_CODE_STEPS_PER_DOUBLING,
    ERROR_CODE_UNIT_M,
    FLAG_ALIGNED,
    FLAG_CALIBRATION_ESTIMATED,
    FLAG_CALIBRATION_ONLINE,
    FLAG_CONFIDENCE_EXPECTED_ERROR,
    FLAG_NETWORK_OUTPUT_REJECTED,
    FLAG_REFINED_CLASSICAL,
    FLAG_REFINED_NETWORK,
    FORMAT_VERSION,
    MAX_BORROWED_FRAMES,
    ConnectError,
    DearError,
    Frame,
    Header,
    PointCloud,
    PointCloudError,
    ReceiveError,
    Subscriber,
)

__all__ = [
    "CAMERA_MODEL_BROWN_CONRADY",
    "CAMERA_MODEL_PINHOLE",
    "CAMERA_MODEL_UNKNOWN",
    "DEFAULT_SERVICE",
    "ERROR_CODE_STEPS_PER_DOUBLING",
    "ERROR_CODE_UNIT_M",
    "FLAG_ALIGNED",
    "FLAG_CALIBRATION_ESTIMATED",
    "FLAG_CALIBRATION_ONLINE",
    "FLAG_CONFIDENCE_EXPECTED_ERROR",
    "FLAG_NETWORK_OUTPUT_REJECTED",
    "FLAG_REFINED_CLASSICAL",
    "FLAG_REFINED_NETWORK",
    "FORMAT_VERSION",
    "MAX_BORROWED_FRAMES",
    "ConnectError",
    "DearError",
    "Frame",
    "Header",
    "PointCloud",
    "PointCloudError",
    "ReceiveError",
    "Subscriber",
    "expected_error_m",
]


def expected_error_m(confidence: npt.ArrayLike) -> npt.NDArray[np.float32]:
    """The expected absolute depth error in metres of each confidence code, for frames whose
    ``header.flags`` has ``FLAG_CONFIDENCE_EXPECTED_ERROR``:
    ``ERROR_CODE_UNIT_M · 2^((255 − code) / ERROR_CODE_STEPS_PER_DOUBLING)`` (255: 1 mm,
    202: 1 cm, 149: 10 cm); NaN where the code is 0 (no depth). Keep the pixels expected
    within 5 cm with ``expected_error_m(frame.confidence) <= 0.05``."""
    codes = np.asarray(confidence, dtype=np.float32)
    err = ERROR_CODE_UNIT_M * np.exp2((255.0 - codes) / ERROR_CODE_STEPS_PER_DOUBLING)
    return np.where(codes > 0, err, np.nan).astype(np.float32)
