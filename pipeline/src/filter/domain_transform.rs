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
//! Cost: O(N) per iteration, independent of `σ_s`. A link's weight depends only on its
//! integer colour difference, so the weights come from a table of `exp` (later rounds square
//! them: `σ_H` halves, so `a^d` squares).

use ndarray::{Array2, ArrayView1, ArrayView3, ArrayViewMut1, ArrayViewMut2, Axis, Zip};
use rayon::prelude::*;

use crate::geometry::surface::is_valid_depth;

/// Columns handled by one task of the vertical pass (a block of the three arrays stays in the
/// core's cache between the two directions).
const COLUMN_BLOCK: usize = 64;

/// Rows filtered together by the horizontal pass. A row's recursion is a serial chain of
/// dependent operations, so one row at a time runs at the latency of that chain; the rows of
/// a group are interleaved (transposed into a tile `[x][row]`) and run side by side as SIMD
/// lanes. Every lane computes exactly the scalar recursion, so the result is unchanged.
const GROUP_ROWS: usize = 16;

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
    /// Feedback weights of the link (x−1 → x) of each pixel, in the horizontal pass's tiles:
    /// group `g` of [`GROUP_ROWS`] rows holds `[x][row]` (rows past the image's last are
    /// padding, weight 0); `x = 0` unused (0).
    w_h: Vec<f32>,
    /// Feedback weights of the link (y−1 → y) of each pixel; row 0 unused.
    w_v: Array2<f32>,
    num: Array2<f32>,
    den: Array2<f32>,
    /// The horizontal pass's tiles of `num` and `den` (layout as `w_h`).
    tile_num: Vec<f32>,
    tile_den: Vec<f32>,
    /// `exp(−k·d)` for every summed colour difference (an integer), so that the weights cost
    /// a table look-up instead of an `exp` per pixel and direction.
    table: Vec<f32>,
}

impl DomainTransformScratch {
    /// Buffers for `(h, w)` images.
    pub fn new(h: usize, w: usize) -> Self {
        let z = || Array2::zeros((h, w));
        let tiled = h.div_ceil(GROUP_ROWS) * GROUP_ROWS * w;
        DomainTransformScratch {
            w_h: vec![0.0; tiled],
            w_v: z(),
            num: z(),
            den: z(),
            tile_num: vec![0.0; tiled],
            tile_den: vec![0.0; tiled],
            table: Vec::with_capacity(3 * 255 + 1),
        }
    }

    /// `(h, w)` the buffers are sized for.
    pub fn dim(&self) -> (usize, usize) {
        self.num.dim()
    }
}

/// Sum over channels of `|a_c − b_c|`.
#[inline(always)]
fn colour_l1(a: &[u8], b: &[u8]) -> usize {
    a.iter()
        .zip(b)
        .map(|(&p, &q)| usize::from(p.abs_diff(q)))
        .sum()
}

/// Calls `f(x, Σ_c |a_c − b_c|)` for the pixels `x` of two pixel rows (`channels`
/// interleaved; the shorter row's length counts), with the common 3-channel case
/// specialised so that the sum is unrolled.
#[inline(always)]
fn for_each_link(a: &[u8], b: &[u8], channels: usize, mut f: impl FnMut(usize, usize)) {
    match channels {
        0 => {}
        3 => {
            for (x, (p, q)) in a.chunks_exact(3).zip(b.chunks_exact(3)).enumerate() {
                f(x, colour_l1(p, q));
            }
        }
        c => {
            for (x, (p, q)) in a.chunks_exact(c).zip(b.chunks_exact(c)).enumerate() {
                f(x, colour_l1(p, q));
            }
        }
    }
}

