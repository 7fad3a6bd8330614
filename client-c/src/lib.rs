//! `dear-client-c`: the C ABI of the `dear-client` SDK (`libdear_client.so` / `.a`, header
//! `include/dear_client.h`, generated from this file by cbindgen; `tests/header.rs` fails when
//! the committed header is stale).
//!
//! The C API mirrors the Rust one: [`dear_client_connect`] is `Client::connect`,
//! [`dear_client_wait`] is `Client::wait_interruptible` (a signal is `DEAR_INTERRUPTED`) and
//! hands out a [`dear_frame`] that borrows the
//! daemon's shared-memory sample (no copy) until [`dear_frame_release`]; the accessors return
//! pointers into that sample. Every function checks its pointer arguments, catches panics
//! (none crosses into C) and reports failures as a [`dear_status`] with a message for
//! [`dear_last_error`].
//!
//! The header struct: [`dear_header`] is a field-for-field `#[repr(C)]` copy of
//! [`dear_proto::FrameHeader`] (its layout is asserted at compile time below), and
//! [`dear_frame_header`] returns a pointer to the header *in shared memory*. One struct rather than an accessor per field: C code reads fields as it would read
//! the README's table, nothing is copied, and the layout is the protocol's, fixed by
//! `FORMAT_VERSION`; accessors would add 34 functions for no safety gained (the pointer is
//! valid exactly as long as the depth pointer is).

// The exported names are C's (`dear_client`, `DEAR_OK`): they appear as written in the header.
#![allow(non_camel_case_types)]

use std::cell::RefCell;
use std::ffi::{c_char, CStr, CString};
use std::mem::offset_of;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::Duration;

use dear_proto::FrameHeader;
use sdk::{Client, Frame, ReceiveError, ReconnectingClient};

/// What a function of this library did. `DEAR_OK` and `DEAR_TIMEOUT` are not failures; every
/// negative value is one, and `dear_last_error()` then says what failed and why.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum dear_status {
    /// Success.
    DEAR_OK = 0,
    /// `dear_client_wait`: no frame arrived within the timeout (not an error: call again).
    DEAR_TIMEOUT = 1,
    /// A pointer argument was NULL, or the service name is not UTF-8.
    DEAR_INVALID_ARGUMENT = -1,
    /// `dear_client_connect` failed: bad service name, unreachable iceoryx2 root
    /// (`DEAR_IOX2_ROOT`), a service made with another contract, no subscriber slot left.
    DEAR_CONNECT_FAILED = -2,
    /// Receiving or waiting failed (the shared memory or the event socket broke).
    DEAR_RECEIVE_FAILED = -3,
    /// A sample arrived that is not a valid frame (corrupt header, other format version); it
    /// was dropped. Not fatal: the next frame may be fine.
    DEAR_BAD_FRAME = -4,
    /// The client already holds `DEAR_MAX_HELD_FRAMES` frames: release one first.
    DEAR_TOO_MANY_FRAMES_HELD = -5,
    /// A signal interrupted the wait (e.g. SIGINT with a handler installed): check your flag
    /// and call again.
    DEAR_INTERRUPTED = -6,
    /// `dear_frame_point_cloud`: the frame carries no intrinsics (`rgb_camera_model` is
    /// `DEAR_CAMERA_MODEL_UNKNOWN`) or unusable ones; the message names the field.
    DEAR_NO_INTRINSICS = -7,
    /// A bug: the library panicked. The message says where; the client may be unusable.
    DEAR_PANIC = -99,
}

/// Frames one client may hold (received and not yet released) at once: the service's QoS
/// `QOS_SUBSCRIBER_BORROWED`. `dear_client_wait` returns `DEAR_TOO_MANY_FRAMES_HELD` beyond it.
pub const DEAR_MAX_HELD_FRAMES: usize = 2;
/// Frame format version this library reads (`dear_header.version`).
pub const DEAR_FORMAT_VERSION: u32 = 3;
/// `sizeof(dear_header)`: format 3's header.
pub const DEAR_HEADER_SIZE: usize = 256;
/// `dear_header.depth_unit_m`: the depth plane is float metres.
pub const DEAR_DEPTH_UNIT_M: f32 = 1.0;
/// `dear_header.rgb_camera_model`: no intrinsics known (the `rgb_*` fields are zero).
pub const DEAR_CAMERA_MODEL_UNKNOWN: u16 = 0;
/// `dear_header.rgb_camera_model`: a pinhole, `rgb_fx, rgb_fy, rgb_cx, rgb_cy`.
pub const DEAR_CAMERA_MODEL_PINHOLE: u16 = 1;
/// `dear_header.rgb_camera_model`: a pinhole with Brown–Conrady distortion, `rgb_distortion`
/// = k1, k2, p1, p2, k3 (OpenCV's order, ROS's `plumb_bob`).
pub const DEAR_CAMERA_MODEL_BROWN_CONRADY: u16 = 2;
/// `dear_header.magic`: "DEAR" as little-endian bytes.
pub const DEAR_MAGIC: u32 = 0x52414544;
/// Bytes of `dear_header.bundle` (UTF-8, NUL-padded: not NUL-terminated when full).
pub const DEAR_BUNDLE_NAME_LEN: usize = 32;
/// Entries of `dear_header.stage_latency_us`: capture, preprocess, flow, fuse, warp,
/// refine, publish, total.
pub const DEAR_STAGE_COUNT: usize = 8;

