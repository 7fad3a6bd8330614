//! The per-pixel confidence published with the refined depth, `u8` 0..=255.
//!
//! Definition, for RGB pixel `p` with warped ToF depth `D_w` (the refinement's input) and
//! refined depth `D_out`:
//!
//! - `0` where `D_w(p)` is invalid (no ToF measurement maps to this RGB pixel: occlusion,
//!   outside the ToF image, dropout) or `D_out(p)` is not a positive finite depth;
//! - otherwise `round(255 · S(p) · A(p))` with
//!   - *support* `S(p)`: the fraction of the 3×3 neighbourhood (image border counts as
//!     missing) whose `D_w` is valid and on the same surface as `D_w(p)` (within
//!     `max(3 %·z, 1 cm)`, [`same_surface`](crate::geometry::surface::same_surface)). It is
//!     low next to holes, at depth edges and on flying pixels, exactly where a small alignment
//!     error changes the depth a lot;
//!   - *agreement* `A(p) = exp(−|D_out − D_w| / tol(D_w))`, `tol` the same-surface tolerance.
//!     The refinement moves a depth far mainly where it judges the measurement wrong (MPI,
//!     flying pixels); a pixel pulled one tolerance away from what was measured gets 0.37.
//!
//!   The result is clamped to at least 1: `0` exactly where the published depth is `0`.
//!
//! So 255 means "measured here, on a smooth surface, and the network agrees with the sensor".

use ndarray::{ArrayView2, ArrayViewMut2, Axis, Zip};
use rayon::prelude::*;

use crate::geometry::surface::{is_valid_depth, surface_tolerance};

/// Writes the confidence of `refined` given the refinement input `warped` into `out`.
///
/// Rows run in parallel on flat slices (non-contiguous inputs are copied once into standard
/// layout); see [`confidence_row`].
///
/// # Panics
/// If the three images do not share one shape.
pub fn confidence_into(
    warped: ArrayView2<f32>,
    refined: ArrayView2<f32>,
    mut out: ArrayViewMut2<u8>,
) {
    let (h, w) = warped.dim();
    assert_eq!(
        refined.dim(),
        (h, w),
        "refined and warped depth shapes differ"
    );
    assert_eq!(out.dim(), (h, w), "confidence and depth shapes differ");
    if h == 0 || w == 0 {
        return;
    }
    let (warped, refined) = (warped.as_standard_layout(), refined.as_standard_layout());
    let warped = warped.as_slice().expect("standard layout is contiguous");
    let refined = refined.as_slice().expect("standard layout is contiguous");
    let row_of = |y: usize| (y * w, (y + 1) * w);
    let support = || vec![0u8; w];
    match out.as_slice_mut() {
        Some(o) => o
            .par_chunks_mut(w)
            .enumerate()
            .for_each_init(support, |support, (y, row)| {
                let (a, b) = row_of(y);
                confidence_row(warped, &refined[a..b], w, y, support, |x, c| row[x] = c);
            }),
        None => Zip::indexed(out.axis_iter_mut(Axis(0))).par_for_each(|y, mut row| {
            let (a, b) = row_of(y);
            let mut support = support();
            confidence_row(warped, &refined[a..b], w, y, &mut support, |x, c| {
                row[x] = c
            });
        }),
    }
}

/// Confidence of row `y` (`warped` is the whole image, `refined` the row), passed to
/// `put(column, value)`; `support` is a row of scratch.
///
/// The 3×3 support of the pixels with all nine neighbours is counted first, for the whole row
/// in one branch-free loop ([`interior_support`], which the compiler vectorises), then each
/// pixel's value is made (the border's support counted there, over the rows and columns that
/// exist). `round` is done by truncation, which gives `f32::round`'s result for the
/// non-negative values below 2²³ met here: without SSE4.1 (the default x86-64 target)
/// `round` is a call per pixel.
#[inline]
fn confidence_row(
    warped: &[f32],
    refined: &[f32],
    w: usize,
    y: usize,
    support: &mut [u8],
    mut put: impl FnMut(usize, u8),
) {
    let h = warped.len() / w;
    let row = |yy: usize| &warped[yy * w..(yy + 1) * w];
    let centre = row(y);
    let above = (y > 0).then(|| row(y - 1));
    let below = (y + 1 < h).then(|| row(y + 1));
    let interior = match (above, below) {
        (Some(a), Some(b)) if w >= 3 => {
            interior_support(a, centre, b, &mut support[1..w - 1]);
            1..w - 1
        }
        _ => 0..0,
    };
    for (x, (&z, &r)) in centre.iter().zip(refined).enumerate() {
        if !is_valid_depth(z) || !is_valid_depth(r) {
            put(x, 0);
            continue;
        }
        let tol = surface_tolerance(z);
        let support = if interior.contains(&x) {
            u32::from(support[x])
        } else {
            let (x0, x1) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let mut support = 0u32;
            for r in [above, Some(centre), below].into_iter().flatten() {
                for &q in &r[x0..=x1] {
                    support += on_surface(z, tol, q);
                }
            }
            support
        };
        let agreement = (-(r - z).abs() / tol).exp();
        let c = 255.0 * support as f32 / 9.0 * agreement;
        let t = c as u32;
        let rounded = if c - t as f32 >= 0.5 { t + 1 } else { t };
        // At least 1: 0 is reserved for "no depth here", so a valid but barely supported depth
        // (e.g. a lone measured pixel the refinement moved far) must not read as invalid.
        put(x, rounded.clamp(1, 255) as u8);
    }
}

