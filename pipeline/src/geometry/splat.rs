//! Forward splatting with a z-buffer: synthesise the RGB view a perturbed calibration would
//! have produced (the paper's §4.3 augmentation and the simulator's perturbation step).
//!
//! Input: an aligned sample on the ToF grid (RGB and ground-truth depth) and a perturbation
//! `P`, meaning "the RGB→ToF flow of the new view is `W(p) = P.flow_at(z(p))`". A ToF pixel `q`
//! at depth `z` therefore lands at `q − P.flow_at(z)` in the virtual RGB view, keeping its
//! depth (a pure x/y baseline shift does not change depth).
//!
//! Splatting, in three passes:
//! 1. every source point spreads bilinear weights over the four target pixels around its
//!    landing point; contributions with weight ≤ [`SPLAT_MIN_WEIGHT`] are dropped (numerical
//!    dust must not claim a pixel); each target keeps the nearest depth (the z-buffer);
//! 2. each target accumulates the contributions on the same surface as its nearest one
//!    ([`same_surface`]: within 3 % / 1 cm), so a foreground never blends with what it hides;
//! 3. a target whose accumulated weight (coverage) reaches [`SPLAT_MIN_COVERAGE`] is valid,
//!    with the weight-normalised colour and depth; others (disocclusions, the border the view
//!    moved away from, mixed pixels where the front surface covers less than half) are
//!    invalid: depth 0, colour black, flow 0, `valid = false`.
//!
//! Bilinear splatting followed by normalisation reproduces a sub-pixel shift of a linear image
//! exactly (the weights at a target are those bilinear *sampling* would use), so smooth images
//! shift accurately. The returned flow is recomputed from the output depth, so at valid pixels
//! it is exactly `P.flow_at(depth)`.

use ndarray::{Array2, Array3, ArrayView2, ArrayView3, ArrayViewMut2, Axis};
use rayon::prelude::*;

use crate::geometry::surface::{is_valid_depth, is_valid_depth_branchless, same_surface};
use crate::geometry::warp::bilinear_weights;
use dear_capture::calibration::Calibration;
use dear_capture::frame::Flow;

/// Contributions at or below this bilinear weight are ignored.
pub const SPLAT_MIN_WEIGHT: f32 = 1e-3;

/// Minimum front-surface coverage (sum of bilinear weights) for a synthesised pixel to be
/// valid. At 0.5, a foreground edge moves by the nearest whole pixel instead of smearing.
pub const SPLAT_MIN_COVERAGE: f32 = 0.5;

/// A synthesised view and its ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthesizedView {
    /// Colour in the virtual RGB view `(H, W, C)`; black where invalid.
    pub rgb: Array3<u8>,
    /// Ground-truth depth in the virtual RGB view, metres; 0 where invalid.
    pub depth: Array2<f32>,
    /// Ground-truth RGB→ToF flow on the virtual RGB grid: `P.flow_at(depth)` where valid, 0
    /// elsewhere.
    pub flow: Flow,
    /// Where the view has content.
    pub valid: Array2<bool>,
}

/// The cell a point splatted at `(tx, ty)` falls in: its top-left pixel `(x0, y0)` and the
/// bilinear weights of the taps `(y0, x0), (y0, x0+1), (y0+1, x0), (y0+1, x0+1)`, or `None`
/// for a non-finite (or absurdly far, ≥ 1e9 px) point.
#[inline]
fn splat_cell(tx: f32, ty: f32) -> Option<(i64, i64, [f32; 4])> {
    // Written so that NaN fails the test.
    if !(tx.abs() < 1e9 && ty.abs() < 1e9) {
        return None;
    }
    let (x0, y0, wts) = cell_within_range(tx, ty);
    Some((i64::from(x0), i64::from(y0), wts))
}

/// [`splat_cell`] of a point the caller has found finite and within 1e9 px of the origin
/// (any other point is taken as the origin).
///
/// `floor` is computed by truncation: without SSE4.1 (the default x86-64 target) `f32::floor`
/// is a call per tap point, which was a tenth of the daemon's splat. The result is the same:
/// `|t| < 1e9 < 2³¹`, and for `|t| ≥ 2²³` every `f32` is already an integer. The truncation is
/// `to_int_unchecked`, not `as i32`, which saturates and which the compiler converts one lane
/// at a time ([`prepare_run`] vectorises over this).
#[inline(always)]
fn cell_within_range(tx: f32, ty: f32) -> (i32, i32, [f32; 4]) {
    let floor = |t: f32| {
        // The callers pass only such values; the select keeps the function sound for any.
        let t = if t.abs() < 1e9 { t } else { 0.0 };
        // SAFETY: `t` is finite and below 1e9 < 2³¹ in magnitude, so its truncation is an i32
        // value (`to_int_unchecked`'s requirement).
        let i = unsafe { t.to_int_unchecked::<i32>() };
        if i as f32 > t {
            i - 1
        } else {
            i
        }
    };
    let (x0, y0) = (floor(tx), floor(ty));
    let (fx, fy) = (tx - x0 as f32, ty - y0 as f32);
    (x0, y0, bilinear_weights(fx, fy))
}