/// `dear_header.flags`: depth was warped onto the RGB grid.
pub const DEAR_FLAG_ALIGNED: u32 = 1 << 0;
/// `dear_header.flags`: refined by the neural network bundle named in `bundle`.
pub const DEAR_FLAG_REFINED_NETWORK: u32 = 1 << 1;
/// `dear_header.flags`: refined by the classical edge-aware filter.
pub const DEAR_FLAG_REFINED_CLASSICAL: u32 = 1 << 2;
/// `dear_header.flags`: a calibration measurement entered the estimate on this frame.
pub const DEAR_FLAG_CALIBRATION_ESTIMATED: u32 = 1 << 3;
/// `dear_header.flags`: the calibration is the online estimate (else the static one).
pub const DEAR_FLAG_CALIBRATION_ONLINE: u32 = 1 << 4;
/// `dear_header.flags`: the network's output was implausible; the classical filter's
/// depth was published instead.
pub const DEAR_FLAG_NETWORK_OUTPUT_REJECTED: u32 = 1 << 5;
/// `dear_header.flags`: the confidence plane holds expected-error codes (see
/// `dear_confidence_expected_error_m`).
pub const DEAR_FLAG_CONFIDENCE_EXPECTED_ERROR: u32 = 1 << 6;

/// `dear_header.calib_health`: not assessed (static calibration, no estimate yet, or an older
/// publisher).
pub const DEAR_CALIB_HEALTH_UNKNOWN: u8 = 0;
/// `dear_header.calib_health`: the evidence agrees with the calibration to 1 px.
pub const DEAR_CALIB_HEALTH_GOOD: u8 = 1;
/// `dear_header.calib_health`: usable; a 1–3 px correction is pending or some direction is
/// not yet known to 1 px.
pub const DEAR_CALIB_HEALTH_CAN_IMPROVE: u8 = 2;
/// `dear_header.calib_health`: the evidence says the calibration is off by 3 px or more.
pub const DEAR_CALIB_HEALTH_NEEDS_RECALIBRATION: u8 = 3;

const _: () = {
    assert!(DEAR_CALIB_HEALTH_UNKNOWN == dear_proto::CalibrationHealth::Unknown as u8);
    assert!(DEAR_CALIB_HEALTH_GOOD == dear_proto::CalibrationHealth::Good as u8);
    assert!(DEAR_CALIB_HEALTH_CAN_IMPROVE == dear_proto::CalibrationHealth::CanImprove as u8);
    assert!(
        DEAR_CALIB_HEALTH_NEEDS_RECALIBRATION
            == dear_proto::CalibrationHealth::NeedsRecalibration as u8
    );
    assert!(DEAR_MAX_HELD_FRAMES == dear_proto::service::QOS_SUBSCRIBER_BORROWED);
    assert!(DEAR_FORMAT_VERSION == dear_proto::FORMAT_VERSION);
    assert!(DEAR_HEADER_SIZE == dear_proto::HEADER_SIZE);
    assert!(DEAR_DEPTH_UNIT_M == dear_proto::DEPTH_UNIT_M);
    assert!(DEAR_CAMERA_MODEL_UNKNOWN == dear_proto::camera_model::UNKNOWN);
    assert!(DEAR_CAMERA_MODEL_PINHOLE == dear_proto::camera_model::PINHOLE);
    assert!(DEAR_CAMERA_MODEL_BROWN_CONRADY == dear_proto::camera_model::BROWN_CONRADY);
    assert!(DEAR_MAGIC == dear_proto::MAGIC);
    assert!(DEAR_BUNDLE_NAME_LEN == dear_proto::header::BUNDLE_NAME_LEN);
    assert!(DEAR_STAGE_COUNT == dear_proto::Stage::ALL.len());
    assert!(DEAR_FLAG_ALIGNED == dear_proto::flags::ALIGNED);
    assert!(DEAR_FLAG_REFINED_NETWORK == dear_proto::flags::REFINED_NETWORK);
    assert!(DEAR_FLAG_REFINED_CLASSICAL == dear_proto::flags::REFINED_CLASSICAL);
    assert!(DEAR_FLAG_CALIBRATION_ESTIMATED == dear_proto::flags::CALIBRATION_ESTIMATED);
    assert!(DEAR_FLAG_CALIBRATION_ONLINE == dear_proto::flags::CALIBRATION_ONLINE);
    assert!(DEAR_FLAG_NETWORK_OUTPUT_REJECTED == dear_proto::flags::NETWORK_OUTPUT_REJECTED);
    assert!(DEAR_FLAG_CONFIDENCE_EXPECTED_ERROR == dear_proto::flags::CONFIDENCE_EXPECTED_ERROR);
};

