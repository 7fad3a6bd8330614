//! Backward warping `out(p) = src(p + W(p))` with bilinear interpolation.
//!
//! The flow lives on the output grid (`flow.dim() == out.dim()`); the source may have any size.
//! A sample point is *inside* when it lies in the convex hull of the source's pixel centres,
//! `0 ≤ x ≤ w−1` and `0 ≤ y ≤ h−1`; anything else (including a non-finite flow) is
//! *outside* and produces an invalid output (depth 0 / `valid = false` / black), never a clamped
//! border value. Outputs are written into caller-provided views so that the daemon can warp
//! straight into shared memory; rows are processed in parallel with rayon.
//!
//! Shape mismatches between the flow and the output are programming errors and panic with a
//! message naming both shapes.

use ndarray::{
    ArrayView2, ArrayView3, ArrayViewMut1, ArrayViewMut2, ArrayViewMut3, Axis, CowArray, Dimension,
    Ix2, Zip,
};

use crate::geometry::surface::{is_valid_depth_branchless, surface_tolerance};
use crate::vector_math::floor_small;
use dear_capture::frame::Flow;

/// The four bilinear neighbours of a sample point and their weights, in the fixed order
/// `(y0,x0), (y0,x1), (y1,x0), (y1,x1)` (ties between equal weights go to the earlier one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Taps {
    /// Row-major flat index `row · w + column` of each neighbour.
    pub idx: [usize; 4],
    /// Bilinear weight of each neighbour; they sum to 1.
    pub w: [f32; 4],
}

/// The bilinear weights of the taps `(y0, x0), (y0, x1), (y1, x0), (y1, x1)` at fractions
/// `(fx, fy)` past `(x0, y0)`: sampling (the warps) and splatting use the same weights.
#[inline(always)]
pub(crate) fn bilinear_weights(fx: f32, fy: f32) -> [f32; 4] {
    [
        (1.0 - fx) * (1.0 - fy),
        fx * (1.0 - fy),
        (1.0 - fx) * fy,
        fx * fy,
    ]
}

/// Bilinear taps of the sample point `(sx, sy)` (column, row) in an `h × w` image, or `None`
/// when the point is outside the convex hull of the pixel centres (or not finite).
#[inline]
pub(crate) fn bilinear_taps(sx: f32, sy: f32, h: usize, w: usize) -> Option<Taps> {
    if h == 0 || w == 0 {
        return None;
    }
    // Written so that NaN fails the test.
    if !(sx >= 0.0 && sx <= (w - 1) as f32 && sy >= 0.0 && sy <= (h - 1) as f32) {
        return None;
    }
    // Non-negative here, so truncation is floor (and avoids a libm call per sample). Through
    // i32 (the point is inside the image, far below 2³¹): x86-64 has no direct f32 → u64
    // conversion, and the emulated one cost a tenth of a warp.
    let x0 = (sx as i32 as usize).min(w - 1);
    let y0 = (sy as i32 as usize).min(h - 1);
    let x1 = (x0 + 1).min(w - 1);
    let y1 = (y0 + 1).min(h - 1);
    let fx = sx - x0 as f32;
    let fy = sy - y0 as f32;
    Some(Taps {
        idx: [y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1],
        w: bilinear_weights(fx, fy),
    })
}

fn assert_flow_matches(flow: &Flow, out: (usize, usize), what: &str) {
    assert_eq!(
        flow.u.dim(),
        out,
        "{what}: flow u has shape {:?} but the output is {:?}",
        flow.u.dim(),
        out
    );
    assert_eq!(
        flow.v.dim(),
        out,
        "{what}: flow v has shape {:?} but the output is {:?}",
        flow.v.dim(),
        out
    );
}

/// The flow planes as row-major slices (borrowed when already contiguous, as they are for
/// every `Flow` built by this crate).
struct FlowRows<'a> {
    u: CowArray<'a, f32, Ix2>,
    v: CowArray<'a, f32, Ix2>,
}

impl<'a> FlowRows<'a> {
    fn new(flow: &'a Flow) -> Self {
        FlowRows {
            u: flow.u.as_standard_layout(),
            v: flow.v.as_standard_layout(),
        }
    }