/// Target pixels and bilinear weights of a point splatted at `(tx, ty)`, clipped to the
/// image and to weights above [`SPLAT_MIN_WEIGHT`].
fn splat_taps(tx: f32, ty: f32, h: usize, w: usize) -> impl Iterator<Item = ((usize, usize), f32)> {
    splat_cell(tx, ty)
        .into_iter()
        .flat_map(move |(x0, y0, wts)| {
            [(0i64, 0i64), (0, 1), (1, 0), (1, 1)]
                .into_iter()
                .zip(wts)
                .filter_map(move |((dy, dx), wt)| {
                    let (y, x) = (y0 + dy, x0 + dx);
                    (wt > SPLAT_MIN_WEIGHT
                        && y >= 0
                        && x >= 0
                        && (y as usize) < h
                        && (x as usize) < w)
                        .then_some(((y as usize, x as usize), wt))
                })
        })
}

/// Passes 1 and 2 of the module's method: the accumulated bilinear weight, weighted depth
/// and (when colour is splatted) weighted colour of the front surface at every target pixel,
/// as flat row-major buffers. Kept between calls by [`SplatScratch`] users: the daemon splats
/// every frame, and fresh 640×480 buffers cost page faults each time.
///
/// The depth-only path ([`splat_depth_with`], the daemon's per-frame alignment) keeps its own
/// buffers: the landing point of every source pixel, computed once, and the passes run per band
/// of target rows in parallel (see `SplatScratch::resolve`).
#[derive(Debug, Clone, Default)]
pub struct SplatScratch {
    zbuf: Vec<f32>,
    weight: Vec<f32>,
    /// Weight of every surface that landed, front or not.
    any_weight: Vec<f32>,
    depth_sum: Vec<f32>,
    /// Depth-only path: the splat cell of every source pixel ([`splat_cell`] of its landing
    /// point, computed once: each band's two passes read it instead of recomputing it).
    cells: Vec<Cell>,
    /// Depth-only path: the source depth, row-major.
    source: Vec<f32>,
    /// Depth-only path: lowest and highest top tap row of each [`SPAN_CHUNK`]-pixel run of a
    /// source row (`(i32::MAX, i32::MIN)` when it has no cell), row-major, so a band skips the
    /// runs that cannot reach it.
    span: Vec<(i32, i32)>,
    /// Depth-only path, per target pixel: `[z-buffer, front weight, any weight, depth sum]`
    /// side by side, the four values each tap touches.
    acc: Vec<[f32; 4]>,
    /// Depth-only path: the output when the caller's view is not contiguous.
    out: Vec<f32>,
}

/// Where source pixel `(y, x)` of depth `z` lands in the target view, if it is a valid source.
#[inline]
fn landing(perturbation: &Calibration, y: usize, x: usize, z: f32) -> Option<(f32, f32)> {
    if !is_valid_depth(z) {
        return None;
    }
    let (fu, fv) = perturbation.flow_at(z)?;
    Some((x as f32 - fu, y as f32 - fv))
}

impl SplatScratch {
    /// Runs passes 1 and 2 over `depth`; `colour_sum` (`(H, W, C)`) also accumulates `rgb`.
    /// The passes index flat buffers: the tests run the daemon unoptimised, where 2-D ndarray
    /// indexing costs several times more. Landing points are recomputed in pass 2 rather than
    /// stored (one division per pixel is cheaper than a 6 MB list at VGA).
    fn splat_front(
        &mut self,
        depth: ArrayView2<f32>,
        perturbation: &Calibration,
        mut colour: Option<(ArrayView3<u8>, &mut Array3<f32>)>,
    ) {
        let (h, w) = depth.dim();
        let reset = |v: &mut Vec<f32>, fill: f32| {
            v.clear();
            v.resize(h * w, fill);
        };
        reset(&mut self.zbuf, f32::INFINITY);
        reset(&mut self.weight, 0.0);
        reset(&mut self.any_weight, 0.0);
        reset(&mut self.depth_sum, 0.0);

        // Pass 1: z-buffer.
        for ((y, x), &z) in depth.indexed_iter() {
            let Some((tx, ty)) = landing(perturbation, y, x, z) else {
                continue;
            };
            for ((ty, tx), _) in splat_taps(tx, ty, h, w) {
                let t = ty * w + tx;
                if z < self.zbuf[t] {
                    self.zbuf[t] = z;
                }
            }
        }

        // Pass 2: accumulate the front surface.
        for ((sy, sx), &z) in depth.indexed_iter() {
            let Some((tx, ty)) = landing(perturbation, sy, sx, z) else {
                continue;
            };
            for ((ty, tx), wt) in splat_taps(tx, ty, h, w) {
                let t = ty * w + tx;
                self.any_weight[t] += wt;
                if same_surface(self.zbuf[t], z) {
                    self.weight[t] += wt;
                    self.depth_sum[t] += wt * z;
                    if let Some((rgb, csum)) = colour.as_mut() {
                        for ch in 0..rgb.dim().2 {
                            csum[(ty, tx, ch)] += wt * f32::from(rgb[(sy, sx, ch)]);
                        }
                    }
                }
            }
        }
    }
}

