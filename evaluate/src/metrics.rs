//! The paper's evaluation metrics, shared by `dear eval`, the simulator's checks and the
//! benchmarks, so every number in RESULTS.md comes from one implementation.
//!
//! - [`aepe`]: average end-point error of a flow over valid pixels (paper Table 1);
//! - [`DepthErrorSplit`]: depth MAE within a maximum range, with pixels ranked by the *input*
//!   depth error and split into quantile classes (paper Tables 2 and 3): low 0–25 %, mid
//!   25–50 %, high 50–75 %, the rest "outliers"; `All` covers every evaluated pixel. Pixels are
//!   ranked within each frame and the sums accumulated over frames, never re-ranked over a set.
//!
//! - [`Reliability`]: how well a predicted per-pixel absolute error (a guarded refiner's
//!   expected-error confidence) matches the error measured against the ground truth, per bin
//!   of the prediction (issue 33's reliability table);
//! - [`TemporalChange`]: mean frame-to-frame change of the depth on static surfaces (pixels
//!   whose ground truth did not change), the flicker a sequence shows.
//!
//! `train/dear_train/metrics.py` mirrors the four definitions in Python (the first two serve
//! the training side: `dear-evaluate`, a run's validation, `model.json`'s `validation`); both
//! are checked against the hand-computed cases in `fixtures/metrics/`
//! (`evaluate/tests/metrics_fixture.rs`, `train/tests/test_metrics_fixture.py`). Change the two
//! together.

use ndarray::{ArrayView2, Zip};

use dear_capture::frame::Flow;
use dear_capture::is_valid_depth;

/// The paper's evaluation range: MAE is computed where the ground truth is within 4 m.
pub const MAX_EVAL_DEPTH_M: f32 = 4.0;

/// Average end-point error (px) of `estimate` against `truth` over pixels where `valid` is
/// true and both flows are finite. `None` when no pixel qualifies.
pub fn aepe(estimate: &Flow, truth: &Flow, valid: ArrayView2<bool>) -> Option<f64> {
    let mut sum = 0.0f64;
    let mut n = 0usize;
    Zip::from(&estimate.u)
        .and(&estimate.v)
        .and(&truth.u)
        .and(&truth.v)
        .and(valid)
        .for_each(|&eu, &ev, &tu, &tv, &ok| {
            if ok
                && eu.is_finite()
                && ev.is_finite()
                && tu.is_finite()
                && tv.is_finite()
                && tu.abs() < 1e9
                && tv.abs() < 1e9
            {
                sum += (((eu - tu) as f64).powi(2) + ((ev - tv) as f64).powi(2)).sqrt();
                n += 1;
            }
        });
    (n > 0).then(|| sum / n as f64)
}

/// Sums of absolute depth errors per class, accumulated over frames. Pixels are ranked *within
/// each frame* by the input's error, so every frame contributes to every class in proportion to
/// its size.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DepthErrorSplit {
    /// `[low, mid, high, outliers]` sums of |output − gt| in metres.
    pub sums: [f64; 4],
    /// Pixels per class that have a valid output.
    pub counts: [u64; 4],
    /// Evaluated pixels (gt and input valid, gt within range) where the output is invalid (0).
    pub missing: u64,
}

/// Class names in the order of [`DepthErrorSplit::sums`].
pub const CLASSES: [&str; 4] = ["low", "mid", "high", "outliers"];

