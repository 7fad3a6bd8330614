//! Flying-pixel removal.
//!
//! A ToF pixel that straddles a depth edge integrates light from both surfaces and reports a
//! depth in between: a point floating in mid-air. Its signature is a pixel that lies strictly
//! between its two neighbours along some direction and is on the same surface as neither.
//! Requiring "between" keeps thin structures (a wire in front of a wall is nearer than both
//! sides) and smooth slopes (a tilted plane is within tolerance of its neighbours).

use ndarray::{ArrayView2, ArrayViewMut2};

use crate::filter::par_rows;
use crate::geometry::surface::{is_valid_depth, is_valid_depth_branchless};
use crate::vector_math::window3x3;

/// Copy `depth` into `out`, writing `0` for invalid pixels and for flying pixels: those that,
/// along some direction (horizontal, vertical, either diagonal) with both neighbours valid, lie strictly between the two neighbours and
/// differ from each by more than `max(rel · z, abs_m)`.
///
/// # Panics
/// If the shapes differ.
pub fn remove_flying_pixels(depth: ArrayView2<f32>, rel: f32, abs_m: f32, out: ArrayViewMut2<f32>) {
    assert_eq!(
        depth.dim(),
        out.dim(),
        "remove_flying_pixels: output shape differs from the input"
    );
    let (h, w) = depth.dim();
    let depth = depth.as_standard_layout();
    let d = depth
        .as_slice()
        .expect("as_standard_layout yields a contiguous array");
    par_rows(out, |y, row| {
        let cur = &d[y * w..(y + 1) * w];
        // The general test, for the image border (no vertical or diagonal pair in the first
        // and last rows, no horizontal or diagonal pair in the first and last columns).
        let general = |x: usize| {
            let z = cur[x];
            if !is_valid_depth(z) {
                return 0.0;
            }
            let tol = (rel * z).max(abs_m);
            let has_lr = x > 0 && x + 1 < w;
            let mut flying = has_lr && mixed(z, tol, cur[x - 1], cur[x + 1]);
            if y > 0 && y + 1 < h {
                let (up, down) = (&d[(y - 1) * w..y * w], &d[(y + 1) * w..(y + 2) * w]);
                flying |= mixed(z, tol, up[x], down[x]);
                if has_lr {
                    flying |= mixed(z, tol, up[x - 1], down[x + 1])
                        | mixed(z, tol, up[x + 1], down[x - 1]);
                }
            }
            if flying {
                0.0
            } else {
                z
            }
        };
        if y == 0 || y + 1 >= h || w < 3 {
            for (x, o) in row.iter_mut().enumerate() {
                *o = general(x);
            }
            return;
        }
        // Interior: every pair exists, and the loop is branch-free (vectorised). The windows
        // are the left, centre and right neighbours of each interior pixel in the three rows.
        let (up, down) = (&d[(y - 1) * w..y * w], &d[(y + 1) * w..(y + 2) * w]);
        interior_row(window3x3([up, cur, down]), (rel, abs_m), &mut row[1..w - 1]);
        row[0] = general(0);
        row[w - 1] = general(w - 1);
    });
}

/// Whether `z` lies strictly between `a` and `b` and off both surfaces (tolerance `tol`).
/// Evaluated without short-circuits: on noisy depth the "between" test is a coin flip, and a
/// mispredicted branch costs more than the arithmetic.
#[inline(always)]
fn mixed(z: f32, tol: f32, a: f32, b: f32) -> bool {
    let (da, db) = (z - a, b - z);
    (da.abs() > tol)
        & (db.abs() > tol)
        & (da * db > 0.0)
        & is_valid_depth_branchless(a)
        & is_valid_depth_branchless(b)
}

/// The interior pixels of one row of [`remove_flying_pixels`]: `window` holds the nine shifted
/// neighbour slices (row-major: up-left … down-right), `out` the row's interior. Branch-free
/// (on noisy depth the "between" test is a coin flip); compiled for AVX-512 and AVX2 as well,
/// chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn interior_row(window: [&[f32]; 9], (rel, abs_m): (f32, f32), out: &mut [f32]) {
    let n = out.len();
    let [ul, uc, ur, cl, cc, cr, dl, dc, dr] = window.map(|s| &s[..n]);
    for i in 0..n {
        let z = cc[i];
        let tol = (rel * z).max(abs_m);
        let flying = mixed(z, tol, cl[i], cr[i])
            | mixed(z, tol, uc[i], dc[i])
            | mixed(z, tol, ul[i], dr[i])
            | mixed(z, tol, ur[i], dl[i]);
        out[i] = if is_valid_depth_branchless(z) & !flying {
            z
        } else {
            0.0
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array2};

    fn run(depth: &Array2<f32>) -> Array2<f32> {
        let mut out = Array2::zeros(depth.dim());
        remove_flying_pixels(depth.view(), 0.03, 0.01, out.view_mut());
        out
    }

    #[test]
    fn mixed_pixel_on_an_edge_is_removed() {
        let d = array![
            [1.0f32, 1.0, 1.7, 3.0, 3.0],
            [1.0, 1.0, 1.7, 3.0, 3.0],
            [1.0, 1.0, 1.7, 3.0, 3.0]
        ];
        let out = run(&d);
        for y in 0..3 {
            assert_eq!(out[(y, 2)], 0.0);
            assert_eq!(out[(y, 1)], 1.0);
            assert_eq!(out[(y, 3)], 3.0);
        }
    }

    #[test]
    fn thin_structures_slopes_and_holes_are_kept() {
        // A wire (nearer than both sides), a gentle slope, an invalid pixel.
        let d = array![
            [2.0f32, 2.0, 1.0, 2.0, 2.0],
            [2.0, 2.02, 2.04, 2.06, 2.08],
            [2.0, 0.0, 2.0, 2.0, 2.0]
        ];
        let out = run(&d);
        assert_eq!(out[(0, 2)], 1.0);
        assert_eq!(out.row(1), d.row(1));
        assert_eq!(out[(2, 1)], 0.0);
        assert_eq!(out[(2, 2)], 2.0);
    }
}
