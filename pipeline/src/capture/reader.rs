//! Opening and validating a capture directory, and reading its frames.

use std::collections::HashSet;
use std::fs;
use std::path::{Path, PathBuf};

use super::error::CaptureError;
use super::layout::{FramePaths, MANIFEST_FILE};
use super::manifest::{CaptureManifest, FORMAT_NAME, FORMAT_VERSION, MAX_SIDE};
use super::{flo, png};
use crate::calibration::Calibration;
use crate::frame::RgbdFrame;

/// An opened, validated capture directory. Frames are read on demand, so a bad frame costs an
/// error for that frame only.
#[derive(Debug, Clone)]
pub struct CaptureDir {
    root: PathBuf,
    manifest: CaptureManifest,
}

impl CaptureDir {
    /// Reads and validates `root/capture.json`.
    pub fn open(root: impl AsRef<Path>) -> Result<Self, CaptureError> {
        let root = root.as_ref().to_owned();
        let path = root.join(MANIFEST_FILE);
        let text = fs::read_to_string(&path).map_err(|e| CaptureError::io(&path, e))?;
        let manifest = parse_manifest(&text).map_err(|message| CaptureError::Manifest {
            path: path.clone(),
            message,
        })?;
        validate(&manifest).map_err(|message| CaptureError::Manifest { path, message })?;
        Ok(CaptureDir { root, manifest })
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    pub fn manifest(&self) -> &CaptureManifest {
        &self.manifest
    }

    /// Number of frames in the manifest.
    pub fn len(&self) -> usize {
        self.manifest.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.manifest.frames.is_empty()
    }

    /// `(width, height)`.
    pub fn size(&self) -> (u32, u32) {
        (self.manifest.width, self.manifest.height)
    }

    /// The files of the frame at `position` in the frame list.
    pub fn frame_paths(&self, position: usize) -> FramePaths {
        FramePaths::new(&self.root, self.manifest.frames[position].id)
    }

    /// Whether every frame has a ground-truth depth file (what evaluation needs).
    pub fn has_ground_truth(&self) -> bool {
        (0..self.len()).all(|i| self.frame_paths(i).gt_depth.is_file())
    }

    /// Reads and checks the frame at `position` (0-based index into the manifest's frame list).
    /// Optional files (ground truth, mask, flow) are read when present: what evaluation and
    /// training need.
    ///
    /// # Panics
    /// If `position >= self.len()` (a programming error, not a data error).
    pub fn read_frame(&self, position: usize) -> Result<RgbdFrame, CaptureError> {
        let mut frame = self.read_sensor_frame(position)?;
        let paths = self.frame_paths(position);
        let size = Some(self.size());
        let scale = self.manifest.depth_scale;
        frame.gt_depth = optional(&paths.gt_depth, |p| png::read_depth(p, size, scale))?;
        frame.mask = optional(&paths.mask, |p| png::read_mask(p, size))?;
        frame.flow = optional(&paths.flow, |p| flo::read_flo(p, size))?;
        Ok(frame)
    }

    /// Reads and checks only what a sensor delivers at `position`: RGB, amplitude and depth
    /// (ground truth, mask and flow stay `None`; the manifest's perturbation is kept, it is
    /// metadata). What the daemon's replay needs: it decodes three PNGs a frame instead of up
    /// to five plus a `.flo`, and a damaged ground-truth file does not cost it a good frame.
    ///
    /// # Panics
    /// If `position >= self.len()` (a programming error, not a data error).
    pub fn read_sensor_frame(&self, position: usize) -> Result<RgbdFrame, CaptureError> {
        let entry = &self.manifest.frames[position];
        let paths = FramePaths::new(&self.root, entry.id);
        let size = Some(self.size());
        let scale = self.manifest.depth_scale;
        let rgb = png::read_rgb(&paths.rgb, size)?;
        let amplitude = png::read_u16(&paths.amplitude, size)?.mapv(f32::from);
        let depth = png::read_depth(&paths.depth, size, scale)?;
        Ok(RgbdFrame {
            perturbation: entry.perturbation,
            ..RgbdFrame::sensor(entry.id, entry.timestamp_ns, rgb, amplitude, depth)
        })
    }
}

fn optional<T>(
    path: &Path,
    read: impl FnOnce(&Path) -> Result<T, CaptureError>,
) -> Result<Option<T>, CaptureError> {
    if path.exists() {
        read(path).map(Some)
    } else {
        Ok(None)
    }
}

/// Deserialises `capture.json` text. A type error names the field it is in (`field
/// `frames[3].timestamp_ns`: invalid type ...`), which serde_json alone reports only as a line
/// and column.
fn parse_manifest(text: &str) -> Result<CaptureManifest, String> {
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
    Ok(manifest)
}

/// Checks the manifest's own consistency; the message names the offending field.
fn validate(m: &CaptureManifest) -> Result<(), String> {
    if m.format != FORMAT_NAME {
        return Err(format!(
            "field `format` is {:?}, expected {FORMAT_NAME:?}",
            m.format
        ));
    }
    if m.version != FORMAT_VERSION {
        return Err(format!(
            "field `version` is {}, this reader supports {FORMAT_VERSION}",
            m.version
        ));
    }
    for (name, side) in [("width", m.width), ("height", m.height)] {
        if side == 0 || side > MAX_SIDE {
            return Err(format!("field `{name}` is {side}, expected 1..={MAX_SIDE}"));
        }
    }
    if !(m.depth_scale > 0.0 && m.depth_scale.is_finite()) {
        return Err(format!(
            "field `depth_scale` is {}, expected a positive number",
            m.depth_scale
        ));
    }
    let k = &m.intrinsics;
    if !(k.fx > 0.0
        && k.fy > 0.0
        && k.fx.is_finite()
        && k.fy.is_finite()
        && k.cx.is_finite()
        && k.cy.is_finite())
    {
        return Err(format!(
            "field `intrinsics` is {k:?}, expected positive finite focal lengths"
        ));
    }
    if let Some(f) = m
        .modulation_frequencies_hz
        .iter()
        .find(|f| !(**f > 0.0 && f.is_finite()))
    {
        return Err(format!(
            "field `modulation_frequencies_hz` contains {f}, expected positive frequencies"
        ));
    }
    // f32 fields take JSON numbers beyond f32 (`1e39`) as infinity; a calibration that is not
    // finite aligns no pixel, so it is refused here, by field, rather than met frame by frame.
    check_calibration("initial_calibration", &m.initial_calibration)?;
    let mut seen = HashSet::new();
    let mut last_time = 0;
    for (i, frame) in m.frames.iter().enumerate() {
        if !seen.insert(frame.id) {
            return Err(format!("frames[{i}].id {} appears twice", frame.id));
        }
        if frame.id > 999_999 {
            return Err(format!(
                "frames[{i}].id {} does not fit the 6-digit file names",
                frame.id
            ));
        }
        if frame.timestamp_ns < last_time {
            return Err(format!(
                "frames[{i}].timestamp_ns {} goes back in time",
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