impl DepthErrorSplit {
    /// Adds one frame. Evaluated pixels: ground truth in `(0, max_depth]` and a valid (> 0)
    /// input. They are ranked by `|input − gt|`; the first quarter is "low", and so on. The
    /// output's error is then accumulated per class; an invalid output (≤ 0) is counted as
    /// missing instead.
    pub fn add_frame(
        &mut self,
        input: ArrayView2<f32>,
        output: ArrayView2<f32>,
        gt: ArrayView2<f32>,
        max_depth: f32,
    ) {
        let mut pixels: Vec<(f32, f32)> = Vec::new(); // (input error, output value - gt)
        Zip::from(input).and(output).and(gt).for_each(|&i, &o, &g| {
            if is_valid_depth(g) && g <= max_depth && is_valid_depth(i) {
                let out_err = if is_valid_depth(o) { o - g } else { f32::NAN };
                pixels.push(((i - g).abs(), out_err));
            }
        });
        // Stable order for ties keeps the split deterministic.
        pixels.sort_by(|a, b| a.0.total_cmp(&b.0));
        let n = pixels.len();
        for (rank, &(_, out_err)) in pixels.iter().enumerate() {
            let class = class_of(rank, n);
            if out_err.is_nan() {
                self.missing += 1;
            } else {
                self.sums[class] += out_err.abs() as f64;
                self.counts[class] += 1;
            }
        }
    }

    /// Merges another accumulator.
    pub fn merge(&mut self, other: &DepthErrorSplit) {
        for k in 0..4 {
            self.sums[k] += other.sums[k];
            self.counts[k] += other.counts[k];
        }
        self.missing += other.missing;
    }

    /// MAE of one class in centimetres.
    pub fn mae_cm(&self, class: usize) -> Option<f64> {
        (self.counts[class] > 0).then(|| 100.0 * self.sums[class] / self.counts[class] as f64)
    }

    /// MAE over all evaluated pixels with a valid output, in centimetres.
    pub fn mae_all_cm(&self) -> Option<f64> {
        let n: u64 = self.counts.iter().sum();
        (n > 0).then(|| 100.0 * self.sums.iter().sum::<f64>() / n as f64)
    }

    /// Fraction of evaluated pixels with a valid output.
    pub fn coverage(&self) -> f64 {
        let n: u64 = self.counts.iter().sum();
        let total = n + self.missing;
        if total == 0 {
            0.0
        } else {
            n as f64 / total as f64
        }
    }
}

/// Upper edges (cm) of the bins of predicted error [`Reliability`] reports; the last bin is
/// open above.
pub const RELIABILITY_EDGES_CM: [f64; 8] = [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0];
const RELIABILITY_BINS: usize = RELIABILITY_EDGES_CM.len() + 1;

/// Predicted against measured absolute depth error, accumulated over frames per bin of the
/// prediction. Evaluated pixels: ground truth in `(0, max_depth]`, a valid output and a finite
/// prediction.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Reliability {
    pub counts: [u64; RELIABILITY_BINS],
    /// Sums of the predicted errors, metres.
    pub predicted: [f64; RELIABILITY_BINS],
    /// Sums of `|output − gt|`, metres.
    pub measured: [f64; RELIABILITY_BINS],
}

/// One bin of a [`Reliability`]: predictions in `[predicted_lo_cm, predicted_hi_cm)` (a row of
/// `dear eval`'s reliability table, as `eval.json` writes it).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ReliabilityBin {
    pub predicted_lo_cm: f64,
    /// `None`: open above.
    pub predicted_hi_cm: Option<f64>,
    pub pixels: u64,
    pub mean_predicted_cm: f64,
    pub mean_measured_cm: f64,
}

impl Reliability {
    /// Adds one frame: `predicted` holds each pixel's predicted absolute error in metres.
    pub fn add_frame(
        &mut self,
        output: ArrayView2<f32>,
        predicted: ArrayView2<f32>,
        gt: ArrayView2<f32>,
        max_depth: f32,
    ) {
        Zip::from(output)
            .and(predicted)
            .and(gt)
            .for_each(|&o, &p, &g| {
                if is_valid_depth(g) && g <= max_depth && is_valid_depth(o) && p.is_finite() {
                    let cm = 100.0 * p as f64;
                    let bin = RELIABILITY_EDGES_CM.partition_point(|&edge| edge <= cm);
                    self.counts[bin] += 1;
                    self.predicted[bin] += p as f64;
                    self.measured[bin] += (o - g).abs() as f64;
                }
            });
    }