/// Source pixels per landing-row span of the depth-only splat: with a span per whole source row,
/// one flying pixel or near outlier (its flow `t/z` is tens of pixels) stretches that row's span
/// over many bands, which then all walk the row; per 64-pixel run it widens only its own run.
/// (On the measured 640×480 frame the change made no measurable difference; it bounds the
/// worst case.)
const SPAN_CHUNK: usize = 64;

/// A source pixel's [`splat_cell`]: the top-left tap `(x0, y0)` and the four bilinear weights;
/// `y0 == NO_CELL` when the pixel has none (invalid depth or a non-finite landing point).
#[derive(Debug, Clone, Copy, Default)]
struct Cell {
    x0: i32,
    y0: i32,
    wts: [f32; 4],
}

const NO_CELL: i32 = i32::MIN;

/// Calls `f(target index within the band, weight, source depth)` for every tap of the
/// depth-only splat that lands in target rows `r0..r1`, in row-major source order and the
/// fixed tap order (those of [`splat_taps`]), skipping the [`SPAN_CHUNK`] runs whose span
/// cannot reach the band. A tap row is `floor(ty)` or `floor(ty) + 1`.
///
/// Taps of weight ≤ [`SPLAT_MIN_WEIGHT`] are *not* filtered out when all four taps of a cell
/// are inside the band: `f` must give them no effect itself, with selects rather than
/// branches (see `SplatScratch::resolve`). Outside that common case only taps above the
/// threshold are passed.
#[inline(always)]
fn band_taps(
    cells: &[Cell],
    source: &[f32],
    spans: &[(i32, i32)],
    w: usize,
    (r0, r1): (usize, usize),
    mut f: impl FnMut(usize, f32, f32),
) {
    let (r0i, r1i) = (r0 as i64, r1 as i64);
    let runs = w.div_ceil(SPAN_CHUNK);
    for (run, &(lo, hi)) in spans.iter().enumerate() {
        if !(i64::from(hi) + 1 >= r0i && i64::from(lo) < r1i) {
            continue;
        }
        let (sy, start) = (run / runs, (run % runs) * SPAN_CHUNK);
        let range = sy * w + start..sy * w + (start + SPAN_CHUNK).min(w);
        let (cells, src) = (&cells[range.clone()], &source[range]);
        for (cell, &z) in cells.iter().zip(src) {
            if cell.y0 == NO_CELL {
                continue;
            }
            let (x0, y0, wts) = (i64::from(cell.x0), i64::from(cell.y0), cell.wts);
            if y0 + 1 < r0i || y0 >= r1i {
                continue;
            }
            if y0 >= r0i && y0 + 1 < r1i && x0 >= 0 && x0 + 1 < w as i64 {
                // The common case, all four taps inside: no per-tap bounds tests.
                let t = (y0 - r0i) as usize * w + x0 as usize;
                for (k, &wt) in wts.iter().enumerate() {
                    f(t + (k >> 1) * w + (k & 1), wt, z);
                }
                continue;
            }
            for (k, &wt) in wts.iter().enumerate() {
                let (y, x) = (y0 + (k >> 1) as i64, x0 + (k & 1) as i64);
                if wt > SPLAT_MIN_WEIGHT && y >= r0i && y < r1i && x >= 0 && (x as usize) < w {
                    f((y - r0i) as usize * w + x as usize, wt, z);
                }
            }
        }
    }
}

