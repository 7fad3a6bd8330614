//! A cheap per-frame alignment check for frames that do not run the rough-flow network: how
//! well the alignment holds, and which way the principal point has moved since the estimate.
//!
//! The RGB image and the ToF amplitude see the same surface markings and the same object
//! outlines, so once the amplitude is warped onto the RGB grid their edges coincide when the
//! alignment is right and drift apart when the calibration has moved. Two numbers come from
//! the normalised cross-correlation (NCC) of the gradient magnitudes of the RGB luma `L` and
//! the warped amplitude `A_w`, over a sparse grid of pixels whose warped depth and its 4
//! neighbours are valid:
//!
//! - the *disagreement* `1 − NCC(|∇L|(p), |∇A_w|(p))`. Its absolute value depends on the scene
//!   (RGB and IR textures differ), so the online estimator compares it with the value measured
//!   right after the last network estimate, not with a fixed threshold;
//! - the *edge shift* `δ = argmax_Δ NCC(|∇L|(p), |∇A_w|(p + Δ))` over integer `Δ` within
//!   `±search_px`, refined to sub-pixel by a parabola through the neighbours of the peak.
//!   `A_w(p) = A(p + Ŵ(p))` with `Ŵ = t̂/z + ĉ` the estimate's flow, and the true flow is
//!   `t/z + c`; if only `c` moved (`c = ĉ + δ`, what OIS wander and thermal drift of the
//!   principal point do frame to frame), the amplitude edge that belongs to the RGB edge at `p`
//!   sits at `p + δ` in `A_w` wherever the depth is locally smooth. So `δ` is a direct, cheap
//!   measurement of the principal-point correction — no network, under a millisecond — which
//!   the online estimator uses to track `c` between network frames. `t` (depth-dependent) is
//!   left to the network.

use ndarray::{ArrayView2, ArrayView3};
use rayon::prelude::*;

use crate::geometry::surface::is_valid_depth_branchless;
use crate::vector_math::window3x3;

/// Fewest sampled pixels for a meaningful correlation.
pub const MIN_SAMPLES: usize = 64;

/// About this many pixels are sampled whatever the resolution (the grid's stride grows with the
/// image), so the check costs about the same at 320×240 and at 640×480 (0.4 and 0.7 ms on one
/// core, `stage_profile`).
const TARGET_SAMPLES: usize = 20_000;

/// The principal-point correction measured from the edges (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeShift {
    /// Correction of `c_x`, px (RGB grid).
    pub du: f32,
    /// Correction of `c_y`, px.
    pub dv: f32,
    /// NCC at the peak.
    pub peak_ncc: f32,
    /// NCC at the peak minus NCC at zero shift (≥ 0): how much the shift explains.
    pub gain: f32,
    /// The peak lies on the border of the search window: the true shift may be larger.
    pub at_limit: bool,
}

/// One frame's alignment check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeAlignment {
    /// `1 − NCC` at zero shift (0 = edges agree perfectly, 1 = uncorrelated, up to 2).
    pub disagreement: f32,
    /// The edge shift; `None` when the correlation has no clear peak (flat in a direction, or
    /// too few samples at some shift).
    pub shift: Option<EdgeShift>,
}

/// The check with its buffers (allocated once per resolution; the daemon calls it per frame).
#[derive(Debug, Clone)]
pub struct EdgeCheck {
    search_px: usize,
    luma: Vec<f32>,
    luma_gradient: Vec<f32>,
    amplitude_gradient: Vec<f32>,
    valid: Vec<bool>,
    samples: Vec<u32>,
    /// `|∇L|` at each sample and its square, in f64 as the sums use them.
    sample_luma: Vec<(f64, f64)>,
    ncc: Vec<f32>,
}

/// Running sums of one NCC.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    n: usize,
    a: f64,
    b: f64,
    aa: f64,
    bb: f64,
    ab: f64,
}

