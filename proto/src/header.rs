//! The frame header and the payload layout.

use iceoryx2::prelude::ZeroCopySend;

/// `"DEAR"` read as a little-endian `u32`.
pub const MAGIC: u32 = u32::from_le_bytes(*b"DEAR");
/// Bumped on any change of the header or payload layout. 2: `run_id` and `sequence` were
/// taken from `reserved` (same size, same offsets for every older field). 3: the RGB camera's
/// intrinsics and the depth unit (`rgb_camera_model` … `rgb_distortion`, `depth_unit_m`) in
/// place of the 6 `reserved` bytes and 64 new ones: the header grew from 192 to 256 bytes,
/// every older field at its offset.
pub const FORMAT_VERSION: u32 = 3;
/// Bytes of [`FrameHeader`] (the iceoryx2 user header's size; a service made with a header of
/// another size is of another format and cannot be opened: [`crate::FrameServiceError`]).
pub const HEADER_SIZE: usize = 256;
/// [`FrameHeader::depth_unit_m`]: the depth plane is `f32` metres.
pub const DEPTH_UNIT_M: f32 = 1.0;
/// Alignment of the payload's start in shared memory: 8, because iceoryx2 places the payload
/// right after the 8-aligned, 256-byte user header (and aligns every chunk to 8). Enough for
/// the `f32` depth plane. It is *not* passed to iceoryx2 as the payload alignment: iceoryx2
/// pads every element of a slice payload to that alignment, so a `[u8]` payload aligned to 64
/// took 64 bytes per byte (a 1.4 GB sparse data file for a 320×240 stream).
pub const PAYLOAD_ALIGNMENT: usize = 8;
/// Bytes of the bundle name field (UTF-8, NUL-padded).
pub const BUNDLE_NAME_LEN: usize = 32;
/// Payload bytes per pixel: `f32` depth, three `u8` RGB, one `u8` confidence.
pub const BYTES_PER_PIXEL: u64 = 8;
/// The largest payload a header can describe: `payload_size` and the plane offsets are `u32`.
pub const MAX_PAYLOAD_SIZE: u64 = u32::MAX as u64;

// Every size below `MAX_PAYLOAD_SIZE` converts to `usize` without loss.
const _: () = assert!(usize::BITS >= 32);

/// Processing flags (`FrameHeader::flags`).
pub mod flags {
    /// Depth was warped onto the RGB grid with a calibration (static or estimated).
    pub const ALIGNED: u32 = 1 << 0;
    /// Depth was refined by a neural network bundle (`FrameHeader::bundle` names it).
    pub const REFINED_NETWORK: u32 = 1 << 1;
    /// Depth was refined by the classical edge-aware filter.
    pub const REFINED_CLASSICAL: u32 = 1 << 2;
    /// A new calibration measurement entered the estimate on this frame: the network ran on
    /// it (inline), or a measurement made in the background was delivered on it.
    pub const CALIBRATION_ESTIMATED: u32 = 1 << 3;
    /// The calibration comes from the online estimator (otherwise: the static calibration).
    pub const CALIBRATION_ONLINE: u32 = 1 << 4;
    /// The refinement network's output on this frame was physically implausible (non-finite,
    /// negative, or moved far from the measurement on many pixels) and was not published: the
    /// depth is the classical filter's (`REFINED_CLASSICAL` is set, `REFINED_NETWORK` is not).
    pub const NETWORK_OUTPUT_REJECTED: u32 = 1 << 5;
    /// The confidence plane holds expected-error codes (`crate::confidence`): the refiner
    /// predicted each pixel's absolute depth error, `1 mm · 2^((255 − v)/16)`. Without this
    /// flag the confidence is the heuristic support × agreement score.
    pub const CONFIDENCE_EXPECTED_ERROR: u32 = 1 << 6;
}

/// [`FrameHeader::rgb_camera_model`]: which camera model the `rgb_*` intrinsics fields hold.
pub mod camera_model {
    /// No intrinsics known: `rgb_fx` … `rgb_distortion` are zero and mean nothing. A frame
    /// never carries made-up numbers: a client that needs intrinsics must get them elsewhere.
    pub const UNKNOWN: u16 = 0;
    /// A pinhole: `rgb_fx`, `rgb_fy`, `rgb_cx`, `rgb_cy`, no distortion (`rgb_distortion` zero).
    pub const PINHOLE: u16 = 1;
    /// A pinhole with Brown–Conrady distortion (OpenCV's and ROS's `plumb_bob`):
    /// `rgb_distortion` = `[k1, k2, p1, p2, k3]`.
    pub const BROWN_CONRADY: u16 = 2;
}

