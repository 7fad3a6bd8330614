//! Analytic test captures: a slanted back wall, a box that slides across it, textured RGB and
//! an amplitude that falls with 1/z². Deterministic, small, written with the real capture
//! writer, so tests need no bundled data.

use std::path::Path;

use dear_capture::{
    Calibration, CaptureDir, CaptureManifest, CaptureWriter, GroundTruth, Intrinsics, RgbdFrame,
};
use ndarray::{Array2, Array3};

/// The factory calibration the tests' captures carry: a few pixels off in every term, so
/// alignment visibly matters.
pub fn factory_calibration() -> Calibration {
    Calibration {
        tx: 4.0,
        ty: 0.5,
        cx: 1.5,
        cy: -1.0,
    }
}

/// Writes `frames` frames of `width`×`height` at 30 fps into `dir`, with a factory calibration
/// of `calibration`.
pub fn write_capture(
    dir: &Path,
    frames: u64,
    width: u32,
    height: u32,
    calibration: Calibration,
) -> CaptureDir {
    let mut writer = writer(dir, frames, width, height, calibration);
    for i in 0..frames {
        writer
            .write_frame(&frame(i, width as usize, height as usize))
            .expect("write test frame");
    }
    writer.finish().expect("finish test capture");
    CaptureDir::open(dir).expect("open test capture")
}

/// An aligned capture of the scene with its ground truth, as `dear-synth generate` writes one:
/// a zero factory calibration, and each frame carrying the noise-free depth ([`true_depth`])
/// and a zero perturbation.
pub fn write_capture_with_ground_truth(
    dir: &Path,
    frames: u64,
    width: u32,
    height: u32,
) -> CaptureDir {
    let (w, h) = (width as usize, height as usize);
    let mut writer = writer(dir, frames, width, height, Calibration::default());
    for i in 0..frames {
        let known = GroundTruth {
            depth: Some(Array2::from_shape_fn((h, w), |(r, c)| {
                true_depth(i, w, h, r, c)
            })),
            perturbation: Some(Calibration::default()),
            ..GroundTruth::default()
        };
        writer
            .write_sample(&frame(i, w, h), &known)
            .expect("write test frame");
    }
    writer.finish().expect("finish test capture");
    CaptureDir::open(dir).expect("open test capture")
}

fn writer(
    dir: &Path,
    frames: u64,
    width: u32,
    height: u32,
    calibration: Calibration,
) -> CaptureWriter {
    let mut manifest =
        CaptureManifest::new(width, height, Intrinsics::from_hfov(width, height, 70.0));
    manifest.initial_calibration = calibration;
    manifest.source = serde_json::Value::String(format!("analytic test scene, {frames} frames"));
    CaptureWriter::create(dir, manifest).expect("create test capture")
}

/// The noise-free depth of frame `i` at pixel `(r, c)`: the ground truth of [`frame`].
pub fn true_depth(i: u64, w: usize, h: usize, r: usize, c: usize) -> f32 {
    let box_left = (w as f32 * 0.2 + i as f32 * 2.0) as usize % (w / 2);
    let in_box = (box_left..box_left + w / 4).contains(&c) && (h / 3..2 * h / 3).contains(&r);
    if in_box {
        0.9
    } else {
        2.5 + 0.004 * c as f32 - 0.002 * r as f32
    }
}

/// Frame `i` of the scene.
pub fn frame(i: u64, w: usize, h: usize) -> RgbdFrame {
    let depth_at = |r: usize, c: usize| true_depth(i, w, h, r, c);
    let depth = Array2::from_shape_fn((h, w), |(r, c)| {
        // A deterministic "noise" pattern and a few invalid pixels, as a real sensor has.
        let noise = (((r * 31 + c * 17 + i as usize * 7) % 13) as f32 - 6.0) * 0.002;
        if (r * 7 + c * 3 + i as usize).is_multiple_of(97) {
            0.0
        } else {
            depth_at(r, c) + noise
        }
    });
    let rgb = Array3::from_shape_fn((h, w, 3), |(r, c, k)| {
        let checker = ((r / 8 + c / 8) % 2) as u8;
        let base: u8 = if depth_at(r, c) < 1.0 { 150 } else { 60 };
        base.wrapping_add(40 * checker + 15 * k as u8)
            .wrapping_add(i as u8)
    });
    let amplitude = depth.mapv(|z| {
        if z > 0.0 {
            (3000.0 / (z * z)).min(65535.0)
        } else {
            0.0
        }
    });
    RgbdFrame::new(i, i * 33_333_333, rgb, amplitude, depth)
}
