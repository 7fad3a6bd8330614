//! Edge maps of the RGB image and the ToF amplitude on one scale: what the direct calibration
//! fit ([`direct`](super::direct)) compares at run time, and the edge-matching baseline of the
//! evaluation (`dear_eval::edge_matching`) matches. Colour and near-infrared intensities
//! differ, but object boundaries show in both, so both sides compare gradient magnitudes.

use ndarray::{Array2, ArrayView2, ArrayView3};

/// Luma (BT.601 weights) of an `(H, W, 3)` RGB image.
pub fn rgb_to_gray(rgb: ArrayView3<u8>) -> Array2<f32> {
    let (h, w, _) = rgb.dim();
    Array2::from_shape_fn((h, w), |(y, x)| {
        0.299 * rgb[[y, x, 0]] as f32
            + 0.587 * rgb[[y, x, 1]] as f32
            + 0.114 * rgb[[y, x, 2]] as f32
    })
}

/// Sobel gradient magnitude, normalised by its 99th percentile so both modalities are on one
/// scale; borders are 0.
pub fn gradient_magnitude(img: ArrayView2<f32>) -> Array2<f32> {
    let (h, w) = img.dim();
    let mut g = Array2::<f32>::zeros((h, w));
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let p = |dy: isize, dx: isize| {
                img[[(y as isize + dy) as usize, (x as isize + dx) as usize]]
            };
            let gx = (p(-1, 1) + 2.0 * p(0, 1) + p(1, 1)) - (p(-1, -1) + 2.0 * p(0, -1) + p(1, -1));
            let gy = (p(1, -1) + 2.0 * p(1, 0) + p(1, 1)) - (p(-1, -1) + 2.0 * p(-1, 0) + p(-1, 1));
            g[[y, x]] = (gx * gx + gy * gy).sqrt();
        }
    }
    normalise_by_p99(&mut g, 5);
    g
}

/// Scales an edge map so that its 99th percentile (of the positive values, estimated on every
/// `sample_stride`-th pixel) becomes 1, clipping above: edge maps of different modalities then
/// share one scale. A map with no positive value is left as it is.
pub(crate) fn normalise_by_p99(g: &mut Array2<f32>, sample_stride: usize) {
    let mut sample: Vec<f32> = g
        .iter()
        .step_by(sample_stride)
        .copied()
        .filter(|v| *v > 0.0)
        .collect();
    if sample.is_empty() {
        return;
    }
    let k = (sample.len() * 99 / 100).min(sample.len() - 1);
    let (_, p99, _) = sample.select_nth_unstable_by(k, f32::total_cmp);
    let scale = p99.max(1e-6);
    g.mapv_inplace(|v| (v / scale).min(1.0));
}

/// A scene with a known misalignment for the tests of the calibration fits (here and, with the
/// feature `test-scene`, dear-eval's edge-matching baseline).
#[cfg(any(test, feature = "test-scene"))]
#[doc(hidden)]
pub mod test_scene {
    use ndarray::{Array2, Array3};

    use crate::geometry::synthesize_view;
    use dear_capture::calibration::Calibration;

    /// Discs at several depths in front of a slanted wall, seen by the ToF camera, and the RGB
    /// view of the scene through `truth` (RGB pixel `p` sees ToF pixel `p + W(p)`). RGB and
    /// amplitude share the boundaries but not the interior pattern. Returns `(rgb, amplitude,
    /// depth)`, the last two on the ToF grid.
    pub fn textured_scene(truth: &Calibration) -> (Array3<u8>, Array2<f32>, Array2<f32>) {
        let (h, w) = (160, 220);
        // Discs give edges in every direction (straight edges alone are ambiguous along
        // themselves and are rightly rejected).
        let discs = [
            (40.0, 50.0, 22.0, 0.8f32),
            (110.0, 60.0, 25.0, 1.2),
            (80.0, 150.0, 30.0, 1.8),
            (45.0, 120.0, 15.0, 1.0),
            (125.0, 170.0, 18.0, 1.5),
        ];
        let depth = Array2::from_shape_fn((h, w), |(y, x)| {
            discs
                .iter()
                .find(|(cy, cx, r, _)| (y as f32 - cy).powi(2) + (x as f32 - cx).powi(2) < r * r)
                .map(|d| d.3)
                .unwrap_or(3.0 + 0.002 * x as f32)
        });
        // Amplitude ~ albedo / z², albedo differs per surface; RGB has its own colours plus a
        // stripe pattern that the amplitude lacks.
        let amplitude = depth.mapv(|z| 2000.0 * (0.3 + (z * 7.0).sin().abs()) / (z * z));
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, k)| {
            let z = depth[[y, x]];
            let base = (60.0 + 50.0 * (z * 5.0).cos().abs() * (k as f32 + 1.0)) as u8;
            base.saturating_add(if (x / 5) % 2 == 0 && z > 2.5 { 20 } else { 0 })
        });
        let mut view = synthesize_view(rgb.view(), depth.view(), truth);
        // A real RGB camera has no disocclusion holes: fill them from the farther neighbour
        // along the row (the background that was hidden), as the scene would show.
        for y in 0..h {
            for x in 0..w {
                if !view.valid[[y, x]] {
                    let left = (0..x).rev().find(|&i| view.valid[[y, i]]);
                    let right = (x + 1..w).find(|&i| view.valid[[y, i]]);
                    let src = match (left, right) {
                        (Some(l), Some(r)) => {
                            if view.depth[[y, l]] > view.depth[[y, r]] {
                                l
                            } else {
                                r
                            }
                        }
                        (Some(l), None) => l,
                        (None, Some(r)) => r,
                        (None, None) => continue,
                    };
                    for k in 0..3 {
                        view.rgb[[y, x, k]] = view.rgb[[y, src, k]];
                    }
                }
            }
        }
        (view.rgb, amplitude, depth)
    }

    /// The direct fit of [`textured_scene`]`(truth)` from the identity, with the settings for
    /// real contours (a ToF contour moves with the nearer surface, depth edges added) and one
    /// blur of 1 px at every level: this scene's edges are aliased binary steps, sharper than
    /// any rendered or camera image, and with the defaults' lighter blur (chosen on rendered
    /// views) its fit ended 1.03 px off at the discs' depths.
    #[cfg(test)]
    pub(crate) fn fit_textured_scene(
        truth: &Calibration,
    ) -> crate::recalibration::direct::DirectFit {
        let (rgb, amplitude, depth) = textured_scene(truth);
        let params = crate::recalibration::direct::DirectFitParams {
            contour_radius: 5,
            depth_edge_weight: 1.0,
            blur_sigma: 1.0,
            finest_blur_sigma: None,
            ..crate::recalibration::direct::DirectFitParams::default()
        };
        crate::recalibration::direct::estimate_calibration_direct(
            rgb.view(),
            amplitude.view(),
            depth.view(),
            Calibration::IDENTITY,
            &params,
        )
    }
}
