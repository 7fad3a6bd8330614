//! The paper's least squares for the weak calibration (DEAR §3, step 4).
//!
//! Per axis, over the pixels with valid depth and positive weight,
//! `min Σ w_p (W_x(p) − (t_x / D(p) + c_x))²` (and the same for y): a line fit of the flow
//! against inverse depth `a = 1/D`. The closed form of the 2×2 normal equations is computed
//! centred (weighted means first, then the weighted covariance), in f64, so that a million
//! pixels at similar depths do not lose the slope to cancellation:
//! `t = Σw(a−ā)(W−W̄) / Σw(a−ā)²`, `c = W̄ − t·ā`.
//!
//! When the inverse depths barely vary (a wall facing the camera) `t` and `c` cannot be told
//! apart. That is reported as [`LsqError::Degenerate`], which carries the weighted means so a
//! caller that knows `t` (the daemon's filtered estimate) can still update the offsets with
//! `c = W̄ − t·ā`. There is no silent fallback to `t = 0`.

use ndarray::ArrayView2;
use thiserror::Error;

use crate::geometry::surface::is_valid_depth;
use dear_capture::calibration::Calibration;
use dear_capture::frame::Flow;

/// Fewest usable pixels for a fit: two unknowns per axis, plus one so the residual means
/// something.
pub const MIN_PIXELS: usize = 3;

/// Smallest relative spread of inverse depth, `std(1/D) / mean(1/D)`, for which `t` and `c`
/// are separable. Below it the slope is set by f32 rounding of the depths, not by geometry.
pub const MIN_REL_INV_DEPTH_SPREAD: f64 = 1e-4;

/// A solved calibration and how well it explains the flow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationFit {
    /// The fitted `(t_x, t_y, c_x, c_y)`.
    pub calibration: Calibration,
    /// Weighted RMS end-point residual `sqrt(Σ w |W − Ŵ|² / Σ w)`, px, over the pixels used,
    /// with the caller's weights (not the robust ones).
    pub rms_residual_px: f32,
    /// Pixels that entered the fit (valid depth, finite flow, positive weight).
    pub pixels_used: usize,
}

/// Why no calibration could be fitted.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LsqError {
    /// Fewer usable pixels than [`MIN_PIXELS`].
    #[error("too few pixels for the calibration fit: {used} usable, at least {required} needed")]
    TooFewPixels {
        /// Usable pixels found.
        used: usize,
        /// [`MIN_PIXELS`].
        required: usize,
    },
    /// All usable pixels are at (nearly) the same depth, so the baseline `t` and the offset `c`
    /// are not separable. With a known `t`, the offsets are `c = mean_flow − t · mean_inv_depth`.
    #[error(
        "degenerate calibration fit: inverse depth spread {rel_inv_depth_spread:.2e} (relative) \
         over {pixels} pixels is too small to separate baseline t from offset c"
    )]
    Degenerate {
        /// `std(1/D) / mean(1/D)` over the usable pixels.
        rel_inv_depth_spread: f64,
        /// Weighted mean of `1/D`, 1/m.
        mean_inv_depth: f32,
        /// Weighted mean flow `(u, v)`, px.
        mean_flow: (f32, f32),
        /// Usable pixels.
        pixels: usize,
    },
    /// The input contained nothing finite to weigh (all weights zero or non-finite sums).
    #[error("calibration fit: total weight is zero or not finite")]
    ZeroWeight,
}

/// Settings of [`solve_calibration_robust`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobustOptions {
    /// Huber threshold on the end-point residual, px: residuals below it count fully, above it
    /// with weight `δ/r` (bounded influence).
    pub huber_delta_px: f32,
    /// Maximum reweighting iterations after the initial least-squares fit; stops earlier once
    /// the flow prediction changes by less than 1e-5 px.
    pub iterations: usize,
    /// The fit uses at most about this many pixels: a regular grid of every `k`-th row and
    /// column, `k` the smallest that brings the frame's pixel count under it (`0`: every
    /// pixel). Four numbers do not need 307,200 equations, and the reweighting passes over
    /// every pixel of a 640×480 flow were a third of a network measurement's time.
    pub max_samples: usize,
}