impl Sums {
    /// Adds the pair `(a, b)`, with `aa = a · a` computed by the caller (once per sample
    /// rather than once per shift): one shift at a time, what [`lane_sums`] does for
    /// [`LANES`] shifts at once (the tests' reference).
    #[cfg(test)]
    fn add_f64(&mut self, a: f64, aa: f64, b: f64) {
        self.n += 1;
        self.a += a;
        self.b += b;
        self.aa += aa;
        self.bb += b * b;
        self.ab += a * b;
    }

    fn ncc(&self) -> Option<f32> {
        if self.n < MIN_SAMPLES {
            return None;
        }
        let n = self.n as f64;
        let va = self.aa / n - (self.a / n).powi(2);
        let vb = self.bb / n - (self.b / n).powi(2);
        let cov = self.ab / n - self.a * self.b / (n * n);
        (va > 1e-12 && vb > 1e-12).then(|| (cov / (va.sqrt() * vb.sqrt())) as f32)
    }
}

/// Shifts along x whose sums one pass over the samples accumulates side by side: a vector
/// of f64 lanes (AVX-512), so that the pass costs about what one shift's did alone.
const LANES: usize = 8;

/// The [`Sums`] of [`LANES`] consecutive shifts along x, one lane each.
#[derive(Debug, Clone, Copy, Default)]
struct LaneSums {
    n: [u64; LANES],
    a: [f64; LANES],
    b: [f64; LANES],
    aa: [f64; LANES],
    bb: [f64; LANES],
    ab: [f64; LANES],
}

impl LaneSums {
    fn lane(&self, l: usize) -> Sums {
        Sums {
            n: self.n[l] as usize,
            a: self.a[l],
            b: self.b[l],
            aa: self.aa[l],
            bb: self.bb[l],
            ab: self.ab[l],
        }
    }
}

/// The sums of shifts `offset + l` (flat index offsets, `l < LANES`): for every sample `i`
/// in order, [`Sums::add_f64`] of its luma gradient and `gradient[i + offset + l]` where
/// `valid[i + offset + l]`. An invalid pixel adds `+0.0` to sums that are `≥ +0.0` (gradient
/// magnitudes), which leaves them bit for bit as skipping it would; selects, not branches,
/// so the lanes vectorise. `valid` and `gradient` must reach `LANES − 1` past every
/// `i + offset` (the check pads them). Compiled for AVX-512 and AVX2 as well, chosen at run
/// time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn lane_sums(
    samples: &[u32],
    sample_luma: &[(f64, f64)],
    valid: &[bool],
    gradient: &[f32],
    offset: isize,
) -> LaneSums {
    // Local accumulators (kept in registers) and masks applied to the bits: with `if ok`
    // selects the compiler split every sum into two masked read-modify-writes in memory.
    let (mut n, mut sa, mut sb) = ([0u64; LANES], [0.0f64; LANES], [0.0f64; LANES]);
    let (mut saa, mut sbb, mut sab) = ([0.0f64; LANES], [0.0f64; LANES], [0.0f64; LANES]);
    let keep = |x: f64, mask: u64| f64::from_bits(x.to_bits() & mask);
    for (&i, &(a, aa)) in samples.iter().zip(sample_luma) {
        let j = (i as isize + offset) as usize;
        let (ok, g) = (&valid[j..j + LANES], &gradient[j..j + LANES]);
        for l in 0..LANES {
            let b = f64::from(g[l]);
            let mask = 0u64.wrapping_sub(u64::from(ok[l]));
            n[l] += mask & 1;
            sa[l] += keep(a, mask);
            sb[l] += keep(b, mask);
            saa[l] += keep(aa, mask);
            sbb[l] += keep(b * b, mask);
            sab[l] += keep(a * b, mask);
        }
    }
    LaneSums {
        n,
        a: sa,
        b: sb,
        aa: saa,
        bb: sbb,
        ab: sab,
    }
}

impl EdgeCheck {
    /// A check that searches shifts within `±search_px` (0: disagreement only).
    pub fn new(search_px: usize) -> Self {
        EdgeCheck {
            search_px,
            luma: Vec::new(),
            luma_gradient: Vec::new(),
            amplitude_gradient: Vec::new(),
            valid: Vec::new(),
            samples: Vec::new(),
            sample_luma: Vec::new(),
            ncc: Vec::new(),
        }
    }

