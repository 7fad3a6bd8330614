//! The full-resolution tail of a format-2 refinement graph, run in Rust.
//!
//! A `gated` refiner's graph (`graphs.refine.apply.kind = "gated-kernel"`) ends at its head: 12
//! maps at 1/`stride` of the frame. This module upsamples them bilinearly to the depth grid and
//! applies them (`train/dear_train/models/kpn.py`, `GatedKernelApply`, is the definition):
//!
//! ```text
//! d   = depth / max_depth                              (normalised, 0 = invalid)
//! w_i = softmax_i(m_i − range_scale · e^{m_11} · |d_i − d|)   over the 3×3 neighbours d_i > 0
//! out = d + σ(m_10) · (Σ w_i d_i + max_bias · tanh(m_9) − d),  0 where d = 0
//! ```
//!
//! tract runs this tail op by op over twelve full-resolution planes (its `Softmax` alone took
//! ~0.8 s per 640×480 frame); fused here it is one pass over the frame. A non-finite result
//! (a corrupt model) falls back to the input depth: the refiner never publishes NaN.

use ndarray::{Array2, ArrayView2, ArrayViewMut2, Axis, CowArray, Ix2};
use rayon::prelude::*;

use crate::filter::MEASURED_CONFIDENCE;
use crate::geometry::surface::is_valid_depth_branchless;
use crate::model::manifest::{ErrorFloor, JumpOn, RefineApply};
use crate::vector_math::{exp_fast, ln_fast};

/// Head channels of the gated refiner: 9 kernel logits, bias, gate, log-sharpness.
pub const GATED_CHANNELS: usize = 12;
/// Head channels of the hybrid refiner: the gated refiner's 12, then the trust-in-classical
/// logit.
pub const HYBRID_CHANNELS: usize = 13;
/// Head channels of the guarded refiner: the hybrid's 13, then the log expected error of the
/// refined depth, the measurement and the classical estimate ([`select_guarded`]).
pub const GUARDED_CHANNELS: usize = 16;

/// A guarded refiner's expected-error maps: logit `m` stands for the expected absolute error
/// `unit · max_depth · e^{clamp(m, ±log_bound)}` metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorMaps {
    pub unit: f32,
    pub log_bound: f32,
    /// Raises the published error where the frame is noisier than the head learnt
    /// ([`floor_expected_error`]).
    pub floor: Option<ErrorFloor>,
}

/// The constants of one gated refiner (from its manifest).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GatedKernel {
    pub stride: usize,
    pub max_bias: f32,
    pub range_scale: f32,
    pub max_depth_m: f32,
    /// `Some` for a hybrid or guarded refiner ([`blend_classical`]): its `jump_scale`.
    pub jump_scale: Option<f32>,
    /// Which pixels the jump term applies to ([`blend_classical`]).
    pub jump_on: JumpOn,
    /// `Some` for a guarded refiner ([`select_guarded`]).
    pub errors: Option<ErrorMaps>,
}

impl GatedKernel {
    pub fn new(apply: &RefineApply, max_depth_m: f32) -> Self {
        GatedKernel {
            stride: apply.stride,
            max_bias: apply.max_bias,
            range_scale: apply.range_scale,
            max_depth_m,
            jump_scale: apply.jump_scale,
            jump_on: apply.jump_on.unwrap_or(JumpOn::EveryPixel),
            errors: apply
                .error_unit
                .zip(apply.log_error_bound)
                .map(|(unit, log_bound)| ErrorMaps {
                    unit,
                    log_bound,
                    floor: apply.error_floor,
                }),
        }
    }
}

/// Two source indices and the weight of the second.
type Tap = (u32, u32, f32);

/// Bilinear source taps of `n_out` pixels upsampled `stride`× from `n_in`: PyTorch's
/// `interpolate(mode="bilinear", align_corners=False)` (half-pixel centres, clamped).
fn taps(n_out: usize, n_in: usize, stride: usize) -> Vec<Tap> {
    (0..n_out)
        .map(|o| {
            let src = ((o as f32 + 0.5) / stride as f32 - 0.5).max(0.0);
            let i0 = (src.floor() as usize).min(n_in - 1);
            let i1 = (i0 + 1).min(n_in - 1);
            (i0 as u32, i1 as u32, src - i0 as f32)
        })
        .collect()
}

/// One row upsampled `stride`× along x exactly as [`taps`] defines it (half-pixel centres,
/// clamped): `low[0]` left of the first centre, then a run of `stride` outputs between each
/// pair of neighbouring samples with the fixed fractions `(p + ½)/stride`, then the last
/// sample. Written as runs instead of per-pixel gathers through `taps`, which cost more than
/// the kernel arithmetic; the fractions are exact in `f32` for the power-of-two strides a
/// manifest allows, so the result is bit-identical to the tap form.
fn upsample_row(low: &[f32], stride: usize, out: &mut [f32]) {
    // The strides a manifest allows (checked when the bundle loads), each with the run length
    // known to the compiler: a run is then one vector multiply-add and store instead of a loop
    // of scalar ones.
    match stride {
        2 => upsample_runs::<2>(low, out),
        4 => upsample_runs::<4>(low, out),
        8 => upsample_runs::<8>(low, out),
        _ => panic!("upsampling stride {stride}: a manifest allows 2, 4 or 8"),
    }
}

