//! The refinement network's output checked against physics before it is published.
//!
//! A refinement removes multi-path interference, flying pixels and noise: it moves a measured
//! depth by centimetres, by up to the gap between two surfaces at an edge, and on a few pixels
//! only by more. A graph that was exported wrongly, quantised badly, fed inputs it was never
//! trained on or tampered with produces something else — every depth ×1000, NaN, negative —
//! and without a check that would be published flagged as network-refined. The guard judges a
//! frame's output as a whole: when more than [`OutputGuard::max_implausible_fraction`] of the
//! pixels with a measured depth come out implausible, the frame is refined by the classical
//! filter instead and the chain reports it ([`RefinementCheck`]).
//!
//! A pixel's output `r` for the measured (warped) depth `z` is implausible when it is not a
//! positive finite depth, or moves further than `max(max_change_m, max_change_ratio · z)`.
//! The defaults (0.5 m, 50 %, 5 % of the pixels) lie well outside what a working refiner does:
//! the shipped bundle moves 1.0–2.0 % of the measured pixels of `samples/demo`'s frames that
//! far (flying pixels at depth edges snapped across the gap), and a broken graph moves all of
//! them (tests in `pipeline/tests/output_guard.rs`).

use ndarray::{ArrayView2, ArrayViewMut2};

use crate::geometry::surface::{is_valid_depth, is_valid_depth_branchless};

/// Bounds on a refinement's output (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputGuard {
    /// Largest plausible change of a measured depth, metres (the floor of the bound).
    pub max_change_m: f32,
    /// Largest plausible change as a fraction of the measured depth.
    pub max_change_ratio: f32,
    /// Fraction of measured pixels that may be implausible before the frame's refinement is
    /// rejected (flying pixels moved across a wide gap are legitimate but rare).
    pub max_implausible_fraction: f32,
}

impl Default for OutputGuard {
    fn default() -> Self {
        OutputGuard {
            max_change_m: 0.5,
            max_change_ratio: 0.5,
            max_implausible_fraction: 0.05,
        }
    }
}

/// What the guard counted on one frame's refinement (and why it was rejected, when it was).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RefinementCheck {
    /// Pixels with a measured depth.
    pub measured: usize,
    /// Of those, outputs that are NaN or infinite.
    pub non_finite: usize,
    /// Of those, outputs at or below zero.
    pub non_positive: usize,
    /// Of those, positive finite outputs moved beyond the bound.
    pub moved_too_far: usize,
}

impl RefinementCheck {
    /// The counts of two parts of a frame together.
    fn add(self, other: Self) -> Self {
        RefinementCheck {
            measured: self.measured + other.measured,
            non_finite: self.non_finite + other.non_finite,
            non_positive: self.non_positive + other.non_positive,
            moved_too_far: self.moved_too_far + other.moved_too_far,
        }
    }

    /// All implausible pixels.
    pub fn implausible(&self) -> usize {
        self.non_finite + self.non_positive + self.moved_too_far
    }

    /// Implausible pixels as a fraction of the measured ones.
    pub fn implausible_fraction(&self) -> f32 {
        self.implausible() as f32 / self.measured.max(1) as f32
    }
}

impl std::fmt::Display for RefinementCheck {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:.1} % of {} measured pixels implausible ({} non-finite, {} at or below zero, {} moved beyond the bound)",
            100.0 * self.implausible_fraction(),
            self.measured,
            self.non_finite,
            self.non_positive,
            self.moved_too_far
        )
    }
}

impl OutputGuard {
    /// Counts the implausible outputs of `refined` against the measured depth `warped` (same
    /// shape).
    ///
    /// # Panics
    /// If the shapes differ.
    pub fn check(&self, warped: ArrayView2<f32>, refined: ArrayView2<f32>) -> RefinementCheck {
        assert_eq!(warped.dim(), refined.dim(), "guard: shapes differ");
        let mut counts = RefinementCheck::default();
        ndarray::Zip::from(&warped)
            .and(&refined)
            .for_each(|&z, &r| self.count(&mut counts, z, r));
        counts
    }

