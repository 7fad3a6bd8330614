//! Observability: how well one frame constrains each direction of the calibration
//! `(t_x, t_y, c_x, c_y)` (issue 32, item 2).
//!
//! A fit of the flow model `W = t/z + c` is a least squares; its normal matrix `JᵀJ`, divided
//! by the residual variance, is the fit's **information matrix** `H` (the inverse of the
//! parameters' covariance). Its eigenvectors are the parameter directions, its eigenvalues how
//! much the frame says along each: a direction `v` (unit length) is known to a standard
//! deviation of `1/√λ`. A frame of a wall facing the camera has edges at one depth only, so
//! `t/z + c` is pinned at that depth and `t` against `c` is not (one eigenvalue near 0 for each
//! of `x` and `y`); a frame whose edges all run horizontally constrains `c_y` and not `c_x`.
//!
//! Units: the matrix is in the calibration's own units, `t` in px·m and `c` in px. A unit step
//! of `t` moves the flow by 1 px at 1 m (3.3 px at 0.3 m, 0.2 px at 5 m), a unit step of `c` by
//! 1 px everywhere, so `1/√λ` reads as "px of flow at about 1 m" for every direction.
//!
//! Correlated samples: neighbouring pixels of an edge map (blurred, Sobel) or of a network's
//! flow are not independent, and a least squares that counts every pixel overstates its
//! information by roughly the area over which its residuals are correlated. Each fit divides by
//! such an area ([`EDGE_PIXELS_PER_SAMPLE`], [`FLOW_PIXELS_PER_SAMPLE`]); the thresholds that
//! read the result ([`crate::recalibration::OnlineConfig::max_direction_std_px`]) were set with these
//! values on the simulator's families, so the two go together.

use dear_capture::calibration::Calibration;

/// ToF pixels per independent sample of the direct fit's edge residual: the edge maps are a
/// 3×3 Sobel gradient (then blurred by `DirectFitParams::blur_sigma`, 0.4 px), correlated over
/// about 3×3 px by the Sobel kernel alone.
pub const EDGE_PIXELS_PER_SAMPLE: f64 = 9.0;
/// RGB pixels per independent sample of a network flow: the rough-flow networks predict at
/// 1/8 of the resolution and upsample, so an 8×8 block carries about one independent vector.
pub const FLOW_PIXELS_PER_SAMPLE: f64 = 64.0;

/// A fit's information matrix over `(t_x, t_y, c_x, c_y)` (see the module docs for its units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Information {
    /// Symmetric, positive semi-definite.
    pub matrix: [[f64; 4]; 4],
}

/// The eigen-decomposition of an [`Information`], eigenvalues ascending.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Eigen {
    /// Eigenvalues, ascending (clamped at 0).
    pub values: [f64; 4],
    /// `vectors[k]` is the unit eigenvector of `values[k]`.
    pub vectors: [[f64; 4]; 4],
}

/// What a frame constrains, read from its [`Information`] with a threshold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observability {
    /// Directions (eigenvectors) known to at most the threshold's standard deviation, 0–4.
    pub constrained: u8,
    /// Standard deviation along the best-constrained direction, px (∞ when none).
    pub best_std_px: f32,
    /// Standard deviation along the worst-constrained direction, px (∞ when singular).
    pub worst_std_px: f32,
    /// Orthogonal projector onto the constrained directions.
    pub projector: [[f64; 4]; 4],
}

impl Information {
    /// No information at all.
    pub const ZERO: Information = Information {
        matrix: [[0.0; 4]; 4],
    };

    /// Every direction known to `std_px` (a prior such as a factory calibration's tolerance).
    pub fn isotropic(std_px: f32) -> Information {
        let l = 1.0 / (f64::from(std_px) * f64::from(std_px)).max(1e-12);
        let mut matrix = [[0.0; 4]; 4];
        for (k, row) in matrix.iter_mut().enumerate() {
            row[k] = l;
        }
        Information { matrix }
    }

    /// The information of a least squares over `(t_x, t_y, c_x, c_y)` whose normal matrix is
    /// `normal` (`Σ JᵀJ`), residual variance `variance` and `pixels_per_sample` correlated
    /// pixels per independent sample. A non-finite or non-positive variance gives no
    /// information.
    pub fn from_normal_matrix(
        normal: [[f64; 4]; 4],
        variance: f64,
        pixels_per_sample: f64,
    ) -> Information {
        let d = variance * pixels_per_sample.max(1.0);
        if !(d.is_finite() && d > 0.0) || normal.iter().flatten().any(|v| !v.is_finite()) {
            return Information::ZERO;
        }
        let mut matrix = normal;
        for (k, row) in matrix.iter_mut().enumerate() {
            for (l, v) in row.iter_mut().enumerate() {
                // Symmetrised.
                *v = 0.5 * (normal[k][l] + normal[l][k]) / d;
            }
        }
        Information { matrix }
    }

