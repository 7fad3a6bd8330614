//! Classical edge-aware depth refinement: the baseline the daemon runs without a model bundle,
//! and a row of every evaluation table.
//!
//! Per frame, in order:
//! 1. [`flying`]: flying pixels (mixed foreground/background depths at edges) are detected;
//! 2. [`snap`]: each is moved onto the neighbouring surface nearest to its measured depth (a
//!    mixed pixel is dominated by the surface it mostly sees; choosing the side by colour, as
//!    [`fill`] does, was measured to be worse, most of all at close range);
//! 3. [`outlier`]: a pixel off the surface of its valid 3 × 3 neighbourhood's median is
//!    replaced by that median (heavy-tailed low-signal noise, which smoothing would spread);
//! 4. [`fill`]: holes are filled from nearby measured pixels of similar colour, never across a
//!    depth edge, up to a maximum radius;
//! 5. [`domain_transform`]: a domain-transform filter guided by the RGB image smooths the depth
//!    within regions of similar colour, over the valid pixels only (O(N), independent of the
//!    spatial scale);
//! 6. [`snap`] again: a smoothed value that lies on no surface measured within a small window
//!    (averaging across a depth edge the colour does not show) is replaced by the nearest
//!    measured surface, so the output contains no mid-air depths.
//!
//! [`ClassicalRefiner`] owns every buffer it needs and reuses them across frames, so the hot
//! path allocates nothing once the first frame of a given size has been processed.

pub mod domain_transform;
pub mod fill;
pub mod flying;
pub mod outlier;
pub mod snap;

use ndarray::{Array2, ArrayView2, ArrayView3, ArrayViewMut2, Zip};

use crate::filter::domain_transform::{
    domain_transform_masked, DomainTransformParams, DomainTransformScratch,
};
use crate::filter::fill::{fill_holes, FillParams};
use crate::filter::flying::remove_flying_pixels;
use crate::filter::outlier::reject_outliers;
use crate::filter::snap::snap_to_surface;
use crate::geometry::surface::{is_valid_depth_branchless, surface_tolerance};

/// Runs `f(y, a_row, b_row)` on every row of `a` and `b` (same number of rows), rows in
/// parallel, on contiguous row slices so that the stages' inner loops are flat (and
/// vectorisable). The refiner's own buffers are contiguous; a row of a strided caller's view
/// goes through a temporary copy.
pub(crate) fn par_rows2<A, B, F>(mut a: ArrayViewMut2<A>, mut b: ArrayViewMut2<B>, f: F)
where
    A: Copy + Send + Sync,
    B: Copy + Send + Sync,
    F: Fn(usize, &mut [A], &mut [B]) + Sync + Send,
{
    Zip::indexed(a.rows_mut())
        .and(b.rows_mut())
        .par_for_each(|y, mut ra, mut rb| {
            if let (Some(sa), Some(sb)) = (ra.as_slice_mut(), rb.as_slice_mut()) {
                return f(y, sa, sb);
            }
            let (mut ta, mut tb) = (ra.to_vec(), rb.to_vec());
            f(y, &mut ta, &mut tb);
            ra.iter_mut().zip(ta).for_each(|(d, s)| *d = s);
            rb.iter_mut().zip(tb).for_each(|(d, s)| *d = s);
        });
}

/// [`par_rows2`] for one output.
pub(crate) fn par_rows<A, F>(mut a: ArrayViewMut2<A>, f: F)
where
    A: Copy + Send + Sync,
    F: Fn(usize, &mut [A]) + Sync + Send,
{
    Zip::indexed(a.rows_mut()).par_for_each(|y, mut ra| {
        if let Some(sa) = ra.as_slice_mut() {
            return f(y, sa);
        }
        let mut ta = ra.to_vec();
        f(y, &mut ta);
        ra.iter_mut().zip(ta).for_each(|(d, s)| *d = s);
    });
}