/// Smooths `depth` (`0` = invalid) guided by `guide` (`(H, W, C)` 8-bit colour) into `out`,
/// over the valid pixels only; writes `0` where no valid pixel is within reach.
///
/// # Panics
/// If the shapes differ from each other or from the scratch's.
pub fn domain_transform_masked(
    guide: ArrayView3<u8>,
    depth: ndarray::ArrayView2<f32>,
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
    let DomainTransformScratch {
        w_h,
        w_v,
        num,
        den,
        tile_num,
        tile_den,
        table,
    } = scratch;
    let guide = guide.as_standard_layout();
    let channels = guide.dim().2;
    let g = guide
        .as_slice()
        .expect("as_standard_layout yields a contiguous array");
    let depth = depth.as_standard_layout();
    let d = depth
        .as_slice()
        .expect("as_standard_layout yields a contiguous array");

    let iterations = params.iterations.max(1);
    let ratio = params.sigma_space / params.sigma_colour.max(f32::MIN_POSITIVE);

    // First round: σ_H,1 = σ_s·√3·2^(N−1)/√(4^N − 1); each later round halves σ_H.
    let sigma_h1 = params.sigma_space.max(1e-3) * 3f32.sqrt() * 2f32.powi(iterations as i32 - 1)
        / (4f32.powi(iterations as i32) - 1.0).sqrt();
    let k = std::f32::consts::SQRT_2 / sigma_h1;
    // The distance `1 + ratio · Σ|ΔI|` of a link depends only on the integer colour sum, which
    // an `f32` holds exactly: the table gives every link exactly the weight `exp` would.
    table.clear();
    table.extend((0..=255 * channels).map(|s| (-k * (1.0 + ratio * s as f32)).exp()));
    let table = &table[..];

    let (Some(num_s), Some(den_s), Some(w_v_s)) =
        (num.as_slice_mut(), den.as_slice_mut(), w_v.as_slice_mut())
    else {
        unreachable!("scratch arrays are in standard layout")
    };
    let tile = GROUP_ROWS * w;
    num_s
        .par_chunks_mut(tile)
        .zip(den_s.par_chunks_mut(tile))
        .zip(w_v_s.par_chunks_mut(tile))
        .zip(w_h.par_chunks_mut(tile))
        .enumerate()
        .for_each(|(group, (((num, den), w_v), w_h))| {
            let y_first = group * GROUP_ROWS;
            let rows = num.len() / w;
            for r in 0..rows {
                let y = y_first + r;
                let px = &g[y * w * channels..(y + 1) * w * channels];
                w_h[r] = 0.0;
                for_each_link(px, &px[channels.min(px.len())..], channels, |x, s| {
                    w_h[(x + 1) * GROUP_ROWS + r] = table[s];
                });
                let w_v = &mut w_v[r * w..(r + 1) * w];
                if y == 0 {
                    w_v.fill(0.0);
                } else {
                    let above = &g[(y - 1) * w * channels..y * w * channels];
                    for_each_link(above, px, channels, |x, s| w_v[x] = table[s]);
                }
                for ((n, m), &z) in num[r * w..(r + 1) * w]
                    .iter_mut()
                    .zip(&mut den[r * w..(r + 1) * w])
                    .zip(&d[y * w..(y + 1) * w])
                {
                    (*n, *m) = if is_valid_depth(z) {
                        (z, 1.0)
                    } else {
                        (0.0, 0.0)
                    };
                }
            }
            // Padding rows of the last group: weight 0 (their lanes stay 0).
            for r in rows..GROUP_ROWS {
                for x in 0..w {
                    w_h[x * GROUP_ROWS + r] = 0.0;
                }
            }
        });

    for round in 0..iterations {
        if round > 0 {
            // σ_H halves: a^d becomes (a^d)².
            w_h.par_iter_mut().for_each(|a| *a *= *a);
            w_v.par_mapv_inplace(|a| a * a);
        }
        horizontal_pass(num, den, w_h, tile_num, tile_den);
        vertical_pass(num, den, w_v);
    }

    Zip::from(&mut out)
        .and(&*num)
        .and(&*den)
        .par_for_each(|o, &n, &m| {
            *o = if m > MIN_WEIGHT { n / m } else { 0.0 };
        });
}

/// Copies the rows of `rows` (row-major, `w` wide) into lanes of `tile` (`[x][lane]`),
/// zeroing the lanes past the last row.
#[inline(always)]
fn rows_to_tile(rows: &[f32], tile: &mut [f32], w: usize) {
    let n = rows.len() / w;
    if n == GROUP_ROWS {
        return transpose(rows, (GROUP_ROWS, w), tile);
    }
    for (x, lanes) in tile.chunks_exact_mut(GROUP_ROWS).enumerate() {
        for (r, lane) in lanes.iter_mut().enumerate() {
            *lane = if r < n { rows[r * w + x] } else { 0.0 };
        }
    }
}

