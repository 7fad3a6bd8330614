//! Rejection of depth outliers by the median of their neighbours.
//!
//! At low signal (few electrons, strong ambient light) ToF noise has heavy tails: single
//! pixels land tens of centimetres off their surface. A linear smoother spreads such a pixel
//! over its neighbourhood instead of removing it; a median ignores it. Only pixels far from
//! the median of their valid 3 × 3 neighbourhood (more than the same-surface tolerance) are
//! replaced, so fine structure within the noise level is left to the edge-aware smoother.
//!
//! The rule does not also ask the pixel to be isolated (few neighbours on its own surface),
//! although that would spare a correct pixel at the corner of a step: in heavy-tailed noise a
//! pixel's neighbours scatter as much as it does, and every such condition tried made the
//! held-out tuning set worse (models/edge/README.md, issue 33).

use ndarray::{ArrayView2, ArrayViewMut2};

use crate::filter::par_rows2;
use crate::geometry::surface::{is_valid_depth, is_valid_depth_branchless, same_surface};
use crate::vector_math::window3x3;

/// Fewest valid pixels (of 9) a neighbourhood needs for its median to overrule the centre:
/// with fewer, the centre may be a thin structure, not noise.
const MIN_VALID_NEIGHBOURS: usize = 5;

/// Sorts nine values (no NaN) ascending with a 25-comparator sorting network: branch-free,
/// so a loop over pixels vectorises.
#[inline(always)]
fn sort9(v: &mut [f32; 9]) {
    // Written out (not a loop over a table of pairs) so that it is fully unrolled and the
    // values stay in registers.
    macro_rules! sort {
        ($(($i:literal, $j:literal)),*) => {$({
            let (a, b) = (v[$i], v[$j]);
            (v[$i], v[$j]) = (if b < a { b } else { a }, if b < a { a } else { b });
        })*};
    }
    sort!((0, 3), (1, 7), (2, 5), (4, 8));
    sort!((0, 7), (2, 4), (3, 8), (5, 6));
    sort!((0, 2), (1, 3), (4, 5), (7, 8));
    sort!((1, 4), (3, 6), (5, 7));
    sort!((0, 1), (2, 4), (3, 5), (6, 8));
    sort!((2, 3), (4, 5), (6, 7));
    sort!((1, 2), (3, 4), (5, 6));
}

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
/// `MIN_VALID_NEIGHBOURS` valid) replaced by that median. `replaced` flags those pixels.
/// Invalid pixels stay invalid (`0`).
///
/// # Panics
/// If the shapes differ.
pub fn reject_outliers(
    depth: ArrayView2<f32>,
    out: ArrayViewMut2<f32>,
    replaced: ArrayViewMut2<bool>,
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
    par_rows2(out, replaced, |y, out_row, flag_row| {
        let (y0, y1) = (y.saturating_sub(1), (y + 1).min(h - 1));
        // The exact rule for pixel `x`: the median of its valid neighbourhood, by sorting.
        let exact = |x: usize, o: &mut f32, f: &mut bool| {
            let centre = z[y * w + x];
            (*o, *f) = (if is_valid_depth(centre) { centre } else { 0.0 }, false);
            if !is_valid_depth(centre) {
                return;
            }
            let (x0, x1) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let mut window = [0.0f32; 9];
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
                return;
            }
            let m = median(&mut window[..n]);
            if !same_surface(m, centre) {
                (*o, *f) = (m, true);
            }
        };
        if y == 0 || y + 1 >= h || w < 3 {
            for (x, (o, f)) in out_row.iter_mut().zip(flag_row.iter_mut()).enumerate() {
                exact(x, o, f);
            }
            return;
        }
        // Interior pixels, branch-free (vectorised over the row): the nine values sorted by a
        // sorting network with the invalid ones as +∞ (after all valid ones), so the median
        // of the n valid values, the k-th smallest (k = (n − 1)/2), is `sorted[k]`. The same
        // value the insertion sort of the valid values gives, so the result is identical.
        let row = |yy: usize| &z[yy * w..(yy + 1) * w];
        let (up, cur, down) = (row(y - 1), row(y), row(y + 1));
        let window = window3x3([up, cur, down]);
        interior_row(window, &mut out_row[1..w - 1], &mut flag_row[1..w - 1]);
        for x in [0, w - 1] {
            exact(x, &mut out_row[x], &mut flag_row[x]);
        }
    });
}

