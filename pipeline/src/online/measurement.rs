//! One calibration measurement: a robust fit of `(t, c)` to a network flow, with the numbers
//! the online filter needs to judge it (how much of the flow it explains, and how well).

use ndarray::{ArrayView2, Zip};

use crate::calibration::Calibration;
use crate::frame::Flow;
use crate::geometry::surface::is_valid_depth;
use crate::geometry::{solve_calibration_robust, LsqError, RobustOptions};

/// A robust calibration fit of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// The fitted `(t_x, t_y, c_x, c_y)`.
    pub calibration: Calibration,
    /// RMS end-point residual over the inliers, px.
    pub rms_residual_px: f32,
    /// Fraction of the usable pixels whose end-point residual is within the inlier threshold.
    pub inlier_fraction: f32,
    /// Usable pixels (valid depth, finite flow).
    pub pixels_used: usize,
}

impl Measurement {
    /// Fits `(t, c)` to `flow` against the depth seen on the RGB grid (`D_rgb`) with Huber IRLS
    /// ([`solve_calibration_robust`]: invalid depths are masked, outlier flow vectors are
    /// down-weighted), then counts the inliers (end-point residual ≤ `inlier_threshold_px`)
    /// and their RMS residual.
    ///
    /// # Errors
    /// The fit's [`LsqError`] (too few pixels, all at one depth, zero weight).
    ///
    /// # Panics
    /// If the flow and the depth shapes differ.
    pub fn from_flow(
        flow: &Flow,
        depth: ArrayView2<f32>,
        robust: RobustOptions,
        inlier_threshold_px: f32,
    ) -> Result<Measurement, LsqError> {
        let fit = solve_calibration_robust(flow, depth, None, robust)?;
        let c = fit.calibration;
        let (mut used, mut inliers, mut sum2) = (0usize, 0usize, 0.0f64);
        Zip::from(&depth)
            .and(&flow.u)
            .and(&flow.v)
            .for_each(|&z, &u, &v| {
                if !is_valid_depth(z) || !u.is_finite() || !v.is_finite() {
                    return;
                }
                used += 1;
                let (pu, pv) = (c.tx / z + c.cx, c.ty / z + c.cy);
                let r = ((u - pu) * (u - pu) + (v - pv) * (v - pv)).sqrt();
                if r <= inlier_threshold_px {
                    inliers += 1;
                    sum2 += f64::from(r * r);
                }
            });
        Ok(Measurement {
            calibration: c,
            rms_residual_px: if inliers > 0 {
                (sum2 / inliers as f64).sqrt() as f32
            } else {
                f32::INFINITY
            },
            inlier_fraction: if used > 0 {
                inliers as f32 / used as f32
            } else {
                0.0
            },
            pixels_used: used,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    #[test]
    fn outlier_vectors_are_counted_and_do_not_bias_the_fit() {
        let truth = Calibration {
            tx: 8.0,
            ty: -3.0,
            cx: 2.0,
            cy: 1.0,
        };
        let (h, w) = (40, 50);
        let depth = Array2::from_shape_fn((h, w), |(y, x)| {
            0.8 + 3.0 * ((x * 7 + y * 13) % 31) as f32 / 30.0
        });
        let mut flow = Flow {
            u: depth.mapv(|z| truth.tx / z + truth.cx),
            v: depth.mapv(|z| truth.ty / z + truth.cy),
        };
        // 10 % of the vectors are wildly wrong (an occluder the network got wrong).
        for y in 0..4 {
            for x in 0..w {
                flow.u[[y, x]] += 25.0;
                flow.v[[y, x]] -= 15.0;
            }
        }
        let m = Measurement::from_flow(&flow, depth.view(), RobustOptions::default(), 3.0).unwrap();
        assert!(
            (m.inlier_fraction - 0.9).abs() < 1e-6,
            "{}",
            m.inlier_fraction
        );
        assert!(m.rms_residual_px < 0.3, "{}", m.rms_residual_px);
        assert!(
            (m.calibration.cx - truth.cx).abs() < 0.3,
            "{:?}",
            m.calibration
        );
        assert!(
            (m.calibration.tx - truth.tx).abs() < 0.6,
            "{:?}",
            m.calibration
        );
        assert_eq!(m.pixels_used, h * w);
    }
}
