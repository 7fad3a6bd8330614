//! The paper's evaluation metrics, shared by `dear eval`, the simulator's checks and the
//! benchmarks, so every number in RESULTS.md comes from one implementation.
//!
//! - [`aepe`]: average end-point error of a flow over valid pixels (paper Table 1);
//! - [`DepthErrorSplit`]: depth MAE within a maximum range, with pixels ranked by the *input*
//!   depth error and split into quantile classes (paper Tables 2 and 3): low 0–25 %, mid
//!   25–50 %, high 50–75 %, the rest "outliers"; `All` covers every evaluated pixel. Pixels are
//!   ranked within each frame and the sums accumulated over frames, never re-ranked over a set.
//!
//! `train/dear_train/evaluation.py` implements the same definitions for the training side
//! (`dear-evaluate`, a run's validation, `model.json`'s `validation`); both are checked against
//! the hand-computed cases in `fixtures/metrics/` (`pipeline/tests/metrics_fixture.rs`,
//! `train/tests/test_metrics_fixture.py`). Change the two together.

use ndarray::{ArrayView2, Zip};

use crate::frame::Flow;
use crate::geometry::is_valid_depth;

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
    fn classes_split_evenly() {
        let classes: Vec<usize> = (0..8).map(|r| class_of(r, 8)).collect();
        assert_eq!(classes, vec![0, 0, 1, 1, 2, 2, 3, 3]);
        assert_eq!(class_of(0, 1), 0);
    }
}