/// The header of a frame: the protocol's `DearFrameHeader` (256 bytes, docs/protocol.md
/// "Frame layout"),
/// field for field. `dear_frame_header()` returns a pointer to it in shared memory (not named
/// `dear_frame_header` itself: in C a type and a function cannot share a name).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct dear_header {
    /// `DEAR_MAGIC`.
    pub magic: u32,
    /// `DEAR_FORMAT_VERSION` (frames of other versions are never handed out).
    pub version: u32,
    /// Frame number from the source; restarts when a replay loops or the daemon restarts.
    pub frame_id: u64,
    /// Capture time given by the source, ns.
    pub capture_timestamp_ns: u64,
    /// `CLOCK_MONOTONIC` at publication, ns (comparable with `clock_gettime` here).
    pub publish_timestamp_ns: u64,
    /// Pixels.
    pub width: u32,
    /// Pixels.
    pub height: u32,
    /// Calibration used, flow model `W = t/z + c`: t_x in px·m.
    pub calib_tx: f32,
    /// t_y in px·m.
    pub calib_ty: f32,
    /// c_x in px.
    pub calib_cx: f32,
    /// c_y in px.
    pub calib_cy: f32,
    /// RMS residual of the last calibration fit to a flow, px; NaN when not measured.
    pub calib_residual_px: f32,
    /// 0 (static / unknown) … 1.
    pub calib_quality: f32,
    /// `DEAR_FLAG_*` bits.
    pub flags: u32,
    /// Frames since the calibration was estimated.
    pub calib_age_frames: u32,
    /// Model bundle name, UTF-8, NUL-padded (not terminated when all 32 bytes are used).
    pub bundle: [u8; 32],
    /// µs per stage: capture, preprocess, flow, fuse, warp, refine, publish, total.
    pub stage_latency_us: [u32; 8],
    /// Byte offset of depth in the payload (0).
    pub depth_offset: u32,
    /// Byte offset of RGB (4·W·H).
    pub rgb_offset: u32,
    /// Byte offset of confidence (7·W·H).
    pub confidence_offset: u32,
    /// Payload bytes used (8·W·H).
    pub payload_size: u32,
    /// Bad input frames skipped since the daemon started.
    pub frames_skipped: u64,
    /// Frames dropped because processing fell behind since the daemon started.
    pub frames_dropped: u64,
    /// Random id of the publisher instance; a new value means the daemon restarted.
    pub run_id: u64,
    /// Samples this publisher instance sent before this one; a gap is frames this client lost.
    pub sequence: u64,
    /// Calibration health, `DEAR_CALIB_HEALTH_*`: 0 unknown, 1 good, 2 can improve, 3 needs
    /// recalibration (docs/calibration-health.md).
    pub calib_health: u8,
    /// Directions of (t_x, t_y, c_x, c_y) the last calibration measurement constrained, 0–4.
    pub calib_constrained: u8,
    /// Model of the RGB intrinsics below, `DEAR_CAMERA_MODEL_*`: 0 unknown (the fields are
    /// zero; no point cloud), 1 pinhole, 2 Brown–Conrady.
    pub rgb_camera_model: u16,
    /// Metres per depth unit: `DEAR_DEPTH_UNIT_M` (1.0; frames with another value are refused).
    pub depth_unit_m: f32,
    /// RGB camera focal length x, px, at the frame's size (the depth's too: it is aligned).
    pub rgb_fx: f32,
    /// Focal length y, px.
    pub rgb_fy: f32,
    /// Principal point x, px (pixel centres at integer coordinates).
    pub rgb_cx: f32,
    /// Principal point y, px.
    pub rgb_cy: f32,
    /// Model 2: k1, k2, p1, p2, k3; otherwise zero.
    pub rgb_distortion: [f32; 5],
    /// Zero.
    pub reserved: [u8; 28],
}

// The mirror has the protocol struct's size, alignment and every field's offset; with
// `from_proto` (same names and types, every field) this pins the layout to `FrameHeader`'s.
const _: () = {
    use std::mem::{align_of, size_of};
    assert!(size_of::<dear_header>() == size_of::<FrameHeader>());
    assert!(align_of::<dear_header>() == align_of::<FrameHeader>());
    macro_rules! same_offsets {
        ($($field:ident),* $(,)?) => {
            $(assert!(offset_of!(dear_header, $field) == offset_of!(FrameHeader, $field));)*
        };
    }
    same_offsets!(
        magic,
        version,
        frame_id,
        capture_timestamp_ns,
        publish_timestamp_ns,
        width,
        height,
        calib_tx,
        calib_ty,
        calib_cx,
        calib_cy,
        calib_residual_px,
        calib_quality,
        flags,
        calib_age_frames,
        bundle,
        stage_latency_us,
        depth_offset,
        rgb_offset,
        confidence_offset,
        payload_size,
        frames_skipped,
        frames_dropped,
        run_id,
        sequence,
        calib_health,
        calib_constrained,
        rgb_camera_model,
        depth_unit_m,
        rgb_fx,
        rgb_fy,
        rgb_cx,
        rgb_cy,
        rgb_distortion,
        reserved,
    );
};

impl dear_header {
    /// A copy of a protocol header. Destructures every field without `..`, so a field added
    /// to `FrameHeader` (or a changed type) fails to compile here until the mirror follows.
    pub fn from_proto(h: &FrameHeader) -> Self {
        let FrameHeader {
            magic,
            version,
            frame_id,
            capture_timestamp_ns,
            publish_timestamp_ns,
            width,
            height,
            calib_tx,
            calib_ty,
            calib_cx,
            calib_cy,
            calib_residual_px,
            calib_quality,
            flags,
            calib_age_frames,
            bundle,
            stage_latency_us,
            depth_offset,
            rgb_offset,
            confidence_offset,
            payload_size,
            frames_skipped,
            frames_dropped,
            run_id,
            sequence,
            calib_health,
            calib_constrained,
            rgb_camera_model,
            depth_unit_m,
            rgb_fx,
            rgb_fy,
            rgb_cx,
            rgb_cy,
            rgb_distortion,
            reserved,
        } = *h;
        dear_header {
            magic,
            version,
            frame_id,
            capture_timestamp_ns,
            publish_timestamp_ns,
            width,
            height,
            calib_tx,
            calib_ty,
            calib_cx,
            calib_cy,
            calib_residual_px,
            calib_quality,
            flags,
            calib_age_frames,
            bundle,
            stage_latency_us,
            depth_offset,
            rgb_offset,
            confidence_offset,
            payload_size,
            frames_skipped,
            frames_dropped,
            run_id,
            sequence,
            calib_health,
            calib_constrained,
            rgb_camera_model,
            depth_unit_m,
            rgb_fx,
            rgb_fy,
            rgb_cx,
            rgb_cy,
            rgb_distortion,
            reserved,
        }
    }