    /// [`check`](Self::check) while writing what a refined frame publishes into `out`: the
    /// refined depth where it and the measurement are valid depths, `0` elsewhere (a caller
    /// whose frame is [rejected](Self::rejects) overwrites it). One pass over the frame, rows
    /// in parallel, instead of two serial ones.
    ///
    /// # Panics
    /// If the shapes differ.
    pub fn check_into(
        &self,
        warped: ArrayView2<f32>,
        refined: ArrayView2<f32>,
        mut out: ArrayViewMut2<f32>,
    ) -> RefinementCheck {
        assert_eq!(warped.dim(), refined.dim(), "guard: shapes differ");
        assert_eq!(out.dim(), warped.dim(), "guard: output shape differs");
        ndarray::Zip::from(out.rows_mut())
            .and(warped.rows())
            .and(refined.rows())
            .par_fold(
                RefinementCheck::default,
                |mut counts, mut o, z, r| {
                    if let (Some(o), Some(z), Some(r)) =
                        (o.as_slice_mut(), z.to_slice(), r.to_slice())
                    {
                        return counts.add(self.check_row(o, z, r));
                    }
                    ndarray::Zip::from(&mut o)
                        .and(&z)
                        .and(&r)
                        .for_each(|o, &z, &r| {
                            *o = if is_valid_depth(z) && is_valid_depth(r) {
                                r
                            } else {
                                0.0
                            };
                            self.count(&mut counts, z, r);
                        });
                    counts
                },
                RefinementCheck::add,
            )
    }

    /// [`check_into`](Self::check_into) of one row on slices: [`count`](Self::count) and the
    /// published value written with selects, so that the loop vectorises (holes make the
    /// branches of `count` unpredictable).
    fn check_row(&self, out: &mut [f32], warped: &[f32], refined: &[f32]) -> RefinementCheck {
        let n = out.len();
        let (warped, refined) = (&warped[..n], &refined[..n]);
        let [mut measured, mut non_finite, mut non_positive, mut moved_too_far] = [0u32; 4];
        for i in 0..n {
            let (z, r) = (warped[i], refined[i]);
            let (measured_here, finite) = (is_valid_depth_branchless(z), r.is_finite());
            let bound = self.max_change_m.max(self.max_change_ratio * z);
            out[i] = if measured_here & is_valid_depth_branchless(r) {
                r
            } else {
                0.0
            };
            measured += u32::from(measured_here);
            non_finite += u32::from(measured_here & !finite);
            non_positive += u32::from(measured_here & finite & (r <= 0.0));
            moved_too_far +=
                u32::from(measured_here & finite & (r > 0.0) & ((r - z).abs() > bound));
        }
        RefinementCheck {
            measured: measured as usize,
            non_finite: non_finite as usize,
            non_positive: non_positive as usize,
            moved_too_far: moved_too_far as usize,
        }
    }

    /// Counts one pixel's output `r` for the measured depth `z`.
    #[inline]
    fn count(&self, counts: &mut RefinementCheck, z: f32, r: f32) {
        if !is_valid_depth(z) {
            return;
        }
        counts.measured += 1;
        if !r.is_finite() {
            counts.non_finite += 1;
        } else if r <= 0.0 {
            counts.non_positive += 1;
        } else if (r - z).abs() > self.max_change_m.max(self.max_change_ratio * z) {
            counts.moved_too_far += 1;
        }
    }

    /// Whether a frame with these counts must not be published as refined. A frame without
    /// any measured pixel is never rejected (there is nothing to refine).
    pub fn rejects(&self, check: &RefinementCheck) -> bool {
        check.measured > 0 && check.implausible_fraction() > self.max_implausible_fraction
    }

