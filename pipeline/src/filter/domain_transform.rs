//! Edge-aware smoothing of depth with the domain transform (Gastal & Oliveira, "Domain
//! Transform for Edge-Aware Image and Video Processing", SIGGRAPH 2011), recursive-filter
//! variant, guided by the RGB image and normalised over the valid depth pixels.
//!
//! The domain transform maps each image line to a 1-D domain in which neighbours `x−1, x` lie
//! `d = 1 + (σ_s / σ_r) · Σ_c |I_c(x) − I_c(x−1)|` apart (`I` in 8-bit RGB units): one pixel in
//! flat colour, far apart across colour edges. A first-order recursive filter with feedback
//! `a^d` (`a = exp(−√2 / σ_H)`) then smooths with a spatial scale of `σ_s` pixels inside
//! regions of similar colour and stops at colour edges. Horizontal and vertical passes
//! alternate for [`DomainTransformParams::iterations`] rounds with `σ_H` shrinking as in the
//! paper (`σ_H,i = σ_s·√3·2^(N−i)/√(4^N − 1)`), so the 2-D result has spatial scale ≈ `σ_s`.
//!
//! Invalid depth (`0`) never enters the average: the filter runs on `m·z` and on the mask
//! `m` with the same weights, and the output is their ratio (normalised convolution). A
//! constant depth is therefore reproduced exactly, and holes neither pull their neighbours
//! towards zero nor need filling first.
//!
//! Cost: O(N) per iteration, independent of `σ_s`; one `exp` per pixel and direction (later
//! rounds square the weights: `σ_H` halves, so `a^d` squares).

use ndarray::{Array2, ArrayView2, ArrayView3, ArrayViewMut2, Axis, Zip};
use rayon::prelude::*;

use crate::geometry::surface::is_valid_depth;

/// Columns handled by one task of the vertical pass (their carries live on the stack).
const COLUMN_BLOCK: usize = 64;

/// Below this total weight of valid pixels the output is `0` (no valid pixel within reach).
const MIN_WEIGHT: f32 = 1e-12;

/// Settings of [`domain_transform_masked`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DomainTransformParams {
    /// Spatial scale σ_s, pixels.
    pub sigma_space: f32,
    /// Colour scale σ_r, in 8-bit units of the per-channel absolute differences summed over
    /// R, G and B: a colour step of `σ_r` counts as `σ_s` extra pixels of distance.
    pub sigma_colour: f32,
    /// Rounds of horizontal + vertical passes (3 in the paper; at least 1).
    pub iterations: usize,
}

/// Buffers of [`domain_transform_masked`], reused across frames.
#[derive(Debug, Clone)]
pub struct DomainTransformScratch {
    /// Feedback weights of the link (x−1 → x) of each pixel; column 0 unused.
    w_h: Array2<f32>,
    /// Feedback weights of the link (y−1 → y) of each pixel; row 0 unused.
    w_v: Array2<f32>,
    num: Array2<f32>,
    den: Array2<f32>,
}

impl DomainTransformScratch {
    /// Buffers for `(h, w)` images.
    pub fn new(h: usize, w: usize) -> Self {
        let z = || Array2::zeros((h, w));
        DomainTransformScratch {
            w_h: z(),
            w_v: z(),
            num: z(),
            den: z(),
        }
    }

    /// `(h, w)` the buffers are sized for.
    pub fn dim(&self) -> (usize, usize) {
        self.num.dim()
    }
}

/// Sum over channels of `|a_c − b_c|`.
#[inline]
fn colour_l1(a: &[u8], b: &[u8]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(&p, &q)| f32::from(p.abs_diff(q)))
        .sum()
}

