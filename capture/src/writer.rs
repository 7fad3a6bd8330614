//! Creating a capture directory frame by frame (simulator, `dear dump`, `perturb`).

use std::fs;
use std::path::{Path, PathBuf};

use crate::error::CaptureError;
use crate::frame::{GroundTruth, RgbdFrame};
use crate::layout::{FramePaths, FRAMES_DIR, MANIFEST_FILE};
use crate::manifest::{CaptureManifest, FrameEntry};
use crate::{flo, png};

/// Writes frames into a new capture directory; [`CaptureWriter::finish`] writes the manifest.
/// The manifest is written last (atomically), so a directory with a `capture.json` is complete.
#[derive(Debug)]
pub struct CaptureWriter {
    root: PathBuf,
    manifest: CaptureManifest,
}

impl CaptureWriter {
    /// Creates `root` (which must not exist, or be empty) and its `frames/` folder. The
    /// manifest's frame list is replaced by the frames written.
    pub fn create(
        root: impl AsRef<Path>,
        mut manifest: CaptureManifest,
    ) -> Result<Self, CaptureError> {
        let root = root.as_ref().to_owned();
        if root.exists() {
            let mut entries = fs::read_dir(&root).map_err(|e| CaptureError::io(&root, e))?;
            if entries.next().is_some() {
                return Err(CaptureError::Format {
                    path: root,
                    expected: "a new or empty directory".into(),
                    found: "a directory with files in it".into(),
                });
            }
        }
        let frames = root.join(FRAMES_DIR);
        fs::create_dir_all(&frames).map_err(|e| CaptureError::io(&frames, e))?;
        manifest.frames.clear();
        Ok(CaptureWriter { root, manifest })
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Frames written so far.
    pub fn len(&self) -> usize {
        self.manifest.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.manifest.frames.is_empty()
    }

    /// Writes one frame's sensor planes and lists it in the manifest (a recording: no ground
    /// truth).
    pub fn write_frame(&mut self, frame: &RgbdFrame) -> Result<(), CaptureError> {
        self.write_sample(frame, &GroundTruth::default())
    }

    /// Writes one frame's files, the ground truth's when present, and lists it in the
    /// manifest with its perturbation.
    pub fn write_sample(
        &mut self,
        frame: &RgbdFrame,
        truth: &GroundTruth,
    ) -> Result<(), CaptureError> {
        let paths = FramePaths::new(&self.root, frame.index);
        let (h, w) = frame.dim();
        let expected = (self.manifest.width, self.manifest.height);
        if (w as u32, h as u32) != expected {
            return Err(CaptureError::resolution(
                &paths.depth,
                expected,
                (w as u32, h as u32),
            ));
        }
        if let Some(last) = self.manifest.frames.last() {
            if frame.index <= last.id || frame.timestamp_ns < last.timestamp_ns {
                return Err(CaptureError::Format {
                    path: paths.depth,
                    expected: format!("a frame after id {} at {} ns", last.id, last.timestamp_ns),
                    found: format!("id {} at {} ns", frame.index, frame.timestamp_ns),
                });
            }
        }
        let scale = self.manifest.depth_scale;
        png::write_rgb(&paths.rgb, frame.rgb.view())?;
        png::write_amplitude(&paths.amplitude, frame.amplitude.view())?;
        png::write_depth(&paths.depth, frame.depth.view(), scale)?;
        if let Some(gt) = &truth.depth {
            png::write_depth(&paths.gt_depth, gt.view(), scale)?;
        }
        if let Some(mask) = &truth.mask {
            png::write_mask(&paths.mask, mask.view())?;
        }
        if let Some(flow) = &truth.flow {
            flo::write_flo(&paths.flow, flow)?;
        }
        self.manifest.frames.push(FrameEntry {
            id: frame.index,
            timestamp_ns: frame.timestamp_ns,
            perturbation: truth.perturbation,
        });
        Ok(())
    }

    /// Writes `capture.json` listing the frames written so far (via a temporary file and a
    /// rename, so a reader sees the old or the new list, never half of one): a recording that
    /// does this now and then stays replayable up to its last update if its writer dies.
    pub fn write_manifest(&self) -> Result<(), CaptureError> {
        let path = self.root.join(MANIFEST_FILE);
        let tmp = self.root.join(format!("{MANIFEST_FILE}.tmp"));
        // What the reader would refuse is not written: a bad manifest (a side of 0, a frame id
        // past the 6-digit names) is the writer's error, named now, not the next reader's.
        self.manifest
            .validate()
            .map_err(|message| CaptureError::Encode {
                path: path.clone(),
                message,
            })?;
        let text =
            serde_json::to_string_pretty(&self.manifest).map_err(|e| CaptureError::Encode {
                path: path.clone(),
                message: e.to_string(),
            })?;
        fs::write(&tmp, text).map_err(|e| CaptureError::io(&tmp, e))?;
        fs::rename(&tmp, &path).map_err(|e| CaptureError::io(&path, e))
    }

    /// Writes `capture.json` (via a temporary file and a rename) and returns the directory.
    pub fn finish(self) -> Result<PathBuf, CaptureError> {
        self.write_manifest()?;
        Ok(self.root)
    }
}