/// Pipeline stages whose latency each frame reports, index into `stage_latency_us`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(usize)]
pub enum Stage {
    /// Reading and decoding the input frame.
    Capture = 0,
    /// Normalisation and preparation of network inputs.
    Preprocess = 1,
    /// Rough flow network and calibration solve.
    Flow = 2,
    /// Flow fusion network.
    Fuse = 3,
    /// Warping depth/amplitude onto the RGB grid.
    Warp = 4,
    /// Depth refinement (network or classical filter).
    Refine = 5,
    /// Loaning and sending the sample.
    Publish = 6,
    /// From the frame's arrival in the daemon to its publication.
    Total = 7,
}

impl Stage {
    pub const ALL: [Stage; 8] = [
        Stage::Capture,
        Stage::Preprocess,
        Stage::Flow,
        Stage::Fuse,
        Stage::Warp,
        Stage::Refine,
        Stage::Publish,
        Stage::Total,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Capture => "capture",
            Stage::Preprocess => "preprocess",
            Stage::Flow => "flow",
            Stage::Fuse => "fuse",
            Stage::Warp => "warp",
            Stage::Refine => "refine",
            Stage::Publish => "publish",
            Stage::Total => "total",
        }
    }
}

/// The iceoryx2 user header of every published frame. `#[repr(C)]`, naturally aligned, no
/// implicit padding, [`HEADER_SIZE`] (256) bytes; offsets are fixed by docs/protocol.md's table and
/// `tests/layout.rs`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("DearFrameHeader")]
pub struct FrameHeader {
    /// [`MAGIC`].
    pub magic: u32,
    /// [`FORMAT_VERSION`].
    pub version: u32,
    /// Frame number from the source (monotonic, may skip when frames are skipped/dropped).
    pub frame_id: u64,
    /// Capture time given by the source, ns (replay: the recorded timestamp).
    pub capture_timestamp_ns: u64,
    /// `CLOCK_MONOTONIC` time of publication, ns (comparable with a client's clock).
    pub publish_timestamp_ns: u64,
    pub width: u32,
    pub height: u32,
    /// Calibration used for this frame (flow model `W = t/z + c`): t_x, px·m.
    pub calib_tx: f32,
    /// t_y, px·m.
    pub calib_ty: f32,
    /// c_x, px.
    pub calib_cx: f32,
    /// c_y, px.
    pub calib_cy: f32,
    /// RMS residual (px) of the last calibration fit to a flow; NaN when not estimated (static)
    /// or when the last fit was to the frame's edges (it has no end-point residual).
    pub calib_residual_px: f32,
    /// Quality of the calibration estimate in [0, 1]; 0 = static / unknown.
    pub calib_quality: f32,
    /// [`flags`].
    pub flags: u32,
    /// Frames since the calibration was last estimated (0 = this frame).
    pub calib_age_frames: u32,
    /// Name of the model bundle (UTF-8, NUL-padded); all zero when none.
    pub bundle: [u8; BUNDLE_NAME_LEN],
    /// Per-stage latency in µs, indexed by [`Stage`]; 0 = stage not run.
    pub stage_latency_us: [u32; 8],
    /// Byte offset of the depth plane in the payload.
    pub depth_offset: u32,
    /// Byte offset of the RGB plane in the payload.
    pub rgb_offset: u32,
    /// Byte offset of the confidence plane in the payload.
    pub confidence_offset: u32,
    /// Bytes of payload in use.
    pub payload_size: u32,
    /// Input frames skipped as bad since the daemon started.
    pub frames_skipped: u64,
    /// Input frames dropped because processing fell behind since the daemon started.
    pub frames_dropped: u64,
    /// Random id the publisher drew when it started (never 0 from `deard`; 0 = the publisher
    /// did not say). A new value means a new publisher instance: the daemon restarted, and
    /// `frame_id`, `sequence` and the counters started again.
    pub run_id: u64,
    /// Samples this publisher instance sent before this one: 0, 1, 2, … with no gaps on the
    /// publisher's side, strictly increasing within one `run_id` (unlike `frame_id`, which
    /// restarts when a replay loops and skips over bad input). A gap seen by a client is the
    /// number of samples it lost (overwritten in its queue because it read too slowly).
    pub sequence: u64,
    /// The calibration's health, a [`crate::CalibrationHealth`] code: 0 unknown, 1 good, 2 can
    /// improve, 3 needs recalibration (docs/calibration-health.md). Taken from `reserved` in
    /// format 2: an older publisher sends 0, "unknown".
    pub calib_health: u8,
    /// Directions of `(t_x, t_y, c_x, c_y)` the last calibration measurement's frame
    /// constrained, 0–4 (4 also when the measurement carried no observability); 0 before any.
    pub calib_constrained: u8,
    /// Which model the RGB camera's intrinsics below are in, a [`camera_model`] code: 0
    /// unknown (no intrinsics), 1 pinhole, 2 Brown–Conrady. Format 3.
    pub rgb_camera_model: u16,
    /// Metres per unit of the depth plane: [`DEPTH_UNIT_M`] (1.0, `f32` metres) in format 3;
    /// [`FrameHeader::validate`] refuses any other value. Format 3.
    pub depth_unit_m: f32,
    /// The RGB camera's focal length along x, px, at the frame's `width`×`height` (the depth is
    /// aligned to the RGB grid, so these are the depth's intrinsics too); 0 when unknown.
    pub rgb_fx: f32,
    /// Focal length along y, px.
    pub rgb_fy: f32,
    /// Principal point x, px (pixel centres at integer coordinates, as OpenCV).
    pub rgb_cx: f32,
    /// Principal point y, px.
    pub rgb_cy: f32,
    /// Brown–Conrady coefficients `[k1, k2, p1, p2, k3]` (OpenCV order) with model 2; zero
    /// otherwise.
    pub rgb_distortion: [f32; 5],
    /// Zero; room for additions without changing the size.
    pub reserved: [u8; 28],
}

