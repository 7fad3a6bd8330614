//! A classical cross-modal alignment baseline: match *edges* between the RGB image and the ToF
//! amplitude, then fit the calibration to the matches with the robust least squares.
//!
//! Colour and near-infrared intensities differ (a pattern may exist in one and not the other),
//! but object boundaries usually show in both, so we compare gradient-magnitude maps rather than
//! intensities. At the strongest-edged patches of the RGB image we search the amplitude's edge
//! map for the displacement with the highest zero-normalised cross-correlation (ZNCC), refine it
//! to sub-pixel by a parabola through the peak, keep confident, unambiguous matches, and solve
//! `W = t / D + c` over them with Huber weights. This is the "no learning" row of the paper's
//! comparison: it has no notion of which edges correspond, which is what the networks learn.

use ndarray::{Array2, ArrayView2, ArrayView3};

use dear_capture::calibration::Calibration;
use dear_capture::frame::Flow;
use dear_pipeline::recalibration::edges::{gradient_magnitude, rgb_to_gray};
use dear_pipeline::recalibration::{
    solve_calibration_robust, CalibrationFit, LsqError, RobustOptions,
};

/// Settings of [`estimate_calibration`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeMatchParams {
    /// Half size of the matched patch, px (patch side = 2·r + 1).
    pub patch_radius: usize,
    /// Largest displacement searched on each axis, px.
    pub search_radius: i32,
    /// Spacing of candidate patch centres, px.
    pub grid_step: usize,
    /// Patches kept, strongest RGB edges first.
    pub max_patches: usize,
    /// Smallest ZNCC of an accepted match.
    pub min_correlation: f32,
    /// The best ZNCC must beat the best one at least 3 px away by this much (unambiguous).
    pub min_peak_margin: f32,
}

impl Default for EdgeMatchParams {
    fn default() -> Self {
        EdgeMatchParams {
            patch_radius: 7,
            search_radius: 20,
            grid_step: 12,
            max_patches: 400,
            min_correlation: 0.5,
            min_peak_margin: 0.05,
        }
    }
}

/// One accepted edge match: RGB pixel `(x, y)` sees ToF pixel `(x + u, y + v)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeMatch {
    pub x: usize,
    pub y: usize,
    pub u: f32,
    pub v: f32,
    pub correlation: f32,
}

/// Matches edges between `rgb` and `amplitude` (both on their own grids) and returns the
/// matches. `amplitude` is raw or normalised; only its edges matter.
pub fn match_edges(
    rgb: ArrayView3<u8>,
    amplitude: ArrayView2<f32>,
    params: &EdgeMatchParams,
) -> Vec<EdgeMatch> {
    let gray = rgb_to_gray(rgb);
    // The amplitude's dynamic range is huge (1/r²); a square root evens it out before edges.
    let amp = amplitude.mapv(|a| a.max(0.0).sqrt());
    let e_rgb = gradient_magnitude(gray.view());
    let e_amp = gradient_magnitude(amp.view());
    let (h, w) = e_rgb.dim();
    let r = params.patch_radius;
    let s = params.search_radius;
    let margin = r + s as usize + 1;
    if h <= 2 * margin || w <= 2 * margin {
        return Vec::new();
    }
    // Candidate centres with the most RGB edge energy.
    let mut candidates: Vec<(f32, usize, usize)> = Vec::new();
    for y in (margin..h - margin).step_by(params.grid_step) {
        for x in (margin..w - margin).step_by(params.grid_step) {
            let energy: f32 = patch(&e_rgb, x, y, r).iter().sum();
            candidates.push((energy, x, y));
        }
    }
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0));
    candidates.truncate(params.max_patches);
    candidates.retain(|c| c.0 > 0.0);
    use rayon::prelude::*;
    candidates
        .par_iter()
        .filter_map(|&(_, x, y)| match_one(&e_rgb, &e_amp, x, y, params))
        .collect()
}