/// Smooths `depth` (`0` = invalid) guided by `guide` (`(H, W, C)` 8-bit colour) into `out`,
/// over the valid pixels only; writes `0` where no valid pixel is within reach.
///
/// # Panics
/// If the shapes differ from each other or from the scratch's.
pub fn domain_transform_masked(
    guide: ArrayView3<u8>,
    depth: ArrayView2<f32>,
    params: &DomainTransformParams,
    scratch: &mut DomainTransformScratch,
    mut out: ArrayViewMut2<f32>,
) {
    let (h, w) = depth.dim();
    assert_eq!(
        (guide.dim().0, guide.dim().1),
        (h, w),
        "domain_transform_masked: guide shape differs from the depth's"
    );
    assert_eq!(
        out.dim(),
        (h, w),
        "domain_transform_masked: output shape differs from the depth's"
    );
    assert_eq!(
        scratch.dim(),
        (h, w),
        "domain_transform_masked: scratch sized for another shape"
    );
    if h == 0 || w == 0 {
        return;
    }
    let DomainTransformScratch { w_h, w_v, num, den } = scratch;
    let guide = guide.as_standard_layout();
    let channels = guide.dim().2;
    let g = guide
        .as_slice()
        .expect("as_standard_layout yields a contiguous array");
    let pixel = |y: usize, x: usize| {
        let i = (y * w + x) * channels;
        &g[i..i + channels]
    };

    let iterations = params.iterations.max(1);
    let ratio = params.sigma_space / params.sigma_colour.max(f32::MIN_POSITIVE);

    // First round: σ_H,1 = σ_s·√3·2^(N−1)/√(4^N − 1); each later round halves σ_H.
    let sigma_h1 = params.sigma_space.max(1e-3) * 3f32.sqrt() * 2f32.powi(iterations as i32 - 1)
        / (4f32.powi(iterations as i32) - 1.0).sqrt();
    let k = std::f32::consts::SQRT_2 / sigma_h1;
    Zip::indexed(w_h.rows_mut())
        .and(w_v.rows_mut())
        .par_for_each(|y, mut wh, mut wv| {
            wh[0] = 0.0;
            for x in 1..w {
                let d = 1.0 + ratio * colour_l1(pixel(y, x), pixel(y, x - 1));
                wh[x] = (-k * d).exp();
            }
            for x in 0..w {
                wv[x] = if y == 0 {
                    0.0
                } else {
                    let d = 1.0 + ratio * colour_l1(pixel(y, x), pixel(y - 1, x));
                    (-k * d).exp()
                };
            }
        });
    Zip::from(&mut *num)
        .and(&mut *den)
        .and(&depth)
        .par_for_each(|n, m, &z| {
            (*n, *m) = if is_valid_depth(z) {
                (z, 1.0)
            } else {
                (0.0, 0.0)
            };
        });

    for round in 0..iterations {
        if round > 0 {
            // σ_H halves: a^d becomes (a^d)².
            w_h.par_mapv_inplace(|a| a * a);
            w_v.par_mapv_inplace(|a| a * a);
        }
        horizontal_pass(num, den, w_h.view());
        vertical_pass(num, den, w_v.view());
    }

    Zip::from(&mut out)
        .and(&*num)
        .and(&*den)
        .par_for_each(|o, &n, &m| {
            *o = if m > MIN_WEIGHT { n / m } else { 0.0 };
        });
}

/// Recursive filter along every row, left to right then right to left, on both signals.
fn horizontal_pass(num: &mut Array2<f32>, den: &mut Array2<f32>, w_h: ArrayView2<f32>) {
    Zip::from(num.rows_mut())
        .and(den.rows_mut())
        .and(w_h.rows())
        .par_for_each(|mut n, mut m, a| {
            let (Some(n), Some(m), Some(a)) = (n.as_slice_mut(), m.as_slice_mut(), a.as_slice())
            else {
                unreachable!("rows of standard-layout arrays are contiguous")
            };
            let w = n.len();
            for x in 1..w {
                n[x] += a[x] * (n[x - 1] - n[x]);
                m[x] += a[x] * (m[x - 1] - m[x]);
            }
            for x in (0..w - 1).rev() {
                n[x] += a[x + 1] * (n[x + 1] - n[x]);
                m[x] += a[x + 1] * (m[x + 1] - m[x]);
            }
        });
}