const _: () = assert!(core::mem::size_of::<FrameHeader>() == HEADER_SIZE);

/// The RGB camera's intrinsics a frame carries ([`FrameHeader::intrinsics`]), at the frame's
/// size: the pinhole `fx, fy, cx, cy` in px and, when known, Brown–Conrady distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraIntrinsics {
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    /// `[k1, k2, p1, p2, k3]` (OpenCV's order, ROS's `plumb_bob`); `None`: no distortion.
    pub distortion: Option<[f32; 5]>,
}

impl CameraIntrinsics {
    /// A pinhole without distortion.
    pub fn pinhole(fx: f32, fy: f32, cx: f32, cy: f32) -> Self {
        CameraIntrinsics {
            fx,
            fy,
            cx,
            cy,
            distortion: None,
        }
    }

    /// Checks that the numbers can be used: focal lengths positive and finite, the rest
    /// finite. The message names the header field (`rgb_fx`, `rgb_distortion[2]`, …).
    pub fn check(&self) -> Result<(), IntrinsicsError> {
        for (field, value) in [("rgb_fx", self.fx), ("rgb_fy", self.fy)] {
            if !(value > 0.0 && value.is_finite()) {
                return Err(IntrinsicsError::Value {
                    field: field.to_string(),
                    value,
                    expected: "a positive finite focal length in px",
                });
            }
        }
        for (field, value) in [("rgb_cx", self.cx), ("rgb_cy", self.cy)] {
            if !value.is_finite() {
                return Err(IntrinsicsError::Value {
                    field: field.to_string(),
                    value,
                    expected: "a finite principal point in px",
                });
            }
        }
        for (i, &value) in self.distortion.iter().flatten().enumerate() {
            if !value.is_finite() {
                return Err(IntrinsicsError::Value {
                    field: format!("rgb_distortion[{i}]"),
                    value,
                    expected: "a finite distortion coefficient",
                });
            }
        }
        Ok(())
    }
}