    /// `(u, v)` of row `y`.
    #[inline]
    fn row(&self, y: usize) -> (&[f32], &[f32]) {
        let w = self.u.ncols();
        let (u, v) = (std_slice(&self.u), std_slice(&self.v));
        (&u[y * w..(y + 1) * w], &v[y * w..(y + 1) * w])
    }
}

/// The elements of a standard-layout array.
#[inline]
fn std_slice<'b, A, D: Dimension>(a: &'b CowArray<'_, A, D>) -> &'b [A] {
    a.as_slice()
        .expect("as_standard_layout yields a contiguous array")
}

/// Depth-aware backward warp of a depth map (metres, `0` = invalid).
///
/// At each output pixel the four bilinear neighbours are examined: neighbours with zero weight
/// or invalid depth are ignored; the valid neighbour with the largest weight (the nearest to
/// the sample point) picks the surface, and only the neighbours on that surface
/// ([`same_surface`](crate::geometry::surface::same_surface): within 3 % of its depth, at
/// least 1 cm) are blended, with their weights renormalised. So a sample between a foreground
/// and a background pixel takes the nearer one's surface instead of inventing a depth in
/// mid-air, and a sample next to a hole is not pulled towards zero. No valid neighbour, or a
/// sample outside the source → `0`.
///
/// A non-contiguous source is copied once into standard layout.
///
/// # Panics
/// If `flow.dim() != out.dim()`.
pub fn warp_depth(src: ArrayView2<f32>, flow: &Flow, mut out: ArrayViewMut2<f32>) {
    assert_flow_matches(flow, out.dim(), "warp_depth");
    let (h, w) = src.dim();
    let src = src.as_standard_layout();
    let s = std_slice(&src);
    let flow = FlowRows::new(flow);
    Zip::indexed(out.rows_mut()).par_for_each(|y, mut out_row| {
        let (u_row, v_row) = flow.row(y);
        for (x, ((o, &u), &v)) in out_row.iter_mut().zip(u_row).zip(v_row).enumerate() {
            *o = match bilinear_taps(x as f32 + u, y as f32 + v, h, w) {
                Some(taps) => sample_depth(s, &taps),
                None => 0.0,
            };
        }
    });
}

/// The discontinuity-aware blend of [`warp_depth`] at one sample point.
///
/// Written with non-short-circuit tests and selects: holes and edges are irregular, and
/// mispredicted branches, not arithmetic, dominated the cost of this function.
#[inline]
fn sample_depth(src: &[f32], taps: &Taps) -> f32 {
    blend_depth(taps.idx.map(|i| src[i]), taps.w)
}

/// [`sample_depth`] on the four tap values `d` with weights `wt`, without a branch (so that
/// a row of samples vectorises).
#[inline(always)]
fn blend_depth(d: [f32; 4], wt: [f32; 4]) -> f32 {
    let mut z = [0.0f32; 4];
    let (mut best_w, mut z_ref) = (0.0f32, 0.0f32);
    for i in 0..4 {
        let usable = (wt[i] > 0.0) & is_valid_depth_branchless(d[i]);
        z[i] = if usable { d[i] } else { 0.0 };
        // Strictly greater: ties go to the earlier tap.
        let nearer = usable & (wt[i] > best_w);
        best_w = if nearer { wt[i] } else { best_w };
        z_ref = if nearer { d[i] } else { z_ref };
    }
    let tol = surface_tolerance(z_ref);
    let (mut acc, mut wsum) = (0.0f32, 0.0f32);
    for (&zi, &wi) in z.iter().zip(&wt) {
        let on_surface = (zi > 0.0) & ((zi - z_ref).abs() <= tol);
        acc += if on_surface { wi * zi } else { 0.0 };
        wsum += if on_surface { wi } else { 0.0 };
    }
    // No usable tap (z_ref = 0): 0, not the 0/0 computed beside it.
    if z_ref <= 0.0 {
        0.0
    } else {
        acc / wsum
    }
}