/// Step 1 of the depth-only splat for one run of a source row (`depth` the run's values, its
/// first pixel at `(y, x_first)`): each pixel's [`Cell`] (what [`landing`] and [`splat_cell`]
/// give, `NO_CELL` with zero weights where they give `None`), and the run's span of top tap
/// rows (`(i32::MAX, i32::MIN)` without a cell). Written with selects, so that the run
/// vectorises; compiled for AVX-512 and AVX2 as well, chosen
/// at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn prepare_run(
    p: &Calibration,
    y: usize,
    x_first: usize,
    depth: &[f32],
    cells: &mut [Cell],
) -> (i32, i32) {
    let n = cells.len().min(depth.len());
    let (mut lo, mut hi) = (i32::MAX, i32::MIN);
    for (i, (c, &z)) in cells[..n].iter_mut().zip(&depth[..n]).enumerate() {
        let (fu, fv) = p.flow_formula(z);
        let (tx, ty) = ((x_first + i) as f32 - fu, y as f32 - fv);
        // `landing`'s and `splat_cell`'s tests: a valid depth, a finite point within 1e9 px.
        let ok = is_valid_depth_branchless(z) & (tx.abs() < 1e9) & (ty.abs() < 1e9);
        // A pixel without a cell is computed at (0, 0), within range, and its result dropped.
        let (tx, ty) = if ok { (tx, ty) } else { (0.0, 0.0) };
        let (x0, y0, wts) = cell_within_range(tx, ty);
        *c = Cell {
            x0: if ok { x0 } else { 0 },
            y0: if ok { y0 } else { NO_CELL },
            wts: if ok { wts } else { [0.0; 4] },
        };
        lo = lo.min(if ok { y0 } else { i32::MAX });
        hi = hi.max(if ok { y0 } else { i32::MIN });
    }
    (lo, hi)
}

/// Where the depth-only splat also writes the flow of its output: the `u` and `v` planes
/// (row-major) and the flow for pixels left invalid (`None`: 0).
pub(crate) type FlowOut<'a> = (&'a mut [f32], &'a mut [f32], Option<(f32, f32)>);

/// Target rows per band of the parallel depth-only splat: about eight bands per thread, so
/// uneven bands (sky above, a near object below) still share the threads out evenly, and
/// tall enough that the source rows two bands both read (those landing across the boundary)
/// stay few.
fn band_rows(h: usize) -> usize {
    h.div_ceil(8 * rayon::current_num_threads()).max(8)
}

impl SplatScratch {
    /// Step 1 of the depth-only splat: every source pixel's splat cell (its [`landing`] point
    /// through [`splat_cell`]) and each run's span of landing rows. Rows run in parallel.
    pub(crate) fn prepare(&mut self, depth: ArrayView2<f32>, perturbation: &Calibration) {
        let (h, w) = depth.dim();
        let n = h * w;
        self.cells.resize(n, Cell::default());
        self.source.resize(n, 0.0);
        let runs = w.div_ceil(SPAN_CHUNK);
        self.span.resize(h * runs, (0, 0));
        if n == 0 {
            return;
        }
        let p = *perturbation;
        self.cells[..n]
            .par_chunks_mut(w)
            .zip(self.source[..n].par_chunks_mut(w))
            .zip(self.span[..h * runs].par_chunks_mut(runs))
            .zip(depth.axis_iter(Axis(0)).into_par_iter())
            .enumerate()
            .for_each(|(y, (((cells, src), spans), row))| {
                src.iter_mut().zip(row).for_each(|(s, &z)| *s = z);
                let runs = cells.chunks_mut(SPAN_CHUNK).zip(src.chunks(SPAN_CHUNK));
                for (k, ((cells, src), span)) in runs.zip(spans.iter_mut()).enumerate() {
                    *span = prepare_run(&p, y, k * SPAN_CHUNK, src, cells);
                }
            });
    }