/// Estimates the calibration from edge matches; `tof_depth` (metres, ToF grid) gives the depth
/// of each match at its ToF end, `D_rgb(p) = D_tof(p + W(p))`.
pub fn estimate_calibration(
    rgb: ArrayView3<u8>,
    amplitude: ArrayView2<f32>,
    tof_depth: ArrayView2<f32>,
    params: &EdgeMatchParams,
) -> Result<(CalibrationFit, usize), LsqError> {
    let matches = match_edges(rgb, amplitude, params);
    let (h, w) = tof_depth.dim();
    let mut u = Vec::new();
    let mut v = Vec::new();
    let mut z = Vec::new();
    for m in &matches {
        let (tx, ty) = ((m.x as f32 + m.u).round(), (m.y as f32 + m.v).round());
        if tx < 0.0 || ty < 0.0 || tx >= w as f32 || ty >= h as f32 {
            continue;
        }
        // The edge that was matched is, most often, an occluding contour, and a contour moves
        // with the *nearer* surface: take the nearest valid depth in the matched patch.
        let depth = min_valid_depth(tof_depth, ty as usize, tx as usize, params.patch_radius);
        if depth > 0.0 {
            u.push(m.u);
            v.push(m.v);
            z.push(depth);
        }
    }
    let n = u.len();
    let flow = Flow {
        u: Array2::from_shape_vec((1, n), u).expect("1×n"),
        v: Array2::from_shape_vec((1, n), v).expect("1×n"),
    };
    let depth = Array2::from_shape_vec((1, n), z).expect("1×n");
    let options = RobustOptions {
        huber_delta_px: 1.5,
        // Every match: they are a few hundred, and a grid step would skip whole columns of them.
        max_samples: 0,
        ..RobustOptions::default()
    };
    solve_calibration_robust(&flow, depth.view(), None, options).map(|fit| (fit, n))
}

/// Like [`estimate_calibration`], falling back to `fallback`'s baseline when the matches all lie
/// at one depth (then only the offsets are updated: `c = mean flow − t·mean(1/D)`).
pub fn estimate_calibration_or(
    rgb: ArrayView3<u8>,
    amplitude: ArrayView2<f32>,
    tof_depth: ArrayView2<f32>,
    params: &EdgeMatchParams,
    fallback: Calibration,
) -> Calibration {
    match estimate_calibration(rgb, amplitude, tof_depth, params) {
        Ok((fit, _)) => fit.calibration,
        Err(LsqError::Degenerate {
            mean_inv_depth,
            mean_flow,
            ..
        }) => Calibration {
            tx: fallback.tx,
            ty: fallback.ty,
            cx: mean_flow.0 - fallback.tx * mean_inv_depth,
            cy: mean_flow.1 - fallback.ty * mean_inv_depth,
        },
        Err(_) => fallback,
    }
}

fn min_valid_depth(depth: ArrayView2<f32>, y: usize, x: usize, r: usize) -> f32 {
    let (h, w) = depth.dim();
    let mut best = f32::INFINITY;
    for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
        for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
            let d = depth[[yy, xx]];
            if dear_capture::is_valid_depth(d) {
                best = best.min(d);
            }
        }
    }
    if best.is_finite() {
        best
    } else {
        0.0
    }
}