/// [`warp_depth`] of `depth` and [`warp_bilinear`] of `amplitude` (same size) with one flow,
/// in one pass: the refiner's two inputs. The sample point and its taps are computed once per
/// pixel instead of once per warp; each output is bit-identical to its own warp's.
///
/// # Panics
/// If the flow or either output does not have the outputs' shape, or the sources' sizes differ.
pub fn warp_depth_and_bilinear(
    depth: ArrayView2<f32>,
    amplitude: ArrayView2<f32>,
    flow: &Flow,
    mut depth_out: ArrayViewMut2<f32>,
    mut amplitude_out: ArrayViewMut2<f32>,
) {
    assert_flow_matches(flow, depth_out.dim(), "warp_depth_and_bilinear");
    assert_eq!(
        amplitude_out.dim(),
        depth_out.dim(),
        "warp_depth_and_bilinear: the amplitude output's shape differs from the depth output's"
    );
    assert_eq!(
        amplitude.dim(),
        depth.dim(),
        "warp_depth_and_bilinear: the amplitude and depth sources' shapes differ"
    );
    let (h, w) = depth.dim();
    let (depth, amplitude) = (depth.as_standard_layout(), amplitude.as_standard_layout());
    let (d, a) = (std_slice(&depth), std_slice(&amplitude));
    let flow = FlowRows::new(flow);
    Zip::indexed(depth_out.rows_mut())
        .and(amplitude_out.rows_mut())
        .par_for_each(|y, mut depth_row, mut amplitude_row| {
            let (u_row, v_row) = flow.row(y);
            match (depth_row.as_slice_mut(), amplitude_row.as_slice_mut()) {
                (Some(od), Some(oa)) => fused_row(d, a, (h, w), y, (u_row, v_row), od, oa),
                _ => {
                    let (mut od, mut oa) = (vec![0.0; u_row.len()], vec![0.0; u_row.len()]);
                    fused_row(d, a, (h, w), y, (u_row, v_row), &mut od, &mut oa);
                    depth_row.iter_mut().zip(od).for_each(|(o, v)| *o = v);
                    amplitude_row.iter_mut().zip(oa).for_each(|(o, v)| *o = v);
                }
            }
        });
}

/// Output pixels [`fused_row`] stages at a time (the staging arrays stay in L1).
const FUSED_CHUNK: usize = 64;