/// The inverse of [`rows_to_tile`] (padding lanes are dropped).
#[inline(always)]
fn tile_to_rows(tile: &[f32], rows: &mut [f32], w: usize) {
    let n = rows.len() / w;
    if n == GROUP_ROWS {
        return transpose(tile, (w, GROUP_ROWS), rows);
    }
    for (r, row) in rows.chunks_exact_mut(w).enumerate() {
        for (v, lanes) in row.iter_mut().zip(tile.chunks_exact(GROUP_ROWS)) {
            *v = lanes[r];
        }
    }
}

/// Writes the transpose of the row-major `(rows, cols)` matrix `src` into `dst` (row-major
/// `(cols, rows)`), in 4 × 4 blocks (four loads of four, four stores of four), which the
/// compiler turns into vector shuffles instead of a scalar load and store per value.
#[inline(always)]
fn transpose(src: &[f32], (rows, cols): (usize, usize), dst: &mut [f32]) {
    let (whole_r, whole_c) = (rows / 4 * 4, cols / 4 * 4);
    for r in (0..whole_r).step_by(4) {
        for c in (0..whole_c).step_by(4) {
            let mut block = [[0.0f32; 4]; 4];
            for (i, b) in block.iter_mut().enumerate() {
                let o = (r + i) * cols + c;
                b.copy_from_slice(&src[o..o + 4]);
            }
            for (k, t) in transpose4(&block).iter().enumerate() {
                let o = (c + k) * rows + r;
                dst[o..o + 4].copy_from_slice(t);
            }
        }
    }
    // The columns past the last whole block, then the rows past it.
    for r in 0..whole_r {
        for c in whole_c..cols {
            dst[c * rows + r] = src[r * cols + c];
        }
    }
    for r in whole_r..rows {
        for c in 0..cols {
            dst[c * rows + r] = src[r * cols + c];
        }
    }
}

/// The transpose of a 4 × 4 block (written out: the compiler makes it four shuffles).
#[inline(always)]
fn transpose4(b: &[[f32; 4]; 4]) -> [[f32; 4]; 4] {
    [
        [b[0][0], b[1][0], b[2][0], b[3][0]],
        [b[0][1], b[1][1], b[2][1], b[3][1]],
        [b[0][2], b[1][2], b[2][2], b[3][2]],
        [b[0][3], b[1][3], b[2][3], b[3][3]],
    ]
}

/// The lanes of column `x` of a tile.
#[inline(always)]
fn lanes(tile: &[f32], x: usize) -> [f32; GROUP_ROWS] {
    tile[x * GROUP_ROWS..(x + 1) * GROUP_ROWS]
        .try_into()
        .expect("a tile holds GROUP_ROWS lanes per column")
}

/// One step of a recursion on `GROUP_ROWS` lanes: `cur += a · (prev − cur)`; returns the new
/// lanes, the next step's `prev`.
#[inline(always)]
fn recurse_lanes(cur: &mut [f32], prev: &[f32; GROUP_ROWS], a: &[f32]) -> [f32; GROUP_ROWS] {
    let (cur, a) = (&mut cur[..GROUP_ROWS], &a[..GROUP_ROWS]);
    for l in 0..GROUP_ROWS {
        cur[l] += a[l] * (prev[l] - cur[l]);
    }
    // Read back from the values just computed: the compiler keeps them in registers (an
    // `array::from_fn` here was not inlined and took the pass from 4.5 to 7 ms).
    lanes(cur, 0)
}

/// Recursive filter along every row, left to right then right to left, on both signals;
/// one task per group of [`GROUP_ROWS`] rows, filtered side by side in a tile.
fn horizontal_pass(
    num: &mut Array2<f32>,
    den: &mut Array2<f32>,
    w_h: &[f32],
    tile_num: &mut [f32],
    tile_den: &mut [f32],
) {
    let w = num.ncols();
    let (Some(num), Some(den)) = (num.as_slice_mut(), den.as_slice_mut()) else {
        unreachable!("scratch arrays are in standard layout")
    };
    let tile = GROUP_ROWS * w;
    num.par_chunks_mut(tile)
        .zip(den.par_chunks_mut(tile))
        .zip(w_h.par_chunks(tile))
        .zip(tile_num.par_chunks_mut(tile))
        .zip(tile_den.par_chunks_mut(tile))
        .for_each(|((((num, den), a), tn), tm)| filter_group(num, den, a, tn, tm, w));
}

