//! `dear-proto`: the wire contract between `deard` and every client.
//!
//! A published frame is one iceoryx2 publish-subscribe sample whose payload is a byte slice
//! (`[u8]`, 64-byte aligned) and whose user header is [`FrameHeader`]. The payload holds, at the
//! offsets the header gives:
//! - aligned refined depth, `f32` metres, `width·height` values, row-major, `0` = invalid;
//! - the RGB image it is aligned to, `u8`, `width·height·3`, row-major, interleaved R,G,B;
//! - per-pixel confidence, `u8`, `width·height` (0 = invalid; with
//!   [`flags::CONFIDENCE_EXPECTED_ERROR`] an expected-error code, see [`confidence`]).
//!
//! After each sample the daemon notifies an iceoryx2 *event* service of the same name, so
//! clients can sleep until a frame arrives instead of polling.
//!
//! docs/protocol.md, "Frame layout", documents the header byte by byte for C and Python
//! clients; `tests/layout.rs` checks that table against this struct.

pub mod confidence;
pub mod header;
pub mod health;
pub mod service;
pub mod time;
pub mod transport;

pub use header::{
    camera_model, flags, random_run_id, CameraIntrinsics, FrameHeader, HeaderError,
    IntrinsicsError, LayoutError, PayloadLayout, Stage, DEPTH_UNIT_M, FORMAT_VERSION, HEADER_SIZE,
    MAGIC, PAYLOAD_ALIGNMENT,
};
pub use health::CalibrationHealth;
pub use service::{
    default_service_name, frame_event_service, frame_service, samples_in_shared_memory,
    validate_service_name, EventServiceError, FrameEventService, FrameService, FrameServiceError,
    ServiceNameError, DEFAULT_CAMERA,
};
pub use transport::{node_config, Transport, IOX2_ROOT_ENV};