/// Why a frame's intrinsics cannot be used ([`FrameHeader::intrinsics`]); every message names
/// the header field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IntrinsicsError {
    #[error(
        "`rgb_camera_model` is {found}: not a camera model of frame format {FORMAT_VERSION} \
         (0 unknown, 1 pinhole, 2 Brown–Conrady)"
    )]
    Model { found: u16 },
    #[error("`{field}` is {value}, expected {expected}")]
    Value {
        field: String,
        value: f32,
        expected: &'static str,
    },
}

impl Default for FrameHeader {
    /// An empty 0×0 frame with magic and version set (iceoryx2 initialises loaned headers with
    /// it; the publisher then overwrites every field).
    fn default() -> Self {
        FrameHeader::new(0, 0, 0)
    }
}

impl FrameHeader {
    /// A header for a `width`×`height` frame with the payload layout filled in and everything
    /// else zero / unknown.
    ///
    /// # Panics
    ///
    /// If the frame's payload is larger than the header can describe (see
    /// [`PayloadLayout::new`]). A publisher makes its layout with `PayloadLayout::new` (which
    /// returns the error) before it makes headers of the same size, so its calls cannot fail;
    /// sizes from anywhere else go through [`FrameHeader::try_new`].
    pub fn new(frame_id: u64, width: u32, height: u32) -> Self {
        match Self::try_new(frame_id, width, height) {
            Ok(header) => header,
            Err(e) => panic!("FrameHeader::new: {e}"),
        }
    }

    /// [`FrameHeader::new`] for a size that may be too large for the protocol.
    pub fn try_new(frame_id: u64, width: u32, height: u32) -> Result<Self, LayoutError> {
        let layout = PayloadLayout::new(width, height)?;
        // The layout's sizes are at most `MAX_PAYLOAD_SIZE` = `u32::MAX`: these casts are exact.
        Ok(FrameHeader {
            magic: MAGIC,
            version: FORMAT_VERSION,
            frame_id,
            capture_timestamp_ns: 0,
            publish_timestamp_ns: 0,
            width,
            height,
            calib_tx: 0.0,
            calib_ty: 0.0,
            calib_cx: 0.0,
            calib_cy: 0.0,
            calib_residual_px: f32::NAN,
            calib_quality: 0.0,
            flags: 0,
            calib_age_frames: 0,
            bundle: [0; BUNDLE_NAME_LEN],
            stage_latency_us: [0; 8],
            depth_offset: layout.depth_offset as u32,
            rgb_offset: layout.rgb_offset as u32,
            confidence_offset: layout.confidence_offset as u32,
            payload_size: layout.size as u32,
            frames_skipped: 0,
            frames_dropped: 0,
            run_id: 0,
            sequence: 0,
            calib_health: 0,
            calib_constrained: 0,
            rgb_camera_model: camera_model::UNKNOWN,
            depth_unit_m: DEPTH_UNIT_M,
            rgb_fx: 0.0,
            rgb_fy: 0.0,
            rgb_cx: 0.0,
            rgb_cy: 0.0,
            rgb_distortion: [0.0; 5],
            reserved: [0; 28],
        })
    }

    /// The bundle name, or `""` when none.
    pub fn bundle_name(&self) -> &str {
        let end = self
            .bundle
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(BUNDLE_NAME_LEN);
        std::str::from_utf8(&self.bundle[..end]).unwrap_or("<invalid utf-8>")
    }

    /// Sets the bundle name, truncated to [`BUNDLE_NAME_LEN`] bytes at a character boundary.
    pub fn set_bundle_name(&mut self, name: &str) {
        self.bundle = [0; BUNDLE_NAME_LEN];
        let mut end = name.len().min(BUNDLE_NAME_LEN);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        self.bundle[..end].copy_from_slice(&name.as_bytes()[..end]);
    }

    /// [`calib_health`](Self::calib_health) as a state (unknown codes read as `Unknown`).
    pub fn calibration_health(&self) -> crate::CalibrationHealth {
        crate::CalibrationHealth::from_code(self.calib_health)
    }

