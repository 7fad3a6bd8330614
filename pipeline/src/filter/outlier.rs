//! Rejection of isolated depth outliers by the median of their neighbours.
//!
//! At low signal (few electrons, strong ambient light) ToF noise has heavy tails: single
//! pixels land tens of centimetres off their surface. A linear smoother spreads such a pixel
//! over its neighbourhood instead of removing it; a median ignores it. Only pixels far from
//! the median of their valid 3 × 3 neighbourhood (more than the same-surface tolerance) are
//! replaced, so fine structure within the noise level is left to the edge-aware smoother.

use ndarray::{ArrayView2, ArrayViewMut2, Axis, Zip};

use crate::geometry::surface::{is_valid_depth, same_surface};

/// Fewest valid pixels (of 9) a neighbourhood needs for its median to overrule the centre:
/// with fewer, the centre may be a thin structure, not noise.
const MIN_VALID_NEIGHBOURS: usize = 5;

/// Median of a small slice (sorted in place); the lower middle for an even count.
fn median(values: &mut [f32]) -> f32 {
    // Insertion sort: at most 9 values, already partly ordered along a row.
    for i in 1..values.len() {
        let v = values[i];
        let mut j = i;
        while j > 0 && values[j - 1] > v {
            values[j] = values[j - 1];
            j -= 1;
        }
        values[j] = v;
    }
    values[(values.len() - 1) / 2]
}

/// Writes `depth` into `out`, with every valid pixel that is not on the surface of the median
/// of its valid 3 × 3 neighbourhood (itself included; at least
/// [`MIN_VALID_NEIGHBOURS`] valid) replaced by that median. `replaced` flags those pixels.
/// Invalid pixels stay invalid (`0`).
///
/// # Panics
/// If the shapes differ.
pub fn reject_outliers(
    depth: ArrayView2<f32>,
    mut out: ArrayViewMut2<f32>,
    mut replaced: ArrayViewMut2<bool>,
) {
    let (h, w) = depth.dim();
    assert_eq!(out.dim(), (h, w), "reject_outliers: output shape differs");
    assert_eq!(
        replaced.dim(),
        (h, w),
        "reject_outliers: flag shape differs"
    );
    let depth = depth.as_standard_layout();
    let z = depth
        .as_slice()
        .expect("as_standard_layout yields a contiguous array");
    Zip::indexed(out.axis_iter_mut(Axis(0)))
        .and(replaced.axis_iter_mut(Axis(0)))
        .par_for_each(|y, mut out_row, mut flag_row| {
            let (y0, y1) = (y.saturating_sub(1), (y + 1).min(h - 1));
            let mut window = [0.0f32; 9];
            for (x, (o, f)) in out_row.iter_mut().zip(flag_row.iter_mut()).enumerate() {
                let centre = z[y * w + x];
                (*o, *f) = (if is_valid_depth(centre) { centre } else { 0.0 }, false);
                if !is_valid_depth(centre) {
                    continue;
                }
                let (x0, x1) = (x.saturating_sub(1), (x + 1).min(w - 1));
                let mut n = 0;
                for yy in y0..=y1 {
                    for &v in &z[yy * w + x0..=yy * w + x1] {
                        if is_valid_depth(v) {
                            window[n] = v;
                            n += 1;
                        }
                    }
                }
                if n < MIN_VALID_NEIGHBOURS {
                    continue;
                }
                let m = median(&mut window[..n]);
                if !same_surface(m, centre) {
                    (*o, *f) = (m, true);
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array2};

    fn run(depth: &Array2<f32>) -> (Array2<f32>, Array2<bool>) {
        let mut out = Array2::zeros(depth.dim());
        let mut flags = Array2::from_elem(depth.dim(), false);
        reject_outliers(depth.view(), out.view_mut(), flags.view_mut());
        (out, flags)
    }

    #[test]
    fn a_spike_on_a_plane_takes_the_median() {
        let mut depth = Array2::from_elem((5, 5), 2.0f32);
        depth[(2, 2)] = 2.6;
        depth[(0, 4)] = 1.2; // a corner spike: 4 valid pixels around it, itself included
        depth[(4, 0)] = 0.0;
        let (out, flags) = run(&depth);
        assert_eq!(out[(2, 2)], 2.0);
        assert!(flags[(2, 2)]);
        // The corner has 4 neighbours: too few to overrule it.
        assert_eq!(out[(0, 4)], 1.2);
        assert!(!flags[(0, 4)]);
        assert_eq!(out[(4, 0)], 0.0, "invalid stays invalid");
        assert_eq!(flags.iter().filter(|&&f| f).count(), 1);
    }

    #[test]
    fn noise_within_the_surface_tolerance_and_edges_are_kept() {
        // ±1 % noise (below the 3 % tolerance) and a clean step edge: nothing is replaced.
        let depth = array![
            [1.00f32, 1.01, 0.99, 3.0, 3.03],
            [0.99, 1.00, 1.01, 3.0, 2.97],
            [1.01, 0.99, 1.00, 3.0, 3.00],
        ];
        let (out, flags) = run(&depth);
        assert_eq!(out, depth);
        assert!(flags.iter().all(|&f| !f));
    }

    #[test]
    fn median_of_small_slices() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.0);
        assert_eq!(median(&mut [5.0]), 5.0);
    }
}
