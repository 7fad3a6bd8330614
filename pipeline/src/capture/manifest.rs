//! `capture.json`: the manifest of a capture directory (docs/design.md, "Capture directory
//! format").

use serde::{Deserialize, Serialize};

use crate::calibration::Calibration;

/// The value of [`CaptureManifest::format`].
pub const FORMAT_NAME: &str = "dear-capture";
/// The manifest version this code writes and reads.
pub const FORMAT_VERSION: u32 = 1;
/// Largest accepted image side, in the manifest and in any image or flow file: guards against a
/// corrupt file asking for absurd buffers.
pub const MAX_SIDE: u32 = 8192;

/// Pinhole intrinsics of the (rectified) camera the frames are given in, pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl Intrinsics {
    /// A centred pinhole with the given horizontal field of view in degrees and square pixels.
    pub fn from_hfov(width: u32, height: u32, hfov_deg: f32) -> Self {
        let f = 0.5 * width as f32 / (0.5 * hfov_deg.to_radians()).tan();
        Intrinsics {
            fx: f,
            fy: f,
            cx: 0.5 * width as f32 - 0.5,
            cy: 0.5 * height as f32 - 0.5,
        }
    }
}

/// One entry of the frame list.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameEntry {
    /// Frame number: the files are `frames/{id:06}.*`.
    pub id: u64,
    /// Capture time in nanoseconds, monotonic within the capture.
    pub timestamp_ns: u64,
    /// The misalignment applied to (or present in) this frame: the ground-truth RGB→ToF flow
    /// is `perturbation.flow_at(gt_depth)`. Absent when unknown (live recordings).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub perturbation: Option<Calibration>,
}

/// The whole manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureManifest {
    /// Always [`FORMAT_NAME`].
    pub format: String,
    /// [`FORMAT_VERSION`].
    pub version: u32,
    pub width: u32,
    pub height: u32,
    /// Intrinsics of the RGB camera (the ToF images are rectified to it by the factory
    /// calibration).
    pub intrinsics: Intrinsics,
    /// The factory (initial, weak) calibration, in the flow model of [`Calibration`].
    #[serde(default)]
    pub initial_calibration: Calibration,
    /// Metres per unit of the 16-bit depth PNGs (0.001 = millimetres).
    pub depth_scale: f32,
    /// ToF modulation frequencies in Hz (empty when unknown).
    #[serde(default)]
    pub modulation_frequencies_hz: Vec<f64>,
    /// Free-form description of where the frames came from (simulator parameters, device, …).
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    pub source: serde_json::Value,
    pub frames: Vec<FrameEntry>,
}

impl CaptureManifest {
    /// A manifest with no frames yet.
    pub fn new(width: u32, height: u32, intrinsics: Intrinsics) -> Self {
        CaptureManifest {
            format: FORMAT_NAME.to_string(),
            version: FORMAT_VERSION,
            width,
            height,
            intrinsics,
            initial_calibration: Calibration::IDENTITY,
            depth_scale: 0.001,
            modulation_frequencies_hz: Vec::new(),
            source: serde_json::Value::Null,
            frames: Vec::new(),
        }
    }
}