    /// The protocol header's bytes read as the mirror, without a copy.
    fn view(h: &FrameHeader) -> &Self {
        // SAFETY: the two structs have the same size, alignment and field offsets (asserted at
        // compile time above) and the same field types (`from_proto`); both are `repr(C)` of
        // plain integers, floats and byte arrays, valid for every bit pattern. The reference
        // keeps `h`'s lifetime.
        unsafe { &*(h as *const FrameHeader).cast::<Self>() }
    }
}

/// A subscription to one frame service (opaque). Made by `dear_client_connect` or
/// `dear_client_connect_reconnecting`, freed by `dear_client_free`.
pub struct dear_client {
    channel: Channel,
}

/// A client's channel: plain, or the SDK's reconnecting one.
enum Channel {
    Plain(Client),
    Reconnecting(ReconnectingClient),
}

/// A received frame (opaque): a borrowed view of the daemon's shared-memory sample, valid
/// until `dear_frame_release`.
pub struct dear_frame {
    frame: Frame,
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last_error(message: String) {
    // A NUL inside would cut the C string short; none is expected (messages are ours and
    // iceoryx2's, names come from C strings), but never fail over it.
    let message = CString::new(message.replace('\0', "?")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = message);
}

/// An error and its sources, `outer: inner: …`, as the `dear` CLI prints them.
fn chain(error: &dyn std::error::Error) -> String {
    let mut message = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        message.push_str(": ");
        message.push_str(&cause.to_string());
        source = cause.source();
    }
    message
}

/// A failure to report: its status and the message for `dear_last_error`.
struct Failure(dear_status, String);

fn invalid(function: &str, argument: &str) -> Failure {
    Failure(
        dear_status::DEAR_INVALID_ARGUMENT,
        format!("{function}: `{argument}` is NULL"),
    )
}

fn panic_message(function: &str, payload: &(dyn std::any::Any + Send)) -> String {
    let what = payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".to_string());
    format!("{function}: internal error (panic): {what}")
}

/// Runs the body of an exported function: its failure or panic becomes a status and the
/// thread's last error; no panic unwinds into C.
fn guard(function: &str, body: impl FnOnce() -> Result<dear_status, Failure>) -> dear_status {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(status)) => status,
        Ok(Err(Failure(status, message))) => {
            set_last_error(message);
            status
        }
        Err(payload) => {
            set_last_error(panic_message(function, payload.as_ref()));
            dear_status::DEAR_PANIC
        }
    }
}

/// [`guard`] for the accessors, which return a pointer: NULL on failure or panic.
fn guard_ptr<T>(function: &str, body: impl FnOnce() -> Result<*const T, String>) -> *const T {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(pointer)) => pointer,
        Ok(Err(message)) => {
            set_last_error(message);
            std::ptr::null()
        }
        Err(payload) => {
            set_last_error(panic_message(function, payload.as_ref()));
            std::ptr::null()
        }
    }
}

/// Subscribes to the frame service `service` (e.g. `"dear/cam0/frames"`, the default camera's)
/// and stores the new client in `*out`. Works whether or not the daemon runs yet: frames arrive
/// once it publishes. The service is looked up under the iceoryx2 root of the
/// environment variable `DEAR_IOX2_ROOT`, else `/dev/shm/dear`; the installed service's clients
/// set `DEAR_IOX2_ROOT=/run/deard/iceoryx2` (README, "Where clients find the service").
///
/// iceoryx2's own log on stderr is kept to errors unless `IOX2_LOG_LEVEL` says otherwise (set
/// on the first call).
///
/// Returns `DEAR_OK`, `DEAR_INVALID_ARGUMENT` (NULL, or a name that is not UTF-8) or
/// `DEAR_CONNECT_FAILED` (`dear_last_error()` names the service and, when it is the cause, the
/// root). On failure `*out` is set to NULL.
///
/// # Safety
///
/// `service` must be NULL or a NUL-terminated string; `out` NULL or valid for a write.
#[no_mangle]
pub unsafe extern "C" fn dear_client_connect(
    service: *const c_char,
    out: *mut *mut dear_client,
) -> dear_status {
    // SAFETY: the caller's promises are this function's.
    unsafe {
        connect("dear_client_connect", service, out, |service| {
            Client::connect(service).map(Channel::Plain)
        })
    }
}