/// One output row of [`warp_depth_and_bilinear`]: the same taps as [`bilinear_taps`] and the
/// same blends as [`sample_depth`] and [`sample_bilinear`], bit for bit, in three passes over
/// [`FUSED_CHUNK`] pixels so that the arithmetic vectorises: the taps of every pixel (a sample
/// outside the source computed at (0, 0) and replaced by 0 at the end), then the eight source
/// values loaded (the only scalar pass), then the blends. Sources of more than 2³² pixels, or
/// wider or taller than 2²², go through the per-pixel functions.
#[allow(clippy::too_many_arguments)]
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn fused_row(
    d: &[f32],
    a: &[f32],
    (h, w): (usize, usize),
    y: usize,
    (u_row, v_row): (&[f32], &[f32]),
    depth_out: &mut [f32],
    amplitude_out: &mut [f32],
) {
    let n = depth_out
        .len()
        .min(amplitude_out.len())
        .min(u_row.len())
        .min(v_row.len());
    let small = (1..1 << 22).contains(&h) && (1..1 << 22).contains(&w);
    if !small || h * w > u32::MAX as usize || n >= 1 << 22 {
        let rows = depth_out.iter_mut().zip(amplitude_out.iter_mut());
        for (x, ((od, oa), (&u, &v))) in rows.zip(u_row.iter().zip(v_row)).enumerate() {
            (*od, *oa) = match bilinear_taps(x as f32 + u, y as f32 + v, h, w) {
                Some(taps) => (sample_depth(d, &taps), sample_bilinear(a, &taps)),
                None => (0.0, 0.0),
            };
        }
        return;
    }
    let (w32, h32) = (w as u32, h as u32);
    let (x_max, y_max, yf) = ((w - 1) as f32, (h - 1) as f32, y as f32);
    let mut idx = [[0u32; FUSED_CHUNK]; 4];
    let mut wt = [[0.0f32; FUSED_CHUNK]; 4];
    let mut inside = [false; FUSED_CHUNK];
    let (mut dv, mut av) = ([[0.0f32; FUSED_CHUNK]; 4], [[0.0f32; FUSED_CHUNK]; 4]);
    let (mut zo, mut bo) = ([0.0f32; FUSED_CHUNK], [0.0f32; FUSED_CHUNK]);
    for start in (0..n).step_by(FUSED_CHUNK) {
        let m = FUSED_CHUNK.min(n - start);
        let (u, v) = (&u_row[start..start + m], &v_row[start..start + m]);
        // Taps. Past `m` (the row's last chunk) lanes compute at u = v = 0 and are dropped.
        for j in 0..FUSED_CHUNK {
            let (du, dv) = if j < m { (u[j], v[j]) } else { (0.0, 0.0) };
            let (sx, sy) = ((start + j) as u32 as f32 + du, yf + dv);
            // `bilinear_taps`'s test, NaN failing it.
            let ok = (sx >= 0.0) & (sx <= x_max) & (sy >= 0.0) & (sy <= y_max);
            let (sx, sy) = if ok { (sx, sy) } else { (0.0, 0.0) };
            let (x0, y0) = (floor_small(sx).min(w32 - 1), floor_small(sy).min(h32 - 1));
            let (x1, y1) = ((x0 + 1).min(w32 - 1), (y0 + 1).min(h32 - 1));
            let (fx, fy) = (sx - x0 as f32, sy - y0 as f32);
            inside[j] = ok;
            (idx[0][j], idx[1][j]) = (y0 * w32 + x0, y0 * w32 + x1);
            (idx[2][j], idx[3][j]) = (y1 * w32 + x0, y1 * w32 + x1);
            for (k, tap_wt) in bilinear_weights(fx, fy).into_iter().enumerate() {
                wt[k][j] = tap_wt;
            }
        }
        // Loads.
        for k in 0..4 {
            for j in 0..m {
                let i = idx[k][j] as usize;
                (dv[k][j], av[k][j]) = (d[i], a[i]);
            }
        }
        // Blends.
        for j in 0..FUSED_CHUNK {
            let tap_wt = [wt[0][j], wt[1][j], wt[2][j], wt[3][j]];
            let z = blend_depth([dv[0][j], dv[1][j], dv[2][j], dv[3][j]], tap_wt);
            let b = blend_bilinear([av[0][j], av[1][j], av[2][j], av[3][j]], tap_wt);
            zo[j] = if inside[j] { z } else { 0.0 };
            bo[j] = if inside[j] { b } else { 0.0 };
        }
        depth_out[start..start + m].copy_from_slice(&zo[..m]);
        amplitude_out[start..start + m].copy_from_slice(&bo[..m]);
    }
}

/// The bilinear blend of [`warp_bilinear`] at one sample point. Zero-weight taps are skipped
/// so that a NaN beyond the sample's cell cannot leak in.
#[inline]
fn sample_bilinear(src: &[f32], t: &Taps) -> f32 {
    blend_bilinear(t.idx.map(|i| src[i]), t.w)
}

/// [`sample_bilinear`] on the four tap values `v` with weights `wt`.
#[inline(always)]
fn blend_bilinear(v: [f32; 4], wt: [f32; 4]) -> f32 {
    (0..4)
        .map(|i| if wt[i] > 0.0 { wt[i] * v[i] } else { 0.0 })
        .sum()
}

/// Plain bilinear backward warp for amplitude-like images (every source value is a
/// measurement; non-finite values propagate).
///
/// Outside the source: `out = 0` and, when a `valid` mask is given, `valid = false`; inside,
/// `valid = true`. A non-contiguous source is copied once into standard layout.
///
/// # Panics
/// If `flow.dim() != out.dim()` or the mask's shape differs from the output's.
pub fn warp_bilinear(
    src: ArrayView2<f32>,
    flow: &Flow,
    mut out: ArrayViewMut2<f32>,
    valid: Option<ArrayViewMut2<bool>>,
) {
    assert_flow_matches(flow, out.dim(), "warp_bilinear");
    let (h, w) = src.dim();
    let src = src.as_standard_layout();
    let s = std_slice(&src);
    let flow = FlowRows::new(flow);
    let row =
        |y: usize, mut out_row: ArrayViewMut1<f32>, mut valid_row: Option<ArrayViewMut1<bool>>| {
            let (u_row, v_row) = flow.row(y);
            for (x, o) in out_row.iter_mut().enumerate() {
                let taps = bilinear_taps(x as f32 + u_row[x], y as f32 + v_row[x], h, w);
                *o = match taps {
                    Some(t) => sample_bilinear(s, &t),
                    None => 0.0,
                };
                if let Some(vr) = valid_row.as_mut() {
                    vr[x] = taps.is_some();
                }
            }
        };
    match valid {
        Some(mut valid) => {
            assert_eq!(
                valid.dim(),
                out.dim(),
                "warp_bilinear: valid mask shape differs from the output"
            );
            Zip::indexed(out.rows_mut())
                .and(valid.rows_mut())
                .par_for_each(|y, o, v| row(y, o, Some(v)));
        }
        None => Zip::indexed(out.rows_mut()).par_for_each(|y, o| row(y, o, None)),
    }
}

