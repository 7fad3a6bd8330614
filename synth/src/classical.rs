//! Training input for refiners that build on the classical filter (the `hybrid` variant,
//! `train/dear_train/models/kpn.py`): the daemon's own [`ClassicalRefiner`] run on every frame of
//! a capture, written beside it as `frames/NNNNNN.classical.png` (`dear-synth classical`).
//!
//! The planes come from the Rust filter itself, not a Python re-implementation, so a refiner
//! is trained on exactly what the daemon will feed it.

use std::path::Path;

use anyhow::{Context, Result};
use ndarray::Array2;
use rayon::prelude::*;

use dear_capture::{png, CaptureDir};
use dear_pipeline::filter::ClassicalRefiner;

/// Runs the classical refiner (default settings, as the daemon) on every frame of the capture
/// at `root` and writes its output next to the frame; returns the number of frames written.
/// `progress` is called with the number of frames done so far.
///
/// # Errors
/// When the capture cannot be opened, a frame cannot be read (the error names it), or a plane
/// cannot be written.
pub fn write_classical_planes(root: &Path, progress: impl Fn(usize) + Sync) -> Result<usize> {
    let dir = CaptureDir::open(root).with_context(|| format!("opening {}", root.display()))?;
    let scale = dir.manifest().depth_scale;
    let done = std::sync::atomic::AtomicUsize::new(0);
    (0..dir.len()).into_par_iter().try_for_each_init(
        ClassicalRefiner::default,
        |refiner, i| -> Result<()> {
            let frame = dir.read_frame(i)?;
            let (h, w) = frame.depth.dim();
            let mut depth = Array2::zeros((h, w));
            let mut confidence = Array2::zeros((h, w));
            refiner.refine_into(
                frame.depth.view(),
                frame.rgb.view(),
                depth.view_mut(),
                confidence.view_mut(),
            );
            let path = dir.frame_paths(i).classical;
            png::write_depth(&path, depth.view(), scale)
                .with_context(|| format!("writing {}", path.display()))?;
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1);
            Ok(())
        },
    )?;
    Ok(dir.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::{generate, GenerateParams};
    use crate::scene::SceneConfig;
    use crate::simulate::SimConfig;

    #[test]
    fn writes_the_daemon_filter_output_for_every_frame() {
        let tmp = tempfile::tempdir().unwrap();
        let params = GenerateParams {
            width: 48,
            height: 32,
            hfov_deg: 70.0,
            count: 2,
            seed: 3,
            sim: SimConfig::default(),
            scene: SceneConfig::default(),
        };
        generate(tmp.path(), &params, |_| {}).unwrap();
        assert_eq!(write_classical_planes(tmp.path(), |_| {}).unwrap(), 2);
        let dir = CaptureDir::open(tmp.path()).unwrap();
        let scale = dir.manifest().depth_scale;
        for i in 0..2 {
            let frame = dir.read_frame(i).unwrap();
            let on_disk =
                png::read_depth(&dir.frame_paths(i).classical, Some(dir.size()), scale).unwrap();
            let mut want = Array2::zeros(frame.depth.dim());
            let mut conf = Array2::zeros(frame.depth.dim());
            ClassicalRefiner::default().refine_into(
                frame.depth.view(),
                frame.rgb.view(),
                want.view_mut(),
                conf.view_mut(),
            );
            // Equal up to the 16-bit unit of the capture.
            for (a, b) in on_disk.iter().zip(want.iter()) {
                assert!((a - b).abs() <= scale * 0.5 + 1e-6, "{a} vs {b}");
            }
            // The filter changed something (it is not a copy of the input).
            assert!(on_disk
                .iter()
                .zip(frame.depth.iter())
                .any(|(a, b)| (a - b).abs() > scale));
        }
    }
}