    /// The information of a flow-model fit to end points `(u, v) = t·a + c` at inverse depths
    /// `a`, given `Σ1`, `Σa` and `Σa²` over the samples used (each contributes one row for
    /// `u` and one for `v`), the residual's variance per coordinate and the pixels per sample.
    pub fn of_flow_fit(n: f64, sum_a: f64, sum_a2: f64, variance: f64, per_sample: f64) -> Self {
        let normal = [
            [sum_a2, 0.0, sum_a, 0.0],
            [0.0, sum_a2, 0.0, sum_a],
            [sum_a, 0.0, n, 0.0],
            [0.0, sum_a, 0.0, n],
        ];
        Information::from_normal_matrix(normal, variance, per_sample)
    }

    /// Sum of two independent pieces of information.
    pub fn add(&self, other: &Information) -> Information {
        let mut matrix = self.matrix;
        for (row, o) in matrix.iter_mut().zip(&other.matrix) {
            for (v, w) in row.iter_mut().zip(o) {
                *v += w;
            }
        }
        Information { matrix }
    }

    /// Eigenvalues (ascending) and unit eigenvectors, by cyclic Jacobi rotations.
    // Small dense linear algebra reads best with indices.
    #[allow(clippy::needless_range_loop)]
    pub fn eigen(&self) -> Eigen {
        let mut a = self.matrix;
        let mut v = [[0.0f64; 4]; 4];
        for (k, row) in v.iter_mut().enumerate() {
            row[k] = 1.0;
        }
        for _sweep in 0..50 {
            let off: f64 = (0..4)
                .flat_map(|p| (p + 1..4).map(move |q| (p, q)))
                .map(|(p, q)| a[p][q] * a[p][q])
                .sum();
            let diag: f64 = (0..4).map(|p| a[p][p] * a[p][p]).sum();
            if off <= 1e-30 * diag.max(1e-300) {
                break;
            }
            for p in 0..4 {
                for q in p + 1..4 {
                    if a[p][q] == 0.0 {
                        continue;
                    }
                    let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                    let t = if theta == 0.0 { 1.0 } else { t };
                    let c = 1.0 / (t * t + 1.0).sqrt();
                    let s = t * c;
                    for k in 0..4 {
                        let (akp, akq) = (a[k][p], a[k][q]);
                        a[k][p] = c * akp - s * akq;
                        a[k][q] = s * akp + c * akq;
                    }
                    for k in 0..4 {
                        let (apk, aqk) = (a[p][k], a[q][k]);
                        a[p][k] = c * apk - s * aqk;
                        a[q][k] = s * apk + c * aqk;
                    }
                    for k in 0..4 {
                        let (vkp, vkq) = (v[k][p], v[k][q]);
                        v[k][p] = c * vkp - s * vkq;
                        v[k][q] = s * vkp + c * vkq;
                    }
                }
            }
        }
        let mut order = [0usize, 1, 2, 3];
        order.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
        let mut values = [0.0; 4];
        let mut vectors = [[0.0; 4]; 4];
        for (k, &i) in order.iter().enumerate() {
            values[k] = a[i][i].max(0.0);
            for r in 0..4 {
                vectors[k][r] = v[r][i];
            }
        }
        Eigen { values, vectors }
    }

    /// The directions known to at most `max_std_px` (eigenvalue `≥ 1/max_std_px²`).
    pub fn observability(&self, max_std_px: f32) -> Observability {
        let e = self.eigen();
        let min_l = 1.0 / (f64::from(max_std_px) * f64::from(max_std_px)).max(1e-12);
        let mut projector = [[0.0f64; 4]; 4];
        let mut constrained = 0u8;
        for (l, u) in e.values.iter().zip(&e.vectors) {
            if *l >= min_l {
                constrained += 1;
                for (r, row) in projector.iter_mut().enumerate() {
                    for (c, p) in row.iter_mut().enumerate() {
                        *p += u[r] * u[c];
                    }
                }
            }
        }
        let std = |l: f64| {
            if l > 0.0 {
                (1.0 / l.sqrt()) as f32
            } else {
                f32::INFINITY
            }
        };
        Observability {
            constrained,
            best_std_px: std(e.values[3]),
            worst_std_px: std(e.values[0]),
            projector,
        }
    }
}

impl Observability {
    /// `from` moved towards `to` only along the constrained directions:
    /// `from + P (to − from)`.
    pub fn step(&self, from: &Calibration, to: &Calibration) -> Calibration {
        let d = [
            f64::from(to.tx - from.tx),
            f64::from(to.ty - from.ty),
            f64::from(to.cx - from.cx),
            f64::from(to.cy - from.cy),
        ];
        let mut s = [0.0f64; 4];
        for (r, row) in self.projector.iter().enumerate() {
            s[r] = row.iter().zip(&d).map(|(p, x)| p * x).sum();
        }
        Calibration {
            tx: from.tx + s[0] as f32,
            ty: from.ty + s[1] as f32,
            cx: from.cx + s[2] as f32,
            cy: from.cy + s[3] as f32,
        }
    }