fn match_one(
    e_rgb: &Array2<f32>,
    e_amp: &Array2<f32>,
    x: usize,
    y: usize,
    p: &EdgeMatchParams,
) -> Option<EdgeMatch> {
    let r = p.patch_radius;
    let s = p.search_radius;
    let reference = zero_mean(&patch(e_rgb, x, y, r))?;
    let side = (2 * s + 1) as usize;
    let mut scores = vec![f32::NEG_INFINITY; side * side];
    for dv in -s..=s {
        for du in -s..=s {
            let cx = (x as i32 + du) as usize;
            let cy = (y as i32 + dv) as usize;
            if let Some(candidate) = zero_mean(&patch(e_amp, cx, cy, r)) {
                scores[((dv + s) as usize) * side + (du + s) as usize] =
                    dot(&reference, &candidate);
            }
        }
    }
    let (best_i, &best) = scores
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))?;
    if best < p.min_correlation {
        return None;
    }
    let (bu, bv) = ((best_i % side) as i32, (best_i / side) as i32);
    // Ambiguity: the best score at least 3 px away from the peak.
    let second = scores
        .iter()
        .enumerate()
        .filter(|(i, _)| {
            ((*i % side) as i32 - bu).abs() >= 3 || ((*i / side) as i32 - bv).abs() >= 3
        })
        .map(|(_, &v)| v)
        .fold(f32::NEG_INFINITY, f32::max);
    if best - second < p.min_peak_margin {
        return None;
    }
    let at = |u: i32, v: i32| -> Option<f32> {
        (0..side as i32).contains(&u).then_some(())?;
        (0..side as i32).contains(&v).then_some(())?;
        let s = scores[v as usize * side + u as usize];
        s.is_finite().then_some(s)
    };
    let sub = |m: Option<f32>, c: f32, pl: Option<f32>| -> f32 {
        match (m, pl) {
            (Some(m), Some(pl)) => {
                let denom = m - 2.0 * c + pl;
                if denom < 0.0 {
                    (0.5 * (m - pl) / denom).clamp(-0.5, 0.5)
                } else {
                    0.0
                }
            }
            _ => 0.0,
        }
    };
    let du = bu as f32 + sub(at(bu - 1, bv), best, at(bu + 1, bv)) - s as f32;
    let dv = bv as f32 + sub(at(bu, bv - 1), best, at(bu, bv + 1)) - s as f32;
    Some(EdgeMatch {
        x,
        y,
        u: du,
        v: dv,
        correlation: best,
    })
}

fn patch(img: &Array2<f32>, x: usize, y: usize, r: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity((2 * r + 1) * (2 * r + 1));
    for yy in y - r..=y + r {
        out.extend(img.row(yy).iter().skip(x - r).take(2 * r + 1));
    }
    out
}

/// Zero-mean, unit-norm copy of a patch; `None` for a flat patch (nothing to match).
fn zero_mean(values: &[f32]) -> Option<Vec<f32>> {
    let mean = values.iter().sum::<f32>() / values.len() as f32;
    let centred: Vec<f32> = values.iter().map(|v| v - mean).collect();
    let norm = centred.iter().map(|v| v * v).sum::<f32>().sqrt();
    (norm > 1e-6).then(|| centred.iter().map(|v| v / norm).collect())
}

fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use dear_pipeline::recalibration::edges::test_scene::textured_scene;
    use ndarray::Array3;

    /// Boxes at three depths in front of a wall; RGB and amplitude share the boundaries but not
    /// the interior pattern. The RGB view is synthesised with a known calibration; the edge
    /// matcher must recover it to within a pixel over the depth range.
    #[test]
    fn recovers_a_known_calibration_on_a_textured_scene() {
        let truth = Calibration {
            tx: 6.0,
            ty: -2.0,
            cx: 3.0,
            cy: 1.5,
        };
        let (rgb, amplitude, depth) = textured_scene(&truth);
        let (fit, n) = estimate_calibration(
            rgb.view(),
            amplitude.view(),
            depth.view(),
            &EdgeMatchParams::default(),
        )
        .expect("enough matches");
        assert!(n >= 15, "matches: {n}");
        for z in [0.8f32, 1.2, 1.8, 3.0] {
            let (eu, ev) = fit.calibration.flow_at(z).unwrap();
            let (tu, tv) = truth.flow_at(z).unwrap();
            assert!(
                (eu - tu).abs() < 1.0 && (ev - tv).abs() < 1.0,
                "z={z}: est ({eu},{ev}) true ({tu},{tv}); {:?}",
                fit
            );
        }
    }

    #[test]
    fn a_flat_image_has_no_matches() {
        let rgb = Array3::from_elem((100, 100, 3), 128u8);
        let amp = Array2::from_elem((100, 100), 500.0f32);
        assert!(match_edges(rgb.view(), amp.view(), &EdgeMatchParams::default()).is_empty());
    }
}