/// `x.round() as u8` for `x` in `[0, 127]` (or NaN: 0), without the call to `roundf` that
/// `round` is on x86-64's baseline: the fraction `x − trunc(x)` of a non-negative float is
/// exact, so rounding half away from zero is `trunc + (fraction ≥ 0.5)`.
#[inline(always)]
fn round_small(x: f32) -> u8 {
    let t = x as u8;
    t + u8::from(x - f32::from(t) >= 0.5)
}

/// Confidence of a measurement replaced from its neighbours (a flying pixel moved onto a
/// neighbouring surface, or an outlier replaced by its neighbourhood's median): which side a
/// mixed pixel belongs to is a guess (the nearest-in-depth side is right about 70 % of the
/// time on simulated frames), so these rank with the filled pixels.
pub const REPLACED_CONFIDENCE: u8 = 64;

/// The lowest confidence of a pixel whose output derives from its own measurement (measured and
/// at most smoothed); below it, the depth was taken from neighbours (filled, snapped, replaced).
pub const MEASURED_CONFIDENCE: u8 = 128;

/// Settings of the [`ClassicalRefiner`]. The defaults were chosen by measurement on simulated
/// aligned frames (`dear eval --baselines`, RESULTS.md); spatial settings are in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassicalParams {
    /// Flying-pixel threshold, relative to the pixel's depth (default 0.03 = 3 %: far above
    /// the noise, well below a typical object boundary).
    pub flying_rel: f32,
    /// Absolute floor of the flying-pixel threshold, metres (default 0.01).
    pub flying_abs_m: f32,
    /// Window half-size in which a flying pixel looks for the surface to move to (default 1:
    /// its 8 neighbours); with none valid there it is left to hole filling.
    pub flying_snap_radius: usize,
    /// Hole filling: search radius (default 5 px), colour scale (default 12 in 8-bit RGB
    /// units), spatial scale (default 3 px).
    pub fill: FillParams,
    /// Edge-aware smoothing: spatial scale (default 4 px), colour scale (default 60: summed
    /// absolute RGB difference in 8-bit units), rounds (default 3).
    pub smoothing: DomainTransformParams,
    /// Window half-size in which a smoothed depth must find a measured surface (default 2).
    pub surface_radius: usize,
}

impl Default for ClassicalParams {
    fn default() -> Self {
        ClassicalParams {
            flying_rel: 0.03,
            flying_abs_m: 0.01,
            flying_snap_radius: 1,
            fill: FillParams {
                radius: 5,
                sigma_colour: 12.0,
                sigma_space: 3.0,
            },
            smoothing: DomainTransformParams {
                sigma_space: 4.0,
                sigma_colour: 60.0,
                iterations: 3,
            },
            surface_radius: 2,
        }
    }
}

/// Per-frame buffers, sized for one resolution.
#[derive(Debug, Clone)]
struct Scratch {
    cleaned: Array2<f32>,
    snapped_in: Array2<f32>,
    flying_snapped: Array2<bool>,
    outlier_free: Array2<f32>,
    outlier_replaced: Array2<bool>,
    filled: Array2<f32>,
    fill_confidence: Array2<u8>,
    smoothed: Array2<f32>,
    surfaced: Array2<f32>,
    surface_snapped: Array2<bool>,
    smoothing: DomainTransformScratch,
}

impl Scratch {
    fn new(h: usize, w: usize) -> Self {
        Scratch {
            cleaned: Array2::zeros((h, w)),
            snapped_in: Array2::zeros((h, w)),
            flying_snapped: Array2::from_elem((h, w), false),
            outlier_free: Array2::zeros((h, w)),
            outlier_replaced: Array2::from_elem((h, w), false),
            filled: Array2::zeros((h, w)),
            fill_confidence: Array2::zeros((h, w)),
            smoothed: Array2::zeros((h, w)),
            surfaced: Array2::zeros((h, w)),
            surface_snapped: Array2::from_elem((h, w), false),
            smoothing: DomainTransformScratch::new(h, w),
        }
    }
}

/// The classical refinement baseline. Not `Sync`-shared: one refiner per processing thread.
#[derive(Debug, Clone, Default)]
pub struct ClassicalRefiner {
    /// The settings in use.
    pub params: ClassicalParams,
    scratch: Option<Scratch>,
}