/// Bilinear backward warp of an 8-bit image `(H, W, C)` (RGB), rounding to the nearest level.
/// Interpolation runs in integer fixed point with the sample position quantised to 1/256 px,
/// which changes no output by more than one level against float bilinear.
///
/// Outside the source: all channels `0` (black) and, when a `valid` mask is given,
/// `valid = false`. A non-contiguous source is copied once into standard layout.
///
/// # Panics
/// If the flow's shape differs from the output's `(H, W)`, the channel counts differ, or the
/// mask's shape differs from `(H, W)`.
pub fn warp_rgb(
    src: ArrayView3<u8>,
    flow: &Flow,
    mut out: ArrayViewMut3<u8>,
    valid: Option<ArrayViewMut2<bool>>,
) {
    let (oh, ow, oc) = out.dim();
    assert_flow_matches(flow, (oh, ow), "warp_rgb");
    let (h, w, c) = src.dim();
    assert_eq!(
        c, oc,
        "warp_rgb: source has {c} channels but the output has {oc}"
    );
    let src = src.as_standard_layout();
    let s = std_slice(&src);
    let flow = FlowRows::new(flow);
    let row =
        |y: usize, mut out_row: ArrayViewMut2<u8>, mut valid_row: Option<ArrayViewMut1<bool>>| {
            let (u_row, v_row) = flow.row(y);
            for x in 0..ow {
                let taps = bilinear_taps(x as f32 + u_row[x], y as f32 + v_row[x], h, w);
                let mut px = out_row.row_mut(x);
                match taps {
                    Some(t) => {
                        // Fixed point: weights in units of 2⁻¹⁶ (the fractional position quantised to
                        // 1/256 px per axis), summing to exactly 2¹⁶; round half up.
                        let fx = (t.w[1] + t.w[3]).clamp(0.0, 1.0);
                        let fy = (t.w[2] + t.w[3]).clamp(0.0, 1.0);
                        let (qx, qy) = ((fx * 256.0 + 0.5) as u32, (fy * 256.0 + 0.5) as u32);
                        let wq = [
                            (256 - qx) * (256 - qy),
                            qx * (256 - qy),
                            (256 - qx) * qy,
                            qx * qy,
                        ];
                        for (ch, o) in px.iter_mut().enumerate() {
                            let acc: u32 = (0..4)
                                .map(|i| wq[i] * u32::from(s[t.idx[i] * c + ch]))
                                .sum();
                            *o = ((acc + (1 << 15)) >> 16) as u8;
                        }
                    }
                    None => px.fill(0),
                }
                if let Some(vr) = valid_row.as_mut() {
                    vr[x] = taps.is_some();
                }
            }
        };
    match valid {
        Some(mut valid) => {
            assert_eq!(
                valid.dim(),
                (oh, ow),
                "warp_rgb: valid mask shape differs from the output"
            );
            Zip::indexed(out.axis_iter_mut(Axis(0)))
                .and(valid.rows_mut())
                .par_for_each(|y, o, v| row(y, o, Some(v)));
        }
        None => Zip::indexed(out.axis_iter_mut(Axis(0))).par_for_each(|y, o| row(y, o, None)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array2, Array3};

    fn const_flow(h: usize, w: usize, u: f32, v: f32) -> Flow {
        Flow {
            u: Array2::from_elem((h, w), u),
            v: Array2::from_elem((h, w), v),
        }
    }

    #[test]
    fn taps_inside_border_and_outside() {
        let t = bilinear_taps(1.25, 0.5, 3, 4).unwrap();
        assert_eq!(t.idx, [1, 2, 5, 6]);
        assert_eq!(t.w, [0.375, 0.125, 0.375, 0.125]);
        // Exactly on the last centre: inside, all weight on it.
        let t = bilinear_taps(3.0, 2.0, 3, 4).unwrap();
        assert_eq!(t.w[0], 1.0);
        assert_eq!(t.idx[0], 2 * 4 + 3);
        assert!(bilinear_taps(3.0001, 1.0, 3, 4).is_none());
        assert!(bilinear_taps(-0.0001, 1.0, 3, 4).is_none());
        assert!(bilinear_taps(f32::NAN, 1.0, 3, 4).is_none());
        assert!(bilinear_taps(0.0, 0.0, 0, 4).is_none());
    }

    #[test]
    fn bilinear_of_a_ramp_is_exact_and_outside_is_invalid() {
        // src(y, x) = 10 y + x: bilinear reproduces it exactly.
        let src = Array2::from_shape_fn((4, 5), |(y, x)| 10.0 * y as f32 + x as f32);
        let flow = const_flow(4, 5, 0.25, 0.5);
        let mut out = Array2::zeros((4, 5));
        let mut valid = Array2::from_elem((4, 5), true);
        warp_bilinear(src.view(), &flow, out.view_mut(), Some(valid.view_mut()));
        for y in 0..4 {
            for x in 0..5 {
                let inside = y < 3 && x < 4;
                assert_eq!(valid[(y, x)], inside, "({y},{x})");
                let want = if inside {
                    10.0 * (y as f32 + 0.5) + x as f32 + 0.25
                } else {
                    0.0
                };
                assert!(
                    (out[(y, x)] - want).abs() < 1e-5,
                    "({y},{x}) {} vs {want}",
                    out[(y, x)]
                );
            }
        }
    }

    #[test]
    fn depth_blends_on_one_surface() {
        // Plane at 2.0/2.02 (one surface): ordinary bilinear.
        let src = array![[2.0f32, 2.02], [2.0, 2.02]];
        let flow = const_flow(1, 1, 0.25, 0.0);
        let mut out = Array2::zeros((1, 1));
        warp_depth(src.view(), &flow, out.view_mut());
        assert!((out[(0, 0)] - 2.005).abs() < 1e-6);
    }

    #[test]
    fn depth_does_not_blend_across_a_step() {
        // Foreground 1 m on the left, background 3 m on the right.
        let src = array![[1.0f32, 3.0], [1.0, 3.0]];
        let mut out = Array2::zeros((1, 1));
        warp_depth(src.view(), &const_flow(1, 1, 0.4, 0.3), out.view_mut());
        assert!((out[(0, 0)] - 1.0).abs() < 1e-6, "{}", out[(0, 0)]);
        warp_depth(src.view(), &const_flow(1, 1, 0.6, 0.3), out.view_mut());
        assert!((out[(0, 0)] - 3.0).abs() < 1e-6, "{}", out[(0, 0)]);
        // A plain bilinear warp would give 1.8 here.
        let mut amp = Array2::zeros((1, 1));
        warp_bilinear(
            src.view(),
            &const_flow(1, 1, 0.4, 0.3),
            amp.view_mut(),
            None,
        );
        assert!((amp[(0, 0)] - 1.8).abs() < 1e-6);
    }

    #[test]
    fn depth_ignores_invalid_neighbours_and_renormalises() {
        // (0,0) invalid; sample at (0.5, 0.5): the three valid ones share weight 1/4 each.
        let src = array![[0.0f32, 2.0], [2.01, 2.02]];
        let mut out = Array2::zeros((1, 1));
        warp_depth(src.view(), &const_flow(1, 1, 0.5, 0.5), out.view_mut());
        assert!((out[(0, 0)] - (2.0 + 2.01 + 2.02) / 3.0).abs() < 1e-6);
        // All invalid → 0; outside → 0.
        let holes = Array2::<f32>::zeros((2, 2));
        warp_depth(holes.view(), &const_flow(1, 1, 0.5, 0.5), out.view_mut());
        assert_eq!(out[(0, 0)], 0.0);
        warp_depth(src.view(), &const_flow(1, 1, 1.5, 0.0), out.view_mut());
        assert_eq!(out[(0, 0)], 0.0);
    }

    #[test]
    fn the_fused_warp_is_both_warps() {
        // A depth step with holes and a NaN amplitude, under a non-uniform flow reaching
        // outside the image, a NaN flow and samples exactly on the last row and column; rows
        // shorter than the fused row's chunk, and longer (two chunks and a part).
        for (h, w) in [(23, 31), (9, 150)] {
            let depth = Array2::from_shape_fn((h, w), |(y, x)| match (y * 7 + x * 3) % 13 {
                0 => 0.0,
                k if x < 15 => 1.0 + 0.01 * k as f32,
                k => 2.5 + 0.02 * k as f32,
            });
            let amplitude = Array2::from_shape_fn((h, w), |(y, x)| {
                if (y, x) == (5, 9) {
                    f32::NAN
                } else {
                    (y * w + x) as f32 * 0.37
                }
            });
            let mut flow = Flow {
                u: Array2::from_shape_fn((h, w), |(y, x)| 0.31 * x as f32 - 4.7 + 0.05 * y as f32),
                v: Array2::from_shape_fn((h, w), |(y, x)| -0.23 * y as f32 + 2.1 + 0.03 * x as f32),
            };
            flow.u[(3, 4)] = f32::NAN;
            // (2, 6) samples the bottom-right pixel centre exactly; (4, 2) the last column.
            (flow.u[(2, 6)], flow.v[(2, 6)]) = ((w - 1 - 6) as f32, (h - 1 - 2) as f32);
            (flow.u[(4, 2)], flow.v[(4, 2)]) = ((w - 1 - 2) as f32, 0.5);
            let (mut d1, mut a1) = (Array2::zeros((h, w)), Array2::zeros((h, w)));
            warp_depth(depth.view(), &flow, d1.view_mut());
            warp_bilinear(amplitude.view(), &flow, a1.view_mut(), None);
            let (mut d2, mut a2) = (Array2::zeros((h, w)), Array2::zeros((h, w)));
            warp_depth_and_bilinear(
                depth.view(),
                amplitude.view(),
                &flow,
                d2.view_mut(),
                a2.view_mut(),
            );
            let bits = |a: &Array2<f32>| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&d1), bits(&d2), "{h}x{w}");
            assert_eq!(bits(&a1), bits(&a2), "{h}x{w}");
            // The case covers what it claims: zeros outside, blends, and the NaN.
            assert!(d1.iter().any(|&z| z == 0.0) && d1.iter().any(|&z| z > 2.0));
            assert!(a1.iter().any(|v| v.is_nan()));
            assert_eq!(a1[(2, 6)], amplitude[(h - 1, w - 1)]);
            assert_eq!((d1[(3, 4)], a1[(3, 4)]), (0.0, 0.0));
        }
    }

    #[test]
    fn rgb_warp_rounds_and_blacks_out_outside() {
        let src = Array3::from_shape_fn((2, 3, 3), |(y, x, c)| (100 * c + 10 * x + y) as u8);
        let flow = const_flow(2, 3, 0.5, 0.0);
        let mut out = Array3::from_elem((2, 3, 3), 7u8);
        let mut valid = Array2::from_elem((2, 3), true);
        warp_rgb(src.view(), &flow, out.view_mut(), Some(valid.view_mut()));
        // (0, 0) samples x = 0.5: channel c is (100c + 0 + 100c + 10)/2 = 100c + 5.
        assert_eq!(out[(0, 0, 0)], 5);
        assert_eq!(out[(0, 0, 2)], 205);
        // (1, 1) samples x = 1.5, y = 1: 100c + 15 + 1.
        assert_eq!(out[(1, 1, 1)], 116);
        // x = 2.5 is outside.
        assert!(!valid[(0, 2)] && valid[(0, 1)]);
        assert_eq!(out.slice(ndarray::s![0, 2, ..]).to_vec(), vec![0, 0, 0]);
    }

    #[test]
    #[should_panic(expected = "warp_depth: flow u has shape")]
    fn shape_mismatch_panics_with_a_message() {
        let src = Array2::<f32>::zeros((2, 2));
        let mut out = Array2::zeros((3, 3));
        warp_depth(src.view(), &Flow::zeros(2, 2), out.view_mut());
    }
}
