//! Classical edge-aware depth refinement: the baseline the daemon runs without a model bundle,
//! and a row of every evaluation table.
//!
//! Per frame, in order:
//! 1. [`flying`]: flying pixels (mixed foreground/background depths at edges) are detected;
//! 2. [`snap`]: each is moved onto the neighbouring surface nearest to its measured depth (a
//!    mixed pixel is dominated by the surface it mostly sees; choosing the side by colour, as
//!    [`fill`] does, was measured to be worse, most of all at close range);
//! 3. [`outlier`]: an isolated pixel off the surface of its valid 3 × 3 neighbourhood's median
//!    is replaced by that median (heavy-tailed low-signal noise, which smoothing would spread);
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
use crate::geometry::surface::{is_valid_depth, surface_tolerance};

/// Confidence of a measurement replaced from its neighbours (a flying pixel moved onto a
/// neighbouring surface, or an outlier replaced by its neighbourhood's median): which side a
/// mixed pixel belongs to is a guess (the nearest-in-depth side is right about 70 % of the
/// time on simulated frames), so these rank with the filled pixels.
pub const REPLACED_CONFIDENCE: u8 = 64;

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
    /// - `128..=254`: measured and smoothed; lower the larger the correction, reaching 128 at
    ///   the same-surface tolerance ([`surface_tolerance`]) of the measurement;
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
        mut out_depth: ArrayViewMut2<f32>,
        mut out_confidence: ArrayViewMut2<u8>,
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
        Zip::from(&mut s.fill_confidence)
            .and(&s.flying_snapped)
            .and(&s.outlier_replaced)
            .par_for_each(|fc, &snapped, &replaced| {
                if (snapped || replaced) && *fc == 0 {
                    *fc = REPLACED_CONFIDENCE;
                }
            });
        Zip::from(&mut out_depth)
            .and(&mut out_confidence)
            .and(&depth)
            .and(&s.filled)
            .and(&s.surfaced)
            .and(&s.fill_confidence)
            .par_for_each(|o, c, &measured, &d, &z, &fc| {
                if !is_valid_depth(d) || !is_valid_depth(z) {
                    (*o, *c) = (0.0, 0);
                    return;
                }
                *o = z;
                *c = if fc > 0 {
                    fc
                } else {
                    let change = (z - measured).abs() / surface_tolerance(measured);
                    255 - (127.0 * change.min(1.0)).round() as u8
                };
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
        assert!(conf.iter().all(|&c| c >= 128), "every pixel is measured");
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