/// [`upsample_row`] for a stride `S` fixed at compile time.
#[inline(always)]
fn upsample_runs<const S: usize>(low: &[f32], out: &mut [f32]) {
    let (n, w) = (low.len(), out.len());
    let lead = (S / 2).min(w);
    out[..lead].fill(low[0]);
    let fractions: [f32; S] = std::array::from_fn(|p| (p as f32 + 0.5) / S as f32);
    let body = &mut out[lead..];
    // Whole runs, one per pair of neighbouring samples, as far as the output reaches.
    let whole = (body.len() / S).min(n.saturating_sub(1));
    for (run, pair) in body[..whole * S].chunks_exact_mut(S).zip(low.windows(2)) {
        let (a, d) = (pair[0], pair[1] - pair[0]);
        for (o, &f) in run.iter_mut().zip(&fractions) {
            *o = a + f * d;
        }
    }
    let rest = &mut body[whole * S..];
    if whole + 1 < n {
        // The output ends inside the next run (a cropped row).
        let (a, d) = (low[whole], low[whole + 1] - low[whole]);
        for (o, &f) in rest.iter_mut().zip(&fractions) {
            *o = a + f * d;
        }
    } else {
        rest.fill(low[n - 1]);
    }
}

#[inline(always)]
fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + exp_fast(-x))
}

#[inline(always)]
fn tanh(x: f32) -> f32 {
    let e = exp_fast(-2.0 * x.abs());
    ((1.0 - e) / (1.0 + e)).copysign(x)
}

/// Applies the gated refiner's `maps` (12 planes at 1/stride, at least
/// `ceil(H/stride) × ceil(W/stride)`) to `depth` (`H × W`, metres) into `out` (metres).
///
/// # Panics
/// When `maps` does not hold [`GATED_CHANNELS`] planes of one shape large enough, or `out` is
/// not the shape of `depth` (the runner allocates both).
pub fn apply_gated(
    maps: &[Array2<f32>],
    depth: ArrayView2<f32>,
    mut out: ArrayViewMut2<f32>,
    k: &GatedKernel,
) {
    assert!(
        maps.len() >= GATED_CHANNELS,
        "gated maps: 12 planes (a hybrid head's 13th is read by blend_classical)"
    );
    let maps = standard_layout(&maps[..GATED_CHANNELS]);
    let maps = &maps[..];
    let (h, w) = depth.dim();
    assert_eq!(out.dim(), (h, w), "output shape");
    let (h4, w4) = maps[0].dim();
    assert!(
        h4 * k.stride >= h && w4 * k.stride >= w && maps.iter().all(|m| m.dim() == (h4, w4)),
        "maps {h4}x{w4} at stride {} do not cover {h}x{w}",
        k.stride
    );
    let ys = taps(h, h4, k.stride);
    let inv_depth = 1.0 / k.max_depth_m;
    let depth = depth.as_standard_layout();
    let depth = depth.as_slice().expect("standard layout is contiguous");
    out.axis_iter_mut(Axis(0))
        .into_par_iter()
        .enumerate()
        .for_each_init(
            || RowScratch::new(w, w4),
            |sc, (y, mut out_row)| {
                let out_row = out_row
                    .as_slice_mut()
                    .expect("rows of a standard-layout output are contiguous");
                gated_row(sc, maps, depth, (h, w), y, ys[y], inv_depth, k, out_row);
            },
        );
}

/// The classical refiner's output on the warped depth, as the hybrid tail reads it
/// (`ClassicalRefiner::refine_into`'s two planes).
#[derive(Debug, Clone, Copy)]
pub struct ClassicalEstimate<'a> {
    /// Depth, metres (0 = invalid).
    pub depth: ArrayView2<'a, f32>,
    /// Its confidence; below [`MEASURED_CONFIDENCE`] the pixel was not measured itself.
    pub confidence: ArrayView2<'a, u8>,
}

/// The hybrid refiner's first step (`HybridKernelApply` in kpn.py): per pixel, the measured
/// `depth` and the `classical` refiner's output are blended with the trust
/// `t = σ(m_12 + j · jump_scale · |c − d| / max_depth)` (map 12 upsampled like the others;
/// `j` = 1, or with [`JumpOn::Replaced`] 1 only where the classical filter replaced the
/// measurement, its confidence below [`MEASURED_CONFIDENCE`], and 0 elsewhere):
///
/// ```text
/// base = d + t · (c − d)   where both are valid
///        d                 where only d is,   c where only c is,   0 where neither
/// ```
///
/// [`apply_gated`] then runs on `base` with maps 0–11. All planes in metres.
///
/// # Panics
/// When `maps` has no plane 12, the planes differ in shape from `depth`, or `k` is not a
/// hybrid kernel.
pub fn blend_classical(
    maps: &[Array2<f32>],
    depth: ArrayView2<f32>,
    classical: ClassicalEstimate,
    mut base: ArrayViewMut2<f32>,
    k: &GatedKernel,
) {
    assert!(
        maps.len() >= HYBRID_CHANNELS,
        "hybrid maps: 13 planes (a guarded head's 14th–16th are read by select_guarded)"
    );
    let jump = k.jump_scale.expect("blend_classical needs a hybrid kernel") / k.max_depth_m;
    let replaced_only = k.jump_on == JumpOn::Replaced;
    let (h, w) = depth.dim();
    assert_eq!(classical.depth.dim(), (h, w), "classical shape");
    assert_eq!(
        classical.confidence.dim(),
        (h, w),
        "classical confidence shape"
    );
    assert_eq!(base.dim(), (h, w), "base shape");
    let trust_map = maps[12].as_standard_layout();
    let trust_map = &trust_map;
    let (h4, w4) = trust_map.dim();
    assert!(
        h4 * k.stride >= h && w4 * k.stride >= w,
        "maps {h4}x{w4} at stride {} do not cover {h}x{w}",
        k.stride
    );
    let ys = taps(h, h4, k.stride);
    base.axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(depth.axis_iter(Axis(0)))
        .zip(classical.depth.axis_iter(Axis(0)))
        .zip(classical.confidence.axis_iter(Axis(0)))
        .enumerate()
        .for_each_init(
            || (vec![0.0f32; w4], vec![0.0f32; w]),
            |(low, full), (y, (((mut out, d_row), c_row), conf_row))| {
                let (y0, y1, fy) = ys[y];
                lerp_rows(map_row(trust_map, y0), map_row(trust_map, y1), fy, low);
                upsample_row(low, k.stride, full);
                let (d_row, c_row) = (contiguous(&d_row), contiguous(&c_row));
                let conf_row = contiguous(&conf_row);
                let jump = RowJump {
                    scale: jump,
                    confidence: &conf_row,
                    replaced_only,
                };
                match out.as_slice_mut() {
                    Some(out) => blend_row(out, &d_row, &c_row, full, jump),
                    None => {
                        let mut row = vec![0.0; w];
                        blend_row(&mut row, &d_row, &c_row, full, jump);
                        out.iter_mut().zip(row).for_each(|(o, b)| *o = b);
                    }
                }
            },
        );
}