    /// Steps 2 and 3 of the depth-only splat after [`prepare`](Self::prepare): passes 1 to 3
    /// of the module's method into `out` (row-major), and when `flow` is given, the flow of
    /// the result into its planes: `P.flow_at(out)` where valid, else the fallback (or 0).
    ///
    /// The target rows are cut into bands that run in parallel; each band walks the source
    /// pixels in row-major order and keeps only the taps that fall inside it. Every target
    /// therefore sees the same contributions in the same order as the serial scatter (a
    /// source adds at most one tap to a target), so the sums, and the output, are
    /// bit-identical and do not depend on the number of threads.
    pub(crate) fn resolve(
        &mut self,
        (h, w): (usize, usize),
        perturbation: &Calibration,
        out: &mut [f32],
        flow: Option<FlowOut<'_>>,
    ) {
        let n = h * w;
        if n == 0 {
            return;
        }
        self.acc.resize(n, [0.0; 4]);
        let p = *perturbation;
        let rows = band_rows(h);
        let runs = w.div_ceil(SPAN_CHUNK);
        let (cells, source, spans) = (&self.cells[..n], &self.source[..n], &self.span[..h * runs]);
        let band = |b: usize, acc: &mut [[f32; 4]], out: &mut [f32], flow: Option<FlowOut<'_>>| {
            let r0 = b * rows;
            let r1 = r0 + acc.len() / w;
            acc.fill([f32::INFINITY, 0.0, 0.0, 0.0]);
            // Both passes are written with selects, not branches: on a slanted surface whether
            // a tap is nearer than the target's current front is close to a coin toss, and
            // the mispredicted branches cost more than the rest of the passes (10.3 → 4.4 ms a
            // 640×480 frame on one core). A tap of weight ≤ SPLAT_MIN_WEIGHT offers +∞ to
            // the z-buffer and adds +0.0 to sums that are ≥ +0.0: no effect, bit for bit.
            // Pass 1: z-buffer.
            band_taps(cells, source, spans, w, (r0, r1), |t, wt, z| {
                let z = if wt > SPLAT_MIN_WEIGHT {
                    z
                } else {
                    f32::INFINITY
                };
                let front = &mut acc[t][0];
                *front = if z < *front { z } else { *front };
            });
            // Pass 2: accumulate the front surface.
            band_taps(cells, source, spans, w, (r0, r1), |t, wt, z| {
                let wt = if wt > SPLAT_MIN_WEIGHT { wt } else { 0.0 };
                let a = &mut acc[t];
                a[2] += wt;
                let front = if same_surface(a[0], z) { wt } else { 0.0 };
                a[1] += front;
                a[3] += front * z;
            });
            // Pass 3: normalise and validate (selects again: coverage and holes are
            // irregular). `flow_at(z)` is `Some` exactly where `z` is a valid depth.
            for (o, a) in out.iter_mut().zip(acc.iter()) {
                let [_, ws, any, zs] = *a;
                let z = zs / ws.max(f32::MIN_POSITIVE);
                *o = if (ws > 0.0) & (any >= SPLAT_MIN_COVERAGE) & is_valid_depth_branchless(z) {
                    z
                } else {
                    0.0
                };
            }
            if let Some((u, v, fallback)) = flow {
                let fallback = fallback.unwrap_or((0.0, 0.0));
                for ((u, v), &z) in u.iter_mut().zip(v.iter_mut()).zip(out.iter()) {
                    let at = p.flow_formula(z);
                    (*u, *v) = if is_valid_depth_branchless(z) {
                        at
                    } else {
                        fallback
                    };
                }
            }
        };
        let bw = rows * w;
        let acc = &mut self.acc[..n];
        match flow {
            Some((u, v, fallback)) => acc
                .par_chunks_mut(bw)
                .zip(out.par_chunks_mut(bw))
                .zip(u.par_chunks_mut(bw))
                .zip(v.par_chunks_mut(bw))
                .enumerate()
                .for_each(|(b, (((acc, out), u), v))| band(b, acc, out, Some((u, v, fallback)))),
            None => acc
                .par_chunks_mut(bw)
                .zip(out.par_chunks_mut(bw))
                .enumerate()
                .for_each(|(b, (acc, out))| band(b, acc, out, None)),
        }
    }

    /// [`resolve`](Self::resolve) into a view of any layout (through a scratch buffer when it
    /// is not contiguous).
    pub(crate) fn resolve_into(
        &mut self,
        perturbation: &Calibration,
        mut out: ArrayViewMut2<f32>,
        flow: Option<FlowOut<'_>>,
    ) {
        let dim = out.dim();
        match out.as_slice_mut() {
            Some(o) => self.resolve(dim, perturbation, o, flow),
            None => {
                let mut buf = std::mem::take(&mut self.out);
                buf.resize(dim.0 * dim.1, 0.0);
                self.resolve(dim, perturbation, &mut buf, flow);
                for (o, &b) in out.iter_mut().zip(&buf) {
                    *o = b;
                }
                self.out = buf;
            }
        }
    }
}