/// As `dear_client_connect`, for a client that keeps its stream across a damaged channel and
/// a service the daemon made again (the Rust SDK's `ReconnectingClient`): a channel that was
/// corrupted (another process wrote into its shared records), or that delivered nothing for
/// `stall_ms` milliseconds (0: the default, 3000; longer than the stream's slowest frame
/// interval), is dropped and connected again every 500 ms. Meanwhile `dear_client_wait`
/// returns `DEAR_TIMEOUT` after its timeout, as on an idle stream, and never
/// `DEAR_RECEIVE_FAILED` for a corrupted channel; a signal ends a wait early with
/// `DEAR_TIMEOUT` (not `DEAR_INTERRUPTED`). `dear_client_reconnects` counts the new channels.
///
/// # Safety
///
/// As `dear_client_connect`.
#[no_mangle]
pub unsafe extern "C" fn dear_client_connect_reconnecting(
    service: *const c_char,
    stall_ms: u32,
    out: *mut *mut dear_client,
) -> dear_status {
    // SAFETY: the caller's promises are this function's.
    unsafe {
        connect(
            "dear_client_connect_reconnecting",
            service,
            out,
            |service| {
                let mut client = ReconnectingClient::connect(service)?;
                if stall_ms > 0 {
                    client.set_stall_timeout(Duration::from_millis(u64::from(stall_ms)));
                }
                Ok(Channel::Reconnecting(client))
            },
        )
    }
}

/// How many times a client from `dear_client_connect_reconnecting` connected again (0 for
/// NULL and for a client from `dear_client_connect`).
///
/// # Safety
///
/// `client` must be NULL or a client not yet freed, used by no other thread during the call.
#[no_mangle]
pub unsafe extern "C" fn dear_client_reconnects(client: *const dear_client) -> u64 {
    // SAFETY: the caller promises NULL or a live client; NULL is refused by `as_ref`.
    match unsafe { client.as_ref() }.map(|c| &c.channel) {
        Some(Channel::Reconnecting(client)) => client.reconnects(),
        _ => 0,
    }
}

/// The body of the connect functions: checks the arguments, makes the channel with `make`
/// and stores the new client in `*out` (NULL on failure).
///
/// # Safety
///
/// As `dear_client_connect`.
unsafe fn connect(
    name: &str,
    service: *const c_char,
    out: *mut *mut dear_client,
    make: impl FnOnce(&str) -> Result<Channel, sdk::ConnectError>,
) -> dear_status {
    guard(name, || {
        if out.is_null() {
            return Err(invalid(name, "out"));
        }
        // SAFETY: `out` is not NULL and the caller promises it is valid for a write.
        unsafe { out.write(std::ptr::null_mut()) };
        if service.is_null() {
            return Err(invalid(name, "service"));
        }
        // SAFETY: not NULL, and the caller promises a NUL-terminated string that outlives the
        // call.
        let service = unsafe { CStr::from_ptr(service) };
        let service = service.to_str().map_err(|_| {
            Failure(
                dear_status::DEAR_INVALID_ARGUMENT,
                format!("{name}: the service name {service:?} is not UTF-8"),
            )
        })?;
        // As the `dear` CLI: iceoryx2's own log (stderr) only for errors unless IOX2_LOG_LEVEL
        // asks for more; every failure reaches the caller as a status and a message anyway.
        static LOG_LEVEL: std::sync::Once = std::sync::Once::new();
        LOG_LEVEL.call_once(|| {
            iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error)
        });
        let channel =
            make(service).map_err(|e| Failure(dear_status::DEAR_CONNECT_FAILED, chain(&e)))?;
        let client = Box::into_raw(Box::new(dear_client { channel }));
        // SAFETY: as above.
        unsafe { out.write(client) };
        Ok(dear_status::DEAR_OK)
    })
}

/// Waits up to `timeout_ms` milliseconds for the next frame (the thread sleeps until the
/// daemon announces one; 0 only takes a queued frame) and stores it in `*out`.
///
/// Returns `DEAR_OK` with a frame, which the caller must give back with `dear_frame_release`;
/// `DEAR_TIMEOUT` when none came in time (not an error; `dear_last_error()` says so too);
/// `DEAR_TOO_MANY_FRAMES_HELD` when the client already holds `DEAR_MAX_HELD_FRAMES` (2)
/// frames; `DEAR_INTERRUPTED` when a signal interrupted the wait; `DEAR_BAD_FRAME` when a
/// sample was not a valid frame (it is dropped; call again); `DEAR_RECEIVE_FAILED`;
/// `DEAR_INVALID_ARGUMENT`. `*out` is NULL unless the status is `DEAR_OK`.
///
/// Each client has a queue of 2 frames: when it is full the oldest is overwritten, so a client
/// that waits too rarely loses frames (a gap in `sequence`), never blocks the daemon.
///
/// # Safety
///
/// `client` must be NULL or a client from `dear_client_connect` not yet freed, used by no
/// other thread during the call; `out` NULL or valid for a write.
#[no_mangle]
pub unsafe extern "C" fn dear_client_wait(
    client: *mut dear_client,
    timeout_ms: u32,
    out: *mut *mut dear_frame,
) -> dear_status {
    const NAME: &str = "dear_client_wait";
    guard(NAME, || {
        if out.is_null() {
            return Err(invalid(NAME, "out"));
        }
        // SAFETY: `out` is not NULL and the caller promises it is valid for a write.
        unsafe { out.write(std::ptr::null_mut()) };
        // SAFETY: the caller promises a live client from a connect function (a `Box` we made)
        // that no other thread uses now; NULL is refused by `as_mut`.
        let Some(client) = (unsafe { client.as_mut() }) else {
            return Err(invalid(NAME, "client"));
        };
        let timeout = Duration::from_millis(u64::from(timeout_ms));
        let (service, received) = match &mut client.channel {
            Channel::Plain(client) => (
                client.service().to_string(),
                client.wait_interruptible(timeout),
            ),
            Channel::Reconnecting(client) => (client.service().to_string(), client.wait(timeout)),
        };
        let frame = match received {
            Ok(Some(frame)) => frame,
            Ok(None) => {
                return Err(Failure(
                    dear_status::DEAR_TIMEOUT,
                    format!("no frame from {service:?} within {timeout_ms} ms"),
                ))
            }
            Err(e) => return Err(Failure(receive_status(&e), receive_message(&e))),
        };
        let frame = Box::into_raw(Box::new(dear_frame { frame }));
        // SAFETY: as above.
        unsafe { out.write(frame) };
        Ok(dear_status::DEAR_OK)
    })
}

