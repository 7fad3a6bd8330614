//! The preview panel (`dear-synth preview`): RGB | amplitude | ToF depth | ground truth | error.
//!
//! ToF depth and ground truth share one colour scale (`dear_picture`'s depth map, the same as
//! the SDK's previews and `dear eval`'s figures; from the 1st to the 99th
//! percentile of the valid ground truth), so equal colours mean equal depths; invalid pixels are
//! black. The error map is ToF − ground truth on the same pixel, blue (too near) – white – red
//! (too far), saturating at ±`error_range_m`; on a misaligned frame it shows the misalignment
//! as well as the ToF errors. Amplitude is shown as `√(a / a₉₉)` (grey).

use dear_picture::{depth_turbo, diverging, INVALID};
use dear_pipeline::RgbdFrame;
use image::{imageops, RgbImage};
use ndarray::Array2;

/// The `q`-quantile of the values passing `keep` (nearest rank, [`dear_stats`]).
fn quantile(a: &Array2<f32>, q: f64, keep: impl Fn(f32) -> bool) -> Option<f32> {
    let mut v: Vec<f32> = a.iter().copied().filter(|&x| keep(x)).collect();
    dear_stats::select_percentile(&mut v, q)
}

fn map_image(a: &Array2<f32>, f: impl Fn(f32) -> [u8; 3]) -> RgbImage {
    let (h, w) = a.dim();
    RgbImage::from_fn(w as u32, h as u32, |x, y| {
        image::Rgb(f(a[(y as usize, x as usize)]))
    })
}

/// Builds the five-panel preview of a frame, each panel scaled by `scale`.
pub fn panel(frame: &RgbdFrame, error_range_m: f32, scale: f64) -> RgbImage {
    let (h, w) = frame.dim();
    let gt = frame
        .gt_depth
        .clone()
        .unwrap_or_else(|| frame.depth.clone());
    let valid = dear_pipeline::is_valid_depth;
    let lo = quantile(&gt, 0.01, valid).unwrap_or(0.0);
    let hi = quantile(&gt, 0.99, valid).unwrap_or(1.0).max(lo + 1e-3);
    let depth_colour = |z: f32| {
        if valid(z) {
            depth_turbo(((z - lo) / (hi - lo)) as f64)
        } else {
            INVALID
        }
    };
    let a99 = quantile(&frame.amplitude, 0.99, |a| a > 0.0)
        .unwrap_or(1.0)
        .max(1e-6);
    let rgb = RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let (x, y) = (x as usize, y as usize);
        image::Rgb([0, 1, 2].map(|c| frame.rgb[(y, x, c)]))
    });
    let amp = map_image(&frame.amplitude, |a| {
        let g = ((a / a99).max(0.0).sqrt().min(1.0) * 255.0) as u8;
        [g, g, g]
    });
    let tof = map_image(&frame.depth, depth_colour);
    let gtimg = map_image(&gt, depth_colour);
    let err = Array2::from_shape_fn((h, w), |p| {
        if valid(frame.depth[p]) && valid(gt[p]) {
            frame.depth[p] - gt[p]
        } else {
            f32::NAN
        }
    });
    let errimg = map_image(&err, |e| {
        if e.is_nan() {
            [0, 0, 0]
        } else {
            diverging((e / error_range_m) as f64)
        }
    });
    let (pw, ph) = (
        ((w as f64 * scale).round() as u32).max(1),
        ((h as f64 * scale).round() as u32).max(1),
    );
    let gap = 4u32;
    let mut out = RgbImage::from_pixel(5 * pw + 4 * gap, ph, image::Rgb([255, 255, 255]));
    for (i, img) in [rgb, amp, tof, gtimg, errimg].into_iter().enumerate() {
        let img = if (pw, ph) == (w as u32, h as u32) {
            img
        } else {
            imageops::resize(&img, pw, ph, imageops::FilterType::Triangle)
        };
        imageops::replace(&mut out, &img, (i as u32 * (pw + gap)) as i64, 0);
    }
    out
}
