//! Opening and validating a capture directory, and reading its frames.

use std::path::{Path, PathBuf};

use crate::error::CaptureError;
use crate::frame::{GroundTruth, RgbdFrame, Sample};
use crate::layout::{FramePaths, MANIFEST_FILE};
use crate::manifest::CaptureManifest;
use crate::{flo, png};

/// The largest `capture.json` read: a manifest takes about 60 bytes a frame, so this is
/// room for about a million frames (15 hours at 20 fps).
pub const MANIFEST_LIMIT: u64 = 64 << 20;

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
        let text = crate::input::read_text_limited(&path, MANIFEST_LIMIT)
            .map_err(|e| CaptureError::io(&path, e))?;
        let manifest = CaptureManifest::from_json(&text)
            .map_err(|message| CaptureError::Manifest { path, message })?;
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

    /// Reads and checks the frame at `position` (0-based index into the manifest's frame list)
    /// with its ground truth: the optional files (ground-truth depth, mask, flow) when present
    /// and the manifest's perturbation. What evaluation and training need.
    ///
    /// # Panics
    /// If `position >= self.len()` (a programming error, not a data error).
    pub fn read_sample(&self, position: usize) -> Result<Sample, CaptureError> {
        let frame = self.read_frame(position)?;
        let paths = self.frame_paths(position);
        let size = Some(self.size());
        let scale = self.manifest.depth_scale;
        let truth = GroundTruth {
            depth: optional(&paths.gt_depth, |p| png::read_depth(p, size, scale))?,
            mask: optional(&paths.mask, |p| png::read_mask(p, size))?,
            flow: optional(&paths.flow, |p| flo::read_flo(p, size))?,
            perturbation: self.manifest.frames[position].perturbation,
        };
        Ok(Sample { frame, truth })
    }

    /// Reads and checks only what a sensor delivers at `position`: RGB, amplitude and depth.
    /// What the daemon's replay needs: it decodes three PNGs a frame instead of up to five plus
    /// a `.flo`, and a damaged ground-truth file does not cost it a good frame.
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
        Ok(RgbdFrame::new(
            entry.id,
            entry.timestamp_ns,
            rgb,
            amplitude,
            depth,
        ))
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