    /// The RGB camera's intrinsics at the frame's size: `Ok(None)` when the publisher knows
    /// none (`rgb_camera_model` 0), an error naming the field when the numbers cannot be used.
    pub fn intrinsics(&self) -> Result<Option<CameraIntrinsics>, IntrinsicsError> {
        let distortion = match self.rgb_camera_model {
            camera_model::UNKNOWN => return Ok(None),
            camera_model::PINHOLE => None,
            camera_model::BROWN_CONRADY => Some(self.rgb_distortion),
            found => return Err(IntrinsicsError::Model { found }),
        };
        let k = CameraIntrinsics {
            fx: self.rgb_fx,
            fy: self.rgb_fy,
            cx: self.rgb_cx,
            cy: self.rgb_cy,
            distortion,
        };
        k.check()?;
        Ok(Some(k))
    }

    /// Sets the intrinsics fields (`None`: model 0, "unknown", every field zero).
    pub fn set_intrinsics(&mut self, intrinsics: Option<&CameraIntrinsics>) {
        let Some(k) = intrinsics else {
            self.rgb_camera_model = camera_model::UNKNOWN;
            (self.rgb_fx, self.rgb_fy, self.rgb_cx, self.rgb_cy) = (0.0, 0.0, 0.0, 0.0);
            self.rgb_distortion = [0.0; 5];
            return;
        };
        (self.rgb_fx, self.rgb_fy, self.rgb_cx, self.rgb_cy) = (k.fx, k.fy, k.cx, k.cy);
        match k.distortion {
            Some(d) => {
                self.rgb_camera_model = camera_model::BROWN_CONRADY;
                self.rgb_distortion = d;
            }
            None => {
                self.rgb_camera_model = camera_model::PINHOLE;
                self.rgb_distortion = [0.0; 5];
            }
        }
    }

    /// Latency of one stage in µs.
    pub fn latency_us(&self, stage: Stage) -> u32 {
        self.stage_latency_us[stage as usize]
    }

    /// Checks a received header against its payload before anything reads the payload: the
    /// magic, the format version, the depth unit (metres), that the frame size fits the protocol, that every plane
    /// offset and `payload_size` are the ones [`PayloadLayout::new`] gives for `width`×`height`
    /// (so the planes lie inside `payload_size`, in order, without overlapping), and that the
    /// payload holds `payload_size` bytes. Never panics, whatever the header's bytes are: the
    /// header comes from another process and may be corrupt or of another protocol version.
    pub fn validate(&self, payload_len: usize) -> Result<PayloadLayout, HeaderError> {
        if self.magic != MAGIC {
            return Err(HeaderError::Magic { found: self.magic });
        }
        if self.version != FORMAT_VERSION {
            return Err(HeaderError::Version {
                found: self.version,
                supported: FORMAT_VERSION,
            });
        }
        if self.depth_unit_m != DEPTH_UNIT_M {
            return Err(HeaderError::DepthUnit {
                found: self.depth_unit_m,
            });
        }
        let layout = PayloadLayout::new(self.width, self.height)?;
        let fields = [
            ("depth_offset", self.depth_offset, layout.depth_offset),
            ("rgb_offset", self.rgb_offset, layout.rgb_offset),
            (
                "confidence_offset",
                self.confidence_offset,
                layout.confidence_offset,
            ),
            ("payload_size", self.payload_size, layout.size),
        ];
        for (field, found, expected) in fields {
            // `expected` ≤ `MAX_PAYLOAD_SIZE` = `u32::MAX` (checked by `PayloadLayout::new`).
            let expected = expected as u32;
            if found != expected {
                return Err(HeaderError::Layout {
                    field,
                    found,
                    expected,
                    width: self.width,
                    height: self.height,
                });
            }
        }
        if payload_len < layout.size {
            return Err(HeaderError::PayloadTooShort {
                len: payload_len,
                payload_size: layout.size,
            });
        }
        Ok(layout)
    }
}

/// A fresh [`FrameHeader::run_id`]: 64 random bits from the kernel (`getrandom(2)`), never 0
/// (0 means "no run id"). Random rather than a start time or a PID, both of which repeat
/// across reboots and containers, so two runs are told apart with certainty in practice.
pub fn random_run_id() -> std::io::Result<u64> {
    loop {
        let mut bytes = [0u8; 8];
        // SAFETY: `bytes` is valid for writes of its length; flags 0 = the urandom pool, which
        // blocks only until the kernel's pool is first initialised at boot.
        let n = unsafe { libc::getrandom(bytes.as_mut_ptr().cast(), bytes.len(), 0) };
        if n < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() == std::io::ErrorKind::Interrupted {
                continue;
            }
            return Err(e);
        }
        // Requests of up to 256 bytes are never short once the pool is initialised; a short
        // read would leave zero bytes, so it is simply retried.
        let id = u64::from_le_bytes(bytes);
        if n as usize == bytes.len() && id != 0 {
            return Ok(id);
        }
    }
}