impl ClassicalRefiner {
    /// A refiner with the given settings; buffers are allocated on the first frame.
    pub fn new(params: ClassicalParams) -> Self {
        ClassicalRefiner {
            params,
            scratch: None,
        }
    }

    /// Refine one depth map (metres, `0` = invalid) guided by the RGB image on the same grid.
    ///
    /// Writes the refined depth (`0` = invalid) and a confidence per pixel:
    /// - `255`: measured, and the output equals the measurement;
    /// - `128..=254` (from [`MEASURED_CONFIDENCE`]): measured and smoothed; lower the larger the
    ///   correction, reaching 128 at the same-surface tolerance ([`surface_tolerance`]) of the
    ///   measurement;
    /// - `1..=127`: not measured here: filled from neighbours (holes; higher the better the
    ///   colour and distance match of the best source), or a flying pixel moved onto a
    ///   neighbouring surface or an outlier replaced by its neighbours' median
    ///   ([`REPLACED_CONFIDENCE`]);
    /// - `0`: invalid, depth `0`.
    ///
    /// # Panics
    /// If `rgb` is not `(H, W, 3)` or the outputs are not `(H, W)` for the depth's `(H, W)`.
    pub fn refine_into(
        &mut self,
        depth: ArrayView2<f32>,
        rgb: ArrayView3<u8>,
        out_depth: ArrayViewMut2<f32>,
        out_confidence: ArrayViewMut2<u8>,
    ) {
        let (h, w) = depth.dim();
        assert_eq!(
            rgb.dim(),
            (h, w, 3),
            "refine_into: rgb is {:?}, expected ({h}, {w}, 3)",
            rgb.dim()
        );
        assert_eq!(
            out_depth.dim(),
            (h, w),
            "refine_into: out_depth shape differs from the depth's"
        );
        assert_eq!(
            out_confidence.dim(),
            (h, w),
            "refine_into: out_confidence shape differs from the depth's"
        );
        let p = self.params;
        if self
            .scratch
            .as_ref()
            .is_none_or(|s| s.cleaned.dim() != (h, w))
        {
            self.scratch = Some(Scratch::new(h, w));
        }
        let Some(s) = self.scratch.as_mut() else {
            unreachable!("scratch was just created")
        };

        remove_flying_pixels(depth, p.flying_rel, p.flying_abs_m, s.cleaned.view_mut());
        snap_to_surface(
            depth,
            s.cleaned.view(),
            p.flying_snap_radius,
            s.snapped_in.view_mut(),
            s.flying_snapped.view_mut(),
        );
        reject_outliers(
            s.snapped_in.view(),
            s.outlier_free.view_mut(),
            s.outlier_replaced.view_mut(),
        );
        fill_holes(
            s.outlier_free.view(),
            rgb,
            &p.fill,
            s.filled.view_mut(),
            s.fill_confidence.view_mut(),
        );
        domain_transform_masked(
            rgb,
            s.filled.view(),
            &p.smoothing,
            &mut s.smoothing,
            s.smoothed.view_mut(),
        );
        snap_to_surface(
            s.smoothed.view(),
            s.filled.view(),
            p.surface_radius,
            s.surfaced.view_mut(),
            s.surface_snapped.view_mut(),
        );

        // Measurements replaced from their neighbours rank with the filled pixels.
        fn slice<T>(a: &Array2<T>) -> &[T] {
            a.as_slice().expect("scratch arrays are contiguous")
        }
        let depth = depth.as_standard_layout();
        let (measured, filled, surfaced) = (
            depth
                .as_slice()
                .expect("as_standard_layout yields a contiguous array"),
            slice(&s.filled),
            slice(&s.surfaced),
        );
        let (fill_confidence, flying_snapped, outlier_replaced) = (
            slice(&s.fill_confidence),
            slice(&s.flying_snapped),
            slice(&s.outlier_replaced),
        );
        par_rows2(out_depth, out_confidence, |y, out_row, conf_row| {
            let row = y * w..(y + 1) * w;
            let depths = [
                &filled[row.clone()],
                &surfaced[row.clone()],
                &measured[row.clone()],
            ];
            let flags = [&flying_snapped[row.clone()], &outlier_replaced[row.clone()]];
            output_row(depths, &fill_confidence[row], flags, out_row, conf_row);
        });
    }

