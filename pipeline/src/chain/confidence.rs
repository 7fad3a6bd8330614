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

use crate::geometry::surface::{is_valid_depth, is_valid_depth_branchless, surface_tolerance};
use crate::vector_math::{exp_fast, floor_small, window3x3};

/// Writes the expected-error codes (`dear_proto::confidence`) of a guarded refiner's
/// `published` depth into `out`: `code_for_log_error(log_error)` where the depth is valid, 0
/// where it is not. `log_error` is `ln` of the expected absolute error in metres
/// (`BundleRunner::expected_log_error`).
///
/// # Panics
/// If the three images do not share one shape.
pub fn expected_error_confidence_into(
    published: ArrayView2<f32>,
    log_error: ArrayView2<f32>,
    mut out: ArrayViewMut2<u8>,
) {
    assert_eq!(
        published.dim(),
        log_error.dim(),
        "depth and error shapes differ"
    );
    assert_eq!(
        published.dim(),
        out.dim(),
        "confidence and depth shapes differ"
    );
    Zip::from(&mut out)
        .and(&published)
        .and(&log_error)
        .par_for_each(|o, &z, &e| {
            *o = if is_valid_depth(z) {
                dear_proto::confidence::code_for_log_error(e)
            } else {
                0
            };
        });
}

/// Writes the confidence of `refined` given the refinement input `warped` into `out`.
///
/// Rows run in parallel on flat slices (non-contiguous inputs are copied once into standard
/// layout); see `confidence_row`.
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
                confidence_row(warped, &refined[a..b], y, support, row);
            }),
        None => Zip::indexed(out.axis_iter_mut(Axis(0))).par_for_each(|y, mut row| {
            let (a, b) = row_of(y);
            let (mut support, mut values) = (support(), vec![0u8; w]);
            confidence_row(warped, &refined[a..b], y, &mut support, &mut values);
            row.iter_mut().zip(values).for_each(|(o, v)| *o = v);
        }),
    }
}

/// Confidence of row `y` into `out` (`warped` is the whole image, `refined` the row);
/// `support` is a row of scratch.
///
/// Pixels with all nine neighbours go through [`interior_support`] and [`interior_confidence`],
/// loops the compiler vectorises; the border (the first and last column, and the first and last
/// row whole) through [`pixel_confidence`], the definition, which counts the support over the
/// rows and columns that exist.
#[inline]
fn confidence_row(warped: &[f32], refined: &[f32], y: usize, support: &mut [u8], out: &mut [u8]) {
    let w = refined.len();
    let h = warped.len() / w;
    let row = |yy: usize| &warped[yy * w..(yy + 1) * w];
    let centre = row(y);
    let above = (y > 0).then(|| row(y - 1));
    let below = (y + 1 < h).then(|| row(y + 1));
    let border: &mut dyn Iterator<Item = usize> = match (above, below) {
        (Some(a), Some(b)) if w >= 3 => {
            let inner = 1..w - 1;
            interior_support(a, centre, b, &mut support[inner.clone()]);
            interior_confidence(
                &centre[inner.clone()],
                &refined[inner.clone()],
                &mut support[inner.clone()],
                &mut out[inner.clone()],
            );
            // The rare pixel too close to a rounding boundary for the fast `exp`: flagged in
            // `support`, made again by the definition.
            for x in inner.filter(|&x| support[x] != 0) {
                out[x] = pixel_confidence(above, centre, below, refined[x], x);
            }
            &mut [0, w - 1].into_iter()
        }
        _ => &mut (0..w),
    };
    for x in border {
        out[x] = pixel_confidence(above, centre, below, refined[x], x);
    }
}

/// The definition at column `x`, for any pixel: the support counted over the rows (`above`,
/// `centre`, `below`) and columns that exist, `f32::exp` for the agreement, and `round` done
/// by truncation, which gives `f32::round`'s result for the non-negative values below 2²³ met
/// here (without SSE4.1, the default x86-64 target, `round` is a call per pixel).
fn pixel_confidence(
    above: Option<&[f32]>,
    centre: &[f32],
    below: Option<&[f32]>,
    r: f32,
    x: usize,
) -> u8 {
    let z = centre[x];
    if !is_valid_depth(z) || !is_valid_depth(r) {
        return 0;
    }
    let tol = surface_tolerance(z);
    let (x0, x1) = (x.saturating_sub(1), (x + 1).min(centre.len() - 1));
    let mut support = 0u32;
    for r in [above, Some(centre), below].into_iter().flatten() {
        for &q in &r[x0..=x1] {
            support += on_surface(z, tol, q);
        }
    }
    let agreement = (-(r - z).abs() / tol).exp();
    let c = 255.0 * support as f32 / 9.0 * agreement;
    let t = c as u32;
    let rounded = if c - t as f32 >= 0.5 { t + 1 } else { t };
    // At least 1: 0 is reserved for "no depth here", so a valid but barely supported depth
    // (e.g. a lone measured pixel the refinement moved far) must not read as invalid.
    rounded.clamp(1, 255) as u8
}