/// The depth of `depth`'s surfaces as seen from the view `perturbation` describes: each pixel
/// of `out` is the front surface's depth, or 0 where no surface lands (disocclusions, the
/// border the view moved away from).
///
/// Unlike [`synthesize_view`], which makes ground truth from clean depth and drops pixels the
/// front surface covers less than half, a pixel is kept when the surfaces landing on it
/// together cover half of it: measured depth has noise, flying pixels and multi-path errors
/// that split one surface into several by the 3 % rule, and dropping those pixels left a
/// fifth of a `dear-synth` frame empty.
///
/// This is how a ToF depth map is aligned to the RGB grid with a *known* calibration: a
/// backward warp would need the RGB-view depth to compute its own flow, and near objects with
/// a large baseline term make any fixed-point iteration for it jump between surfaces.
///
/// # Panics
/// If `out`'s shape differs from `depth`'s.
pub fn splat_depth_into(
    depth: ArrayView2<f32>,
    perturbation: &Calibration,
    out: ArrayViewMut2<f32>,
) {
    splat_depth_with(depth, perturbation, out, &mut SplatScratch::default());
}

/// [`splat_depth_into`] with buffers kept in `scratch` between calls.
///
/// # Panics
/// If `out`'s shape differs from `depth`'s.
pub fn splat_depth_with(
    depth: ArrayView2<f32>,
    perturbation: &Calibration,
    out: ArrayViewMut2<f32>,
    scratch: &mut SplatScratch,
) {
    assert_eq!(out.dim(), depth.dim(), "splat_depth_into: shapes differ");
    scratch.prepare(depth, perturbation);
    scratch.resolve_into(perturbation, out, None);
}