/// One group of [`GROUP_ROWS`] rows of [`horizontal_pass`]: into tiles, both directions of the
/// recursion, back into rows. Compiled for AVX-512 and AVX2 as well (a tile step is then one or
/// two vectors instead of four), chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn filter_group(
    num: &mut [f32],
    den: &mut [f32],
    a: &[f32],
    tn: &mut [f32],
    tm: &mut [f32],
    w: usize,
) {
    rows_to_tile(num, tn, w);
    rows_to_tile(den, tm, w);
    // Each step's lanes are passed to the next as a value (registers), not read again from the
    // tile: the recursion is a chain of dependent steps, and a store-to-load round trip per
    // step lengthened it.
    let (mut pn, mut pm) = (lanes(tn, 0), lanes(tm, 0));
    for x in 1..w {
        let at = x * GROUP_ROWS..(x + 1) * GROUP_ROWS;
        pn = recurse_lanes(&mut tn[at.clone()], &pn, &a[at.clone()]);
        pm = recurse_lanes(&mut tm[at.clone()], &pm, &a[at]);
    }
    for x in (0..w - 1).rev() {
        let (at, link) = (
            x * GROUP_ROWS..(x + 1) * GROUP_ROWS,
            &a[(x + 1) * GROUP_ROWS..],
        );
        pn = recurse_lanes(&mut tn[at.clone()], &pn, link);
        pm = recurse_lanes(&mut tm[at], &pm, link);
    }
    tile_to_rows(tn, num, w);
    tile_to_rows(tm, den, w);
}

/// One step of the vertical recursion on a row segment: `cur += a · (prev − cur)`, for both
/// signals. Compiled for AVX-512 and AVX2 as well, chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn recurse_row(n: &mut [f32], m: &mut [f32], a: &[f32], prev_n: &[f32], prev_m: &[f32]) {
    let len = n.len();
    let (m, a, prev_n, prev_m) = (&mut m[..len], &a[..len], &prev_n[..len], &prev_m[..len]);
    for i in 0..len {
        n[i] += a[i] * (prev_n[i] - n[i]);
        m[i] += a[i] * (prev_m[i] - m[i]);
    }
}

/// The contiguous slices of two rows of a column block.
fn slices<'a>(
    n: ArrayViewMut1<'a, f32>,
    m: ArrayViewMut1<'a, f32>,
) -> (&'a mut [f32], &'a mut [f32]) {
    let (Some(n), Some(m)) = (n.into_slice(), m.into_slice()) else {
        unreachable!("rows of a column block are contiguous")
    };
    (n, m)
}

/// The contiguous slice of a row of a column block.
fn row(a: ArrayView1<'_, f32>) -> &[f32] {
    let Some(a) = a.to_slice() else {
        unreachable!("rows of a column block are contiguous")
    };
    a
}