/// How close (in 1/255 units) to a rounding boundary the fast path's value may be and still be
/// trusted: [`exp_fast`]'s relative error (below 10⁻⁶, tested with it) and the standard `exp`'s
/// last bit move a value of at most 255 by less than 3·10⁻⁴.
const ROUNDING_MARGIN: f32 = 1e-3;

/// [`pixel_confidence`] of interior pixels from their counted `support` (replaced by 1 where
/// the result must be made again by the definition, else 0), with [`exp_fast`] and rounding
/// without a float-to-integer conversion, written with selects so that it vectorises. The
/// result equals the definition's wherever the value is not within [`ROUNDING_MARGIN`] of a
/// rounding boundary; those pixels are flagged.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn interior_confidence(centre: &[f32], refined: &[f32], support: &mut [u8], out: &mut [u8]) {
    let n = out.len();
    let (centre, refined, support) = (&centre[..n], &refined[..n], &mut support[..n]);
    for i in 0..n {
        let (z, r) = (centre[i], refined[i]);
        let ok = is_valid_depth_branchless(z) & is_valid_depth_branchless(r);
        let tol = surface_tolerance(z);
        let agreement = exp_fast(-(r - z).abs() / tol);
        let c = 255.0 * f32::from(support[i]) / 9.0 * agreement;
        // Only a valid pixel's value is in [0, 255], where `floor_small` holds; the others
        // are replaced by 0 below whatever it returns.
        let c = if ok { c } else { 0.0 };
        let t = floor_small(c);
        let fraction = c - t as f32;
        let rounded = t + u32::from(fraction >= 0.5);
        let near_boundary = ok & ((fraction - 0.5).abs() < ROUNDING_MARGIN);
        out[i] = if ok { rounded.clamp(1, 255) as u8 } else { 0 };
        support[i] = u8::from(near_boundary);
    }
}

/// 1 when `q` is a valid depth on the surface of `z` (tolerance `tol`), else 0: `same_surface`
/// with the tolerance computed once, without short-circuits (depth edges and holes are
/// irregular, and mispredicted branches dominated the 2-D indexed version).
#[inline(always)]
fn on_surface(z: f32, tol: f32, q: f32) -> u32 {
    u32::from((q > 0.0) & q.is_finite() & ((q - z).abs() <= tol))
}

/// The 3×3 support of pixels `1..w−1` of the centre row (`out[i]` for column `i + 1`), from
/// the rows above and below: every neighbour exists. Written over equal-length shifted slices
/// so that the loop has no bounds checks and vectorises; an invalid centre gets a count that
/// [`confidence_row`] does not use.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn interior_support(above: &[f32], centre: &[f32], below: &[f32], out: &mut [u8]) {
    let n = out.len();
    let [a0, a1, a2, c0, c1, c2, b0, b1, b2] = window3x3([above, centre, below]).map(|s| &s[..n]);
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

    /// Every pixel is the definition's value ([`pixel_confidence`]), bit for bit: on a frame
    /// with holes, NaNs and depth steps, and refined depths placed so that most values land
    /// within a hair of a rounding boundary, where the fast `exp` alone would round some of
    /// them the other way.
    #[test]
    fn every_pixel_is_the_definition() {
        let (h, w) = (40, 211);
        let warped = Array2::from_shape_fn((h, w), |(y, x)| match (x * 7 + y * 13) % 29 {
            0 => 0.0,
            1 => f32::NAN,
            k if x < 90 => 0.8 + 0.0005 * k as f32,
            k => 2.4 + 0.001 * k as f32,
        });
        let refined = Array2::from_shape_fn((h, w), |(y, x)| {
            let z = warped[(y, x)];
            if (x + y) % 31 == 0 {
                return 0.0;
            }
            // 255 · exp(−d / tol) = k + ½ for a level k picked per pixel.
            let level = ((x * 5 + y * 11) % 254) as f32 + 1.5;
            let d = -surface_tolerance(z) * (level / 255.0).ln();
            if x % 2 == 0 {
                z + d
            } else {
                z - d
            }
        });
        let mut out = Array2::zeros((h, w));
        confidence_into(warped.view(), refined.view(), out.view_mut());
        let row = |y: usize| warped.row(y).to_slice().unwrap();
        for ((y, x), &c) in out.indexed_iter() {
            let (above, below) = ((y > 0).then(|| row(y - 1)), (y + 1 < h).then(|| row(y + 1)));
            let expected = pixel_confidence(above, row(y), below, refined[(y, x)], x);
            assert_eq!(c, expected, "({y}, {x})");
        }
        assert!(out.iter().filter(|&&c| c > 1 && c < 255).count() > h * w / 2);
    }
}
