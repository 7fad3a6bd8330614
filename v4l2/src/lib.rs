//! Live capture from V4L2 devices for `deard` and `dear devices`.
//!
//! - [`device`]: every `/dev/video*` node with its driver, formats, sizes, frame rates and
//!   controls; opening a node with a requested format (the error lists what the node offers);
//!   setting controls by name.
//! - [`stream`]: mmap streaming of one node: buffers with the driver's timestamp and sequence,
//!   and errors that say what happened (device gone, busy, no permission).
//! - [`pixel`]: the pixel formats ToF and RGB modules deliver, decoded into depth, amplitude and
//!   RGB planes (including host-side 4-phase ToF demodulation).
//! - [`pair`]: pairing ToF and RGB frames by timestamp, counting what stays unpaired.

// `deny`, not `forbid`: ndarray's `s!` macro allows `unsafe_code` inside its expansion.
#![deny(unsafe_code)]

pub mod device;
pub mod pair;
pub mod pixel;
pub mod stream;