/// The guarded refiner's last step (`GuardedKernelApply` in kpn.py). `published` holds the
/// hybrid refinement `r` on entry; per pixel, of the candidates with a valid depth — `r`, the
/// measurement `d`, the classical estimate `c` — the one whose expected-error logit (maps 13,
/// 14, 15, upsampled like the others, clamped to ±`log_bound`) is smallest is published (ties:
/// `r`, then `d`, then `c`), and `ln` of its expected error in metres goes to `log_error`
/// (`+∞` where no candidate is valid: the depth is then 0). The comparison is made on the
/// logits, which order the errors as the errors themselves do, so no exponential is taken.
/// A non-finite logit (a corrupt model) disqualifies its candidate; a pixel left without one
/// keeps the measurement.
///
/// # Panics
/// When `maps` has fewer than [`GUARDED_CHANNELS`] planes, the planes differ in shape from
/// `depth`, or `k` is not a guarded kernel.
pub fn select_guarded(
    maps: &[Array2<f32>],
    depth: ArrayView2<f32>,
    classical: ArrayView2<f32>,
    mut published: ArrayViewMut2<f32>,
    mut log_error: ArrayViewMut2<f32>,
    k: &GatedKernel,
) {
    assert!(maps.len() >= GUARDED_CHANNELS, "guarded maps: 16 planes");
    let errors = k.errors.expect("select_guarded needs a guarded kernel");
    let (h, w) = depth.dim();
    for (name, dim) in [
        ("classical", classical.dim()),
        ("published", published.dim()),
        ("log_error", log_error.dim()),
    ] {
        assert_eq!(dim, (h, w), "{name} shape");
    }
    let error_maps = standard_layout(&maps[HYBRID_CHANNELS..GUARDED_CHANNELS]);
    let error_maps = &error_maps[..];
    let (h4, w4) = error_maps[0].dim();
    assert!(
        h4 * k.stride >= h && w4 * k.stride >= w,
        "maps {h4}x{w4} at stride {} do not cover {h}x{w}",
        k.stride
    );
    let log_unit = (errors.unit * k.max_depth_m).ln();
    let ys = taps(h, h4, k.stride);
    published
        .axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(log_error.axis_iter_mut(Axis(0)))
        .zip(depth.axis_iter(Axis(0)))
        .zip(classical.axis_iter(Axis(0)))
        .enumerate()
        .for_each_init(
            || (vec![0.0f32; w4], vec![0.0f32; 3 * w], vec![0.0f32; 2 * w]),
            |(low, full, rows), (y, (((mut out, mut err), d_row), c_row))| {
                let (y0, y1, fy) = ys[y];
                for (m, full) in error_maps.iter().zip(full.chunks_exact_mut(w)) {
                    lerp_rows(map_row(m, y0), map_row(m, y1), fy, low);
                    upsample_row(low, k.stride, full);
                }
                let (d_row, c_row) = (contiguous(&d_row), contiguous(&c_row));
                let (mr, rest) = full.split_at(w);
                let (md, mc) = rest.split_at(w);
                let logits = GuardedLogits {
                    refined: mr,
                    measured: md,
                    classical: mc,
                };
                let bound = errors.log_bound;
                match (out.as_slice_mut(), err.as_slice_mut()) {
                    (Some(o), Some(e)) => {
                        guarded_row(o, e, &d_row, &c_row, logits, bound, log_unit)
                    }
                    _ => {
                        // Strided views: through a contiguous copy of the row.
                        let (out_row, err_row) = rows.split_at_mut(w);
                        out_row
                            .iter_mut()
                            .zip(out.iter())
                            .for_each(|(o, r)| *o = *r);
                        guarded_row(out_row, err_row, &d_row, &c_row, logits, bound, log_unit);
                        out.iter_mut().zip(&*out_row).for_each(|(o, v)| *o = *v);
                        err.iter_mut().zip(&*err_row).for_each(|(o, v)| *o = *v);
                    }
                }
            },
        );
}