/// Why a received [`FrameHeader`] was refused ([`FrameHeader::validate`]). Every message names
/// the header field that is wrong, in backticks, with the value found and the one expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HeaderError {
    #[error(
        "`magic` is {found:#010x}, expected {MAGIC:#010x} (\"DEAR\"): not a DEAR frame header"
    )]
    Magic { found: u32 },
    /// A header of another protocol version: its fields may mean something else, so none is
    /// read. The message names both versions so the user knows which side to upgrade.
    #[error(
        "`version` is {found}: the publisher speaks frame format version {found}, this client \
         reads version {supported} only (update the older of the two)"
    )]
    Version { found: u32, supported: u32 },
    /// The depth plane is not in metres: no publisher of this format sends that.
    #[error(
        "`depth_unit_m` is {found}, expected {DEPTH_UNIT_M} (the depth plane is f32 metres in \
         frame format {FORMAT_VERSION})"
    )]
    DepthUnit { found: f32 },
    /// `width`×`height` needs a payload larger than the header can describe.
    #[error(transparent)]
    Size(#[from] LayoutError),
    /// A plane offset or `payload_size` differs from the layout of the frame's size.
    #[error("`{field}` is {found}, but a {width}×{height} frame has {expected}")]
    Layout {
        field: &'static str,
        found: u32,
        expected: u32,
        width: u32,
        height: u32,
    },
    /// The sample's payload is shorter than the header's `payload_size`.
    #[error("`payload_size` is {payload_size} bytes, but the sample's payload has only {len}")]
    PayloadTooShort { len: usize, payload_size: usize },
}

/// A frame size whose payload the header cannot describe: more than [`MAX_PAYLOAD_SIZE`] bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "`width`×`height` is {width}×{height}: {pixels} pixels need {BYTES_PER_PIXEL} bytes each, \
     more than the {MAX_PAYLOAD_SIZE} bytes a frame's payload may have (`payload_size` is a u32)"
)]
pub struct LayoutError {
    pub width: u32,
    pub height: u32,
    /// `width·height` (cannot overflow: both are below 2³²).
    pub pixels: u64,
}

/// Where each plane of a frame lies in the payload: depth (`f32`), then RGB (`u8`×3), then
/// confidence (`u8`). Depth first keeps it aligned to the payload's [`PAYLOAD_ALIGNMENT`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PayloadLayout {
    pub width: usize,
    pub height: usize,
    pub depth_offset: usize,
    pub rgb_offset: usize,
    pub confidence_offset: usize,
    pub size: usize,
}

impl PayloadLayout {
    /// The layout of a `width`×`height` frame. Checked: a size whose payload exceeds
    /// [`MAX_PAYLOAD_SIZE`] is an error, never an overflow, since the size may come from a
    /// received (possibly corrupt) header or an input file.
    pub fn new(width: u32, height: u32) -> Result<Self, LayoutError> {
        // Below 2³² each, so the product fits a u64; the byte count may not, hence checked_mul.
        let pixels = u64::from(width) * u64::from(height);
        let too_large = LayoutError {
            width,
            height,
            pixels,
        };
        let size = pixels
            .checked_mul(BYTES_PER_PIXEL)
            .filter(|&size| size <= MAX_PAYLOAD_SIZE)
            .ok_or(too_large)?;
        // From here every value is at most `size` ≤ u32::MAX, which fits a usize (asserted
        // above): plain arithmetic cannot overflow.
        let pixels = pixels as usize;
        let depth_offset = 0;
        let rgb_offset = depth_offset + 4 * pixels;
        let confidence_offset = rgb_offset + 3 * pixels;
        Ok(PayloadLayout {
            width: width as usize,
            height: height as usize,
            depth_offset,
            rgb_offset,
            confidence_offset,
            size: size as usize,
        })
    }

    pub fn pixels(&self) -> usize {
        self.width * self.height
    }
}