    /// [`check`](Self::check), kept only when the guard [`rejects`](Self::rejects) it.
    pub fn judge(
        &self,
        warped: ArrayView2<f32>,
        refined: ArrayView2<f32>,
    ) -> Option<RefinementCheck> {
        let check = self.check(warped, refined);
        self.rejects(&check).then_some(check)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    fn scene() -> Array2<f32> {
        Array2::from_shape_fn((20, 30), |(y, x)| {
            if (y + x) % 11 == 0 {
                0.0
            } else {
                1.0 + 0.05 * x as f32
            }
        })
    }

    #[test]
    fn a_refinement_of_centimetres_and_a_few_edge_jumps_passes() {
        let z = scene();
        let mut r = z.mapv(|z| if z > 0.0 { z + 0.03 } else { 0.0 });
        // 2 % of the pixels moved across a 1.5 m gap (flying pixels snapped to the background).
        for x in 0..12 {
            r[[5, x]] += 1.5;
        }
        assert_eq!(OutputGuard::default().judge(z.view(), r.view()), None);
    }

    #[test]
    fn scaled_nan_and_negative_outputs_are_rejected_and_counted() {
        let z = scene();
        let measured = z.iter().filter(|&&v| v > 0.0).count();
        let guard = OutputGuard::default();
        let scaled = guard
            .judge(z.view(), z.mapv(|v| v * 1000.0).view())
            .unwrap();
        assert_eq!(
            (scaled.measured, scaled.moved_too_far),
            (measured, measured)
        );
        let nan = guard.judge(z.view(), z.mapv(|_| f32::NAN).view()).unwrap();
        assert_eq!(nan.non_finite, measured);
        let negative = guard.judge(z.view(), z.mapv(|v| -v).view()).unwrap();
        assert_eq!(negative.non_positive, measured);
        assert!((negative.implausible_fraction() - 1.0).abs() < 1e-6);
        assert!(
            negative.to_string().contains("at or below zero"),
            "{negative}"
        );
    }

    #[test]
    fn check_into_counts_as_check_and_writes_the_published_depth() {
        let z = scene();
        // Every kind of output: moved a little, NaN, negative, too far, and refined where
        // nothing was measured.
        let r = Array2::from_shape_fn(z.dim(), |(y, x)| match (y * 30 + x) % 9 {
            0 => f32::NAN,
            1 => -1.0,
            2 => z[[y, x]] * 1000.0,
            3 => f32::INFINITY,
            4 => 0.0,
            _ => 1.5 + 0.01 * x as f32,
        });
        let guard = OutputGuard::default();
        let mut out = Array2::from_elem(z.dim(), 7.0f32);
        let counted = guard.check_into(z.view(), r.view(), out.view_mut());
        assert_eq!(counted, guard.check(z.view(), r.view()));
        assert!(counted.non_finite > 0 && counted.non_positive > 0 && counted.moved_too_far > 0);
        for ((y, x), &o) in out.indexed_iter() {
            let (zv, rv) = (z[[y, x]], r[[y, x]]);
            let want = if is_valid_depth(zv) && is_valid_depth(rv) {
                rv
            } else {
                0.0
            };
            assert_eq!(o.to_bits(), want.to_bits(), "({y}, {x})");
        }
    }

    #[test]
    fn the_fraction_threshold_decides() {
        let z = Array2::from_elem((10, 10), 2.0f32);
        let mut r = z.clone();
        // 5 of 100 pixels NaN: at the threshold, not beyond it.
        for x in 0..5 {
            r[[0, x]] = f32::NAN;
        }
        let guard = OutputGuard::default();
        assert_eq!(guard.judge(z.view(), r.view()), None);
        r[[0, 5]] = f32::NAN;
        assert_eq!(guard.judge(z.view(), r.view()).unwrap().non_finite, 6);
    }

    #[test]
    fn a_frame_without_measured_depth_is_not_rejected() {
        let z = Array2::zeros((4, 4));
        let r = Array2::from_elem((4, 4), f32::NAN);
        assert_eq!(OutputGuard::default().judge(z.view(), r.view()), None);
    }
}