impl Default for RobustOptions {
    /// δ = 1 px (the scale of a good flow network's error), 20 iterations, at most 40,000
    /// pixels (every 3rd row and column at 640×480, every 2nd at 320×240).
    fn default() -> Self {
        RobustOptions {
            huber_delta_px: 1.0,
            iterations: 20,
            max_samples: 40_000,
        }
    }
}

impl RobustOptions {
    /// The grid step for an `h × w` flow: the smallest `k` with `⌈h/k⌉·⌈w/k⌉ ≤ max_samples`.
    pub fn sample_step(&self, (h, w): (usize, usize)) -> usize {
        if self.max_samples == 0 {
            return 1;
        }
        (1..)
            .find(|&k| h.div_ceil(k) * w.div_ceil(k) <= self.max_samples)
            .unwrap_or(1)
    }
}

/// One usable pixel of a fit: its inverse depth (`1 / z` in f64), depth,
/// flow and the caller's weight.
#[derive(Debug, Clone, Copy)]
struct Sample {
    a: f64,
    z: f32,
    u: f32,
    v: f32,
    w: f32,
}

/// The usable pixels of every `step`-th row and column, in row-major order.
fn gather(
    flow: &Flow,
    depth: &ArrayView2<f32>,
    weights: Option<&ArrayView2<f32>>,
    step: usize,
) -> Vec<Sample> {
    let mut samples = Vec::new();
    for (y, row) in depth.outer_iter().enumerate().step_by(step) {
        for (x, &z) in row.iter().enumerate().step_by(step) {
            let (u, v) = (flow.u[(y, x)], flow.v[(y, x)]);
            let w = weights.map_or(1.0, |w| w[(y, x)]);
            if usable(z, u, v, w).is_some() {
                let a = 1.0 / z as f64;
                samples.push(Sample { a, z, u, v, w });
            }
        }
    }
    samples
}

