//! `capture.json`: the manifest of a capture directory (docs/capture-format.md), and the rules
//! it is read by.
//!
//! The rules live in two forms side by side: as `#[schemars(...)]` bounds on the types, from
//! which [`crate::schema`] generates the JSON Schema the Python reader validates with, and in
//! [`CaptureManifest::validate`], which the Rust reader runs (serde does not read the bounds).
//! Both name the same constants, and `fixtures/capture/bad_manifests.json` lists manifests each
//! of which both languages must refuse. What JSON Schema cannot say (ids unique, timestamps in
//! order) only `validate` and its Python twin check.

use std::collections::HashSet;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::calibration::Calibration;

/// The value of [`CaptureManifest::format`].
/// The largest `depth_scale`: one centimetre per unit, so the 16-bit range reaches 655 m, far
/// beyond any ToF module. A larger one (1e30 was accepted) makes every valid pixel a depth no
/// sensor measures.
pub const MAX_DEPTH_SCALE: f32 = 0.01;

pub const FORMAT_NAME: &str = "dear-capture";
/// The manifest version this code writes and reads.
pub const FORMAT_VERSION: u32 = 1;
/// Largest accepted image side, in the manifest and in any image or flow file: guards against a
/// corrupt file asking for absurd buffers.
pub const MAX_SIDE: u32 = 8192;
/// Largest frame id: the file names have six digits (`frames/{id:06}.*`).
pub const MAX_FRAME_ID: u64 = 999_999;

/// Pinhole intrinsics of the (rectified) camera the frames are given in, pixels. The focal
/// lengths are positive and every value is finite as an f32.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    #[schemars(range(max = f32::MAX), extend("exclusiveMinimum" = 0))]
    pub fx: f32,
    #[schemars(range(max = f32::MAX), extend("exclusiveMinimum" = 0))]
    pub fy: f32,
    #[schemars(range(min = -f32::MAX, max = f32::MAX))]
    pub cx: f32,
    #[schemars(range(min = -f32::MAX, max = f32::MAX))]
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

/// `FX,FY,CX,CY`: the RGB camera's pinhole intrinsics given on the command line (`dear dump`,
/// `dear record`, `dear-ros2`; a clap value parser): positive focal lengths, all values finite.
pub fn parse_intrinsics(s: &str) -> Result<Intrinsics, String> {
    let values: Vec<f32> = s
        .split(',')
        .map(|v| v.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{s:?} is not four comma-separated numbers FX,FY,CX,CY"))?;
    let [fx, fy, cx, cy] = values[..] else {
        return Err(format!(
            "{s:?} has {} values, expected FX,FY,CX,CY",
            values.len()
        ));
    };
    if !(fx > 0.0 && fy > 0.0 && values.iter().all(|v| v.is_finite())) {
        return Err(format!(
            "{s:?}: focal lengths must be positive and all values finite"
        ));
    }
    Ok(Intrinsics { fx, fy, cx, cy })
}

/// One entry of the frame list. Ids are unique and timestamps never decrease along the list
/// (checked by the readers; JSON Schema cannot say it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FrameEntry {
    /// Frame number: the files are `frames/{id:06}.*`.
    #[schemars(range(max = MAX_FRAME_ID))]
    pub id: u64,
    /// Capture time in nanoseconds, monotonic within the capture.
    #[schemars(range(max = u64::MAX))]
    pub timestamp_ns: u64,
    /// The misalignment applied to (or present in) this frame: the ground-truth RGB→ToF flow
    /// is `perturbation.flow_at(gt_depth)`. Absent when unknown (live recordings).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub perturbation: Option<Calibration>,
}

/// The whole manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(
    title = "capture.json",
    description = "Manifest of a DEAR capture directory"
)]
pub struct CaptureManifest {
    /// Always `dear-capture` ([`FORMAT_NAME`]).
    #[schemars(extend("const" = FORMAT_NAME))]
    pub format: String,
    /// The manifest version, 1 ([`FORMAT_VERSION`]).
    #[schemars(extend("const" = FORMAT_VERSION))]
    pub version: u32,
    /// Image width in pixels, every plane.
    #[schemars(range(min = 1, max = MAX_SIDE))]
    pub width: u32,
    /// Image height in pixels, every plane.
    #[schemars(range(min = 1, max = MAX_SIDE))]
    pub height: u32,
    /// Intrinsics of the RGB camera (the ToF images are rectified to it by the factory
    /// calibration).
    pub intrinsics: Intrinsics,
    /// The RGB camera's Brown–Conrady lens distortion `[k1, k2, p1, p2, k3]` (OpenCV's order,
    /// ROS's `plumb_bob`), each finite; absent when there is none (a pinhole, the simulator's
    /// camera). deard publishes it with the intrinsics in every frame header.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(transform = finite_items)]
    pub distortion: Option<[f32; 5]>,
    /// The factory (initial, weak) calibration, in the flow model of [`Calibration`]
    /// (identity when absent).
    #[serde(default)]
    pub initial_calibration: Calibration,
    /// Metres per unit of the 16-bit depth PNGs (0.001 = millimetres); at most
    /// [`MAX_DEPTH_SCALE`].
    #[schemars(range(max = MAX_DEPTH_SCALE), extend("exclusiveMinimum" = 0))]
    pub depth_scale: f32,
    /// ToF modulation frequencies in Hz (empty when unknown), each positive.
    #[serde(default)]
    #[schemars(transform = positive_items)]
    pub modulation_frequencies_hz: Vec<f64>,
    /// Free-form description of where the frames came from (simulator parameters, device, …).
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    pub source: serde_json::Value,
    /// The frames, in capture order.
    pub frames: Vec<FrameEntry>,
}

