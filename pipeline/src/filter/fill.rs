//! Colour-guided hole filling.
//!
//! An invalid pixel takes its depth from measured pixels nearby that look like it: among the
//! valid pixels within a square window it picks the one with the lowest cost
//! `|ΔRGB|²/σ_c² + |Δp|²/σ_s²`, then averages the valid pixels *on that pixel's surface*
//! (weights `≈ exp(−(cost − cost_best)/2)`), so a hole at an object boundary is filled from
//! the side whose colour matches and never with an average of foreground and background.
//! Pixels with no valid depth within the radius stay invalid.

use ndarray::{ArrayView2, ArrayView3, ArrayViewMut2};

use crate::filter::par_rows2;
use crate::geometry::surface::{is_valid_depth_branchless, same_surface};

/// Settings of [`fill_holes`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FillParams {
    /// Half-size of the search window, px.
    pub radius: usize,
    /// Colour scale σ_c, in 8-bit RGB units (Euclidean distance).
    pub sigma_colour: f32,
    /// Spatial scale σ_s, px.
    pub sigma_space: f32,
}

/// `≈ exp(−g)` for `g ≥ 0`: `1 / (1 + g + g²/2 + g³/6)`, the reciprocal of the truncated
/// Taylor series of `exp(g)`. Monotone, exact to first order, within 0.03 of `exp(−g)` for
/// `g ≤ 10`; a tenth of the cost of `expf`, which dominated filling at VGA.
#[inline]
fn soft_exp_neg(g: f32) -> f32 {
    1.0 / (1.0 + g * (1.0 + g * (0.5 + g * (1.0 / 6.0))))
}

/// Largest usable [`FillParams::radius`]; larger values are clamped to it (the per-pixel cost
/// table lives on the stack).
pub const MAX_FILL_RADIUS: usize = 10;

/// Pixels in the largest search window.
const WINDOW: usize = (2 * MAX_FILL_RADIUS + 1) * (2 * MAX_FILL_RADIUS + 1);

/// Candidates whose cost exceeds the best by this much (relative weight < 0.5 %) are skipped.
const MAX_COST_GAP: f32 = 20.0;

