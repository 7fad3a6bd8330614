//! Window sums over `(2r+1) × (2r+1)` boxes in O(N), independent of the radius.
//!
//! Two separable passes with running sums: along rows (one task per row), then down columns
//! (one task per block of [`COLUMN_BLOCK`] columns, whose accumulators live on the stack, so a
//! call never allocates). Accumulators are f64 so that sliding over a 640-pixel row does not
//! drift. Windows are clipped at the image border (sums over the in-image part only); callers
//! divide by a box sum of the mask, so clipping needs no correction.

use ndarray::{ArrayView2, ArrayViewMut2, Axis};
use rayon::prelude::*;

/// Columns handled by one task of the vertical pass.
const COLUMN_BLOCK: usize = 64;

/// Rows handled together by one task of the horizontal pass.
const ROW_GROUP: usize = 4;

/// `out(y, x) = Σ src(y', x')` over `|y'−y| ≤ r`, `|x'−x| ≤ r` inside the image. `tmp` holds
/// the horizontal pass.
///
/// # Panics
/// If the three arrays do not share one shape.
pub fn box_sum(
    src: ArrayView2<f32>,
    r: usize,
    mut tmp: ArrayViewMut2<f32>,
    mut out: ArrayViewMut2<f32>,
) {
    assert_eq!(
        src.dim(),
        tmp.dim(),
        "box_sum: scratch shape differs from the source"
    );
    assert_eq!(
        src.dim(),
        out.dim(),
        "box_sum: output shape differs from the source"
    );
    let (h, w) = src.dim();
    if h == 0 || w == 0 {
        return;
    }
    let src = src.as_standard_layout();
    let src_flat = src
        .as_slice()
        .expect("as_standard_layout yields a contiguous array");
    // Horizontal pass, ROW_GROUP rows per task interleaved: each running sum is a chain of
    // dependent additions, and independent chains side by side keep the FPU busy.
    tmp.axis_chunks_iter_mut(Axis(0), ROW_GROUP)
        .into_par_iter()
        .enumerate()
        .for_each(|(g, mut t)| {
            let y0 = g * ROW_GROUP;
            let rows = t.nrows();
            let row = |k: usize| &src_flat[(y0 + k) * w..(y0 + k + 1) * w];
            let mut acc = [0.0f64; ROW_GROUP];
            for (k, a) in acc.iter_mut().enumerate().take(rows) {
                *a = row(k)[..=r.min(w - 1)].iter().map(|&v| f64::from(v)).sum();
            }
            for x in 0..w {
                for (k, a) in acc.iter_mut().enumerate().take(rows) {
                    let s = row(k);
                    t[(k, x)] = *a as f32;
                    let add = if x + r + 1 < w {
                        f64::from(s[x + r + 1])
                    } else {
                        0.0
                    };
                    let sub = if x >= r { f64::from(s[x - r]) } else { 0.0 };
                    *a += add - sub;
                }
            }
        });
    let tmp = tmp.view();
    out.axis_chunks_iter_mut(Axis(1), COLUMN_BLOCK)
        .into_par_iter()
        .zip(tmp.axis_chunks_iter(Axis(1), COLUMN_BLOCK).into_par_iter())
        .for_each(|(mut o, t)| {
            let cw = t.ncols();
            let mut acc = [0.0f64; COLUMN_BLOCK];
            for y in 0..=r.min(h - 1) {
                for (a, &v) in acc.iter_mut().zip(t.row(y)) {
                    *a += f64::from(v);
                }
            }
            for y in 0..h {
                for (ov, &a) in o.row_mut(y).iter_mut().zip(&acc[..cw]) {
                    *ov = a as f32;
                }
                if y + r + 1 < h {
                    for (a, &v) in acc.iter_mut().zip(t.row(y + r + 1)) {
                        *a += f64::from(v);
                    }
                }
                if y >= r {
                    for (a, &v) in acc.iter_mut().zip(t.row(y - r)) {
                        *a -= f64::from(v);
                    }
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    fn brute(src: &Array2<f32>, r: usize) -> Array2<f32> {
        let (h, w) = src.dim();
        Array2::from_shape_fn((h, w), |(y, x)| {
            let mut s = 0.0;
            for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
                for xx in x.saturating_sub(r)..=(x + r).min(w - 1) {
                    s += src[(yy, xx)];
                }
            }
            s
        })
    }

    #[test]
    fn matches_brute_force_including_borders_and_wide_images() {
        for &(h, w, r) in &[(7, 9, 2), (5, 150, 3), (3, 4, 6), (1, 1, 1), (20, 70, 0)] {
            let src = Array2::from_shape_fn((h, w), |(y, x)| ((y * 31 + x * 17) % 23) as f32 - 5.0);
            let mut tmp = Array2::zeros((h, w));
            let mut out = Array2::zeros((h, w));
            box_sum(src.view(), r, tmp.view_mut(), out.view_mut());
            let want = brute(&src, r);
            for (a, b) in out.iter().zip(&want) {
                assert!((a - b).abs() < 1e-3, "{h}x{w} r={r}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn ones_count_the_clipped_window() {
        let src = Array2::from_elem((6, 6), 1.0f32);
        let mut tmp = Array2::zeros((6, 6));
        let mut out = Array2::zeros((6, 6));
        box_sum(src.view(), 1, tmp.view_mut(), out.view_mut());
        assert_eq!(out[(0, 0)], 4.0);
        assert_eq!(out[(0, 3)], 6.0);
        assert_eq!(out[(3, 3)], 9.0);
    }
}
