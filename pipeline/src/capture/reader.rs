//! Opening and validating a capture directory, and reading its frames.

use std::collections::HashSet;
use std::fs;
use std::path::{Path, PathBuf};

use super::error::CaptureError;
use super::layout::{FramePaths, MANIFEST_FILE};
use super::manifest::{CaptureManifest, FORMAT_NAME, FORMAT_VERSION};
use super::{flo, png};
use crate::frame::RgbdFrame;

/// Largest accepted image side: guards against a corrupt manifest asking for absurd buffers.
const MAX_SIDE: u32 = 8192;

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
        let manifest: CaptureManifest =
            serde_json::from_str(&text).map_err(|e| CaptureError::Manifest {
                path: path.clone(),
                message: e.to_string(),
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
    /// Optional files (ground truth, mask, flow) are read when present.
    ///
    /// # Panics
    /// If `position >= self.len()` (a programming error, not a data error).
    pub fn read_frame(&self, position: usize) -> Result<RgbdFrame, CaptureError> {
        let entry = &self.manifest.frames[position];
        let paths = FramePaths::new(&self.root, entry.id);
        let size = Some(self.size());
        let scale = self.manifest.depth_scale;
        let rgb = png::read_rgb(&paths.rgb, size)?;
        let amplitude = png::read_u16(&paths.amplitude, size)?.mapv(f32::from);
        let depth = png::read_depth(&paths.depth, size, scale)?;
        let gt_depth = optional(&paths.gt_depth, |p| png::read_depth(p, size, scale))?;
        let mask = optional(&paths.mask, |p| png::read_mask(p, size))?;
        let flow = optional(&paths.flow, |p| flo::read_flo(p, size))?;
        Ok(RgbdFrame {
            index: entry.id,
            timestamp_ns: entry.timestamp_ns,
            rgb,
            amplitude,
            depth,
            gt_depth,
            mask,
            flow,
            perturbation: entry.perturbation,
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
    }
    Ok(())
}