/// Weighted moments of the samples with the per-sample weight `weight_at(sample)`, centred in
/// two passes (means first, then the covariances). The weights are computed once into `weights`
/// (both passes read them; a Huber weight costs a division, a square root and the model's flow).
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn sample_moments(
    samples: &[Sample],
    weights: &mut Vec<f32>,
    weight_at: impl Fn(&Sample) -> f32,
) -> Moments {
    weights.clear();
    weights.extend(samples.iter().map(weight_at));
    let (mut n, mut sw, mut sa, mut su, mut sv) = (0usize, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (s, &w) in samples.iter().zip(weights.iter()) {
        if let Some(w) = usable(s.z, s.u, s.v, w) {
            n += 1;
            sw += w;
            sa += w * s.a;
            su += w * s.u as f64;
            sv += w * s.v as f64;
        }
    }
    let (mean_a, mean_u, mean_v) = if sw > 0.0 {
        (sa / sw, su / sw, sv / sw)
    } else {
        (0.0, 0.0, 0.0)
    };
    let (mut saa, mut sau, mut sav) = (0.0f64, 0.0f64, 0.0f64);
    for (s, &w) in samples.iter().zip(weights.iter()) {
        if let Some(w) = usable(s.z, s.u, s.v, w) {
            let da = s.a - mean_a;
            saa += w * da * da;
            sau += w * da * (s.u as f64 - mean_u);
            sav += w * da * (s.v as f64 - mean_v);
        }
    }
    Moments {
        n,
        sw,
        mean_a,
        mean_u,
        mean_v,
        saa,
        sau,
        sav,
    }
}

/// Weighted sums over the usable pixels, centred in two passes.
struct Moments {
    n: usize,
    sw: f64,
    mean_a: f64,
    mean_u: f64,
    mean_v: f64,
    saa: f64,
    sau: f64,
    sav: f64,
}

fn check_shapes(flow: &Flow, depth: &ArrayView2<f32>, weights: Option<&ArrayView2<f32>>) {
    assert_eq!(
        flow.u.dim(),
        depth.dim(),
        "solve_calibration: flow u and depth shapes differ"
    );
    assert_eq!(
        flow.v.dim(),
        depth.dim(),
        "solve_calibration: flow v and depth shapes differ"
    );
    if let Some(w) = weights {
        assert_eq!(
            w.dim(),
            depth.dim(),
            "solve_calibration: weights and depth shapes differ"
        );
    }
}

/// The weight of one pixel, or `None` when it does not enter the fit.
#[inline]
fn usable(z: f32, u: f32, v: f32, w: f32) -> Option<f64> {
    (is_valid_depth(z) && u.is_finite() && v.is_finite() && w > 0.0 && w.is_finite())
        .then_some(w as f64)
}

fn solve_moments(m: &Moments) -> Result<Calibration, LsqError> {
    if m.n < MIN_PIXELS {
        return Err(LsqError::TooFewPixels {
            used: m.n,
            required: MIN_PIXELS,
        });
    }
    if !(m.sw > 0.0 && m.sw.is_finite()) {
        return Err(LsqError::ZeroWeight);
    }
    let rel_spread = (m.saa / m.sw).sqrt() / m.mean_a;
    // NaN (no spread at all, 0/0) counts as degenerate too.
    if rel_spread.is_nan() || rel_spread < MIN_REL_INV_DEPTH_SPREAD {
        return Err(LsqError::Degenerate {
            rel_inv_depth_spread: rel_spread,
            mean_inv_depth: m.mean_a as f32,
            mean_flow: (m.mean_u as f32, m.mean_v as f32),
            pixels: m.n,
        });
    }
    let tx = m.sau / m.saa;
    let ty = m.sav / m.saa;
    Ok(Calibration {
        tx: tx as f32,
        ty: ty as f32,
        cx: (m.mean_u - tx * m.mean_a) as f32,
        cy: (m.mean_v - ty * m.mean_a) as f32,
    })
}

/// End-point residual of the model at one pixel, px.
#[inline]
fn residual(c: &Calibration, z: f32, u: f32, v: f32) -> f32 {
    let (pu, pv) = c.flow_at(z).unwrap_or((0.0, 0.0));
    // sqrt, not hypot (per pixel and iteration; flows are far from overflowing).
    let (du, dv) = (u - pu, v - pv);
    (du * du + dv * dv).sqrt()
}

/// Weighted RMS end-point residual of `c` over the samples, with the caller's weights.
fn rms_residual(c: &Calibration, samples: &[Sample]) -> f32 {
    let (mut se, mut sw) = (0.0f64, 0.0f64);
    for s in samples {
        let r = residual(c, s.z, s.u, s.v) as f64;
        se += s.w as f64 * r * r;
        sw += s.w as f64;
    }
    if sw > 0.0 {
        (se / sw).sqrt() as f32
    } else {
        0.0
    }
}

/// Least-squares fit of `(t_x, t_y, c_x, c_y)` to a flow on the RGB grid and the depth seen
/// there (`D_rgb`), optionally weighted per pixel (a mask is a 0/1 weight).
///
/// Pixels with invalid depth (`≤ 0` or non-finite), non-finite flow, or non-positive /
/// non-finite weight are skipped.
///
/// # Errors
/// [`LsqError::TooFewPixels`], [`LsqError::Degenerate`] (all depths nearly equal) or
/// [`LsqError::ZeroWeight`].
///
/// # Panics
/// If the flow, depth and weights do not share one shape.
pub fn solve_calibration(
    flow: &Flow,
    depth: ArrayView2<f32>,
    weights: Option<ArrayView2<f32>>,
) -> Result<CalibrationFit, LsqError> {
    check_shapes(flow, &depth, weights.as_ref());
    let samples = gather(flow, &depth, weights.as_ref(), 1);
    let m = sample_moments(&samples, &mut Vec::new(), |s| s.w);
    let calibration = solve_moments(&m)?;
    Ok(CalibrationFit {
        calibration,
        rms_residual_px: rms_residual(&calibration, &samples),
        pixels_used: m.n,
    })
}

/// [`solve_calibration`] made robust to gross flow errors by iteratively reweighted least
/// squares with Huber weights on the *end-point* residual (a flow vector that is wrong is
/// usually wrong in both components, so both axes drop it together).
///
/// Starts from the plain least-squares fit; each iteration multiplies the caller's weight by
/// `min(1, δ/r)` with `r` the current end-point residual. The Huber objective is convex, so the
/// iteration converges to its unique minimum; an outlier's pull on the estimate is bounded by
/// `δ` (with a fraction `f` of one-sided outliers, by about `f·δ/(1−f)` px).
///
/// # Errors
/// As [`solve_calibration`]; a degenerate reweighted problem reports the same errors.
///
/// # Panics
/// If the flow, depth and weights do not share one shape.
pub fn solve_calibration_robust(
    flow: &Flow,
    depth: ArrayView2<f32>,
    weights: Option<ArrayView2<f32>>,
    options: RobustOptions,
) -> Result<CalibrationFit, LsqError> {
    check_shapes(flow, &depth, weights.as_ref());
    // The usable pixels of the sampling grid, gathered once: every pass below reads only them.
    let step = options.sample_step(depth.dim());
    let samples = gather(flow, &depth, weights.as_ref(), step);
    let mut weights = Vec::with_capacity(samples.len());
    let mut calibration = solve_moments(&sample_moments(&samples, &mut weights, |s| s.w))?;
    let delta = options.huber_delta_px.max(f32::MIN_POSITIVE);
    // Range of inverse depth, to measure convergence as a change of the predicted flow.
    let (mut a_min, mut a_max) = (f32::INFINITY, 0.0f32);
    for &z in depth.iter().filter(|&&z| is_valid_depth(z)) {
        a_min = a_min.min(1.0 / z);
        a_max = a_max.max(1.0 / z);
    }
    for _ in 0..options.iterations {
        let c = calibration;
        let m = sample_moments(&samples, &mut weights, |s| {
            let r = residual(&c, s.z, s.u, s.v);
            if r > delta {
                s.w * (delta / r)
            } else {
                s.w
            }
        });
        let next = solve_moments(&m)?;
        let change = [a_min, a_max]
            .iter()
            .map(|&a| {
                let du = (next.tx - c.tx) * a + (next.cx - c.cx);
                let dv = (next.ty - c.ty) * a + (next.cy - c.cy);
                du.hypot(dv)
            })
            .fold(0.0f32, f32::max);
        calibration = next;
        if change < 1e-5 {
            break;
        }
    }
    Ok(CalibrationFit {
        calibration,
        rms_residual_px: rms_residual(&calibration, &samples),
        pixels_used: samples.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    const TRUE: Calibration = Calibration {
        tx: 12.0,
        ty: -4.0,
        cx: 3.5,
        cy: -1.25,
    };

    /// A scene with depths from 0.5 m to 4.5 m and some invalid pixels, and its exact flow.
    fn scene(h: usize, w: usize) -> (Array2<f32>, Flow) {
        let depth = Array2::from_shape_fn((h, w), |(y, x)| {
            if (x * 7 + y * 3) % 11 == 0 {
                0.0
            } else {
                0.5 + 4.0 * ((x * 13 + y * 29) % 97) as f32 / 96.0
            }
        });
        let flow = Flow {
            u: depth.mapv(|z| TRUE.flow_at(z).map_or(0.0, |f| f.0)),
            v: depth.mapv(|z| TRUE.flow_at(z).map_or(0.0, |f| f.1)),
        };
        (depth, flow)
    }

    fn assert_close(c: Calibration, want: Calibration, tol: f32) {
        for (got, want, name) in [
            (c.tx, want.tx, "tx"),
            (c.ty, want.ty, "ty"),
            (c.cx, want.cx, "cx"),
            (c.cy, want.cy, "cy"),
        ] {
            assert!(
                (got - want).abs() <= tol,
                "{name}: {got} vs {want} (tol {tol})"
            );
        }
    }

    #[test]
    fn recovers_exact_calibration() {
        let (depth, flow) = scene(48, 64);
        let fit = solve_calibration(&flow, depth.view(), None).unwrap();
        assert_close(fit.calibration, TRUE, 1e-4);
        assert!(fit.rms_residual_px < 1e-4);
        let invalid = depth.iter().filter(|&&z| z == 0.0).count();
        assert_eq!(fit.pixels_used, 48 * 64 - invalid);
    }

    #[test]
    fn hand_solved_two_depths() {
        // Depths 1 and 2 (a = 1, 0.5), u = 3 and 2: slope t = 2, offset c = 1.
        // A third pixel at depth 1 with u = 3 keeps the fit exact; weights 0 drop a bad one.
        let depth = Array2::from_shape_vec((1, 4), vec![1.0, 2.0, 1.0, 1.0]).unwrap();
        let flow = Flow {
            u: Array2::from_shape_vec((1, 4), vec![3.0, 2.0, 3.0, 100.0]).unwrap(),
            v: Array2::from_shape_vec((1, 4), vec![-1.0, 0.0, -1.0, 100.0]).unwrap(),
        };
        let w = Array2::from_shape_vec((1, 4), vec![1.0, 1.0, 1.0, 0.0]).unwrap();
        let fit = solve_calibration(&flow, depth.view(), Some(w.view())).unwrap();
        assert_close(
            fit.calibration,
            Calibration {
                tx: 2.0,
                ty: -2.0,
                cx: 1.0,
                cy: 1.0,
            },
            1e-6,
        );
        assert_eq!(fit.pixels_used, 3);
    }

    #[test]
    fn weighted_residual_is_the_rms_end_point_error() {
        // Two depths, each with two pixels whose u differs by ±1 around the line: the fit is the
        // line itself and the RMS residual is exactly 1.
        let depth = Array2::from_shape_vec((1, 4), vec![1.0, 1.0, 2.0, 2.0]).unwrap();
        let flow = Flow {
            u: Array2::from_shape_vec((1, 4), vec![4.0, 2.0, 3.0, 1.0]).unwrap(),
            v: Array2::zeros((1, 4)),
        };
        let fit = solve_calibration(&flow, depth.view(), None).unwrap();
        assert_close(
            fit.calibration,
            Calibration {
                tx: 2.0,
                ty: 0.0,
                cx: 1.0,
                cy: 0.0,
            },
            1e-6,
        );
        assert!((fit.rms_residual_px - 1.0).abs() < 1e-6);
    }

    #[test]
    fn errors_on_too_few_and_degenerate() {
        let depth = Array2::from_elem((2, 2), 0.0f32);
        let err = solve_calibration(&Flow::zeros(2, 2), depth.view(), None).unwrap_err();
        assert_eq!(
            err,
            LsqError::TooFewPixels {
                used: 0,
                required: MIN_PIXELS
            }
        );

        let depth = Array2::from_elem((4, 4), 2.0f32);
        let flow = Flow {
            u: Array2::from_elem((4, 4), 5.0),
            v: Array2::from_elem((4, 4), -1.0),
        };
        match solve_calibration(&flow, depth.view(), None).unwrap_err() {
            LsqError::Degenerate {
                mean_inv_depth,
                mean_flow,
                pixels,
                ..
            } => {
                assert_eq!(mean_inv_depth, 0.5);
                assert_eq!(mean_flow, (5.0, -1.0));
                assert_eq!(pixels, 16);
            }
            e => panic!("unexpected {e:?}"),
        }
    }

    /// Deterministic pseudo-random numbers in [0, 1) for the tests.
    fn hash01(i: u64) -> f32 {
        let mut x = i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03;
        x ^= x >> 31;
        x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x ^= x >> 29;
        (x >> 40) as f32 / (1u64 << 24) as f32
    }

    #[test]
    fn robust_fit_ignores_gross_outliers_where_plain_ls_does_not() {
        let (depth, mut flow) = scene(48, 64);
        // Small noise everywhere (±0.1 px), and 20 % of the pixels replaced by a one-sided gross
        // error of 8..40 px (a mismatched region).
        let mut outliers = 0;
        for (i, ((&z, u), v)) in depth
            .iter()
            .zip(flow.u.iter_mut())
            .zip(flow.v.iter_mut())
            .enumerate()
        {
            let i = i as u64;
            *u += 0.2 * (hash01(3 * i) - 0.5);
            *v += 0.2 * (hash01(3 * i + 1) - 0.5);
            if z > 0.0 && hash01(3 * i + 2) < 0.2 {
                outliers += 1;
                *u += 8.0 + 32.0 * hash01(7 * i + 5);
                *v -= 8.0 + 32.0 * hash01(11 * i + 3);
            }
        }
        let used = depth.iter().filter(|&&z| z > 0.0).count();
        assert!((outliers as f32 / used as f32 - 0.2).abs() < 0.03);

        let plain = solve_calibration(&flow, depth.view(), None)
            .unwrap()
            .calibration;
        let robust = solve_calibration_robust(
            &flow,
            depth.view(),
            None,
            RobustOptions {
                huber_delta_px: 0.25,
                iterations: 50,
                max_samples: 0,
            },
        )
        .unwrap()
        .calibration;
        // Compare the predicted flow over the depth range rather than raw (t, c), whose errors
        // are correlated.
        let err = |c: Calibration| {
            [0.5f32, 1.0, 2.0, 4.5]
                .iter()
                .map(|&z| {
                    let (a, b) = (c.flow_at(z).unwrap(), TRUE.flow_at(z).unwrap());
                    (a.0 - b.0).hypot(a.1 - b.1)
                })
                .fold(0.0f32, f32::max)
        };
        assert!(
            err(plain) > 3.0,
            "plain LS should be pulled away: {}",
            err(plain)
        );
        assert!(
            err(robust) < 0.15,
            "robust fit error {} px ({robust:?})",
            err(robust)
        );
    }

    #[test]
    fn sample_step_is_the_smallest_grid_under_the_budget() {
        let o = RobustOptions::default();
        assert_eq!(o.sample_step((480, 640)), 3);
        assert_eq!(o.sample_step((240, 320)), 2);
        assert_eq!(o.sample_step((100, 100)), 1);
        let every = RobustOptions {
            max_samples: 0,
            ..o
        };
        assert_eq!(every.sample_step((480, 640)), 1);
    }

    #[test]
    fn the_sampled_robust_fit_matches_the_full_one_on_a_large_flow() {
        // 480×640 with 20 % gross outliers: a third of the rows and columns recover the same
        // calibration as every pixel, to a hundredth of a pixel of flow.
        let (h, w) = (480, 640);
        let depth = Array2::from_shape_fn((h, w), |(y, x)| {
            0.8 + 3.0 * ((x * 7 + y * 13) % 97) as f32 / 97.0
        });
        let mut flow = Flow {
            u: depth.mapv(|z| TRUE.tx / z + TRUE.cx),
            v: depth.mapv(|z| TRUE.ty / z + TRUE.cy),
        };
        for (i, (u, v)) in flow.u.iter_mut().zip(flow.v.iter_mut()).enumerate() {
            let n = hash01(i as u64);
            *u += 0.2 * (n - 0.5);
            if n < 0.2 {
                *u += 15.0;
                *v -= 9.0;
            }
        }
        let sampled =
            solve_calibration_robust(&flow, depth.view(), None, RobustOptions::default()).unwrap();
        let full = solve_calibration_robust(
            &flow,
            depth.view(),
            None,
            RobustOptions {
                max_samples: 0,
                ..RobustOptions::default()
            },
        )
        .unwrap();
        assert_eq!(full.pixels_used, h * w);
        assert_eq!(sampled.pixels_used, 160 * 214);
        for z in [0.8f32, 3.8] {
            let (su, sv) = sampled.calibration.flow_at(z).unwrap();
            let (fu, fv) = full.calibration.flow_at(z).unwrap();
            assert!(
                (su - fu).abs() < 0.01 && (sv - fv).abs() < 0.01,
                "{sampled:?} vs {full:?}"
            );
        }
        // One-sided outliers bias a Huber fit by about f·δ/(1−f) = 0.25 px, sampled or not.
        assert_close(sampled.calibration, TRUE, 0.5);
    }
}
