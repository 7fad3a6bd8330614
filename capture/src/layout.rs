//! Where each file of a frame lives inside a capture directory.

use std::path::{Path, PathBuf};

/// Name of the manifest file.
pub const MANIFEST_FILE: &str = "capture.json";
/// Sub-directory holding the per-frame files.
pub const FRAMES_DIR: &str = "frames";

/// The paths of one frame's files (`frames/NNNNNN.<kind>.<ext>`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FramePaths {
    pub rgb: PathBuf,
    pub amplitude: PathBuf,
    pub depth: PathBuf,
    pub gt_depth: PathBuf,
    pub mask: PathBuf,
    pub flow: PathBuf,
    /// The classical refiner's output for the frame's depth (training input of refiners that
    /// take it; `dear-synth classical`), 16-bit like the depth.
    pub classical: PathBuf,
}

impl FramePaths {
    /// The files of frame `id` in the capture directory `root`.
    pub fn new(root: &Path, id: u64) -> Self {
        let dir = root.join(FRAMES_DIR);
        let file = |suffix: &str| dir.join(format!("{id:06}.{suffix}"));
        FramePaths {
            rgb: file("rgb.png"),
            amplitude: file("amp.png"),
            depth: file("depth.png"),
            gt_depth: file("gt.png"),
            mask: file("mask.png"),
            flow: file("flow.flo"),
            classical: file("classical.png"),
        }
    }
}
