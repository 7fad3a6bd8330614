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
is left either. The README's "Python" section has the rules.
"""

from dear._dear import (
    DEFAULT_SERVICE,
    FLAG_ALIGNED,
    FLAG_CALIBRATION_ESTIMATED,
    FLAG_CALIBRATION_ONLINE,
    FLAG_NETWORK_OUTPUT_REJECTED,
    FLAG_REFINED_CLASSICAL,
    FLAG_REFINED_NETWORK,
    FORMAT_VERSION,
    MAX_BORROWED_FRAMES,
    ConnectError,
    DearError,
    Frame,
    Header,
    ReceiveError,
    Subscriber,
)

__all__ = [
    "DEFAULT_SERVICE",
    "FLAG_ALIGNED",
    "FLAG_CALIBRATION_ESTIMATED",
    "FLAG_CALIBRATION_ONLINE",
    "FLAG_NETWORK_OUTPUT_REJECTED",
    "FLAG_REFINED_CLASSICAL",
    "FLAG_REFINED_NETWORK",
    "FORMAT_VERSION",
    "MAX_BORROWED_FRAMES",
    "ConnectError",
    "DearError",
    "Frame",
    "Header",
    "ReceiveError",
    "Subscriber",
]
