//! Keeping depth on measured surfaces.
//!
//! A depth value is *on a surface* at a pixel when some valid reference depth within a small
//! window lies within the same-surface tolerance of it
//! ([`same_surface`]). A value that is on no nearby
//! surface floats in mid-air, between a foreground and a background: a flying pixel. The
//! classical refiner uses this rule twice: to move the flying pixels of the input onto the
//! neighbouring surface nearest in depth, and after smoothing, so that averaging across a
//! depth edge the guide does not show can never create a mid-air depth.

use ndarray::{ArrayView2, ArrayViewMut2};

use crate::filter::par_rows2;
use crate::geometry::surface::{is_valid_depth_branchless, same_surface};

/// For every pixel with a valid `value`: keeps it when a valid `reference` depth within
/// `radius` (Chebyshev distance, the pixel itself included) is on its surface, else replaces
/// it by the valid reference depth in that window nearest to it (the first in row-major order
/// on a tie); `0` when the window holds no valid reference or the value is invalid.
///
/// Writes into `snapped` whether the value was replaced.
///
/// # Panics
/// If the shapes differ.
pub fn snap_to_surface(
    value: ArrayView2<f32>,
    reference: ArrayView2<f32>,
    radius: usize,
    out: ArrayViewMut2<f32>,
    snapped: ArrayViewMut2<bool>,
) {
    let (h, w) = value.dim();
    assert_eq!(
        reference.dim(),
        (h, w),
        "snap_to_surface: reference shape differs from the values'"
    );
    assert_eq!(out.dim(), (h, w), "snap_to_surface: output shape differs");
    assert_eq!(snapped.dim(), (h, w), "snap_to_surface: flag shape differs");
    let reference = reference.as_standard_layout();
    let r = reference
        .as_slice()
        .expect("as_standard_layout yields a contiguous array");
    let value = value.as_standard_layout();
    let v = value
        .as_slice()
        .expect("as_standard_layout yields a contiguous array");
    par_rows2(out, snapped, |y, out_row, flag_row| {
        snap_row((v, r), (h, w), y, radius, out_row, flag_row);
    });
}

/// One row `y` of [`snap_to_surface`] (`v` the values, `r` the reference, whole images).
/// Compiled for AVX-512 and AVX2 as well, chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn snap_row(
    (v, r): (&[f32], &[f32]),
    (h, w): (usize, usize),
    y: usize,
    radius: usize,
    out_row: &mut [f32],
    flag_row: &mut [bool],
) {
    let value_row = &v[y * w..(y + 1) * w];
    let own_row = &r[y * w..(y + 1) * w];
    // The common case first, branch-free (vectorised): the pixel's own reference is on
    // the value's surface. Every other valid value is left at 0 here and searched for
    // below (a kept value is valid, so never 0).
    for (((o, f), &v), &own) in out_row
        .iter_mut()
        .zip(flag_row.iter_mut())
        .zip(value_row)
        .zip(own_row)
    {
        let keep =
            is_valid_depth_branchless(v) & is_valid_depth_branchless(own) & same_surface(own, v);
        (*o, *f) = (if keep { v } else { 0.0 }, false);
    }
    let (y0, y1) = (y.saturating_sub(radius), (y + radius).min(h - 1));
    // Every valid value not kept above: search the window, without branches on the data
    // (valid and invalid depths mix at random near holes): whether any valid reference is
    // on the value's surface, and the first (row-major) of the valid ones nearest to it.
    let search = |x: usize, v: f32| {
        let (x0, x1) = (x.saturating_sub(radius), (x + radius).min(w - 1));
        let mut nearest = (f32::INFINITY, 0.0f32);
        let mut on_surface = false;
        for yy in y0..=y1 {
            for &z in &r[yy * w + x0..=yy * w + x1] {
                let ok = is_valid_depth_branchless(z);
                on_surface |= ok & same_surface(z, v);
                let d = if ok { (z - v).abs() } else { f32::INFINITY };
                if d < nearest.0 {
                    nearest = (d, z);
                }
            }
        }
        if on_surface {
            (v, false)
        } else if nearest.0.is_finite() {
            (nearest.1, true)
        } else {
            (0.0, false)
        }
    };
    // The pixels to search are found 64 at a time as a bit mask: a branch per pixel on
    // whether it needs the search was mispredicted often enough to cost more than the
    // searches themselves.
    for start in (0..w).step_by(64) {
        let end = (start + 64).min(w);
        let mut pending = (start..end).fold(0u64, |bits, x| {
            let needs_search = (out_row[x] == 0.0) & is_valid_depth_branchless(value_row[x]);
            bits | (u64::from(needs_search) << (x - start))
        });
        while pending != 0 {
            let x = start + pending.trailing_zeros() as usize;
            pending &= pending - 1;
            (out_row[x], flag_row[x]) = search(x, value_row[x]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array2};

    fn run(
        value: &Array2<f32>,
        reference: &Array2<f32>,
        radius: usize,
    ) -> (Array2<f32>, Array2<bool>) {
        let mut out = Array2::zeros(value.dim());
        let mut flags = Array2::from_elem(value.dim(), false);
        snap_to_surface(
            value.view(),
            reference.view(),
            radius,
            out.view_mut(),
            flags.view_mut(),
        );
        (out, flags)
    }

    #[test]
    fn values_on_a_nearby_surface_are_kept() {
        // 1.02 is within 3 % of the 1.0 two columns away; 2.95 within 3 % of 3.0.
        let reference = array![[1.0f32, 0.0, 0.0, 3.0]];
        let value = array![[1.0f32, 1.02, 2.95, 3.0]];
        let (out, flags) = run(&value, &reference, 2);
        assert_eq!(out, value);
        assert!(flags.iter().all(|&f| !f));
    }

    #[test]
    fn mid_air_values_move_to_the_surface_nearest_in_depth() {
        let reference = array![[1.0f32, 0.0, 3.0], [1.0, 0.0, 3.0]];
        let value = array![[1.0f32, 1.6, 3.0], [1.0, 2.5, 3.0]];
        let (out, flags) = run(&value, &reference, 1);
        assert_eq!(out, array![[1.0f32, 1.0, 3.0], [1.0, 3.0, 3.0]]);
        assert_eq!(flags, array![[false, true, false], [false, true, false]]);
    }

    #[test]
    fn no_reference_in_reach_or_invalid_value_gives_zero() {
        let reference = array![[2.0f32, 0.0, 0.0, 0.0]];
        let value = array![[0.0f32, 2.0, 2.0, 7.0]];
        let (out, _) = run(&value, &reference, 1);
        // x=0: invalid value; x=1: 2.0 is on the surface at x=0; x=2, 3: nothing in reach.
        assert_eq!(out, array![[0.0f32, 2.0, 0.0, 0.0]]);
    }
}