    /// Measures the alignment of `rgb` `(H, W, 3)` with `warped_amplitude` `(H, W)` where
    /// `warped_depth` is valid. `None` when fewer than [`MIN_SAMPLES`] pixels qualify, either
    /// image is flat there, or the shapes differ.
    pub fn measure(
        &mut self,
        rgb: ArrayView3<u8>,
        warped_amplitude: ArrayView2<f32>,
        warped_depth: ArrayView2<f32>,
    ) -> Option<EdgeAlignment> {
        let (h, w) = warped_depth.dim();
        let r = self.search_px;
        if rgb.dim() != (h, w, 3)
            || warped_amplitude.dim() != (h, w)
            || h < 2 * r + 3
            || w < 2 * r + 3
        {
            return None;
        }
        self.gradients(rgb, warped_amplitude, warped_depth);

        // Sample pixels at least r + 1 from the border so every shifted index is inside.
        let stride = ((h * w) as f64 / TARGET_SAMPLES as f64)
            .sqrt()
            .round()
            .max(2.0) as usize;
        self.samples.clear();
        for y in (r + 1..h - r - 1).step_by(stride) {
            for x in (r + 1..w - r - 1).step_by(stride) {
                let i = y * w + x;
                if self.valid[i] {
                    self.samples.push(i as u32);
                }
            }
        }

        self.sample_luma.clear();
        self.sample_luma.extend(self.samples.iter().map(|&i| {
            let a = f64::from(self.luma_gradient[i as usize]);
            (a, a * a)
        }));

        // One task per row of shifts; one pass over the samples accumulates the sums of up
        // to LANES of its shifts side by side (see `lane_sums`). Each shift's sums still run
        // over the samples in order, as `Sums::add_f64` adds them, so the result does not depend
        // on the threads or on the lanes.
        let side = 2 * r + 1;
        self.ncc.clear();
        self.ncc.resize(side * side, f32::NAN);
        let (samples, sample_luma) = (&self.samples, &self.sample_luma);
        let (valid, amplitude_gradient) = (&self.valid, &self.amplitude_gradient);
        self.ncc
            .par_chunks_mut(side)
            .enumerate()
            .for_each(|(dy, row)| {
                for (chunk, ncc) in row.chunks_mut(LANES).enumerate() {
                    let dx0 = chunk * LANES;
                    let offset =
                        (dy as isize - r as isize) * w as isize + (dx0 as isize - r as isize);
                    let lanes = lane_sums(samples, sample_luma, valid, amplitude_gradient, offset);
                    for (l, ncc) in ncc.iter_mut().enumerate() {
                        *ncc = lanes.lane(l).ncc().unwrap_or(f32::NAN);
                    }
                }
            });
        // The window's centre is the zero shift.
        let zero = self.ncc[r * side + r];
        if !zero.is_finite() {
            return None;
        }
        Some(EdgeAlignment {
            disagreement: 1.0 - zero,
            shift: self.peak(zero),
        })
    }

