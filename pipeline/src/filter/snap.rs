//! Keeping depth on measured surfaces.
//!
//! A depth value is *on a surface* at a pixel when some valid reference depth within a small
//! window lies within the same-surface tolerance of it
//! ([`same_surface`](crate::geometry::surface::same_surface)). A value that is on no nearby
//! surface floats in mid-air, between a foreground and a background: a flying pixel. The
//! classical refiner uses this rule twice: to move the flying pixels of the input onto the
//! neighbouring surface nearest in depth, and after smoothing, so that averaging across a
//! depth edge the guide does not show can never create a mid-air depth.

use ndarray::{ArrayView2, ArrayViewMut2, Axis, Zip};

use crate::geometry::surface::{is_valid_depth, same_surface};

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
    mut out: ArrayViewMut2<f32>,
    mut snapped: ArrayViewMut2<bool>,
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
    Zip::indexed(out.axis_iter_mut(Axis(0)))
        .and(snapped.axis_iter_mut(Axis(0)))
        .and(value.axis_iter(Axis(0)))
        .par_for_each(|y, mut out_row, mut flag_row, value_row| {
            let (y0, y1) = (y.saturating_sub(radius), (y + radius).min(h - 1));
            for (x, (o, f)) in out_row.iter_mut().zip(flag_row.iter_mut()).enumerate() {
                let v = value_row[x];
                *f = false;
                *o = 0.0;
                if !is_valid_depth(v) {
                    continue;
                }
                // The common case first: the pixel's own reference is on the value's surface.
                let own = r[y * w + x];
                if is_valid_depth(own) && same_surface(own, v) {
                    *o = v;
                    continue;
                }
                let (x0, x1) = (x.saturating_sub(radius), (x + radius).min(w - 1));
                let mut nearest = (f32::INFINITY, 0.0f32);
                let mut on_surface = false;
                'window: for yy in y0..=y1 {
                    for &z in &r[yy * w + x0..=yy * w + x1] {
                        if !is_valid_depth(z) {
                            continue;
                        }
                        if same_surface(z, v) {
                            on_surface = true;
                            break 'window;
                        }
                        let d = (z - v).abs();
                        if d < nearest.0 {
                            nearest = (d, z);
                        }
                    }
                }
                if on_surface {
                    *o = v;
                } else if nearest.0.is_finite() {
                    (*o, *f) = (nearest.1, true);
                }
            }
        });
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