    /// The bins that hold pixels, from the smallest prediction up.
    pub fn bins(&self) -> Vec<ReliabilityBin> {
        (0..RELIABILITY_BINS)
            .filter(|&b| self.counts[b] > 0)
            .map(|b| {
                let n = self.counts[b] as f64;
                ReliabilityBin {
                    predicted_lo_cm: if b == 0 {
                        0.0
                    } else {
                        RELIABILITY_EDGES_CM[b - 1]
                    },
                    predicted_hi_cm: RELIABILITY_EDGES_CM.get(b).copied(),
                    pixels: self.counts[b],
                    mean_predicted_cm: 100.0 * self.predicted[b] / n,
                    mean_measured_cm: 100.0 * self.measured[b] / n,
                }
            })
            .collect()
    }
}

/// Ground truths closer than this (metres) count as the same static surface.
pub const STATIC_TOLERANCE_M: f32 = 1e-3;

/// Mean absolute change of the depth between consecutive frames over *static* pixels: ground
/// truth valid, within range and unchanged (to [`STATIC_TOLERANCE_M`]) in both frames, and the
/// depth valid in both. On a still scene this is pure flicker: noise, and corrections that
/// come and go.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TemporalChange {
    pub sum: f64,
    pub count: u64,
}

impl TemporalChange {
    /// Adds the pair (`previous`, `current`) of consecutive frames.
    pub fn add_pair(
        &mut self,
        (previous, previous_gt): (ArrayView2<f32>, ArrayView2<f32>),
        (current, current_gt): (ArrayView2<f32>, ArrayView2<f32>),
        max_depth: f32,
    ) {
        Zip::from(previous)
            .and(previous_gt)
            .and(current)
            .and(current_gt)
            .for_each(|&a, &ga, &b, &gb| {
                let still = is_valid_depth(ga)
                    && is_valid_depth(gb)
                    && ga <= max_depth
                    && (ga - gb).abs() <= STATIC_TOLERANCE_M;
                if still && is_valid_depth(a) && is_valid_depth(b) {
                    self.sum += (a - b).abs() as f64;
                    self.count += 1;
                }
            });
    }

    /// The mean change in centimetres; `None` before any static pixel.
    pub fn mean_cm(&self) -> Option<f64> {
        (self.count > 0).then(|| 100.0 * self.sum / self.count as f64)
    }
}