/// Fill the invalid pixels of `depth` into `out` (valid pixels are copied), and write into
/// `fill_confidence` `0` for measured or unfilled pixels and `1..=127` for filled ones:
/// `round(127 · exp(−cost_best/2))`, how well the best source matched.
///
/// # Panics
/// If the shapes differ.
pub fn fill_holes(
    depth: ArrayView2<f32>,
    rgb: ArrayView3<u8>,
    params: &FillParams,
    out: ArrayViewMut2<f32>,
    fill_confidence: ArrayViewMut2<u8>,
) {
    let (h, w) = depth.dim();
    let channels = rgb.dim().2;
    assert_eq!(
        (rgb.dim().0, rgb.dim().1),
        (h, w),
        "fill_holes: rgb and depth shapes differ"
    );
    assert_eq!(out.dim(), (h, w), "fill_holes: output shape differs");
    assert_eq!(
        fill_confidence.dim(),
        (h, w),
        "fill_holes: confidence shape differs"
    );
    let r = params.radius.min(MAX_FILL_RADIUS);
    let inv_c = 1.0 / (params.sigma_colour * params.sigma_colour).max(f32::MIN_POSITIVE);
    let inv_s = 1.0 / (params.sigma_space * params.sigma_space).max(f32::MIN_POSITIVE);
    let depth = depth.as_standard_layout();
    let d = depth
        .as_slice()
        .expect("as_standard_layout yields a contiguous array");
    let rgb = rgb.as_standard_layout();
    let c = rgb
        .as_slice()
        .expect("as_standard_layout yields a contiguous array");
    let colour_dist2 = |i: usize, j: usize| -> f32 {
        let dist2 = |a: &[u8], b: &[u8]| -> i32 {
            a.iter()
                .zip(b)
                .map(|(&p, &q)| (i32::from(p) - i32::from(q)).pow(2))
                .sum()
        };
        // RGB, the only guide the refiners pass, with its length known to the compiler: the
        // generic loop over `channels` was the largest part of the window scan.
        let sum = if channels == 3 {
            dist2(&c[i * 3..i * 3 + 3], &c[j * 3..j * 3 + 3])
        } else {
            dist2(
                &c[i * channels..(i + 1) * channels],
                &c[j * channels..(j + 1) * channels],
            )
        };
        sum as f32
    };
    // The fill of hole `(y, x)`: `(depth, confidence)`, or `None` with no valid pixel in reach.
    // Written without branches on the data where it can be: holes and their edges are
    // irregular, and mispredicted branches, not arithmetic, were most of this function's cost.
    // `costs` is the caller's buffer for the window's costs (row-major, the invalid ones +∞):
    // one per row of holes, because clearing a window-sized array for every hole cost a fifth
    // of the fill at 640×480.
    let fill = |y: usize, x: usize, costs: &mut [f32; WINDOW]| -> Option<(f32, u8)> {
        let i = y * w + x;
        let (y0, y1) = (y.saturating_sub(r), (y + r).min(h - 1));
        let (x0, x1) = (x.saturating_sub(r), (x + r).min(w - 1));
        let (mut n, mut valid_count) = (0, 0);
        let mut best = (f32::INFINITY, 0.0f32); // (cost, depth)
        for yy in y0..=y1 {
            let dy = yy as f32 - y as f32;
            for xx in x0..=x1 {
                let j = yy * w + xx;
                let zz = d[j];
                let ok = is_valid_depth_branchless(zz);
                let dx = xx as f32 - x as f32;
                let cost = colour_dist2(i, j) * inv_c + (dy * dy + dx * dx) * inv_s;
                let cost = if ok { cost } else { f32::INFINITY };
                costs[n] = cost;
                n += 1;
                valid_count += usize::from(ok);
                best = if cost < best.0 { (cost, zz) } else { best };
            }
        }
        if valid_count == 0 {
            return None;
        }
        let (best_cost, z_ref) = best;
        let (mut acc, mut wsum) = (0.0f32, 0.0f32);
        // The window again, in the same order, so the sums are those of one pass.
        let mut costs = costs[..n].iter();
        for yy in y0..=y1 {
            for (&zz, &cost) in d[yy * w + x0..=yy * w + x1].iter().zip(costs.by_ref()) {
                // An invalid pixel's gap is +∞ (or NaN): never taken.
                let gap = cost - best_cost;
                let take = (gap < MAX_COST_GAP) & same_surface(z_ref, zz);
                // Relative to the best match, so the weights cannot all underflow.
                let wgt = soft_exp_neg(0.5 * gap);
                acc += if take { wgt * zz } else { 0.0 };
                wsum += if take { wgt } else { 0.0 };
            }
        }
        let confidence = (127.0 * (-best_cost * 0.5).exp()).round().clamp(1.0, 127.0) as u8;
        Some((acc / wsum, confidence))
    };
    par_rows2(out, fill_confidence, |y, out_row, conf_row| {
        let row = &d[y * w..(y + 1) * w];
        let mut costs = [0.0f32; WINDOW];
        // Measured pixels copied; the holes found 64 at a time as a bit mask and filled.
        for start in (0..w).step_by(64) {
            let end = (start + 64).min(w);
            let mut holes = 0u64;
            for x in start..end {
                let z = row[x];
                let ok = is_valid_depth_branchless(z);
                (out_row[x], conf_row[x]) = (if ok { z } else { 0.0 }, 0);
                holes |= u64::from(!ok) << (x - start);
            }
            while holes != 0 {
                let x = start + holes.trailing_zeros() as usize;
                holes &= holes - 1;
                if let Some(filled) = fill(y, x, &mut costs) {
                    (out_row[x], conf_row[x]) = filled;
                }
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, Array3};

    const PARAMS: FillParams = FillParams {
        radius: 3,
        sigma_colour: 10.0,
        sigma_space: 2.0,
    };

    #[test]
    fn hole_on_a_boundary_is_filled_from_the_matching_colour() {
        // Left half dark at 1 m, right half bright at 3 m; a hole in column 3 (dark) and 4
        // (bright).
        let (h, w) = (5, 8);
        let rgb = Array3::from_shape_fn((h, w, 3), |(_, x, _)| if x < 4 { 30 } else { 220 });
        let mut depth = Array2::from_shape_fn((h, w), |(_, x)| if x < 4 { 1.0 } else { 3.0 });
        depth.column_mut(3).fill(0.0);
        depth.column_mut(4).fill(0.0);
        let mut out = Array2::zeros((h, w));
        let mut conf = Array2::zeros((h, w));
        fill_holes(
            depth.view(),
            rgb.view(),
            &PARAMS,
            out.view_mut(),
            conf.view_mut(),
        );
        for y in 0..h {
            assert!((out[(y, 3)] - 1.0).abs() < 1e-6);
            assert!((out[(y, 4)] - 3.0).abs() < 1e-6);
            // Best source 1 px away, same colour: cost 1/4, confidence 127·e^(−1/8) = 112.
            assert_eq!(conf[(y, 3)], 112);
            assert_eq!(conf[(y, 0)], 0);
        }
    }

    #[test]
    fn soft_exp_tracks_exp() {
        assert_eq!(soft_exp_neg(0.0), 1.0);
        for k in 0..100 {
            let g = k as f32 * 0.1;
            assert!((soft_exp_neg(g) - (-g).exp()).abs() < 0.03, "g = {g}");
            assert!(soft_exp_neg(g + 0.1) < soft_exp_neg(g));
        }
    }

    #[test]
    fn pixels_beyond_the_radius_stay_invalid() {
        let rgb = Array3::from_elem((1, 10, 3), 100u8);
        let mut depth = Array2::zeros((1, 10));
        depth[(0, 0)] = 2.0;
        let mut out = Array2::zeros((1, 10));
        let mut conf = Array2::zeros((1, 10));
        fill_holes(
            depth.view(),
            rgb.view(),
            &PARAMS,
            out.view_mut(),
            conf.view_mut(),
        );
        for x in 0..10 {
            let filled = x <= 3;
            assert_eq!(out[(0, x)], if filled { 2.0 } else { 0.0 }, "x = {x}");
            assert_eq!(conf[(0, x)] > 0, filled && x > 0, "x = {x}");
        }
    }
}
