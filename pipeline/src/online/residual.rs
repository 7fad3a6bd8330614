//! A cheap per-frame alignment check for frames that do not run the rough-flow network.
//!
//! The RGB image and the ToF amplitude see the same surface markings and the same object
//! outlines, so once the amplitude is warped onto the RGB grid their edges coincide when the
//! alignment is right and drift apart when the calibration has moved. The signal is
//! `1 − NCC(|∇L|, |∇A_w|)`, the normalised cross-correlation of the gradient magnitudes of the
//! RGB luma `L` and the warped amplitude `A_w`, on a stride-2 grid of pixels whose warped depth
//! and its 4 neighbours are valid. Its absolute value depends on the scene (RGB and IR textures
//! differ), so the online estimator compares it with the value measured right after the last
//! network estimate, not with a fixed threshold.

use ndarray::{ArrayView2, ArrayView3};

use crate::geometry::surface::is_valid_depth;

/// Fewest sampled pixels for a meaningful correlation.
pub const MIN_SAMPLES: usize = 64;

/// `1 − NCC` of the gradient magnitudes (0 = edges agree perfectly, 1 = uncorrelated, up to 2),
/// or `None` when fewer than [`MIN_SAMPLES`] pixels qualify or either image is flat there.
///
/// Images of different shapes give `None`.
pub fn edge_disagreement(
    rgb: ArrayView3<u8>,
    warped_amplitude: ArrayView2<f32>,
    warped_depth: ArrayView2<f32>,
) -> Option<f32> {
    let (h, w) = warped_depth.dim();
    if rgb.dim() != (h, w, 3) || warped_amplitude.dim() != (h, w) || h < 3 || w < 3 {
        return None;
    }
    let luma = |y: usize, x: usize| {
        0.299 * f64::from(rgb[[y, x, 0]])
            + 0.587 * f64::from(rgb[[y, x, 1]])
            + 0.114 * f64::from(rgb[[y, x, 2]])
    };
    let (mut n, mut sa, mut sb, mut saa, mut sbb, mut sab) = (0usize, 0.0, 0.0, 0.0, 0.0, 0.0);
    for y in (1..h - 1).step_by(2) {
        for x in (1..w - 1).step_by(2) {
            let ok = [(y, x), (y - 1, x), (y + 1, x), (y, x - 1), (y, x + 1)]
                .iter()
                .all(|&p| is_valid_depth(warped_depth[p]));
            if !ok {
                continue;
            }
            let gl =
                (luma(y, x + 1) - luma(y, x - 1)).hypot(luma(y + 1, x) - luma(y - 1, x)) / 255.0;
            let a = |yy: usize, xx: usize| f64::from(warped_amplitude[[yy, xx]]);
            let ga = (a(y, x + 1) - a(y, x - 1)).hypot(a(y + 1, x) - a(y - 1, x));
            if !ga.is_finite() {
                continue;
            }
            n += 1;
            sa += gl;
            sb += ga;
            saa += gl * gl;
            sbb += ga * ga;
            sab += gl * ga;
        }
    }
    if n < MIN_SAMPLES {
        return None;
    }
    let nf = n as f64;
    let va = saa / nf - (sa / nf).powi(2);
    let vb = sbb / nf - (sb / nf).powi(2);
    let cov = sab / nf - sa * sb / (nf * nf);
    if !(va > 1e-12 && vb > 1e-12) {
        return None;
    }
    Some((1.0 - cov / (va.sqrt() * vb.sqrt())) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, Array3};

    fn texture(y: usize, x: usize, shift: usize) -> f32 {
        let xs = x + shift;
        (((xs / 5) + (y / 7)) % 2) as f32 * 0.6 + 0.2 * ((xs * 3 + y) % 11) as f32 / 10.0
    }

    #[test]
    fn aligned_edges_agree_and_shifted_ones_do_not() {
        let (h, w) = (60, 80);
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, _)| (texture(y, x, 0) * 255.0) as u8);
        let depth = Array2::from_elem((h, w), 2.0f32);
        let aligned = Array2::from_shape_fn((h, w), |(y, x)| texture(y, x, 0));
        let shifted = Array2::from_shape_fn((h, w), |(y, x)| texture(y, x, 3));
        let good = edge_disagreement(rgb.view(), aligned.view(), depth.view()).unwrap();
        let bad = edge_disagreement(rgb.view(), shifted.view(), depth.view()).unwrap();
        assert!(good < 0.05, "aligned: {good}");
        assert!(bad > good + 0.3, "aligned {good}, shifted {bad}");
        // No valid depth: no signal.
        let none = Array2::zeros((h, w));
        assert_eq!(
            edge_disagreement(rgb.view(), aligned.view(), none.view()),
            None
        );
    }
}