    /// [`refine_into`](Self::refine_into) into new arrays: `(depth, confidence)`.
    pub fn refine(
        &mut self,
        depth: ArrayView2<f32>,
        rgb: ArrayView3<u8>,
    ) -> (Array2<f32>, Array2<u8>) {
        let mut out = Array2::zeros(depth.dim());
        let mut conf = Array2::zeros(depth.dim());
        self.refine_into(depth, rgb, out.view_mut(), conf.view_mut());
        (out, conf)
    }
}

/// One row of [`ClassicalRefiner::refine_into`]'s output and confidence from the stages'
/// results (`[filled, surfaced, measured]` depths, the fill confidence, the
/// `[flying_snapped, outlier_replaced]` flags). Written with selects (every pixel computes
/// every case; validity and the flags pick one) so that the loop vectorises, as holes make the
/// branches unpredictable; compiled for AVX-512 and AVX2 as well, chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn output_row(
    [filled, surfaced, measured]: [&[f32]; 3],
    fill_confidence: &[u8],
    [flying_snapped, outlier_replaced]: [&[bool]; 2],
    out: &mut [f32],
    confidence: &mut [u8],
) {
    for (x, (o, c)) in out.iter_mut().zip(confidence.iter_mut()).enumerate() {
        let (d, z, measured) = (filled[x], surfaced[x], measured[x]);
        let ok = is_valid_depth_branchless(d) & is_valid_depth_branchless(z);
        let replaced = flying_snapped[x] | outlier_replaced[x];
        let fc = match fill_confidence[x] {
            0 if replaced => REPLACED_CONFIDENCE,
            fc => fc,
        };
        // Measured here (used where fc = 0): lower the larger the smoothing's correction.
        let change = (z - measured).abs() / surface_tolerance(measured);
        // 255 − 127 = MEASURED_CONFIDENCE at the tolerance and beyond.
        let smoothed = 255 - round_small(127.0 * change.min(1.0));
        *o = if ok { z } else { 0.0 };
        *c = if !ok {
            0
        } else if fc > 0 {
            fc
        } else {
            smoothed
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::surface::same_surface;
    use ndarray::Array3;

    /// Deterministic approximately Gaussian noise (sum of 4 uniforms, unit variance).
    pub(crate) fn gauss(i: usize) -> f32 {
        let u = |k: usize| {
            let mut x = ((i * 4 + k) as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
            x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((x ^ (x >> 31)) >> 40) as f32 / (1u64 << 24) as f32
        };
        ((u(0) + u(1) + u(2) + u(3)) - 2.0) * 3.0f32.sqrt()
    }

    fn std_dev(v: impl Iterator<Item = f32>) -> f32 {
        let v: Vec<f32> = v.collect();
        let m = v.iter().sum::<f32>() / v.len() as f32;
        (v.iter().map(|x| (x - m) * (x - m)).sum::<f32>() / v.len() as f32).sqrt()
    }

    fn textured_rgb(h: usize, w: usize) -> Array3<u8> {
        // Mild texture (±3 levels), below the guided filter's edge scale.
        Array3::from_shape_fn((h, w, 3), |(y, x, c)| {
            (120 + ((x * 7 + y * 13 + c) % 7)) as u8
        })
    }

    #[test]
    fn noise_on_a_plane_is_reduced() {
        let (h, w) = (60, 80);
        let depth = Array2::from_shape_fn((h, w), |(y, x)| 2.0 + 0.01 * gauss(y * w + x));
        let rgb = textured_rgb(h, w);
        let (out, conf) = ClassicalRefiner::default().refine(depth.view(), rgb.view());
        let inner = |a: &Array2<f32>| {
            a.slice(ndarray::s![5..h - 5, 5..w - 5])
                .iter()
                .copied()
                .collect::<Vec<_>>()
                .into_iter()
        };
        let before = std_dev(inner(&depth).map(|z| z - 2.0));
        let after = std_dev(inner(&out).map(|z| z - 2.0));
        assert!(before > 0.009, "input noise {before}");
        assert!(after < before / 4.0, "std {before} → {after}");
        assert!(
            conf.iter().all(|&c| c >= MEASURED_CONFIDENCE),
            "every pixel is measured"
        );
    }

    #[test]
    fn step_edge_stays_sharp() {
        // 1 m on the left (dark), 2 m on the right (bright), with 5 mm noise.
        let (h, w) = (30, 40);
        let depth = Array2::from_shape_fn((h, w), |(y, x)| {
            (if x < 20 { 1.0 } else { 2.0 }) + 0.005 * gauss(y * w + x)
        });
        let rgb = Array3::from_shape_fn((h, w, 3), |(_, x, _)| if x < 20 { 40 } else { 200 });
        let (out, _) = ClassicalRefiner::default().refine(depth.view(), rgb.view());
        for ((y, x), &z) in out.indexed_iter() {
            let level = if x < 20 { 1.0 } else { 2.0 };
            assert!(
                (z - level).abs() < 0.02,
                "({y},{x}): {z} is between the levels"
            );
        }
    }

    #[test]
    fn step_edge_without_a_colour_edge_is_not_averaged() {
        let (h, w) = (30, 40);
        let depth = Array2::from_shape_fn((h, w), |(_, x)| if x < 20 { 1.0f32 } else { 2.0 });
        let rgb = textured_rgb(h, w);
        let (out, _) = ClassicalRefiner::default().refine(depth.view(), rgb.view());
        // Smoothing may lean towards the other side (the guide shows no edge), but the
        // surface snap bounds it: every output is on its own side's surface.
        for ((y, x), &z) in out.indexed_iter() {
            let level = if x < 20 { 1.0 } else { 2.0 };
            assert!(same_surface(level, z), "({y},{x}): {z}");
        }
    }

    #[test]
    fn hole_is_filled_and_far_holes_stay_empty() {
        let (h, w) = (40, 60);
        let mut depth = Array2::from_elem((h, w), 1.5f32);
        // A 4×4 hole in the middle, and the right-most 20 columns without any measurement.
        depth.slice_mut(ndarray::s![18..22, 18..22]).fill(0.0);
        depth.slice_mut(ndarray::s![.., 40..]).fill(0.0);
        let rgb = textured_rgb(h, w);
        let (out, conf) = ClassicalRefiner::default().refine(depth.view(), rgb.view());
        for y in 18..22 {
            for x in 18..22 {
                assert!(
                    (out[(y, x)] - 1.5).abs() < 1e-4,
                    "({y},{x}) = {}",
                    out[(y, x)]
                );
                assert!((1..=127).contains(&conf[(y, x)]));
            }
        }
        // Filled up to the radius (5) next to the measured area, empty beyond.
        assert!(out[(10, 44)] > 0.0 && out[(10, 45)] == 0.0 && conf[(10, 45)] == 0);
        assert_eq!(out[(10, 59)], 0.0);
    }

    #[test]
    fn flying_pixel_is_removed_and_snapped_to_a_surface() {
        let (h, w) = (20, 30);
        let mut depth = Array2::from_shape_fn((h, w), |(_, x)| if x < 15 { 1.0f32 } else { 3.0 });
        // Mixed pixels along the edge in a few rows, seeing mostly the background.
        for y in 5..10 {
            depth[(y, 15)] = 2.4;
        }
        // Colour puts column 15 with the background.
        let rgb = Array3::from_shape_fn((h, w, 3), |(_, x, _)| if x < 15 { 50 } else { 210 });
        let (out, conf) = ClassicalRefiner::default().refine(depth.view(), rgb.view());
        // Moved onto the surface nearest in depth, the background.
        for y in 5..10 {
            assert!(same_surface(3.0, out[(y, 15)]), "row {y}: {}", out[(y, 15)]);
            assert!(conf[(y, 15)] <= 127, "refilled, not measured");
        }
        for ((y, x), &z) in out.indexed_iter() {
            let on_a_surface = same_surface(1.0, z) || same_surface(3.0, z);
            assert!(on_a_surface, "({y},{x}): {z} floats between the surfaces");
        }
    }

    /// Noisy depth with edges, holes, NaN and isolated spikes, and a textured guide with a
    /// colour edge: exercises every branch of every stage.
    fn awkward_frame(h: usize, w: usize) -> (Array2<f32>, Array3<u8>) {
        let depth = Array2::from_shape_fn((h, w), |(y, x)| {
            let i = y * w + x;
            let level = if x * 3 < w {
                0.8
            } else if (x + y) % 40 < 25 {
                1.6
            } else {
                3.5
            };
            match i % 23 {
                0 | 7 => 0.0,
                11 if y % 3 == 0 => f32::NAN,
                5 => level * 1.4,
                13 => 2.2,
                _ => level * (1.0 + 0.012 * gauss(i)),
            }
        });
        let mut depth = depth;
        let (hy, hx) = (h / 3..(h / 3 + 9).min(h), w / 2..(w / 2 + 12).min(w));
        depth.slice_mut(ndarray::s![hy, hx]).fill(0.0);
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, c)| {
            (if x * 3 < w { 40 } else { 170 } + (x * 7 + y * 13 + c) % 9) as u8
        });
        (depth, rgb)
    }

    /// The stages as they were written before they were vectorised (one pixel at a time, 2-D
    /// indexing), for the bit-for-bit comparisons below.
    mod plain {
        use crate::geometry::surface::{is_valid_depth, same_surface};
        use ndarray::Array2;

        pub fn flying(d: &Array2<f32>, rel: f32, abs_m: f32) -> Array2<f32> {
            let (h, w) = d.dim();
            // A sample off the image is invalid (0).
            let at = |y: isize, x: isize| {
                if y < 0 || x < 0 || y >= h as isize || x >= w as isize {
                    0.0
                } else {
                    d[(y as usize, x as usize)]
                }
            };
            Array2::from_shape_fn((h, w), |(y, x)| {
                let z = d[(y, x)];
                if !is_valid_depth(z) {
                    return 0.0;
                }
                let tol = (rel * z).max(abs_m);
                let (y, x) = (y as isize, x as isize);
                let flying = [(0, 1), (1, 0), (1, 1), (1, -1)].iter().any(|&(dy, dx)| {
                    let (a, b) = (at(y - dy, x - dx), at(y + dy, x + dx));
                    let (a2, b2) = (at(y - 2 * dy, x - 2 * dx), at(y + 2 * dy, x + 2 * dx));
                    let (da, db) = (z - a, b - z);
                    let between = is_valid_depth(a)
                        && is_valid_depth(b)
                        && da.abs() > tol
                        && db.abs() > tol
                        && da * db > 0.0;
                    let step = !is_valid_depth(a2)
                        || !is_valid_depth(b2)
                        || ((a + a2) - (b + b2)).abs() > 4.0 * tol;
                    between && step
                });
                if flying {
                    0.0
                } else {
                    z
                }
            })
        }

        pub fn snap(
            v: &Array2<f32>,
            r: &Array2<f32>,
            radius: usize,
        ) -> (Array2<f32>, Array2<bool>) {
            let (h, w) = v.dim();
            let mut out = Array2::zeros((h, w));
            let mut flags = Array2::from_elem((h, w), false);
            for ((y, x), &v) in v.indexed_iter() {
                if !is_valid_depth(v) {
                    continue;
                }
                let mut nearest = (f32::INFINITY, 0.0f32);
                let mut on_surface = false;
                for yy in y.saturating_sub(radius)..=(y + radius).min(h - 1) {
                    for xx in x.saturating_sub(radius)..=(x + radius).min(w - 1) {
                        let z = r[(yy, xx)];
                        if !is_valid_depth(z) {
                            continue;
                        }
                        on_surface |= same_surface(z, v);
                        if (z - v).abs() < nearest.0 {
                            nearest = ((z - v).abs(), z);
                        }
                    }
                }
                if on_surface {
                    out[(y, x)] = v;
                } else if nearest.0.is_finite() {
                    (out[(y, x)], flags[(y, x)]) = (nearest.1, true);
                }
            }
            (out, flags)
        }
    }

    fn assert_bits_equal(a: &Array2<f32>, b: &Array2<f32>, what: &str) {
        for ((i, x), y) in a.indexed_iter().zip(b) {
            assert_eq!(x.to_bits(), y.to_bits(), "{what} at {i:?}: {x} vs {y}");
        }
    }

    #[test]
    fn flying_and_snap_match_the_plain_rules_bit_for_bit() {
        for (h, w) in [(41, 67), (2, 9), (9, 2), (1, 1)] {
            let (depth, _) = awkward_frame(h, w);
            let mut cleaned = Array2::zeros((h, w));
            flying::remove_flying_pixels(depth.view(), 0.03, 0.01, cleaned.view_mut());
            assert_bits_equal(&cleaned, &plain::flying(&depth, 0.03, 0.01), "flying");
            for radius in [1, 2] {
                let mut out = Array2::zeros((h, w));
                let mut flags = Array2::from_elem((h, w), false);
                snap_to_surface(
                    depth.view(),
                    cleaned.view(),
                    radius,
                    out.view_mut(),
                    flags.view_mut(),
                );
                let (expect, expect_flags) = plain::snap(&depth, &cleaned, radius);
                assert_bits_equal(&out, &expect, "snap");
                assert_eq!(flags, expect_flags);
            }
        }
    }

    #[test]
    fn strided_outputs_get_the_same_result() {
        // Output views with a column stride go through the stages' row copies.
        let (h, w) = (35, 50);
        let (depth, rgb) = awkward_frame(h, w);
        let mut r = ClassicalRefiner::default();
        let (out, conf) = r.refine(depth.view(), rgb.view());
        let mut wide = Array2::<f32>::zeros((h, 2 * w));
        let mut wide_conf = Array2::<u8>::zeros((h, 2 * w));
        r.refine_into(
            depth.view(),
            rgb.view(),
            wide.slice_mut(ndarray::s![.., ..;2]),
            wide_conf.slice_mut(ndarray::s![.., ..;2]),
        );
        assert_bits_equal(&wide.slice(ndarray::s![.., ..;2]).to_owned(), &out, "depth");
        assert_eq!(wide_conf.slice(ndarray::s![.., ..;2]), conf);
        assert!(conf.iter().any(|&c| c == REPLACED_CONFIDENCE));
        assert!(conf.iter().any(|&c| (128..255).contains(&c)));
    }

    #[test]
    fn round_small_is_round() {
        // Every float near each half-integer, and a sweep of the rest of [0, 127].
        for k in 0..=127u32 {
            let half = k as f32 + 0.5;
            let mut x = half;
            for _ in 0..64 {
                x = f32::from_bits(x.to_bits() - 1);
            }
            for _ in 0..128 {
                if x <= 127.0 {
                    assert_eq!(round_small(x), x.round() as u8, "{x}");
                }
                x = f32::from_bits(x.to_bits() + 1);
            }
        }
        let top = 127.0f32.to_bits();
        for bits in (0..=top).step_by(9973).chain([top, 0]) {
            let x = f32::from_bits(bits);
            assert_eq!(round_small(x), x.round() as u8, "{x}");
        }
        assert_eq!(round_small(f32::NAN), f32::NAN.round() as u8);
    }

    #[test]
    fn reuses_buffers_and_handles_a_size_change() {
        let mut r = ClassicalRefiner::default();
        for &(h, w) in &[(10, 12), (10, 12), (7, 5)] {
            let depth = Array2::from_elem((h, w), 1.0f32);
            let rgb = Array3::from_elem((h, w, 3), 90u8);
            let (out, conf) = r.refine(depth.view(), rgb.view());
            assert!(out.iter().all(|&z| (z - 1.0).abs() < 1e-5));
            assert!(conf.iter().all(|&c| c == 255));
        }
    }
}