/// The interior pixels of one row (see [`reject_outliers`]'s comment on the method): `window`
/// holds the nine shifted neighbour slices, `out` and `replaced` the row's interior. Compiled
/// for AVX-512 and AVX2 as well (sixteen or eight pixels' sorting networks side by side), chosen
/// at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn interior_row(window: [&[f32]; 9], out: &mut [f32], replaced: &mut [bool]) {
    let n = out.len();
    let window = window.map(|s| &s[..n]);
    let replaced = &mut replaced[..n];
    for i in 0..n {
        let mut v = [0.0f32; 9];
        let mut count = 0u32;
        for (v, s) in v.iter_mut().zip(window) {
            let ok = is_valid_depth_branchless(s[i]);
            count += u32::from(ok);
            *v = if ok { s[i] } else { f32::INFINITY };
        }
        sort9(&mut v);
        let m = match count {
            0..=6 => v[2],
            7..=8 => v[3],
            _ => v[4],
        };
        let centre = window[4][i];
        let keep = is_valid_depth_branchless(centre);
        let replace = keep & (count >= MIN_VALID_NEIGHBOURS as u32) & !same_surface(m, centre);
        out[i] = if replace {
            m
        } else if keep {
            centre
        } else {
            0.0
        };
        replaced[i] = replace;
    }
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
    fn sorting_network_sorts_every_input() {
        // 0-1 principle: a comparator network that sorts every 0/1 input sorts every input.
        for bits in 0u32..512 {
            let mut v: [f32; 9] = std::array::from_fn(|i| ((bits >> i) & 1) as f32);
            sort9(&mut v);
            assert!(v.windows(2).all(|p| p[0] <= p[1]), "{bits:09b}: {v:?}");
        }
        let mut v = [
            3.0,
            f32::INFINITY,
            1.0,
            9.0,
            2.0,
            f32::INFINITY,
            5.0,
            4.0,
            0.5,
        ];
        sort9(&mut v);
        assert_eq!(v[..7], [0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 9.0]);
    }

    #[test]
    fn matches_the_median_rule_on_noisy_depth_with_holes() {
        // Heavy-tailed noise, holes and a step edge: every pixel as the rule says, computed
        // independently (gather the valid 3 × 3 values, sort, take the lower middle).
        let (h, w) = (40, 50);
        let depth = Array2::from_shape_fn((h, w), |(y, x)| {
            let i = y * w + x;
            let g = crate::filter::tests::gauss(i);
            if i % 7 == 3 || i % 11 == 5 {
                0.0
            } else if i % 13 == 0 {
                f32::NAN
            } else {
                (if x < 25 { 1.0 } else { 2.5 }) * (1.0 + 0.02 * g * g * g.signum())
            }
        });
        let (out, flags) = run(&depth);
        for y in 0..h {
            for x in 0..w {
                let c = depth[(y, x)];
                let mut vals: Vec<f32> = (y.saturating_sub(1)..=(y + 1).min(h - 1))
                    .flat_map(|yy| {
                        (x.saturating_sub(1)..=(x + 1).min(w - 1)).map(move |xx| (yy, xx))
                    })
                    .map(|p| depth[p])
                    .filter(|&v| is_valid_depth(v))
                    .collect();
                vals.sort_by(f32::total_cmp);
                let (expect, flag) = if !is_valid_depth(c) {
                    (0.0, false)
                } else if vals.len() >= MIN_VALID_NEIGHBOURS
                    && !same_surface(vals[(vals.len() - 1) / 2], c)
                {
                    (vals[(vals.len() - 1) / 2], true)
                } else {
                    (c, false)
                };
                assert_eq!(out[(y, x)].to_bits(), expect.to_bits(), "({y},{x})");
                assert_eq!(flags[(y, x)], flag, "({y},{x})");
            }
        }
        assert!(flags.iter().filter(|&&f| f).count() > 20);
    }

    #[test]
    fn median_of_small_slices() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.0);
        assert_eq!(median(&mut [5.0]), 5.0);
    }
}