    /// The NCC peak with sub-pixel refinement, if it is a clear one.
    fn peak(&self, zero: f32) -> Option<EdgeShift> {
        let r = self.search_px;
        let side = 2 * r + 1;
        if r == 0 || self.ncc.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let best = (0..side * side).max_by(|&a, &b| self.ncc[a].total_cmp(&self.ncc[b]))?;
        let (bx, by) = (best % side, best / side);
        let peak = self.ncc[best];
        // Parabola through the peak and its neighbours along one axis; none on the border.
        let refine = |prev: Option<f32>, next: Option<f32>| -> Option<f32> {
            let (Some(p), Some(n)) = (prev, next) else {
                return Some(0.0);
            };
            let curvature = p - 2.0 * peak + n;
            // A flat direction (no edges across it) has no peak to speak of.
            (curvature < -1e-4).then(|| (0.5 * (p - n) / curvature).clamp(-0.5, 0.5))
        };
        let get = |x: usize, y: usize| self.ncc[y * side + x];
        let fx = refine(
            bx.checked_sub(1).map(|x| get(x, by)),
            (bx + 1 < side).then(|| get(bx + 1, by)),
        )?;
        let fy = refine(
            by.checked_sub(1).map(|y| get(bx, y)),
            (by + 1 < side).then(|| get(bx, by + 1)),
        )?;
        Some(EdgeShift {
            du: bx as f32 - r as f32 + fx,
            dv: by as f32 - r as f32 + fy,
            peak_ncc: peak,
            gain: peak - zero,
            at_limit: bx == 0 || by == 0 || bx == side - 1 || by == side - 1,
        })
    }

    /// Gradient magnitudes (central differences) of the luma (`/255`) and of the warped
    /// amplitude, and where both are defined: the pixel and its 4 neighbours have valid depth.
    fn gradients(
        &mut self,
        rgb: ArrayView3<u8>,
        warped_amplitude: ArrayView2<f32>,
        warped_depth: ArrayView2<f32>,
    ) {
        let (h, w) = warped_depth.dim();
        let n = h * w;
        self.luma.resize(n, 0.0);
        self.luma_gradient.resize(n, 0.0);
        // The amplitude's gradient and the validity reach LANES past the image, invalid, so
        // that `lane_sums` reads whole lanes (the pad is reset: a larger frame may have left
        // values there).
        self.amplitude_gradient.resize(n + LANES, 0.0);
        self.amplitude_gradient[n..].fill(0.0);
        self.valid.resize(n + LANES, false);
        self.valid[n..].fill(false);
        let rgb = rgb.as_standard_layout();
        let rgb = rgb.as_slice().expect("standard layout is contiguous");
        let amplitude = warped_amplitude.as_standard_layout();
        let amplitude = amplitude.as_slice().expect("standard layout is contiguous");
        let depth = warped_depth.as_standard_layout();
        let depth = depth.as_slice().expect("standard layout is contiguous");
        self.luma
            .par_chunks_mut(w)
            .zip(rgb.par_chunks(3 * w))
            .for_each(|(luma, rgb)| luma_row(rgb, luma));
        let luma = &self.luma;
        // Rows in parallel, on flat slices; the border rows and columns stay invalid.
        self.luma_gradient
            .par_chunks_mut(w)
            .zip(self.amplitude_gradient[..n].par_chunks_mut(w))
            .zip(self.valid[..n].par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, ((lg, ag), valid))| {
                lg.fill(0.0);
                ag.fill(0.0);
                valid.fill(false);
                if y == 0 || y + 1 >= h {
                    return;
                }
                fn row(img: &[f32], w: usize, yy: usize) -> &[f32] {
                    &img[yy * w..(yy + 1) * w]
                }
                let (d0, d1, d2) = (row(depth, w, y - 1), row(depth, w, y), row(depth, w, y + 1));
                let (a0, a1, a2) = (
                    row(amplitude, w, y - 1),
                    row(amplitude, w, y),
                    row(amplitude, w, y + 1),
                );
                let (l0, l1, l2) = (row(luma, w, y - 1), row(luma, w, y), row(luma, w, y + 1));
                gradient_row([d0, d1, d2], [a0, a1, a2], [l0, l1, l2], ag, lg, valid);
            });
    }
}

/// Luma (`/255`) of one row of interleaved RGB. Compiled for AVX-512 and AVX2 as well,
/// chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn luma_row(rgb: &[u8], luma: &mut [f32]) {
    for (l, p) in luma.iter_mut().zip(rgb.chunks_exact(3)) {
        *l = (0.299 * f32::from(p[0]) + 0.587 * f32::from(p[1]) + 0.114 * f32::from(p[2])) / 255.0;
    }
}