/// Forward-warp an aligned `(rgb, depth)` sample on the ToF grid into the RGB view that the
/// perturbation `P` describes; see the module documentation for the method.
///
/// # Panics
/// If `rgb` is not `(H, W, C)` over the depth's `(H, W)`.
pub fn synthesize_view(
    rgb: ArrayView3<u8>,
    depth: ArrayView2<f32>,
    perturbation: &Calibration,
) -> SynthesizedView {
    let (h, w) = depth.dim();
    let (rh, rw, c) = rgb.dim();
    assert_eq!(
        (rh, rw),
        (h, w),
        "synthesize_view: rgb is {rh}×{rw} but depth is {h}×{w}"
    );

    let mut scratch = SplatScratch::default();
    let mut csum = Array3::zeros((h, w, c));
    scratch.splat_front(depth, perturbation, Some((rgb, &mut csum)));
    let (wsum, zsum) = (&scratch.weight, &scratch.depth_sum);

    // Pass 3: normalise and validate.
    let mut out = SynthesizedView {
        rgb: Array3::zeros((h, w, c)),
        depth: Array2::zeros((h, w)),
        flow: Flow::zeros(h, w),
        valid: Array2::from_elem((h, w), false),
    };
    for (t, &ws) in wsum.iter().enumerate() {
        let (y, x) = (t / w, t % w);
        if ws < SPLAT_MIN_COVERAGE {
            continue;
        }
        let z = zsum[t] / ws;
        let Some((fu, fv)) = perturbation.flow_at(z) else {
            continue;
        };
        out.depth[(y, x)] = z;
        out.flow.u[(y, x)] = fu;
        out.flow.v[(y, x)] = fv;
        out.valid[(y, x)] = true;
        for ch in 0..c {
            out.rgb[(y, x, ch)] = (csum[(y, x, ch)] / ws + 0.5).floor().clamp(0.0, 255.0) as u8;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::warp::{warp_depth, warp_rgb};

    #[test]
    fn constant_plane_shifts_by_the_analytic_sub_pixel_amount() {
        let (h, w) = (20, 40);
        let z = 2.0f32;
        // u = 0.6/2 = 0.3 px, v = −0.4/2 = −0.2 px.
        let p = Calibration {
            tx: 0.6,
            ty: -0.4,
            cx: 0.0,
            cy: 0.0,
        };
        let depth = Array2::from_elem((h, w), z);
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, ch)| match ch {
            0 => (10 + 4 * x) as u8,
            1 => (20 + 3 * y) as u8,
            _ => 100,
        });
        let view = synthesize_view(rgb.view(), depth.view(), &p);
        // out(p) = src(x + 0.3, y − 0.2), linear in x and y, so exact up to rounding.
        for y in 1..h - 1 {
            for x in 0..w - 1 {
                assert!(view.valid[(y, x)], "({y},{x}) should be valid");
                let r = 10.0 + 4.0 * (x as f32 + 0.3);
                let g = 20.0 + 3.0 * (y as f32 - 0.2);
                assert!(
                    (f32::from(view.rgb[(y, x, 0)]) - r).abs() <= 0.5,
                    "R at ({y},{x})"
                );
                assert!(
                    (f32::from(view.rgb[(y, x, 1)]) - g).abs() <= 0.5,
                    "G at ({y},{x})"
                );
                assert_eq!(view.rgb[(y, x, 2)], 100);
                assert!((view.depth[(y, x)] - z).abs() < 1e-6);
                assert_eq!(view.flow.u[(y, x)], 0.3);
                assert_eq!(view.flow.v[(y, x)], -0.2);
            }
        }
        // The last column would need source column 39.3: only source 39 reaches it (weight 0.7
        // ≥ SPLAT_MIN_COVERAGE), so it is valid with that source's colour, not extrapolated.
        for y in 1..h - 1 {
            assert!(view.valid[(y, w - 1)]);
            assert_eq!(view.rgb[(y, w - 1, 0)], 10 + 4 * 39);
        }
        // A shift of 0.7 px leaves the last column only 0.3 of a source: invalid, all zero.
        let p = Calibration {
            tx: 1.4,
            ty: 0.0,
            cx: 0.0,
            cy: 0.0,
        };
        let view = synthesize_view(rgb.view(), depth.view(), &p);
        for y in 0..h {
            assert!(view.valid[(y, w - 2)]);
            assert!(!view.valid[(y, w - 1)]);
            assert_eq!(view.depth[(y, w - 1)], 0.0);
            assert_eq!(view.flow.u[(y, w - 1)], 0.0);
            assert_eq!(view.rgb[(y, w - 1, 2)], 0);
        }
    }

    /// Background at 2 m, a foreground square at 1 m over columns 20..=27, rows 5..=14;
    /// the colour encodes the source column so we can see where each pixel came from.
    fn square_scene() -> (Array3<u8>, Array2<f32>) {
        let (h, w) = (20, 40);
        let fg = |y: usize, x: usize| (5..=14).contains(&y) && (20..=27).contains(&x);
        let depth = Array2::from_shape_fn((h, w), |(y, x)| if fg(y, x) { 1.0 } else { 2.0 });
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, ch)| match ch {
            0 => x as u8,
            1 => y as u8,
            _ => {
                if fg(y, x) {
                    255
                } else {
                    50
                }
            }
        });
        (rgb, depth)
    }

    #[test]
    fn foreground_occludes_on_one_side_and_disoccludes_on_the_other() {
        let (rgb, depth) = square_scene();
        // tx = 8: the foreground moves 8 px left, the background 4 px left.
        let p = Calibration {
            tx: 8.0,
            ty: 0.0,
            cx: 0.0,
            cy: 0.0,
        };
        let view = synthesize_view(rgb.view(), depth.view(), &p);
        for y in 0..20 {
            for x in 0..40 {
                let in_rows = (5..=14).contains(&y);
                let (valid, z, src_x) = if x >= 36 {
                    (false, 0.0, 0) // no source beyond the right border
                } else if in_rows && (12..=19).contains(&x) {
                    (true, 1.0, x + 8) // the foreground, occluding background columns 16..=19
                } else if in_rows && (20..=23).contains(&x) {
                    (false, 0.0, 0) // disocclusion: 8 − 4 = 4 px wide, right of the square
                } else {
                    (true, 2.0, x + 4)
                };
                assert_eq!(view.valid[(y, x)], valid, "valid at ({y},{x})");
                assert_eq!(view.depth[(y, x)], z, "depth at ({y},{x})");
                if valid {
                    assert_eq!(
                        view.rgb[(y, x, 0)] as usize,
                        src_x,
                        "source column at ({y},{x})"
                    );
                    assert_eq!(view.rgb[(y, x, 2)], if z == 1.0 { 255 } else { 50 });
                    assert_eq!(view.flow.u[(y, x)], 8.0 / z);
                    assert_eq!(view.flow.v[(y, x)], 0.0);
                } else {
                    assert_eq!(view.rgb[(y, x, 0)], 0);
                }
            }
        }
    }

    #[test]
    fn warping_the_source_with_the_returned_flow_reproduces_the_view() {
        // Integer shifts: exact, edges included.
        let (rgb, depth) = square_scene();
        let p = Calibration {
            tx: 8.0,
            ty: -4.0,
            cx: 1.0,
            cy: 2.0,
        };
        let view = synthesize_view(rgb.view(), depth.view(), &p);
        let mut d = Array2::zeros((20, 40));
        let mut c = Array3::zeros((20, 40, 3));
        warp_depth(depth.view(), &view.flow, d.view_mut());
        warp_rgb(rgb.view(), &view.flow, c.view_mut(), None);
        let n_valid = view.valid.iter().filter(|&&v| v).count();
        assert!(n_valid > 400);
        for ((y, x), &v) in view.valid.indexed_iter() {
            if v {
                assert_eq!(d[(y, x)], view.depth[(y, x)], "depth at ({y},{x})");
                for ch in 0..3 {
                    assert_eq!(c[(y, x, ch)], view.rgb[(y, x, ch)], "rgb at ({y},{x},{ch})");
                }
            }
        }
    }

    #[test]
    fn round_trip_on_a_smooth_slanted_scene_with_sub_pixel_flow() {
        let (h, w) = (30, 40);
        let depth =
            Array2::from_shape_fn((h, w), |(y, x)| 1.5 + 0.01 * x as f32 + 0.005 * y as f32);
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, ch)| {
            let t = x as f32 * 0.2 + y as f32 * 0.15 + ch as f32;
            (128.0 + 60.0 * t.sin()) as u8
        });
        let p = Calibration {
            tx: 2.7,
            ty: -1.9,
            cx: 0.35,
            cy: 0.6,
        };
        let view = synthesize_view(rgb.view(), depth.view(), &p);
        let mut d = Array2::zeros((h, w));
        let mut c = Array3::zeros((h, w, 3));
        let mut cv = Array2::from_elem((h, w), false);
        warp_depth(depth.view(), &view.flow, d.view_mut());
        warp_rgb(rgb.view(), &view.flow, c.view_mut(), Some(cv.view_mut()));
        let mut checked = 0;
        for ((y, x), &v) in view.valid.indexed_iter() {
            if v && cv[(y, x)] {
                checked += 1;
                assert!(
                    (d[(y, x)] - view.depth[(y, x)]).abs() < 2e-4,
                    "depth at ({y},{x})"
                );
                for ch in 0..3 {
                    let diff = (i32::from(c[(y, x, ch)]) - i32::from(view.rgb[(y, x, ch)])).abs();
                    assert!(diff <= 2, "rgb at ({y},{x},{ch}): {diff}");
                }
            }
        }
        assert!(
            checked > (h - 4) * (w - 4),
            "only {checked} pixels compared"
        );
    }

    /// The daemon's depth-only splat (landing cells computed once, bands in parallel, passes
    /// written with selects) gives bit for bit what the serial scatter of [`SplatScratch::
    /// splat_front`] gives with the depth-only validity rule, on a scene that exercises every
    /// select: noisy depths a few millimetres apart landing on one target (the z-buffer's
    /// near-ties), depth steps (taps off the front surface), holes, sub-threshold taps
    /// (whole-pixel flows give weights of exactly 0) and sources landing outside the image.
    #[test]
    fn depth_only_splat_matches_the_serial_scatter_bit_for_bit() {
        let (h, w) = (61, 83);
        let mut state = 0x2545_f491u32;
        let mut noise = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            f32::from(u16::try_from(state >> 16).unwrap()) / 65536.0 - 0.5
        };
        let depth = Array2::from_shape_fn((h, w), |(y, x)| {
            let surface = if (15..40).contains(&y) && (30..60).contains(&x) {
                0.6 + 0.002 * x as f32
            } else {
                2.0 + 0.01 * y as f32
            };
            if (x * 7 + y * 3) % 23 == 0 {
                0.0
            } else {
                surface + 0.004 * noise()
            }
        });
        for p in [
            // Sub-pixel flows: t/z varies with depth.
            Calibration {
                tx: 3.1,
                ty: -1.3,
                cx: 0.4,
                cy: 0.25,
            },
            // Whole-pixel flow at every depth: three of every four taps weigh 0.
            Calibration {
                tx: 0.0,
                ty: 0.0,
                cx: 2.0,
                cy: -1.0,
            },
            // Large flows: many sources land outside.
            Calibration {
                tx: 12.0,
                ty: 6.0,
                cx: -3.3,
                cy: 1.7,
            },
        ] {
            let mut reference = SplatScratch::default();
            reference.splat_front(depth.view(), &p, None);
            let expected = Array2::from_shape_fn((h, w), |(y, x)| {
                let t = y * w + x;
                let ws = reference.weight[t];
                let z = reference.depth_sum[t] / ws.max(f32::MIN_POSITIVE);
                let covered = reference.any_weight[t] >= SPLAT_MIN_COVERAGE;
                if ws > 0.0 && covered && p.flow_at(z).is_some() {
                    z
                } else {
                    0.0
                }
            });
            let mut out = Array2::from_elem((h, w), f32::NAN);
            splat_depth_with(
                depth.view(),
                &p,
                out.view_mut(),
                &mut SplatScratch::default(),
            );
            assert!(
                expected.iter().filter(|&&z| z > 0.0).count() > h * w / 2,
                "{p:?}"
            );
            for (((y, x), &a), &b) in out.indexed_iter().zip(expected.iter()) {
                assert_eq!(a.to_bits(), b.to_bits(), "{p:?}: pixel ({y}, {x})");
            }
        }
    }
}