/// Raises `log_error` (`ln` metres, as [`select_guarded`] leaves it) to at least
/// `ln(min(scale · m, cap_m))`, where `m` is the mean of `|depth − classical|` (metres) over
/// the pixels of the `(2·radius + 1)²` window (clipped at the frame's border) where both are
/// valid; a pixel whose window has no such pixel, or whose error is not finite (no depth), is
/// left as it is. Box sums along rows, then along columns.
///
/// # Panics
/// When the three planes differ in shape, or `log_error`'s rows are not contiguous (the
/// runner's own plane is).
pub fn floor_expected_error(
    depth: ArrayView2<f32>,
    classical: ArrayView2<f32>,
    mut log_error: ArrayViewMut2<f32>,
    floor: &ErrorFloor,
) {
    let (h, w) = depth.dim();
    assert_eq!(classical.dim(), (h, w), "classical shape");
    assert_eq!(log_error.dim(), (h, w), "log_error shape");
    let r = floor.radius;
    // Per row: the window sums along the row of |d − c| (first `w` values) and of the count of
    // valid pairs (the next `w`), as a running sum: one add and one subtract a pixel.
    let mut row_sums = Array2::<f32>::zeros((h, 2 * w));
    row_sums
        .axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(depth.axis_iter(Axis(0)))
        .zip(classical.axis_iter(Axis(0)))
        .for_each_init(
            || (vec![0.0f32; w], vec![0.0f32; w]),
            |(diff, both), ((mut out, d), c)| {
                let (d, c) = (contiguous(&d), contiguous(&c));
                for (((df, b), &d), &c) in diff.iter_mut().zip(both.iter_mut()).zip(&*d).zip(&*c) {
                    let valid = is_valid_depth_branchless(d) & is_valid_depth_branchless(c);
                    *b = if valid { 1.0 } else { 0.0 };
                    *df = if valid { (d - c).abs() } else { 0.0 };
                }
                let out = out.as_slice_mut().expect("a fresh array is contiguous");
                let (sum, count) = out.split_at_mut(w);
                let (mut s, mut n) = (0.0f32, 0.0f32);
                for x in 0..r.min(w) {
                    s += diff[x];
                    n += both[x];
                }
                for x in 0..w {
                    if x + r < w {
                        s += diff[x + r];
                        n += both[x + r];
                    }
                    if x > r {
                        s -= diff[x - r - 1];
                        n -= both[x - r - 1];
                    }
                    // The count is exact; the sum of the valid pairs is kept non-negative (a
                    // running sum can leave a rounding residue where the window empties).
                    sum[x] = if n > 0.5 { s.max(0.0) } else { 0.0 };
                    count[x] = n;
                }
            },
        );
    let cap = floor.cap_m;
    let scale = floor.scale;
    log_error
        .axis_iter_mut(Axis(0))
        .into_par_iter()
        .enumerate()
        .for_each_init(
            || vec![0.0f32; 2 * w],
            |column, (y, mut errors)| {
                column.fill(0.0);
                let rows = y.saturating_sub(r)..(y + r + 1).min(h);
                for row in row_sums.slice(ndarray::s![rows, ..]).rows() {
                    let row = row.to_slice().expect("a fresh array is contiguous");
                    column.iter_mut().zip(row).for_each(|(a, &v)| *a += v);
                }
                let (sum, count) = column.split_at(w);
                let errors = errors
                    .as_slice_mut()
                    .expect("log_error rows are contiguous");
                for ((e, &s), &n) in errors.iter_mut().zip(sum).zip(count) {
                    // Selects, so the loop vectorises. A non-finite error (no depth) stays.
                    let f = (scale * s / n.max(1.0)).min(cap);
                    let raise = (s > 0.0) & e.is_finite() & (exp_fast(*e) < f);
                    let ln_floor = ln_fast(f.max(f32::MIN_POSITIVE));
                    *e = if raise { ln_floor } else { *e };
                }
            },
        );
}

/// One row of the three expected-error logits of [`select_guarded`], full resolution.
#[derive(Clone, Copy)]
struct GuardedLogits<'a> {
    refined: &'a [f32],
    measured: &'a [f32],
    classical: &'a [f32],
}

/// One row of [`select_guarded`] (`out`: the refined row on entry), written with selects so
/// that it vectorises.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn guarded_row(
    out: &mut [f32],
    log_error: &mut [f32],
    d_row: &[f32],
    c_row: &[f32],
    m: GuardedLogits<'_>,
    bound: f32,
    log_unit: f32,
) {
    let pixels = out
        .iter_mut()
        .zip(log_error.iter_mut())
        .zip(d_row.iter().zip(c_row))
        .zip(m.refined.iter().zip(m.measured).zip(m.classical));
    for (((o, e), (&d, &c)), ((&mr, &md), &mc)) in pixels {
        let r = *o;
        // A candidate's logit, or +∞ when its depth is invalid or its logit is not finite.
        let logit = |z: f32, m: f32| {
            let ok = is_valid_depth_branchless(z) & m.is_finite();
            if ok {
                m.clamp(-bound, bound)
            } else {
                f32::INFINITY
            }
        };
        let (lr, ld, lc) = (logit(r, mr), logit(d, md), logit(c, mc));
        let d_or_c = if ld <= lc { d } else { c };
        let l_d_or_c = ld.min(lc);
        let take_r = lr <= l_d_or_c;
        let best = if take_r { lr } else { l_d_or_c };
        let value = if take_r { r } else { d_or_c };
        let chosen = best < f32::INFINITY;
        // No candidate: the measurement where there is one (only a corrupt map gets here
        // with one), else no depth.
        let fallback = if is_valid_depth_branchless(d) { d } else { 0.0 };
        *o = if chosen { value } else { fallback };
        *e = if chosen {
            best + log_unit
        } else {
            f32::INFINITY
        };
    }
}

/// The maps in standard layout (borrowed: the runner's maps already are), so that a map row
/// is a slice.
fn standard_layout(maps: &[Array2<f32>]) -> Vec<CowArray<'_, f32, Ix2>> {
    maps.iter().map(|m| m.as_standard_layout()).collect()
}

