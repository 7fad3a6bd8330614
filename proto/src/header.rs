//! The frame header and the payload layout.

use iceoryx2::prelude::ZeroCopySend;

/// `"DEAR"` read as a little-endian `u32`.
pub const MAGIC: u32 = u32::from_le_bytes(*b"DEAR");
/// Bumped on any change of the header or payload layout.
pub const FORMAT_VERSION: u32 = 1;
/// Alignment of the payload in shared memory: enough for `f32` and for SIMD loads.
pub const PAYLOAD_ALIGNMENT: usize = 64;
/// Bytes of the bundle name field (UTF-8, NUL-padded).
pub const BUNDLE_NAME_LEN: usize = 32;

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
/// implicit padding, 192 bytes; offsets are fixed by the README's table and `tests/layout.rs`.
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
    /// Zero; room for additions without changing the size.
    pub reserved: [u8; 24],
}

const _: () = assert!(core::mem::size_of::<FrameHeader>() == 192);

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
    pub fn new(frame_id: u64, width: u32, height: u32) -> Self {
        let layout = PayloadLayout::new(width, height);
        FrameHeader {
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
            reserved: [0; 24],
        }
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

    /// Latency of one stage in µs.
    pub fn latency_us(&self, stage: Stage) -> u32 {
        self.stage_latency_us[stage as usize]
    }

    /// Checks magic, version and that the payload layout is the one this crate expects for the
    /// frame size, so a client never reads out of bounds.
    pub fn validate(&self, payload_len: usize) -> Result<PayloadLayout, String> {
        if self.magic != MAGIC {
            return Err(format!(
                "frame header magic is {:#010x}, expected {MAGIC:#010x}",
                self.magic
            ));
        }
        if self.version != FORMAT_VERSION {
            return Err(format!(
                "frame format version {} is not supported (this client reads {FORMAT_VERSION})",
                self.version
            ));
        }
        let layout = PayloadLayout::new(self.width, self.height);
        let found = (
            self.depth_offset as usize,
            self.rgb_offset as usize,
            self.confidence_offset as usize,
            self.payload_size as usize,
        );
        let expected = (
            layout.depth_offset,
            layout.rgb_offset,
            layout.confidence_offset,
            layout.size,
        );
        if found != expected {
            return Err(format!(
                "payload layout {found:?} does not match {expected:?} for {}x{}",
                self.width, self.height
            ));
        }
        if payload_len < layout.size {
            return Err(format!(
                "payload is {payload_len} bytes, the header needs {}",
                layout.size
            ));
        }
        Ok(layout)
    }
}

/// Where each plane of a frame lies in the payload: depth (`f32`), then RGB (`u8`×3), then
/// confidence (`u8`). Depth first keeps it aligned to the payload's 64-byte alignment.
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
    pub fn new(width: u32, height: u32) -> Self {
        let (width, height) = (width as usize, height as usize);
        let pixels = width * height;
        let depth_offset = 0;
        let rgb_offset = depth_offset + 4 * pixels;
        let confidence_offset = rgb_offset + 3 * pixels;
        PayloadLayout {
            width,
            height,
            depth_offset,
            rgb_offset,
            confidence_offset,
            size: confidence_offset + pixels,
        }
    }

    pub fn pixels(&self) -> usize {
        self.width * self.height
    }
}