fn receive_status(error: &ReceiveError) -> dear_status {
    use iceoryx2::port::listener::ListenerWaitError;
    match error {
        ReceiveError::Receive {
            source: iceoryx2::port::ReceiveError::ExceedsMaxBorrows,
            ..
        } => dear_status::DEAR_TOO_MANY_FRAMES_HELD,
        ReceiveError::Wait {
            source: ListenerWaitError::InterruptSignal,
            ..
        } => dear_status::DEAR_INTERRUPTED,
        ReceiveError::BadFrame { .. } => dear_status::DEAR_BAD_FRAME,
        _ => dear_status::DEAR_RECEIVE_FAILED,
    }
}

fn receive_message(error: &ReceiveError) -> String {
    match receive_status(error) {
        dear_status::DEAR_TOO_MANY_FRAMES_HELD => format!(
            "{}: this client holds {DEAR_MAX_HELD_FRAMES} frames, the most it may; release one \
             with dear_frame_release before waiting for the next",
            chain(error)
        ),
        _ => chain(error),
    }
}

/// Gives a frame back to the daemon's shared memory. `frame` is invalid afterwards, and so
/// is every pointer its accessors returned. NULL is ignored (as by `free`). Frames may be
/// released before or after their client is freed.
///
/// # Safety
///
/// `frame` must be NULL or a frame from `dear_client_wait` not yet released, used by no other
/// thread during the call (nor its client: a frame and its client share unsynchronised state).
#[no_mangle]
pub unsafe extern "C" fn dear_frame_release(frame: *mut dear_frame) {
    if frame.is_null() {
        return;
    }
    guard("dear_frame_release", || {
        // SAFETY: the caller promises a frame from `dear_client_wait` (a `Box` we made) that
        // was not released before; this takes it back exactly once.
        drop(unsafe { Box::from_raw(frame) });
        Ok(dear_status::DEAR_OK)
    });
}

/// Unsubscribes and frees a client. NULL is ignored.
///
/// # Safety
///
/// `client` must be NULL or a client from `dear_client_connect` not yet freed, used by no
/// other thread during the call. Its frames stay valid until released.
#[no_mangle]
pub unsafe extern "C" fn dear_client_free(client: *mut dear_client) {
    if client.is_null() {
        return;
    }
    guard("dear_client_free", || {
        // SAFETY: the caller promises a client from `dear_client_connect` (a `Box` we made)
        // that was not freed before; this takes it back exactly once.
        drop(unsafe { Box::from_raw(client) });
        Ok(dear_status::DEAR_OK)
    });
}

/// The frame's header, in shared memory; valid until the frame is released. NULL (and
/// `dear_last_error()` set) when `frame` is NULL. The header was checked before the frame was
/// handed out: magic, version and the plane offsets are the protocol's.
///
/// # Safety
///
/// `frame` must be NULL or a frame from `dear_client_wait` not yet released.
#[no_mangle]
pub unsafe extern "C" fn dear_frame_header(frame: *const dear_frame) -> *const dear_header {
    const NAME: &str = "dear_frame_header";
    guard_ptr(NAME, || {
        // SAFETY: the caller promises NULL or a live frame from `dear_client_wait`.
        let frame = unsafe { frame.as_ref() }.ok_or_else(|| invalid(NAME, "frame").1)?;
        Ok(dear_header::view(frame.frame.header()) as *const dear_header)
    })
}

/// A plane of a frame as a pointer and a length, for the accessors below.
///
/// # Safety
///
/// `frame` must be NULL or a live frame; `len` NULL or valid for a write.
unsafe fn plane<T>(
    function: &str,
    frame: *const dear_frame,
    len: *mut usize,
    select: fn(&Frame) -> &[T],
) -> *const T {
    guard_ptr(function, || {
        if !len.is_null() {
            // SAFETY: not NULL, and the caller promises it is valid for a write.
            unsafe { len.write(0) };
        }
        // SAFETY: the caller promises NULL or a live frame from `dear_client_wait`.
        let frame = unsafe { frame.as_ref() }.ok_or_else(|| invalid(function, "frame").1)?;
        let values = select(&frame.frame);
        if !len.is_null() {
            // SAFETY: as above.
            unsafe { len.write(values.len()) };
        }
        Ok(values.as_ptr())
    })
}

/// Aligned, refined depth in metres, `height` rows of `width` values, row-major; 0 = invalid.
/// `*len` (when `len` is not NULL) receives the number of values, `width·height`. Points into
/// shared memory: valid until the frame is released; read-only. NULL when `frame` is NULL.
///
/// # Safety
///
/// `frame` must be NULL or a frame from `dear_client_wait` not yet released; `len` NULL or
/// valid for a write.
#[no_mangle]
pub unsafe extern "C" fn dear_frame_depth(frame: *const dear_frame, len: *mut usize) -> *const f32 {
    // SAFETY: the caller's promises are `plane`'s.
    unsafe { plane("dear_frame_depth", frame, len, Frame::depth) }
}

