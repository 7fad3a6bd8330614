//! Classical edge-aware depth refinement: the baseline the daemon runs without a model bundle,
//! and a row of every evaluation table.
//!
//! Per frame, in order:
//! 1. [`flying`]: flying pixels (mixed foreground/background depths at edges) are invalidated;
//! 2. [`fill`]: holes are filled from nearby measured pixels of similar colour, never across a
//!    depth edge, up to a maximum radius;
//! 3. [`guided`]: a masked guided filter with the RGB luma as guide smooths the depth while
//!    following colour edges (O(N), independent of the radius);
//! 4. a safeguard keeps the unfiltered value wherever the filter would move a pixel by more
//!    than a small tolerance: that happens only at depth edges the guide does not show
//!    (e.g. two surfaces of the same colour), where averaging would invent mid-air depths.
//!
//! [`ClassicalRefiner`] owns every buffer it needs and reuses them across frames, so the hot
//! path allocates nothing once the first frame of a given size has been processed.

pub mod boxsum;
pub mod fill;
pub mod flying;
pub mod guided;

use ndarray::{Array2, ArrayView2, ArrayView3, ArrayViewMut2, Zip};

use crate::filter::fill::{fill_holes, FillParams};
use crate::filter::flying::remove_flying_pixels;
use crate::filter::guided::{guided_filter_masked, GuidedScratch};

/// Settings of the [`ClassicalRefiner`]. The defaults are tuned for VGA ToF depth (noise of
/// ~0.5 % of depth) and 8-bit RGB.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassicalParams {
    /// Flying-pixel threshold, relative to the pixel's depth (default 0.03 = 3 %: far above
    /// the noise, well below a typical object boundary).
    pub flying_rel: f32,
    /// Absolute floor of the flying-pixel threshold, metres (default 0.01).
    pub flying_abs_m: f32,
    /// Hole filling: search radius (default 5 px), colour scale (default 12 in 8-bit RGB
    /// units), spatial scale (default 3 px).
    pub fill: FillParams,
    /// Guided-filter window radius (default 4: 9 × 9 windows).
    pub guided_radius: usize,
    /// Guided-filter regulariser ε on the luma guide in `[0, 1]` (default 1e-3: luma edges
    /// weaker than ~0.03 — 8 grey levels — are smoothed across).
    pub guided_eps: f32,
    /// Largest change the filter may make, relative to depth (default 0.02); beyond it the
    /// unfiltered value is kept.
    pub max_correction_rel: f32,
    /// Absolute floor of the largest change, metres (default 0.01).
    pub max_correction_abs_m: f32,
}

impl Default for ClassicalParams {
    fn default() -> Self {
        ClassicalParams {
            flying_rel: 0.03,
            flying_abs_m: 0.01,
            fill: FillParams {
                radius: 5,
                sigma_colour: 12.0,
                sigma_space: 3.0,
            },
            guided_radius: 4,
            guided_eps: 1e-3,
            max_correction_rel: 0.02,
            max_correction_abs_m: 0.01,
        }
    }
}

/// Per-frame buffers, sized for one resolution.
#[derive(Debug, Clone)]
struct Scratch {
    luma: Array2<f32>,
    cleaned: Array2<f32>,
    filled: Array2<f32>,
    smoothed: Array2<f32>,
    fill_confidence: Array2<u8>,
    guided: GuidedScratch,
}

impl Scratch {
    fn new(h: usize, w: usize) -> Self {
        Scratch {
            luma: Array2::zeros((h, w)),
            cleaned: Array2::zeros((h, w)),
            filled: Array2::zeros((h, w)),
            smoothed: Array2::zeros((h, w)),
            fill_confidence: Array2::zeros((h, w)),
            guided: GuidedScratch::new(h, w),
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
    /// - `255`: measured, and the output equals the measurement (including pixels at depth
    ///   edges where smoothing was refused);
    /// - `128..=254`: measured and smoothed; lower the larger the correction, reaching 128 at
    ///   the largest allowed change (`max_correction_*`);
    /// - `1..=127`: filled from neighbours (flying or missing pixels); higher the better the
    ///   colour and distance match of the best source;
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
        if self.scratch.as_ref().is_none_or(|s| s.luma.dim() != (h, w)) {
            self.scratch = Some(Scratch::new(h, w));
        }
        let Some(s) = self.scratch.as_mut() else {
            unreachable!("scratch was just created")
        };

        Zip::from(&mut s.luma)
            .and(rgb.lanes(ndarray::Axis(2)))
            .par_for_each(|l, px| {
                *l = (0.299 * f32::from(px[0])
                    + 0.587 * f32::from(px[1])
                    + 0.114 * f32::from(px[2]))
                    / 255.0;
            });
        remove_flying_pixels(depth, p.flying_rel, p.flying_abs_m, s.cleaned.view_mut());
        fill_holes(
            s.cleaned.view(),
            rgb,
            &p.fill,
            s.filled.view_mut(),
            s.fill_confidence.view_mut(),
        );
        guided_filter_masked(
            s.luma.view(),
            s.filled.view(),
            p.guided_radius,
            p.guided_eps,
            &mut s.guided,
            s.smoothed.view_mut(),
        );

        Zip::from(&mut out_depth)
            .and(&mut out_confidence)
            .and(&s.filled)
            .and(&s.smoothed)
            .and(&s.fill_confidence)
            .par_for_each(|o, c, &d, &g, &fc| {
                if d.is_nan() || d <= 0.0 {
                    (*o, *c) = (0.0, 0);
                    return;
                }
                let tol = (p.max_correction_rel * d).max(p.max_correction_abs_m);
                let change = (g - d).abs();
                let out = if change <= tol { g } else { d };
                *o = out;
                *c = if fc > 0 {
                    fc
                } else {
                    let used = if change <= tol { change } else { 0.0 };
                    255 - (127.0 * (used / tol).min(1.0)).round() as u8
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
    use ndarray::Array3;

    /// Deterministic approximately Gaussian noise (sum of 4 uniforms, unit variance).
    fn gauss(i: usize) -> f32 {
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
        for ((y, x), &z) in out.indexed_iter() {
            let level = if x < 20 { 1.0 } else { 2.0 };
            let tol = 0.02 * level;
            assert!((z - level).abs() <= tol + 1e-6, "({y},{x}): {z}");
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
        // Mixed pixels along the edge in a few rows.
        for y in 5..10 {
            depth[(y, 15)] = 2.0;
        }
        // Colour puts column 15 with the background.
        let rgb = Array3::from_shape_fn((h, w, 3), |(_, x, _)| if x < 15 { 50 } else { 210 });
        let (out, conf) = ClassicalRefiner::default().refine(depth.view(), rgb.view());
        // Snapped to the background surface (the guided filter's ε shrinks a colour-edge step
        // by ~1 %, so "on the surface" means within the correction tolerance, not exact).
        for y in 5..10 {
            assert!(
                (out[(y, 15)] - 3.0).abs() < 0.06,
                "row {y}: {}",
                out[(y, 15)]
            );
            assert!(conf[(y, 15)] <= 127, "refilled, not measured");
        }
        for ((y, x), &z) in out.indexed_iter() {
            let on_a_surface = (z - 1.0).abs() <= 0.02 || (z - 3.0).abs() <= 0.06;
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
