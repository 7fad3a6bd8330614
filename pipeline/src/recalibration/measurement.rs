//! One calibration measurement: a fit of `(t, c)` on one frame, with the numbers the online
//! filter needs to judge it. Two kinds of fit produce one: the robust least squares of a
//! network flow (how much of the flow it explains, and how well), and the direct fit to the
//! frame's edges ([`crate::recalibration::direct`]; how well the RGB and amplitude edges then correlate).

use ndarray::{ArrayView2, Zip};

use crate::geometry::surface::is_valid_depth;
use crate::recalibration::direct::DirectFit;
use crate::recalibration::observability::{Information, Observability, FLOW_PIXELS_PER_SAMPLE};
use crate::recalibration::{solve_calibration_robust, LsqError, RobustOptions};
use dear_capture::calibration::Calibration;
use dear_capture::frame::Flow;

/// A calibration fit of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// The fitted `(t_x, t_y, c_x, c_y)`.
    pub calibration: Calibration,
    /// What the fit rests on, and how well it fits.
    pub evidence: Evidence,
    /// How well the frame constrains each direction of `(t, c)`
    /// ([`crate::recalibration::observability`]); `None` when unknown, which the estimator treats as
    /// constraining every direction.
    pub information: Option<Information>,
}

/// What a [`Measurement`] was fitted to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Evidence {
    /// A dense flow (the rough-flow network's), by robust least squares.
    Flow {
        /// RMS end-point residual over the inliers, px.
        rms_residual_px: f32,
        /// Fraction of the usable pixels whose end-point residual is within the inlier
        /// threshold.
        inlier_fraction: f32,
        /// Usable pixels (valid depth, finite flow).
        pixels_used: usize,
    },
    /// The frame's RGB and amplitude edges, by the direct fit.
    Edges {
        /// Edge-map correlation at the fitted calibration.
        correlation: f32,
        /// Edge-map correlation at the calibration the fit started from.
        initial_correlation: f32,
    },
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
        let (mut sum_a, mut sum_a2) = (0.0f64, 0.0f64);
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
                    let a = f64::from(1.0 / z);
                    sum_a += a;
                    sum_a2 += a * a;
                }
            });
        // The inliers' information, the residual variance per coordinate from their RMS end
        // point error (at least 0.05 px: a flow the model explains exactly is still a network's).
        let rms = if inliers > 0 {
            (sum2 / inliers as f64).sqrt()
        } else {
            f64::INFINITY
        };
        let variance = 0.5 * rms.max(0.05).powi(2);
        let information = Information::of_flow_fit(
            inliers as f64,
            sum_a,
            sum_a2,
            variance,
            FLOW_PIXELS_PER_SAMPLE,
        );
        Ok(Measurement {
            calibration: c,
            information: Some(information),
            evidence: Evidence::Flow {
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
            },
        })
    }

    /// The measurement of a direct fit, `None` when the fit fell back to its starting point
    /// (it then measured nothing).
    pub fn from_direct_fit(fit: &DirectFit) -> Option<Measurement> {
        (!fit.fell_back).then_some(Measurement {
            calibration: fit.calibration,
            information: Some(fit.information),
            evidence: Evidence::Edges {
                correlation: fit.correlation,
                initial_correlation: fit.initial_correlation,
            },
        })
    }

    /// A direct fit that did not beat the calibration in use
    /// ([`crate::recalibration::direct::estimate_calibration_direct_against`] fell back to its reference):
    /// that calibration, constraining nothing (zero information), so that the online estimator
    /// leaves its estimate where it is.
    pub fn keeping_reference(fit: &DirectFit) -> Measurement {
        Measurement {
            calibration: fit.calibration,
            information: Some(Information::ZERO),
            evidence: Evidence::Edges {
                correlation: fit.correlation,
                initial_correlation: fit.initial_correlation,
            },
        }
    }

    /// How well the calibration fits its evidence, in `[0, 1]`: for a flow fit
    /// `inlier_fraction / (1 + rms²)` (rms in px; 1 for a flow the model explains exactly, 0.5
    /// at 1 px RMS), for an edge fit the edge-map correlation (0 when negative).
    pub fn fit_quality(&self) -> f32 {
        let q = match self.evidence {
            Evidence::Flow {
                rms_residual_px,
                inlier_fraction,
                ..
            } => inlier_fraction / (1.0 + rms_residual_px * rms_residual_px),
            Evidence::Edges { correlation, .. } => correlation,
        };
        if q.is_nan() {
            0.0
        } else {
            q.clamp(0.0, 1.0)
        }
    }

    /// What the frame constrains at the threshold `max_std_px` (every direction when the
    /// information is unknown).
    pub fn observability(&self, max_std_px: f32) -> Observability {
        self.information
            .unwrap_or(Information::isotropic(0.0))
            .observability(max_std_px)
    }

    /// The flow fit's inlier RMS end-point residual, px (`None` for an edge fit, which has no
    /// end-point residual).
    pub fn residual_px(&self) -> Option<f32> {
        match self.evidence {
            Evidence::Flow {
                rms_residual_px, ..
            } => Some(rms_residual_px),
            Evidence::Edges { .. } => None,
        }
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
        let Evidence::Flow {
            rms_residual_px,
            inlier_fraction,
            pixels_used,
        } = m.evidence
        else {
            panic!("a flow fit has flow evidence: {m:?}");
        };
        assert!((inlier_fraction - 0.9).abs() < 1e-6, "{inlier_fraction}");
        assert!(rms_residual_px < 0.3, "{rms_residual_px}");
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
        assert_eq!(pixels_used, h * w);
    }
}