    /// Whether every direction is constrained.
    pub fn complete(&self) -> bool {
        self.constrained == 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn eigen_decomposition_reconstructs_the_matrix() {
        let m = [
            [4.0, 1.0, 2.0, 0.5],
            [1.0, 3.0, 0.0, 1.0],
            [2.0, 0.0, 5.0, 0.2],
            [0.5, 1.0, 0.2, 1.0],
        ];
        let e = Information { matrix: m }.eigen();
        assert!(e.values.windows(2).all(|w| w[0] <= w[1]), "{:?}", e.values);
        for r in 0..4 {
            for c in 0..4 {
                let x: f64 = (0..4)
                    .map(|k| e.values[k] * e.vectors[k][r] * e.vectors[k][c])
                    .sum();
                assert!((x - m[r][c]).abs() < 1e-9, "{r} {c}: {x} vs {}", m[r][c]);
            }
        }
    }

    /// Flow samples at one depth constrain `t/z + c` there and not `t` against `c`: two
    /// directions are free, and a step along them is projected away.
    #[test]
    fn one_depth_leaves_two_directions_free() {
        // 1000 samples at 2 m (a = 0.5), 0.1 px noise.
        let n = 1000.0;
        let info = Information::of_flow_fit(n, 0.5 * n, 0.25 * n, 0.01, 1.0);
        let obs = info.observability(0.2);
        assert_eq!(obs.constrained, 2);
        assert!(obs.worst_std_px.is_infinite() || obs.worst_std_px > 1e3);
        let from = Calibration {
            tx: 6.0,
            ty: -2.0,
            cx: 3.0,
            cy: 1.0,
        };
        // A step that keeps the flow at 2 m (t up by 2, c down by 1): nothing moves.
        let along_free = Calibration {
            tx: 8.0,
            cx: 2.0,
            ..from
        };
        let moved = obs.step(&from, &along_free);
        for (a, b) in [
            (moved.tx, from.tx),
            (moved.ty, from.ty),
            (moved.cx, from.cx),
            (moved.cy, from.cy),
        ] {
            assert!((a - b).abs() < 1e-5, "{moved:?}");
        }
        // A shift of c alone changes the flow at 2 m: its observable part is applied, and the
        // flow at 2 m then matches the target's exactly.
        let shift = Calibration { cx: 4.0, ..from };
        let moved = obs.step(&from, &shift);
        let flow = |c: Calibration| c.tx * 0.5 + c.cx;
        assert!((flow(moved) - flow(shift)).abs() < 1e-5, "{moved:?}");
        // Two depths: all four.
        let info2 = info.add(&Information::of_flow_fit(n, 2.0 * n, 4.0 * n, 0.01, 1.0));
        assert_eq!(info2.observability(0.2).constrained, 4);
        assert_eq!(Information::ZERO.observability(0.2).constrained, 0);
        assert_eq!(
            Information::isotropic(0.5).observability(1.0).constrained,
            4
        );
    }

    use crate::recalibration::direct::{estimate_calibration_direct, DirectFitParams};
    use crate::recalibration::edges::test_scene::fit_textured_scene;
    use crate::recalibration::{Measurement, OnlineCalibrator, OnlineConfig};
    use ndarray::{Array2, Array3};

    const TRUTH: Calibration = Calibration {
        tx: 6.0,
        ty: -2.0,
        cx: 3.0,
        cy: 1.5,
    };

    /// Largest flow difference over 0.3–5 m, px.
    fn flow_error(a: Calibration, b: Calibration) -> f32 {
        [0.3f32, 0.5, 1.0, 2.0, 5.0]
            .iter()
            .map(|&z| {
                let (p, q) = (a.flow_at(z).unwrap(), b.flow_at(z).unwrap());
                (p.0 - q.0).hypot(p.1 - q.1)
            })
            .fold(0.0, f32::max)
    }

    /// An aligned low-texture frame: a bare wall 2.5 m away facing the camera, with a door
    /// frame and a skirting board (edges in both modalities, all at one depth), seen through
    /// `truth`.
    fn bare_wall(truth: &Calibration) -> (Array3<u8>, Array2<f32>, Array2<f32>) {
        let (h, w) = (160, 220);
        let z = 2.5f32;
        let depth = Array2::from_elem((h, w), z);
        // Soft bars (Gaussian profile, σ = 1.5 px), so that the RGB view can be sampled at the
        // sub-pixel flow: the door's jambs and lintel, and a skirting board.
        let bar = |d: f32| (-0.5 * d * d / 2.25).exp();
        let edge = |y: f32, x: f32| {
            let in_door_y = (40.0..140.0).contains(&y);
            let in_door_x = (70.0..=124.0).contains(&x);
            let jambs = if in_door_y {
                bar(x - 72.0).max(bar(x - 122.0))
            } else {
                0.0
            };
            let lintel = if in_door_x { bar(y - 41.0) } else { 0.0 };
            jambs.max(lintel).max(bar(y - 136.0))
        };
        let amplitude =
            Array2::from_shape_fn((h, w), |(y, x)| 300.0 + 600.0 * edge(y as f32, x as f32));
        // RGB pixel p sees ToF pixel p + W(z).
        let (u, v) = truth.flow_at(z).unwrap();
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, k)| {
            let e = edge(y as f32 + v, x as f32 + u);
            (180.0 - (140.0 - 10.0 * k as f32) * e) as u8
        });
        (rgb, amplitude, depth)
    }

    /// Issue 32, item 2: the direct fit of an aligned bare wall, started from a calibration
    /// that is wrong along the direction a single depth cannot see (`t` and `c` off together,
    /// and 1 px off at the wall too: what the network's rough fit gives on such a frame),
    /// corrects the flow at the wall's depth and measures `c` given that wrong `t`. Its information says it constrains two directions, and an
    /// estimator that starts from the correct (factory) calibration does not move: within
    /// 0.1 px of flow anywhere in 0.3–5 m after 10 such frames. Without the projection the
    /// same measurements move it by more than 3 px at 0.3 m.
    #[test]
    fn an_aligned_bare_wall_leaves_a_correct_calibration_where_it_is() {
        let (rgb, amplitude, depth) = bare_wall(&TRUTH);
        // t + 3, c − 1.2 keeps the flow at 2.5 m (a = 0.4); the network is also 1 px off
        // there (else the fit gains nothing and falls back to it).
        let network = Calibration {
            tx: TRUTH.tx + 3.0,
            ty: TRUTH.ty - 2.0,
            cx: TRUTH.cx - 1.2 + 1.0,
            cy: TRUTH.cy + 0.8 - 0.5,
        };
        let fit = estimate_calibration_direct(
            rgb.view(),
            amplitude.view(),
            depth.view(),
            network,
            &DirectFitParams::default(),
        );
        assert!(!fit.baseline_fitted, "one depth: t is held {fit:?}");
        let m = Measurement::from_direct_fit(&fit).expect("the wall's edges fit");
        let config = OnlineConfig {
            interval_frames: 1,
            ..OnlineConfig::default()
        };
        let obs = m.observability(config.max_direction_std_px);
        assert_eq!(obs.constrained, 2, "{obs:?} {fit:?}");
        let run = |config: OnlineConfig| {
            let mut est = OnlineCalibrator::with_prior(config, TRUTH);
            for _ in 0..10 {
                est.begin_frame();
                est.end_frame(Some(Ok(m)), None);
            }
            est.estimate().unwrap()
        };
        let kept = run(config);
        assert!(flow_error(kept, TRUTH) < 0.1, "{kept:?} {fit:?}");
        let blind = run(OnlineConfig {
            max_direction_std_px: f32::INFINITY,
            ..config
        });
        assert!(flow_error(blind, TRUTH) > 3.0, "{blind:?}");
    }

    /// The other half: a textured frame (discs at five depths) misaligned by several pixels
    /// constrains every direction, and the estimator started from the factory calibration (the
    /// identity) converges to the truth as before.
    #[test]
    fn a_textured_misaligned_frame_still_converges() {
        let fit = fit_textured_scene(&TRUTH);
        let m = Measurement::from_direct_fit(&fit).expect("the discs fit");
        let config = OnlineConfig {
            interval_frames: 1,
            ..OnlineConfig::default()
        };
        let obs = m.observability(config.max_direction_std_px);
        assert_eq!(obs.constrained, 4, "{obs:?}");
        let mut est = OnlineCalibrator::with_prior(config, Calibration::IDENTITY);
        for _ in 0..3 {
            est.begin_frame();
            est.end_frame(Some(Ok(m)), None);
        }
        let e = est.estimate().unwrap();
        assert!(flow_error(Calibration::IDENTITY, TRUTH) > 6.0);
        assert!(flow_error(e, fit.calibration) < 1e-4, "{e:?} vs {fit:?}");
        let near = [0.8f32, 1.0, 1.2, 1.5, 1.8]
            .iter()
            .map(|&z| {
                let (p, q) = (e.flow_at(z).unwrap(), TRUTH.flow_at(z).unwrap());
                (p.0 - q.0).hypot(p.1 - q.1)
            })
            .fold(0.0, f32::max);
        assert!(near < 1.0, "{near} px at the discs' depths: {e:?}");
    }
}