/// Schema of an array of numbers finite as f32 (the maximum refuses the infinity Python's
/// `json` reads `1e400` as, and what f32 cannot hold).
fn finite_items(schema: &mut schemars::Schema) {
    if let Some(items) = schema.get_mut("items").and_then(|i| i.as_object_mut()) {
        items.insert("minimum".into(), (-f64::from(f32::MAX)).into());
        items.insert("maximum".into(), f64::from(f32::MAX).into());
    }
}

/// Schema of an array of positive finite numbers: `inner(range(...))` has no exclusive bound.
/// The maximum refuses the infinity Python's `json` reads `1e400` as (serde refuses the text).
fn positive_items(schema: &mut schemars::Schema) {
    if let Some(items) = schema.get_mut("items").and_then(|i| i.as_object_mut()) {
        items.insert("exclusiveMinimum".into(), 0.into());
        items.insert("maximum".into(), f64::MAX.into());
    }
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
            distortion: None,
            initial_calibration: Calibration::IDENTITY,
            depth_scale: 0.001,
            modulation_frequencies_hz: Vec::new(),
            source: serde_json::Value::Null,
            frames: Vec::new(),
        }
    }

    /// Parses and validates `capture.json` text. The message names the offending field; a type
    /// error too (``field `frames[3].timestamp_ns`: invalid type ...``), which serde_json alone
    /// reports only as a line and column.
    pub fn from_json(text: &str) -> Result<Self, String> {
        let mut de = serde_json::Deserializer::from_str(text);
        let manifest: CaptureManifest = serde_path_to_error::deserialize(&mut de).map_err(|e| {
            let field = e.path().to_string();
            if field == "." {
                e.inner().to_string()
            } else {
                format!("field `{field}`: {}", e.inner())
            }
        })?;
        // What serde_json::from_str checks too: nothing but whitespace after the object.
        de.end().map_err(|e| e.to_string())?;
        manifest.validate()?;
        Ok(manifest)
    }

    /// Checks the manifest's own consistency (the bounds of the schema and what it cannot
    /// express); the message names the offending field.
    pub fn validate(&self) -> Result<(), String> {
        if self.format != FORMAT_NAME {
            return Err(format!(
                "field `format` is {:?}, expected {FORMAT_NAME:?}",
                self.format
            ));
        }
        if self.version != FORMAT_VERSION {
            return Err(format!(
                "field `version` is {}, this reader supports {FORMAT_VERSION}",
                self.version
            ));
        }
        for (name, side) in [("width", self.width), ("height", self.height)] {
            if side == 0 || side > MAX_SIDE {
                return Err(format!("field `{name}` is {side}, expected 1..={MAX_SIDE}"));
            }
        }
        if !(self.depth_scale > 0.0 && self.depth_scale <= MAX_DEPTH_SCALE) {
            return Err(format!(
                "field `depth_scale` is {}, expected metres per unit in (0, {MAX_DEPTH_SCALE}] \
                 (0.001 = millimetres)",
                self.depth_scale
            ));
        }
        let k = &self.intrinsics;
        for (name, v) in [("fx", k.fx), ("fy", k.fy)] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(format!(
                    "field `intrinsics.{name}` is {v}, expected a positive finite focal length"
                ));
            }
        }
        for (name, v) in [("cx", k.cx), ("cy", k.cy)] {
            if !v.is_finite() {
                return Err(format!(
                    "field `intrinsics.{name}` is {v}, expected a finite number"
                ));
            }
        }
        if let Some(d) = &self.distortion {
            if let Some((i, k)) = d.iter().enumerate().find(|(_, k)| !k.is_finite()) {
                return Err(format!(
                    "field `distortion[{i}]` is {k}, expected a finite Brown–Conrady \
                     coefficient (distortion = [k1, k2, p1, p2, k3])"
                ));
            }
        }
        if let Some((i, f)) = self
            .modulation_frequencies_hz
            .iter()
            .enumerate()
            .find(|(_, f)| !(**f > 0.0 && f.is_finite()))
        {
            return Err(format!(
                "field `modulation_frequencies_hz[{i}]` is {f}, expected a positive frequency"
            ));
        }
        // f32 fields take JSON numbers beyond f32 (`1e39`) as infinity; a calibration that is
        // not finite aligns no pixel, so it is refused here, by field, rather than met frame by
        // frame.
        check_calibration("initial_calibration", &self.initial_calibration)?;
        let mut seen = HashSet::new();
        let mut last_time = 0;
        for (i, frame) in self.frames.iter().enumerate() {
            if frame.id > MAX_FRAME_ID {
                return Err(format!(
                    "field `frames[{i}].id` is {}, beyond {MAX_FRAME_ID}: it does not fit the \
                     6-digit file names",
                    frame.id
                ));
            }
            if !seen.insert(frame.id) {
                return Err(format!(
                    "field `frames[{i}].id` is {}, which appears twice",
                    frame.id
                ));
            }
            if frame.timestamp_ns < last_time {
                return Err(format!(
                    "field `frames[{i}].timestamp_ns` is {}, before the previous frame's \
                     {last_time} (timestamps must be monotonic)",
                    frame.timestamp_ns
                ));
            }
            last_time = frame.timestamp_ns;
            if let Some(p) = &frame.perturbation {
                check_calibration(&format!("frames[{i}].perturbation"), p)?;
            }
        }
        Ok(())
    }
}

/// Every parameter of `c` is finite; the error names `field.<parameter>`.
fn check_calibration(field: &str, c: &Calibration) -> Result<(), String> {
    for (name, v) in [("tx", c.tx), ("ty", c.ty), ("cx", c.cx), ("cy", c.cy)] {
        if !v.is_finite() {
            return Err(format!(
                "field `{field}.{name}` is {v}, expected a finite number (beyond f32's range?)"
            ));
        }
    }
    Ok(())
}