/// Row `y` of a standard-layout low-resolution map.
#[inline]
fn map_row<'a>(m: &'a CowArray<'_, f32, Ix2>, y: u32) -> &'a [f32] {
    let w = m.ncols();
    let s = m
        .as_slice()
        .expect("standard_layout made the maps contiguous");
    &s[y as usize * w..(y as usize + 1) * w]
}

/// `low = a + fy · (b − a)`, the vertical tap of one low-resolution row. On slices, not
/// ndarray row iterators, which the compiler left scalar.
#[inline(always)]
fn lerp_rows(a: &[f32], b: &[f32], fy: f32, low: &mut [f32]) {
    for ((l, &a), &b) in low.iter_mut().zip(a).zip(b) {
        *l = a + fy * (b - a);
    }
}

/// A row as a slice, borrowed when contiguous.
fn contiguous<'a, T: Clone>(row: &'a ndarray::ArrayView1<'_, T>) -> std::borrow::Cow<'a, [T]> {
    match row.as_slice() {
        Some(s) => std::borrow::Cow::Borrowed(s),
        None => std::borrow::Cow::Owned(row.to_vec()),
    }
}

/// The jump term of one row of [`blend_classical`]: its scale (per metre), the classical
/// filter's confidence row, and whether only the pixels it replaced take the term.
#[derive(Clone, Copy)]
struct RowJump<'a> {
    scale: f32,
    confidence: &'a [u8],
    replaced_only: bool,
}

/// One row of [`blend_classical`], written with selects (every pixel computes the blend, the
/// validity of `d` and `c` picks the result) so that it vectorises.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn blend_row(out: &mut [f32], d_row: &[f32], c_row: &[f32], logits: &[f32], jump: RowJump) {
    let pixels = out
        .iter_mut()
        .zip(d_row.iter().zip(c_row))
        .zip(logits.iter().zip(jump.confidence));
    for ((o, (&d, &c)), (&logit, &confidence)) in pixels {
        let measured = confidence >= MEASURED_CONFIDENCE;
        let scale = if jump.replaced_only & measured {
            0.0
        } else {
            jump.scale
        };
        let t = sigmoid(logit + scale * (c - d).abs());
        let b = d + t * (c - d);
        // A corrupt trust map falls back to the measurement.
        let b = if b.is_finite() { b } else { d };
        let (d_ok, c_ok) = (is_valid_depth_branchless(d), is_valid_depth_branchless(c));
        let only_c = if c_ok { c } else { 0.0 };
        let only_d = if d_ok { d } else { only_c };
        *o = if d_ok & c_ok { b } else { only_d };
    }
}

/// Per-thread buffers of one output row (allocated once per rayon job, not per row).
struct RowScratch {
    /// One vertically interpolated low-resolution map row.
    low: Vec<f32>,
    /// The 12 maps at full resolution, `12 × w`.
    full: Vec<f32>,
    /// The three depth rows around the output row, normalised, edge-replicated: `3 × (w + 2)`.
    pad: Vec<f32>,
}

impl RowScratch {
    fn new(w: usize, w4: usize) -> Self {
        RowScratch {
            low: vec![0.0; w4],
            full: vec![0.0; GATED_CHANNELS * w],
            pad: vec![0.0; 3 * (w + 2)],
        }
    }
}

/// Output pixels whose softmax [`gated_row`] computes together.
const TAIL_CHUNK: usize = 64;