/// The RGB image the depth is aligned to: `height·width·3` bytes, row-major, interleaved R, G,
/// B. `*len` receives the number of bytes. Valid until the frame is released; read-only.
///
/// # Safety
///
/// As `dear_frame_depth`.
#[no_mangle]
pub unsafe extern "C" fn dear_frame_rgb(frame: *const dear_frame, len: *mut usize) -> *const u8 {
    // SAFETY: the caller's promises are `plane`'s.
    unsafe { plane("dear_frame_rgb", frame, len, Frame::rgb) }
}

/// Per-pixel confidence, `height·width` bytes: 0 = invalid (exactly where depth is 0). With
/// `DEAR_FLAG_CONFIDENCE_EXPECTED_ERROR` set, an expected-error code
/// (`dear_confidence_expected_error_m`); otherwise 255 = measured and kept, in between =
/// filled or smoothed. `*len` receives the number of bytes.
/// Valid until the frame is released; read-only.
///
/// # Safety
///
/// As `dear_frame_depth`.
#[no_mangle]
pub unsafe extern "C" fn dear_frame_confidence(
    frame: *const dear_frame,
    len: *mut usize,
) -> *const u8 {
    // SAFETY: the caller's promises are `plane`'s.
    unsafe { plane("dear_frame_confidence", frame, len, Frame::confidence) }
}

/// The frame's point cloud, organised: for pixel `i = v·width + u` (row-major, as the planes),
/// `xyz[3i .. 3i+3]` is the point `(x, y, z)` in metres in the RGB camera's optical frame (x
/// right, y down, z forward) and `valid[i]` is 1, or — where the pixel has no valid depth, or
/// its ray cannot be undistorted — `xyz` is NaN and `valid[i]` is 0 (never a point at the
/// origin). Its colour is `dear_frame_rgb()[3i .. 3i+3]`, its confidence
/// `dear_frame_confidence()[i]`.
///
/// The math is the Rust SDK's (`dear_client::points`): the pixel's ray from the header's
/// intrinsics — pinhole `((u − cx)/fx, (v − cy)/fy)`, with Brown–Conrady distortion undone by
/// Newton's method — times the z-depth.
///
/// `xyz_len` must be `3·width·height` floats, `valid_len` `width·height` bytes; `valid` may be
/// NULL (then `valid_len` is ignored; test `isnan(xyz[3i + 2])` instead). Returns `DEAR_OK`;
/// `DEAR_NO_INTRINSICS` when the header has no (or unusable) intrinsics; `DEAR_INVALID_ARGUMENT`
/// for a NULL `frame`/`xyz` or a wrong length (the message names it). Nothing is written on
/// failure.
///
/// # Safety
///
/// `frame` must be NULL or a frame from `dear_client_wait` not yet released; `xyz` NULL or
/// valid for writes of `xyz_len` floats; `valid` NULL or valid for writes of `valid_len` bytes.
#[no_mangle]
pub unsafe extern "C" fn dear_frame_point_cloud(
    frame: *const dear_frame,
    xyz: *mut f32,
    xyz_len: usize,
    valid: *mut u8,
    valid_len: usize,
) -> dear_status {
    const NAME: &str = "dear_frame_point_cloud";
    guard(NAME, || {
        // SAFETY: the caller promises NULL or a live frame from `dear_client_wait`.
        let frame = &unsafe { frame.as_ref() }
            .ok_or_else(|| invalid(NAME, "frame"))?
            .frame;
        if xyz.is_null() {
            return Err(invalid(NAME, "xyz"));
        }
        let header = frame.header();
        let no_intrinsics = |e: sdk::PointCloudError| {
            Failure(dear_status::DEAR_NO_INTRINSICS, format!("{NAME}: {e}"))
        };
        let intrinsics = sdk::points::header_intrinsics(header).map_err(no_intrinsics)?;
        let (width, height) = frame.size();
        let rays = sdk::Rays::shared(&intrinsics, width, height).map_err(|source| {
            no_intrinsics(sdk::PointCloudError::Intrinsics {
                frame_id: header.frame_id,
                source,
            })
        })?;
        let wrong_length = |e: sdk::PointCloudError| {
            Failure(dear_status::DEAR_INVALID_ARGUMENT, format!("{NAME}: {e}"))
        };
        rays.check_len("`xyz` (xyz_len)", xyz_len, 3)
            .map_err(wrong_length)?;
        if !valid.is_null() {
            rays.check_len("`valid` (valid_len)", valid_len, 1)
                .map_err(wrong_length)?;
        }
        // SAFETY: not NULL, and the caller promises `xyz_len` writable floats, which is
        // 3·width·height (checked above); no Rust reference to them exists elsewhere.
        let xyz = unsafe { std::slice::from_raw_parts_mut(xyz, xyz_len) };
        let mut valid = (!valid.is_null()).then(|| {
            // SAFETY: as for `xyz`: `valid_len` = width·height writable bytes (checked).
            unsafe { std::slice::from_raw_parts_mut(valid, valid_len) }
        });
        rays.back_project_with(frame.depth(), |i, point| {
            xyz[3 * i..3 * i + 3].copy_from_slice(&point.unwrap_or([f32::NAN; 3]));
            if let Some(valid) = valid.as_deref_mut() {
                valid[i] = u8::from(point.is_some());
            }
        })
        .map_err(wrong_length)?;
        Ok(dear_status::DEAR_OK)
    })
}