/// 1 when `q` is a valid depth on the surface of `z` (tolerance `tol`), else 0: `same_surface`
/// with the tolerance computed once, without short-circuits (depth edges and holes are
/// irregular, and mispredicted branches dominated the 2-D indexed version).
#[inline(always)]
fn on_surface(z: f32, tol: f32, q: f32) -> u32 {
    u32::from((q > 0.0) & q.is_finite() & ((q - z).abs() <= tol))
}

/// `r[..n]`, `r[1..n + 1]` and `r[2..n + 2]`.
#[inline(always)]
fn shifted(r: &[f32], n: usize) -> (&[f32], &[f32], &[f32]) {
    let r = &r[..n + 2];
    (&r[..n], &r[1..n + 1], &r[2..n + 2])
}

/// The 3×3 support of pixels `1..w−1` of the centre row (`out[i]` for column `i + 1`), from
/// the rows above and below: every neighbour exists. Written over equal-length shifted slices
/// so that the loop has no bounds checks and vectorises; an invalid centre gets a count that
/// [`confidence_row`] does not use.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl", "x86_64+avx2"))]
fn interior_support(above: &[f32], centre: &[f32], below: &[f32], out: &mut [u8]) {
    let n = out.len();
    let (a0, a1, a2) = shifted(above, n);
    let (c0, c1, c2) = shifted(centre, n);
    let (b0, b1, b2) = shifted(below, n);
    for i in 0..n {
        let z = c1[i];
        let tol = surface_tolerance(z);
        let on = |q: f32| on_surface(z, tol, q);
        let count = on(a0[i]) + on(a1[i]) + on(a2[i]) + on(c0[i]) + on(c1[i]) + on(c2[i]);
        out[i] = (count + on(b0[i]) + on(b1[i]) + on(b2[i])) as u8;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    #[test]
    fn full_confidence_inside_a_plane_and_none_at_holes() {
        let warped = Array2::from_elem((5, 5), 2.0f32);
        let mut refined = warped.clone();
        let mut out = Array2::zeros((5, 5));
        confidence_into(warped.view(), refined.view(), out.view_mut());
        assert_eq!(out[[2, 2]], 255);
        // Corner: 4 of 9 neighbours exist.
        assert_eq!(out[[0, 0]], (255.0f32 * 4.0 / 9.0).round() as u8);
        // A hole: zero there, and 8/9 support around it.
        let mut holed = warped.clone();
        holed[[2, 2]] = 0.0;
        confidence_into(holed.view(), refined.view(), out.view_mut());
        assert_eq!(out[[2, 2]], 0);
        assert_eq!(out[[2, 1]], (255.0f32 * 8.0 / 9.0).round() as u8);
        // Refinement moved the centre by one tolerance (6 cm at 2 m): exp(-1).
        refined[[2, 2]] = 2.06;
        confidence_into(warped.view(), refined.view(), out.view_mut());
        assert_eq!(out[[2, 2]], (255.0f32 * (-1.0f32).exp()).round() as u8);
        // An invalid refined depth gives zero.
        refined[[2, 2]] = f32::NAN;
        confidence_into(warped.view(), refined.view(), out.view_mut());
        assert_eq!(out[[2, 2]], 0);
    }

    #[test]
    fn depth_edges_lower_the_support() {
        // Left half at 1 m, right half at 3 m: pixels next to the edge see 6/9 same-surface.
        let warped = Array2::from_shape_fn((5, 6), |(_, x)| if x < 3 { 1.0f32 } else { 3.0 });
        let mut out = Array2::zeros((5, 6));
        confidence_into(warped.view(), warped.view(), out.view_mut());
        assert_eq!(out[[2, 2]], (255.0f32 * 6.0 / 9.0).round() as u8);
        assert_eq!(out[[2, 1]], 255);
    }

    #[test]
    fn zero_exactly_where_there_is_no_depth() {
        // A lone measured pixel among holes, which the refinement moved 50 tolerances away:
        // support 1/9, agreement e^-50; unclamped that rounds to 0 and reads as "no depth".
        let mut warped = Array2::zeros((5, 5));
        warped[[2, 2]] = 2.0f32;
        let mut refined = warped.clone();
        refined[[2, 2]] = 2.0 + 50.0 * surface_tolerance(2.0);
        let mut out = Array2::from_elem((5, 5), 7u8);
        confidence_into(warped.view(), refined.view(), out.view_mut());
        assert_eq!(out[[2, 2]], 1);
        for ((y, x), &c) in out.indexed_iter() {
            assert_eq!(c == 0, (y, x) != (2, 2), "({y}, {x})");
        }
    }
}