/// One output row, written as loops over the row's pixels (structure of arrays) so that the
/// compiler vectorises them; `exp_fast` is branch-free for the same reason.
#[allow(clippy::too_many_arguments)]
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn gated_row(
    sc: &mut RowScratch,
    maps: &[CowArray<'_, f32, Ix2>],
    depth: &[f32],
    (h, w): (usize, usize),
    y: usize,
    (y0, y1, fy): Tap,
    inv_depth: f32,
    k: &GatedKernel,
    out: &mut [f32],
) {
    // The 12 maps of this row at full resolution: vertical, then horizontal taps.
    for (c, m) in maps.iter().enumerate() {
        lerp_rows(map_row(m, y0), map_row(m, y1), fy, &mut sc.low);
        upsample_row(&sc.low, k.stride, &mut sc.full[c * w..(c + 1) * w]);
    }
    // Normalised depth rows y−1, y, y+1 with one replicated column on each side.
    for (j, r) in [y.saturating_sub(1), y, (y + 1).min(h - 1)]
        .into_iter()
        .enumerate()
    {
        let src = &depth[r * w..(r + 1) * w];
        let dst = &mut sc.pad[j * (w + 2)..(j + 1) * (w + 2)];
        for (d, s) in dst[1..=w].iter_mut().zip(src) {
            *d = s * inv_depth;
        }
        dst[0] = dst[1];
        dst[w + 1] = dst[w];
    }
    // The rest in chunks of TAIL_CHUNK pixels, whose softmax arguments and sums stay in the
    // core's L1 cache (whole rows of them did not).
    for c0 in (0..w).step_by(TAIL_CHUNK) {
        let n = TAIL_CHUNK.min(w - c0);
        let centre = &sc.pad[(w + 2) + 1 + c0..][..n];
        let (mut sharp, mut amax) = ([0.0f32; TAIL_CHUNK], [f32::NEG_INFINITY; TAIL_CHUNK]);
        let (sharp, amax) = (&mut sharp[..n], &mut amax[..n]);
        for (s, m) in sharp.iter_mut().zip(&sc.full[11 * w + c0..][..n]) {
            *s = k.range_scale * exp_fast(*m);
        }
        let mut args = [[0.0f32; TAIL_CHUNK]; 9];
        for (i, args) in args.iter_mut().enumerate() {
            let (dy, dx) = (i / 3, i % 3);
            let nb = &sc.pad[dy * (w + 2) + dx + c0..][..n];
            let logits = &sc.full[i * w + c0..][..n];
            let args = &mut args[..n];
            for x in 0..n {
                let v = nb[x];
                let a = logits[x] - sharp[x] * (v - centre[x]).abs();
                // Invalid neighbours (depth 0) get no weight at all.
                let a = if v > 0.0 { a } else { f32::NEG_INFINITY };
                args[x] = a;
                // A compare, not f32::max: it vectorises (max's NaN rule does not). A NaN
                // logit still reaches the result through exp and is caught there.
                if a > amax[x] {
                    amax[x] = a;
                }
            }
        }
        let (mut sum_e, mut sum_en) = ([0.0f32; TAIL_CHUNK], [0.0f32; TAIL_CHUNK]);
        let (sum_e, sum_en) = (&mut sum_e[..n], &mut sum_en[..n]);
        for (i, args) in args.iter().enumerate() {
            let (dy, dx) = (i / 3, i % 3);
            let nb = &sc.pad[dy * (w + 2) + dx + c0..][..n];
            let args = &args[..n];
            for x in 0..n {
                let e = exp_fast(args[x] - amax[x]);
                let e = if nb[x] > 0.0 { e } else { 0.0 };
                sum_e[x] += e;
                sum_en[x] += e * nb[x];
            }
        }
        let (bias, gate) = (&sc.full[9 * w + c0..][..n], &sc.full[10 * w + c0..][..n]);
        let out = &mut out[c0..c0 + n];
        for x in 0..n {
            let d = centre[x];
            let filtered = sum_en[x] / sum_e[x];
            let r = (d + sigmoid(gate[x]) * (filtered + k.max_bias * tanh(bias[x]) - d))
                * k.max_depth_m;
            out[x] = if d.is_nan() || d <= 0.0 {
                0.0
            } else if r.is_finite() {
                r
            } else {
                d * k.max_depth_m
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kernel() -> GatedKernel {
        GatedKernel {
            stride: 4,
            max_bias: 0.05,
            range_scale: 100.0,
            max_depth_m: 10.0,
            jump_scale: None,
            jump_on: JumpOn::EveryPixel,
            errors: None,
        }
    }

    /// The classical estimate `depth` with its `confidence`.
    fn measured<'a>(
        depth: ArrayView2<'a, f32>,
        confidence: &'a Array2<u8>,
    ) -> ClassicalEstimate<'a> {
        ClassicalEstimate {
            depth,
            confidence: confidence.view(),
        }
    }

    fn maps(h4: usize, w4: usize, f: impl Fn(usize, usize, usize) -> f32) -> Vec<Array2<f32>> {
        (0..GATED_CHANNELS)
            .map(|c| Array2::from_shape_fn((h4, w4), |(y, x)| f(c, y, x)))
            .collect()
    }

    #[test]
    fn sigmoid_and_tanh_match_std() {
        assert!((tanh(0.3) - 0.3f32.tanh()).abs() < 1e-6);
        assert!((tanh(-2.0) - (-2.0f32).tanh()).abs() < 1e-6);
        assert!((sigmoid(1.5) - 1.0 / (1.0 + (-1.5f32).exp())).abs() < 1e-6);
    }

    #[test]
    fn taps_follow_half_pixel_centres() {
        let t = taps(8, 2, 4);
        // Output 0 and 1 sit left of input 0's centre: clamped to it.
        assert_eq!(t[0], (0, 1, 0.0));
        assert_eq!(t[1], (0, 1, 0.0));
        // Output 2: src = 2.5/4 − 0.5 = 0.125.
        assert_eq!((t[2].0, t[2].1), (0, 1));
        assert!((t[2].2 - 0.125).abs() < 1e-6);
        // Past the last centre: clamped to the last input.
        assert_eq!((t[7].0, t[7].1), (1, 1));
    }

    #[test]
    fn row_upsampling_is_the_tap_form_bit_for_bit() {
        for stride in [2usize, 4, 8] {
            for n_in in [1usize, 2, 3, 7, 40] {
                // Outputs up to the padded width and a cropped one.
                for w in [n_in * stride, (n_in * stride).saturating_sub(3).max(1)] {
                    let low: Vec<f32> = (0..n_in).map(|i| (i as f32 * 0.37).sin() * 3.0).collect();
                    let mut fast = vec![f32::NAN; w];
                    upsample_row(&low, stride, &mut fast);
                    for (x, &(x0, x1, fx)) in taps(w, n_in, stride).iter().enumerate() {
                        let a = low[x0 as usize];
                        let want = a + fx * (low[x1 as usize] - a);
                        assert_eq!(
                            fast[x].to_bits(),
                            want.to_bits(),
                            "stride {stride}, {n_in} -> {w}, x {x}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn closed_gate_returns_the_input_and_holes_stay_holes() {
        let mut depth = Array2::from_shape_fn((9, 13), |(y, x)| 1.0 + 0.1 * (x + y) as f32);
        depth[[4, 4]] = 0.0;
        let m = maps(3, 4, |c, _, _| if c == 10 { -40.0 } else { 0.3 });
        let mut out = Array2::zeros((9, 13));
        apply_gated(&m, depth.view(), out.view_mut(), &kernel());
        assert_eq!(out[[4, 4]], 0.0);
        for (o, d) in out.iter().zip(depth.iter()) {
            assert!((o - d).abs() < 1e-5, "{o} vs {d}");
        }
    }

    #[test]
    fn open_gate_averages_only_valid_neighbours_on_one_side_of_a_step() {
        // A 1 m step; zero logits, zero bias, open gate, sharp range term.
        let depth = Array2::from_shape_fn((8, 8), |(_, x)| if x < 4 { 1.0 } else { 2.0 });
        let mut holed = depth.clone();
        holed[[3, 2]] = 0.0;
        let m = maps(2, 2, |c, _, _| match c {
            10 => 40.0,
            _ => 0.0,
        });
        let mut out = Array2::zeros((8, 8));
        apply_gated(&m, holed.view(), out.view_mut(), &kernel());
        for ((y, x), o) in out.indexed_iter() {
            if (y, x) == (3, 2) {
                assert_eq!(*o, 0.0);
            } else {
                assert!((o - depth[[y, x]]).abs() < 1e-3, "({y},{x}) {o}");
            }
        }
    }

    fn hybrid() -> GatedKernel {
        GatedKernel {
            jump_scale: Some(300.0),
            ..kernel()
        }
    }

    fn hybrid_maps(trust: f32) -> Vec<Array2<f32>> {
        (0..HYBRID_CHANNELS)
            .map(|c| Array2::from_elem((2, 2), if c == 12 { trust } else { 0.0 }))
            .collect()
    }

    /// 16 maps at 1/4 of 8×8: the hybrid's (`hybrid_maps(0)`), then constant error logits.
    fn guarded_maps(refined: f32, measured: f32, classical: f32) -> Vec<Array2<f32>> {
        let mut maps = hybrid_maps(0.0);
        for v in [refined, measured, classical] {
            maps.push(Array2::from_elem((2, 2), v));
        }
        maps
    }

    #[test]
    fn guarded_selection_falls_back_to_the_measurement_on_a_corrupt_map() {
        let k = GatedKernel {
            errors: Some(ErrorMaps {
                unit: 1e-3,
                log_bound: 6.0,
                floor: None,
            }),
            ..hybrid()
        };
        let depth = Array2::from_elem((8, 8), 2.0f32);
        let classical = Array2::from_elem((8, 8), 2.5f32);
        let refined = Array2::from_elem((8, 8), 2.2f32);
        let run = |maps: &[Array2<f32>]| {
            let (mut out, mut err) = (refined.clone(), Array2::zeros((8, 8)));
            select_guarded(
                maps,
                depth.view(),
                classical.view(),
                out.view_mut(),
                err.view_mut(),
                &k,
            );
            (out, err)
        };
        // The smallest logit wins; its error is unit · max_depth · e^logit (clamped to ±6).
        let (out, err) = run(&guarded_maps(1.0, 0.5, 9.0));
        assert!(out.iter().all(|&v| v == 2.0));
        assert!(err.iter().all(|&e| (e - (0.01f32.ln() + 0.5)).abs() < 1e-6));
        let (out, err) = run(&guarded_maps(-9.0, 0.5, 9.0));
        assert!(out.iter().all(|&v| v == 2.2));
        assert!(err.iter().all(|&e| (e - (0.01f32.ln() - 6.0)).abs() < 1e-6));
        // A NaN or infinite logit disqualifies its candidate; all three: the measurement.
        let (out, _) = run(&guarded_maps(f32::NAN, f32::INFINITY, 2.0));
        assert!(out.iter().all(|&v| v == 2.5));
        let (out, err) = run(&guarded_maps(f32::NAN, f32::NAN, f32::NAN));
        assert!(out.iter().all(|&v| v == 2.0));
        assert!(err.iter().all(|e| e.is_infinite()));
    }

    #[test]
    fn the_error_floor_follows_the_local_disagreement_capped_and_only_raises() {
        let floor = ErrorFloor {
            scale: 2.0,
            radius: 1,
            cap_m: 0.15,
        };
        // 6×8: |d − c| is 1 cm in columns 0–3, 10 cm in 4–7; (0, 0) has no depth and the
        // classical estimate is missing in rows 4–5, columns 6–7.
        let depth = Array2::from_shape_fn((6, 8), |(y, x)| match (y, x) {
            (0, 0) => 0.0,
            _ => 2.0,
        });
        let classical = Array2::from_shape_fn((6, 8), |(y, x)| match (y, x) {
            (4.., 6..) => 0.0,
            (_, 0..4) => 2.01,
            _ => 2.1,
        });
        let small = 0.001f32.ln();
        let mut err = Array2::from_elem((6, 8), small);
        err[[0, 0]] = f32::INFINITY;
        err[[2, 1]] = 0.5f32.ln();
        floor_expected_error(depth.view(), classical.view(), err.view_mut(), &floor);
        let close = |y: usize, x: usize, metres: f32| (err[[y, x]] - metres.ln()).abs() < 1e-5;
        // 2 × the window's mean: 2 cm inside the left part; a larger prediction stays.
        assert!(close(1, 1, 0.02) && close(3, 2, 0.02), "{err:?}");
        assert!(close(2, 1, 0.5));
        // At the boundary: columns 2–4 (two of 1 cm, one of 10) and 3–5 (one and two).
        assert!(close(2, 3, 2.0 * 0.12 / 3.0) && close(2, 4, 2.0 * 0.21 / 3.0));
        // The right part: 2 × 10 cm, capped at 15.
        assert!(close(1, 6, 0.15));
        // (0, 1): five valid pairs in its clipped window ((0, 0) has no depth), all 1 cm.
        assert!(close(0, 1, 0.02));
        // (4, 6): the classical estimate is missing at six of its nine pixels; the three valid
        // pairs are 10 cm: the cap again.
        assert!(close(4, 6, 0.15));
        // No depth: untouched; a window without a valid pair ((5, 7)): untouched.
        assert!(err[[0, 0]].is_infinite());
        assert_eq!(err[[5, 7]], small);
    }

    #[test]
    fn blend_follows_the_trust_map_and_fills_from_whichever_is_valid() {
        let depth = Array2::from_shape_fn((8, 8), |(y, x)| match (y, x) {
            (0, 0) => 0.0,
            _ => 2.0,
        });
        let classical = Array2::from_shape_fn((8, 8), |(y, x)| match (y, x) {
            (1, 1) | (0, 0) => 0.0,
            (2, 2) => 3.0,
            _ => 2.001,
        });
        let mut base = Array2::zeros((8, 8));
        let all_measured = Array2::from_elem((8, 8), 255u8);
        // Strongly distrusted: the measurement, except a far jump (1 m ≙ logit +30).
        blend_classical(
            &hybrid_maps(-20.0),
            depth.view(),
            measured(classical.view(), &all_measured),
            base.view_mut(),
            &hybrid(),
        );
        assert_eq!(base[[0, 0]], 0.0, "neither valid");
        assert_eq!(base[[1, 1]], 2.0, "only the measurement");
        assert!((base[[3, 3]] - 2.0).abs() < 1e-6);
        assert!((base[[2, 2]] - 3.0).abs() < 1e-3, "{}", base[[2, 2]]);
        // Half trust: halfway (the 1 mm jump adds only 0.03 to the logit).
        blend_classical(
            &hybrid_maps(0.0),
            depth.view(),
            measured(classical.view(), &all_measured),
            base.view_mut(),
            &hybrid(),
        );
        assert!((base[[3, 3]] - 2.0005).abs() < 2e-5, "{}", base[[3, 3]]);
        // A hole in the measurement that the classical filter filled is taken from it.
        let mut holed = depth.clone();
        holed[[5, 5]] = 0.0;
        blend_classical(
            &hybrid_maps(0.0),
            holed.view(),
            measured(classical.view(), &all_measured),
            base.view_mut(),
            &hybrid(),
        );
        assert_eq!(base[[5, 5]], 2.001);
        // Strided views (columns of column-major arrays) give the same values bit for bit.
        let (mut base_t, holed_t, classical_t) = (
            Array2::zeros((8, 8)).reversed_axes(),
            holed.t().to_owned(),
            classical.t().to_owned(),
        );
        blend_classical(
            &hybrid_maps(0.0),
            holed_t.t(),
            ClassicalEstimate {
                depth: classical_t.t(),
                confidence: all_measured.t(),
            },
            base_t.view_mut(),
            &hybrid(),
        );
        assert!(base_t
            .iter()
            .zip(&base)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    #[test]
    fn with_jump_on_replaced_only_the_pixels_the_classical_filter_replaced_take_the_jump() {
        // A 1 m move at (2, 2) and (5, 5), a 1 mm one everywhere else; the classical filter
        // measured (2, 2) and smoothed it far (confidence 128) but replaced (5, 5) (64).
        let depth = Array2::from_elem((8, 8), 2.0f32);
        let classical = Array2::from_shape_fn((8, 8), |(y, x)| match (y, x) {
            (2, 2) | (5, 5) => 3.0,
            _ => 2.001,
        });
        let confidence = Array2::from_shape_fn((8, 8), |(y, x)| match (y, x) {
            (2, 2) => MEASURED_CONFIDENCE,
            (5, 5) => MEASURED_CONFIDENCE - 64,
            _ => 250,
        });
        let estimate = measured(classical.view(), &confidence);
        let mut every = Array2::zeros((8, 8));
        let mut replaced = Array2::zeros((8, 8));
        let maps = hybrid_maps(-20.0);
        blend_classical(&maps, depth.view(), estimate, every.view_mut(), &hybrid());
        let only_replaced = GatedKernel {
            jump_on: JumpOn::Replaced,
            ..hybrid()
        };
        blend_classical(
            &maps,
            depth.view(),
            estimate,
            replaced.view_mut(),
            &only_replaced,
        );
        // Every pixel: both far moves win over the distrust (logit −20 + 30).
        assert!((every[[2, 2]] - 3.0).abs() < 1e-3, "{}", every[[2, 2]]);
        assert!((every[[5, 5]] - 3.0).abs() < 1e-3, "{}", every[[5, 5]]);
        // Replaced only: the smoothed pixel keeps its measurement, the replaced one does not.
        assert!(
            (replaced[[2, 2]] - 2.0).abs() < 1e-6,
            "{}",
            replaced[[2, 2]]
        );
        assert!(
            (replaced[[5, 5]] - 3.0).abs() < 1e-3,
            "{}",
            replaced[[5, 5]]
        );
        // Small moves are the trust map's alone either way: identical.
        for (y, x) in [(0, 0), (3, 4), (7, 7)] {
            assert_eq!(
                every[[y, x]].to_bits(),
                replaced[[y, x]].to_bits(),
                "({y},{x})"
            );
        }
    }

    #[test]
    fn non_finite_maps_fall_back_to_the_input() {
        let depth = Array2::from_elem((4, 4), 1.5f32);
        let m = maps(1, 1, |c, _, _| if c == 9 { f32::NAN } else { 0.0 });
        let mut out = Array2::zeros((4, 4));
        apply_gated(&m, depth.view(), out.view_mut(), &kernel());
        assert!(out.iter().all(|v| *v == 1.5));
    }
}