/// The gradient magnitudes of the amplitude and the luma at the interior pixels of one row, and
/// where both are defined (the pixel and its 4 neighbours have valid depth), from the rows
/// above, at and below (`[y − 1, y, y + 1]`) of the depth, amplitude and luma. Compiled for
/// AVX-512 and AVX2 as well, chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn gradient_row(
    [d0, d1, d2]: [&[f32]; 3],
    [a0, a1, a2]: [&[f32]; 3],
    [l0, l1, l2]: [&[f32]; 3],
    ag: &mut [f32],
    lg: &mut [f32],
    valid: &mut [bool],
) {
    let w = d1.len();
    if w < 3 {
        return;
    }
    // sqrt, not hypot: no overflow to guard against here, and hypot was 4 % of a VGA frame.
    let magnitude = |gx: f32, gy: f32| (gx * gx + gy * gy).sqrt();
    // Equal-length slices of the neighbours (left, right, up, down, centre), so that the loop
    // has no bounds checks left to stop it vectorising; validity picks the gradients with
    // selects (holes make branches on it unpredictable).
    let n = w - 2;
    let [_, du, _, dl, dc, dr, _, dd, _] = window3x3([d0, d1, d2]);
    let [_, au, _, al, _, ar, _, ad, _] = window3x3([a0, a1, a2]);
    let [_, lu, _, ll, _, lr, _, ld, _] = window3x3([l0, l1, l2]);
    let (ag, lg, valid) = (&mut ag[1..=n], &mut lg[1..=n], &mut valid[1..=n]);
    for i in 0..n {
        let ok = is_valid_depth_branchless(dc[i])
            & is_valid_depth_branchless(du[i])
            & is_valid_depth_branchless(dd[i])
            & is_valid_depth_branchless(dl[i])
            & is_valid_depth_branchless(dr[i]);
        let ga = magnitude(ar[i] - al[i], ad[i] - au[i]);
        let gl = magnitude(lr[i] - ll[i], ld[i] - lu[i]);
        let ok = ok & ga.is_finite();
        ag[i] = if ok { ga } else { 0.0 };
        lg[i] = if ok { gl } else { 0.0 };
        valid[i] = ok;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, Array3};

    /// A blocky texture with some fine structure, sampled at `x + sx`, `y + sy`.
    fn texture(y: f32, x: f32) -> f32 {
        let (xi, yi) = (x.floor() as i64, y.floor() as i64);
        let block = ((xi.div_euclid(5) + yi.div_euclid(7)) % 2) as f32 * 0.6;
        block + 0.2 * ((xi * 3 + yi).rem_euclid(11)) as f32 / 10.0
    }

    fn scene(h: usize, w: usize, sx: f32, sy: f32) -> (Array3<u8>, Array2<f32>) {
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, _)| {
            (texture(y as f32, x as f32) * 255.0) as u8
        });
        // The warped amplitude sees the RGB pixel p at p + (sx, sy).
        let amplitude =
            Array2::from_shape_fn((h, w), |(y, x)| texture(y as f32 - sy, x as f32 - sx));
        (rgb, amplitude)
    }

    #[test]
    fn aligned_edges_agree_and_shifted_ones_do_not() {
        let (h, w) = (60, 80);
        let depth = Array2::from_elem((h, w), 2.0f32);
        let mut check = EdgeCheck::new(0);
        let (rgb, aligned) = scene(h, w, 0.0, 0.0);
        let (_, shifted) = scene(h, w, 3.0, 0.0);
        let good = check
            .measure(rgb.view(), aligned.view(), depth.view())
            .unwrap();
        let bad = check
            .measure(rgb.view(), shifted.view(), depth.view())
            .unwrap();
        assert!(good.disagreement < 0.05, "aligned: {good:?}");
        assert!(
            bad.disagreement > good.disagreement + 0.3,
            "aligned {good:?}, shifted {bad:?}"
        );
        assert_eq!(good.shift, None, "no search window, no shift");
        // No valid depth: no signal.
        let none = Array2::zeros((h, w));
        assert_eq!(check.measure(rgb.view(), aligned.view(), none.view()), None);
    }

    #[test]
    fn the_edge_shift_is_the_principal_point_correction() {
        let (h, w) = (90, 120);
        let depth = Array2::from_elem((h, w), 2.0f32);
        let mut check = EdgeCheck::new(3);
        for (sx, sy) in [(0.0, 0.0), (2.0, -1.0), (-3.0, 2.0), (1.0, 3.0)] {
            let (rgb, amplitude) = scene(h, w, sx, sy);
            let m = check
                .measure(rgb.view(), amplitude.view(), depth.view())
                .unwrap();
            let s = m.shift.expect("a clear peak");
            // The amplitude edge of RGB pixel p is at p + (sx, sy): c must grow by that.
            assert!(
                (s.du - sx).abs() < 0.35 && (s.dv - sy).abs() < 0.35,
                "shift ({sx}, {sy}) measured {s:?}"
            );
            assert!(s.gain >= 0.0);
            assert_eq!(s.at_limit, sx.abs() >= 3.0 || sy.abs() >= 3.0);
        }
    }

    #[test]
    fn a_shift_beyond_the_window_is_flagged() {
        // One bright rectangle (no repeating texture to alias with), seen 5 px to the right.
        let (h, w) = (90, 120);
        let rect =
            |y: f32, x: f32| f32::from((30.0..70.0).contains(&x) && (25.0..60.0).contains(&y));
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, _)| {
            (rect(y as f32, x as f32) * 200.0) as u8
        });
        let amplitude = Array2::from_shape_fn((h, w), |(y, x)| rect(y as f32, x as f32 - 5.0));
        let depth = Array2::from_elem((h, w), 2.0f32);
        let s = EdgeCheck::new(2)
            .measure(rgb.view(), amplitude.view(), depth.view())
            .unwrap()
            .shift
            .expect("a peak");
        assert!(s.at_limit && s.du == 2.0, "{s:?}");
        assert!(s.dv.abs() < 0.35, "{s:?}");
    }

    #[test]
    fn wrong_shapes_give_none() {
        let (rgb, amplitude) = scene(30, 40, 0.0, 0.0);
        let depth = Array2::from_elem((30, 41), 2.0f32);
        assert_eq!(
            EdgeCheck::new(2).measure(rgb.view(), amplitude.view(), depth.view()),
            None
        );
    }

    #[test]
    fn lanes_give_each_shift_the_sums_of_one_shift_at_a_time_bit_for_bit() {
        // Holes in the depth (invalid samples at some shifts), radii narrower and wider than
        // one vector of lanes, and a smaller frame after a larger one.
        let mut check = EdgeCheck::new(0);
        for (h, w, radius) in [(70, 90, 5), (48, 64, 1), (60, 80, 3), (40, 50, 6)] {
            let (rgb, amplitude) = scene(h, w, 1.0, -2.0);
            let depth = Array2::from_shape_fn((h, w), |(y, x)| {
                if (x * 7 + y * 3) % 11 == 0 || (x > 20 && x < 26) {
                    0.0
                } else {
                    1.0 + 0.01 * x as f32
                }
            });
            check.search_px = radius;
            check.measure(rgb.view(), amplitude.view(), depth.view());
            let side = 2 * radius + 1;
            assert_eq!(check.ncc.len(), side * side);
            for (k, &got) in check.ncc.iter().enumerate() {
                let offset = (k / side) as isize * w as isize + (k % side) as isize
                    - radius as isize * (w as isize + 1);
                let mut one = Sums::default();
                for (&i, &(a, aa)) in check.samples.iter().zip(&check.sample_luma) {
                    let j = (i as isize + offset) as usize;
                    if check.valid[j] {
                        one.add_f64(a, aa, f64::from(check.amplitude_gradient[j]));
                    }
                }
                let want = one.ncc().unwrap_or(f32::NAN);
                assert_eq!(
                    got.to_bits(),
                    want.to_bits(),
                    "{w}x{h}, radius {radius}, shift {k}"
                );
            }
        }
    }
}