/// Recursive filter down every column, top to bottom then bottom to top, on both signals;
/// one task per block of columns (which stays in the core's cache between the two
/// directions).
fn vertical_pass(num: &mut Array2<f32>, den: &mut Array2<f32>, w_v: &Array2<f32>) {
    num.axis_chunks_iter_mut(Axis(1), COLUMN_BLOCK)
        .into_par_iter()
        .zip(den.axis_chunks_iter_mut(Axis(1), COLUMN_BLOCK))
        .zip(w_v.axis_chunks_iter(Axis(1), COLUMN_BLOCK))
        .for_each(|((mut n, mut m), a)| {
            // Top to bottom, the link of row y joining it to row y−1.
            let mut rows = n.rows_mut().into_iter().zip(m.rows_mut());
            let Some((n0, m0)) = rows.next() else { return };
            let mut prev = slices(n0, m0);
            for ((nr, mr), ar) in rows.zip(a.rows().into_iter().skip(1)) {
                let (nr, mr) = slices(nr, mr);
                recurse_row(nr, mr, row(ar), prev.0, prev.1);
                prev = (nr, mr);
            }
            // Bottom to top, row y joined to row y+1 by row y+1's link.
            let mut rows = n.rows_mut().into_iter().zip(m.rows_mut()).rev();
            let Some((n0, m0)) = rows.next() else { return };
            let mut prev = slices(n0, m0);
            for ((nr, mr), ar) in rows.zip(a.rows().into_iter().rev()) {
                let (nr, mr) = slices(nr, mr);
                recurse_row(nr, mr, row(ar), prev.0, prev.1);
                prev = (nr, mr);
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

    /// The filter written plainly (one `exp` per link, one row or column at a time): the
    /// optimised passes (weight table, row tiles, column blocks) must match it bit for bit.
    fn reference(depth: &Array2<f32>, rgb: &Array3<u8>, p: &DomainTransformParams) -> Array2<f32> {
        let (h, w) = depth.dim();
        let iterations = p.iterations.max(1);
        let ratio = p.sigma_space / p.sigma_colour.max(f32::MIN_POSITIVE);
        let sigma_h1 = p.sigma_space.max(1e-3) * 3f32.sqrt() * 2f32.powi(iterations as i32 - 1)
            / (4f32.powi(iterations as i32) - 1.0).sqrt();
        let k = std::f32::consts::SQRT_2 / sigma_h1;
        let l1 = |a: (usize, usize), b: (usize, usize)| -> f32 {
            (0..rgb.dim().2)
                .map(|c| f32::from(rgb[(a.0, a.1, c)].abs_diff(rgb[(b.0, b.1, c)])))
                .sum()
        };
        let mut wh = Array2::from_shape_fn((h, w), |(y, x)| {
            if x == 0 {
                0.0
            } else {
                (-k * (1.0 + ratio * l1((y, x), (y, x - 1)))).exp()
            }
        });
        let mut wv = Array2::from_shape_fn((h, w), |(y, x)| {
            if y == 0 {
                0.0
            } else {
                (-k * (1.0 + ratio * l1((y, x), (y - 1, x)))).exp()
            }
        });
        let mut n = depth.mapv(|z| if is_valid_depth(z) { z } else { 0.0 });
        let mut m = depth.mapv(|z| if is_valid_depth(z) { 1.0f32 } else { 0.0 });
        for round in 0..iterations {
            if round > 0 {
                wh.mapv_inplace(|a| a * a);
                wv.mapv_inplace(|a| a * a);
            }
            for s in [&mut n, &mut m] {
                for y in 0..h {
                    for x in 1..w {
                        s[(y, x)] += wh[(y, x)] * (s[(y, x - 1)] - s[(y, x)]);
                    }
                    for x in (0..w - 1).rev() {
                        s[(y, x)] += wh[(y, x + 1)] * (s[(y, x + 1)] - s[(y, x)]);
                    }
                }
                for x in 0..w {
                    for y in 1..h {
                        s[(y, x)] += wv[(y, x)] * (s[(y - 1, x)] - s[(y, x)]);
                    }
                    for y in (0..h - 1).rev() {
                        s[(y, x)] += wv[(y + 1, x)] * (s[(y + 1, x)] - s[(y, x)]);
                    }
                }
            }
        }
        Array2::from_shape_fn(
            (h, w),
            |i| if m[i] > MIN_WEIGHT { n[i] / m[i] } else { 0.0 },
        )
    }

    #[test]
    fn matches_the_plain_filter_bit_for_bit() {
        // Sizes that are not multiples of the row group or the column block, noisy depth
        // with holes and NaN, textured colour; also 1 and 4 channels.
        for (h, w, channels, iterations) in [
            (37, 83, 3, 3),
            (16, 64, 3, 2),
            (5, 130, 1, 1),
            (19, 7, 4, 3),
        ] {
            let depth = Array2::from_shape_fn((h, w), |(y, x)| {
                let i = y * w + x;
                match i % 17 {
                    3 => 0.0,
                    9 => f32::NAN,
                    _ => (if x < w / 2 { 1.2 } else { 2.7 }) + 0.03 * gauss(i),
                }
            });
            let rgb = Array3::from_shape_fn((h, w, channels), |(y, x, c)| {
                ((x * 37 + y * 11 + c * 5 + (x / 9) * 90) % 256) as u8
            });
            let p = DomainTransformParams {
                iterations,
                ..PARAMS
            };
            let (out, expect) = (run(&depth, &rgb, &p), reference(&depth, &rgb, &p));
            for (i, (a, b)) in out.iter().zip(&expect).enumerate() {
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "{h}x{w}x{channels} pixel {i}: {a} vs {b}"
                );
            }
        }
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