/// The expected absolute depth error in metres that confidence `code` stands for in a frame
/// with `DEAR_FLAG_CONFIDENCE_EXPECTED_ERROR`: `0.001 · 2^((255 − code) / 16)` (255: 1 mm,
/// 202: 1 cm, 149: 10 cm); NaN for 0 (no depth).
#[no_mangle]
pub extern "C" fn dear_confidence_expected_error_m(code: u8) -> f32 {
    dear_proto::confidence::expected_error_m(code).unwrap_or(f32::NAN)
}

/// The message of the last failure on this thread: what failed and why, with the service
/// name and, when it is the cause, the iceoryx2 root (the full error chain, `outer: cause:
/// …`). Set whenever a function returns a status other than `DEAR_OK` (`DEAR_TIMEOUT`
/// included) or an accessor returns NULL; successful calls leave it as it was. Never NULL
/// (`""` before any failure); valid until the next failing call on this thread.
#[no_mangle]
pub extern "C" fn dear_last_error() -> *const c_char {
    // The string lives in this thread's slot until `set_last_error` replaces it on this
    // thread; the pointer stays valid until then.
    LAST_ERROR
        .try_with(|e| e.borrow().as_ptr())
        .unwrap_or(c"(dear_last_error: thread is exiting)".as_ptr())
}

/// A static name of a status (`"DEAR_TIMEOUT"`), for messages. Never NULL.
#[no_mangle]
pub extern "C" fn dear_status_name(status: dear_status) -> *const c_char {
    use dear_status::*;
    let name: &CStr = match status {
        DEAR_OK => c"DEAR_OK",
        DEAR_TIMEOUT => c"DEAR_TIMEOUT",
        DEAR_INVALID_ARGUMENT => c"DEAR_INVALID_ARGUMENT",
        DEAR_CONNECT_FAILED => c"DEAR_CONNECT_FAILED",
        DEAR_RECEIVE_FAILED => c"DEAR_RECEIVE_FAILED",
        DEAR_BAD_FRAME => c"DEAR_BAD_FRAME",
        DEAR_TOO_MANY_FRAMES_HELD => c"DEAR_TOO_MANY_FRAMES_HELD",
        DEAR_INTERRUPTED => c"DEAR_INTERRUPTED",
        DEAR_NO_INTRINSICS => c"DEAR_NO_INTRINSICS",
        DEAR_PANIC => c"DEAR_PANIC",
    };
    name.as_ptr()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn last_error() -> String {
        // SAFETY: `dear_last_error` returns a NUL-terminated string valid until the next
        // failure on this thread.
        unsafe { CStr::from_ptr(dear_last_error()) }
            .to_string_lossy()
            .into_owned()
    }

    #[test]
    fn a_panic_becomes_a_status_and_a_message() {
        let status = guard("dear_test", || panic!("boom {}", 7));
        assert_eq!(status, dear_status::DEAR_PANIC);
        assert_eq!(last_error(), "dear_test: internal error (panic): boom 7");
        let pointer: *const u8 = guard_ptr("dear_test_ptr", || panic!("static message"));
        assert!(pointer.is_null());
        assert_eq!(
            last_error(),
            "dear_test_ptr: internal error (panic): static message"
        );
    }

    #[test]
    fn the_mirror_reads_the_protocol_header_in_place() {
        let mut h = FrameHeader::new(42, 320, 240);
        h.run_id = 0xfeed;
        h.sequence = 9;
        h.calib_cx = 1.5;
        h.set_bundle_name("edge/hybrid");
        h.stage_latency_us[7] = 1234;
        let view = dear_header::view(&h);
        assert_eq!(
            std::ptr::addr_of!(*view).cast::<u8>(),
            std::ptr::addr_of!(h).cast()
        );
        assert_eq!(view.frame_id, 42);
        assert_eq!((view.width, view.height), (320, 240));
        assert_eq!((view.run_id, view.sequence), (0xfeed, 9));
        assert_eq!(view.calib_cx, 1.5);
        assert_eq!(&view.bundle[..11], b"edge/hybrid");
        assert_eq!(view.stage_latency_us[7], 1234);
        assert_eq!(view.payload_size, 8 * 320 * 240);
        // NaN != NaN: compare the bits of the copy and the view.
        let copy = dear_header::from_proto(&h);
        assert_eq!(
            copy.calib_residual_px.to_bits(),
            view.calib_residual_px.to_bits()
        );
        assert_eq!(copy.frame_id, view.frame_id);
    }

    #[test]
    fn every_status_has_its_name() {
        use dear_status::*;
        for status in [
            DEAR_OK,
            DEAR_TIMEOUT,
            DEAR_INVALID_ARGUMENT,
            DEAR_CONNECT_FAILED,
            DEAR_RECEIVE_FAILED,
            DEAR_BAD_FRAME,
            DEAR_TOO_MANY_FRAMES_HELD,
            DEAR_INTERRUPTED,
            DEAR_NO_INTRINSICS,
            DEAR_PANIC,
        ] {
            // SAFETY: a static NUL-terminated string.
            let name = unsafe { CStr::from_ptr(dear_status_name(status)) };
            assert_eq!(name.to_str().unwrap(), format!("{status:?}"));
        }
    }
}