/// One step of the vertical recursion on a row segment: `row += a · (carry − row)`, then
/// `carry = row`, for both signals.
#[inline]
fn recurse_row(n: &mut [f32], m: &mut [f32], a: &[f32], carry_n: &mut [f32], carry_m: &mut [f32]) {
    for ((((n, m), &a), cn), cm) in n
        .iter_mut()
        .zip(m.iter_mut())
        .zip(a)
        .zip(carry_n.iter_mut())
        .zip(carry_m.iter_mut())
    {
        *n += a * (*cn - *n);
        *m += a * (*cm - *m);
        *cn = *n;
        *cm = *m;
    }
}

/// Recursive filter down every column, top to bottom then bottom to top, on both signals;
/// one task per block of columns, whose carries (the previous row) live on the stack.
fn vertical_pass(num: &mut Array2<f32>, den: &mut Array2<f32>, w_v: ArrayView2<f32>) {
    let h = num.nrows();
    num.axis_chunks_iter_mut(Axis(1), COLUMN_BLOCK)
        .into_par_iter()
        .zip(den.axis_chunks_iter_mut(Axis(1), COLUMN_BLOCK))
        .zip(w_v.axis_chunks_iter(Axis(1), COLUMN_BLOCK))
        .for_each(|((mut n, mut m), a)| {
            let cw = n.ncols();
            let mut carry_n = [0.0f32; COLUMN_BLOCK];
            let mut carry_m = [0.0f32; COLUMN_BLOCK];
            let (carry_n, carry_m) = (&mut carry_n[..cw], &mut carry_m[..cw]);
            for (c, &v) in carry_n.iter_mut().zip(n.row(0)) {
                *c = v;
            }
            for (c, &v) in carry_m.iter_mut().zip(m.row(0)) {
                *c = v;
            }
            // Top to bottom, the link of row y joining it to row y−1; then bottom to top, row
            // y joined to row y+1 by row y+1's link (the carry starts as the last row).
            let rows = (1..h)
                .map(|y| (y, y))
                .chain((0..h.saturating_sub(1)).rev().map(|y| (y, y + 1)));
            for (y, link) in rows {
                let mut nr = n.row_mut(y);
                let mut mr = m.row_mut(y);
                let ar = a.row(link);
                let (Some(nr), Some(mr), Some(ar)) =
                    (nr.as_slice_mut(), mr.as_slice_mut(), ar.as_slice())
                else {
                    unreachable!("rows of a column block are contiguous")
                };
                recurse_row(nr, mr, ar, carry_n, carry_m);
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::tests::gauss;
    use ndarray::Array3;

    const PARAMS: DomainTransformParams = DomainTransformParams {
        sigma_space: 4.0,
        sigma_colour: 60.0,
        iterations: 3,
    };

    fn run(depth: &Array2<f32>, rgb: &Array3<u8>, params: &DomainTransformParams) -> Array2<f32> {
        let (h, w) = depth.dim();
        let mut s = DomainTransformScratch::new(h, w);
        let mut out = Array2::zeros((h, w));
        domain_transform_masked(rgb.view(), depth.view(), params, &mut s, out.view_mut());
        out
    }

    fn rms(v: impl Iterator<Item = f32>) -> f32 {
        let v: Vec<f32> = v.collect();
        (v.iter().map(|x| x * x).sum::<f32>() / v.len() as f32).sqrt()
    }

    #[test]
    fn constant_depth_is_unchanged_around_holes_and_colour_edges() {
        let (h, w) = (23, 150); // wider than two column blocks
        let mut depth = Array2::from_elem((h, w), 2.5f32);
        depth.slice_mut(ndarray::s![5..9, 10..30]).fill(0.0);
        depth[(0, 0)] = f32::NAN;
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, c)| {
            ((x * 37 + y * 11 + c * 5) % 256) as u8
        });
        let out = run(&depth, &rgb, &PARAMS);
        for ((y, x), &z) in out.indexed_iter() {
            assert!((z - 2.5).abs() < 1e-5, "({y},{x}): {z}");
        }
    }

    #[test]
    fn hole_does_not_pull_neighbours_towards_zero() {
        // The right half is invalid; the measured pixels next to it keep the plane's depth,
        // and the reachable hole pixels get it too.
        let (h, w) = (20, 40);
        let depth = Array2::from_shape_fn((h, w), |(_, x)| if x < 20 { 1.5f32 } else { 0.0 });
        let rgb = Array3::from_elem((h, w, 3), 100u8);
        let out = run(&depth, &rgb, &PARAMS);
        for y in 0..h {
            assert!((out[(y, 19)] - 1.5).abs() < 1e-5, "{}", out[(y, 19)]);
            assert!((out[(y, 25)] - 1.5).abs() < 1e-5, "{}", out[(y, 25)]);
        }
        // Nothing valid at all → 0 everywhere.
        let out = run(&Array2::zeros((h, w)), &rgb, &PARAMS);
        assert!(out.iter().all(|&z| z == 0.0));
    }

    #[test]
    fn noise_on_a_plane_is_reduced_five_fold() {
        // σ_s = 4 px: white noise drops ~6.7× (measured; the recursive filter's kernel is
        // exponential, with heavier tails and a sharper peak than a Gaussian's).
        let (h, w) = (80, 100);
        let depth = Array2::from_shape_fn((h, w), |(y, x)| 3.0 + 0.05 * gauss(y * w + x));
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, c)| {
            (120 + (x * 7 + y * 13 + c) % 9) as u8
        });
        let out = run(&depth, &rgb, &PARAMS);
        let inner = |a: &Array2<f32>| {
            a.slice(ndarray::s![8..h - 8, 8..w - 8])
                .iter()
                .map(|z| z - 3.0)
                .collect::<Vec<_>>()
        };
        let (before, after) = (rms(inner(&depth).into_iter()), rms(inner(&out).into_iter()));
        assert!(before > 0.045, "input noise {before}");
        assert!(after < before / 5.0, "rms {before} → {after}");
    }

    #[test]
    fn step_edge_along_a_colour_edge_stays_sharp() {
        // 1 m dark left, 2 m bright right (a colour step of 3·160 = 480 ≫ σ_r = 60).
        let (h, w) = (30, 40);
        let depth = Array2::from_shape_fn((h, w), |(_, x)| if x < 20 { 1.0f32 } else { 2.0 });
        let rgb = Array3::from_shape_fn((h, w, 3), |(_, x, _)| if x < 20 { 40 } else { 200 });
        let out = run(&depth, &rgb, &PARAMS);
        for ((y, x), &z) in out.indexed_iter() {
            let level = if x < 20 { 1.0 } else { 2.0 };
            assert!((z - level).abs() < 1e-3, "({y},{x}): {z}");
        }
        // Without the colour edge the same step is smeared (what the refiner's surface snap
        // is for): the filter is edge-aware through the guide only.
        let flat = Array3::from_elem((h, w, 3), 120u8);
        let out = run(&depth, &flat, &PARAMS);
        assert!((out[(15, 19)] - 1.0).abs() > 0.1, "{}", out[(15, 19)]);
    }

    #[test]
    fn a_single_round_and_a_single_pixel_work() {
        let p = DomainTransformParams {
            iterations: 1,
            ..PARAMS
        };
        let depth = Array2::from_elem((1, 1), 0.7f32);
        let out = run(&depth, &Array3::zeros((1, 1, 3)), &p);
        assert!((out[(0, 0)] - 0.7).abs() < 1e-6);
    }
}