/// Quantile class of the pixel at `rank` (0-based) among `n`: 0 for the first 25 %, …, 3 for
/// the last 25 %.
fn class_of(rank: usize, n: usize) -> usize {
    ((4 * rank) / n.max(1)).min(3)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{arr2, Array2};

    #[test]
    fn aepe_by_hand() {
        let est = Flow {
            u: arr2(&[[1.0, 0.0], [3.0, 0.0]]),
            v: arr2(&[[0.0, 0.0], [4.0, 9.0]]),
        };
        let gt = Flow::zeros(2, 2);
        let valid = arr2(&[[true, true], [true, false]]);
        // errors 1, 0, 5 (the 9 is masked out)
        assert!((aepe(&est, &gt, valid.view()).unwrap() - 2.0).abs() < 1e-12);
        assert_eq!(
            aepe(&est, &gt, Array2::from_elem((2, 2), false).view()),
            None
        );
    }

    #[test]
    fn quantile_split_by_hand() {
        // Eight evaluated pixels with input errors 0.01..0.08 m (ranked in that order), plus one
        // beyond 4 m and one with invalid input, which are ignored.
        let gt = arr2(&[[1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 5.0, 1.0]]);
        let input = arr2(&[[1.08, 1.01, 1.07, 1.02, 1.06, 1.03, 1.05, 1.04, 5.5, 0.0]]);
        // Output errors chosen per pixel: ranks (by input error) 0..8 map to outputs below.
        let output = arr2(&[[1.10, 1.001, 1.0, 0.998, 0.95, 1.003, 1.02, 0.0, 1.0, 1.0]]);
        let mut split = DepthErrorSplit::default();
        split.add_frame(input.view(), output.view(), gt.view(), MAX_EVAL_DEPTH_M);
        // Ranks: 1.01(r0,out .001) 1.02(r1,out .002) 1.03(r2,.003) 1.04(r3, invalid) 1.05(r4,.02)
        //        1.06(r5,.05) 1.07(r6,0) 1.08(r7,.10)
        assert_eq!(split.counts, [2, 1, 2, 2]);
        assert_eq!(split.missing, 1);
        assert!(
            (split.mae_cm(0).unwrap() - 0.15).abs() < 1e-4,
            "{:?}",
            split.mae_cm(0)
        );
        assert!((split.mae_cm(1).unwrap() - 0.3).abs() < 1e-4);
        assert!((split.mae_cm(2).unwrap() - 3.5).abs() < 1e-4);
        assert!((split.mae_cm(3).unwrap() - 5.0).abs() < 1e-4);
        let all = (0.001 + 0.002 + 0.003 + 0.02 + 0.05 + 0.0 + 0.10) / 7.0 * 100.0;
        assert!((split.mae_all_cm().unwrap() - all).abs() < 1e-4);
        assert!((split.coverage() - 7.0 / 8.0).abs() < 1e-12);
    }

    #[test]
    fn reliability_bins_by_hand() {
        let gt = arr2(&[[1.0, 1.0, 1.0, 1.0, 5.0, 1.0]]);
        let out = arr2(&[[1.002, 1.004, 1.1, 0.0, 5.0, 1.3]]);
        // Predictions 0.3 cm, 0.4 cm (bin < 0.5), 5 cm (4–8), an invalid output, beyond 4 m,
        // and a NaN prediction: three pixels in two bins.
        let pred = arr2(&[[0.003, 0.004, 0.05, 0.01, 0.01, f32::NAN]]);
        let mut r = Reliability::default();
        r.add_frame(out.view(), pred.view(), gt.view(), MAX_EVAL_DEPTH_M);
        let bins = r.bins();
        assert_eq!(bins.len(), 2);
        assert_eq!(
            (
                bins[0].predicted_lo_cm,
                bins[0].predicted_hi_cm,
                bins[0].pixels
            ),
            (0.0, Some(0.5), 2)
        );
        assert!((bins[0].mean_predicted_cm - 0.35).abs() < 1e-4);
        assert!((bins[0].mean_measured_cm - 0.3).abs() < 1e-4);
        assert_eq!(
            (
                bins[1].predicted_lo_cm,
                bins[1].predicted_hi_cm,
                bins[1].pixels
            ),
            (4.0, Some(8.0), 1)
        );
        assert!((bins[1].mean_measured_cm - 10.0).abs() < 1e-3);
    }

    #[test]
    fn temporal_change_counts_static_pixels_only() {
        let gt0 = arr2(&[[1.0, 2.0, 3.0, 1.0]]);
        let gt1 = arr2(&[[1.0, 2.5, 3.0, 1.0]]); // the second pixel moved: not static
        let d0 = arr2(&[[1.01, 2.0, 3.0, 0.0]]);
        let d1 = arr2(&[[0.99, 2.5, 3.03, 1.0]]); // the last was invalid before
        let mut t = TemporalChange::default();
        t.add_pair(
            (d0.view(), gt0.view()),
            (d1.view(), gt1.view()),
            MAX_EVAL_DEPTH_M,
        );
        assert_eq!(t.count, 2);
        assert!(
            (t.mean_cm().unwrap() - 2.5).abs() < 1e-4,
            "{:?}",
            t.mean_cm()
        );
        assert_eq!(TemporalChange::default().mean_cm(), None);
    }

    #[test]
    fn classes_split_evenly() {
        let classes: Vec<usize> = (0..8).map(|r| class_of(r, 8)).collect();
        assert_eq!(classes, vec![0, 0, 1, 1, 2, 2, 3, 3]);
        assert_eq!(class_of(0, 1), 0);
    }
}
