//! Step 1 of the chain: sensor data → network inputs, exactly as the bundle's `model.json`
//! (`normalisation`) and the training package (`dear_train.data.dataset`) define them.
//!
//! - RGB: `value / 255`, one plane per channel (the graphs take planar NCHW);
//! - amplitude: `I = I_raw · D²` (undoes the 1/D² fall-off so the IR image looks like an
//!   albedo image, which can be matched to RGB), divided by its `p`-th percentile over the
//!   pixels with valid depth and clipped to `[0, 1]`; 0 where the depth is invalid. A
//!   percentile rather than the maximum, so a few specular pixels do not darken the image.
//!   The percentile interpolates linearly between order statistics, as NumPy's default does,
//!   so Rust and PyTorch feed the network the same numbers.

use ndarray::{Array2, ArrayView2, ArrayView3, ArrayViewMut2, Zip};

use crate::geometry::surface::is_valid_depth;

/// Normalised amplitude into `out`; returns the scale (the percentile), or `None` when no pixel
/// has valid depth or the scale is not positive (then `out` is all zeros, as in training).
///
/// `scratch` holds the valid products for the percentile; it is reused across frames.
///
/// # Panics
/// If the three images do not share one shape (the chain checks shapes first).
pub fn normalize_amplitude_into(
    raw: ArrayView2<f32>,
    depth: ArrayView2<f32>,
    percentile: f32,
    scratch: &mut Vec<f32>,
    mut out: ArrayViewMut2<f32>,
) -> Option<f32> {
    assert_eq!(raw.dim(), depth.dim(), "amplitude and depth shapes differ");
    assert_eq!(out.dim(), depth.dim(), "output and depth shapes differ");
    Zip::from(&mut out)
        .and(&raw)
        .and(&depth)
        .par_for_each(|o, &a, &z| *o = if is_valid_depth(z) { a * z * z } else { 0.0 });
    scratch.clear();
    scratch.extend(
        out.iter()
            .zip(depth.iter())
            .filter(|(_, &z)| is_valid_depth(z))
            .map(|(&i, _)| i),
    );
    let scale = percentile_linear(scratch, percentile).filter(|s| *s > 0.0 && s.is_finite());
    match scale {
        Some(s) => out.par_mapv_inplace(|i| (i / s).clamp(0.0, 1.0)),
        None => out.fill(0.0),
    }
    scale
}

/// The `p`-th percentile (0..=100) of `values` with linear interpolation between the closest
/// ranks (NumPy's default `method="linear"`); reorders `values`. `None` when empty or when a
/// value is NaN.
pub fn percentile_linear(values: &mut [f32], p: f32) -> Option<f32> {
    let n = values.len();
    if n == 0 || values.iter().any(|v| v.is_nan()) {
        return None;
    }
    let rank = f64::from(p.clamp(0.0, 100.0)) / 100.0 * (n - 1) as f64;
    let lo = rank.floor() as usize;
    let frac = rank - lo as f64;
    let (values, lo) = narrow_to_rank(values, lo);
    let (_, &mut lo_v, upper) = values.select_nth_unstable_by(lo, f32::total_cmp);
    if frac == 0.0 || upper.is_empty() {
        return Some(lo_v);
    }
    let hi_v = upper.iter().copied().fold(f32::INFINITY, f32::min);
    Some((f64::from(lo_v) + frac * (f64::from(hi_v) - f64::from(lo_v))) as f32)
}

/// Values from which [`narrow_to_rank`] looks for a threshold first.
const NARROW_MIN_VALUES: usize = 1 << 16;
/// Size of [`narrow_to_rank`]'s subsample.
const NARROW_SAMPLE: usize = 4096;
/// How many sample ranks below the wanted one [`narrow_to_rank`] sets its threshold: about ten
/// standard deviations of where the 99th percentile falls in the sample, so it almost never
/// has to give up.
const NARROW_MARGIN: usize = 64;

/// The values of rank `lo` and above (in `f32::total_cmp` order) are in the returned prefix of
/// `values` (reordered), at rank `lo'` within it: a threshold just below the wanted rank is
/// read from an evenly spaced subsample, and only the values at or above it are kept, so that
/// a high percentile of a frame selects among a few thousand values instead of all of them
/// (the full selection was most of the amplitude normalisation at 640×480). The order
/// statistics, and so the percentile, are exactly those of all the values; when the threshold
/// lands above the wanted rank (or there is too little to gain) all of `values` is returned.
fn narrow_to_rank(values: &mut [f32], lo: usize) -> (&mut [f32], usize) {
    let n = values.len();
    let k = (lo * NARROW_SAMPLE / n.max(1)).saturating_sub(NARROW_MARGIN);
    if n < NARROW_MIN_VALUES || k == 0 {
        return (values, lo);
    }
    let mut sample = [0.0f32; NARROW_SAMPLE];
    for (s, v) in sample
        .iter_mut()
        .zip(values.iter().step_by(n / NARROW_SAMPLE))
    {
        *s = *v;
    }
    let (_, &mut threshold, _) = sample.select_nth_unstable_by(k, f32::total_cmp);
    let mut kept = 0;
    for i in 0..n {
        if values[i].total_cmp(&threshold).is_ge() {
            values.swap(kept, i);
            kept += 1;
        }
    }
    let below = n - kept;
    if below > lo {
        return (values, lo);
    }
    (&mut values[..kept], lo - below)
}

/// RGB `(H, W, 3)` u8 → three planes `value / 255`.
///
/// # Panics
/// If `rgb` does not have 3 channels or the planes' shape differs from `(H, W)`.
pub fn rgb_planes_into(rgb: ArrayView3<u8>, planes: &mut [Array2<f32>; 3]) {
    let (h, w, c) = rgb.dim();
    assert_eq!(c, 3, "rgb has {c} channels, expected 3");
    for plane in planes.iter() {
        assert_eq!(plane.dim(), (h, w), "rgb plane shape differs");
    }
    // The 256 possible values, each computed as `f32::from(v) / 255.0`.
    let mut lut = [0.0f32; 256];
    for (v, l) in lut.iter_mut().enumerate() {
        *l = f32::from(v as u8) / 255.0;
    }
    let [r, g, b] = planes;
    // One pass over the interleaved pixels, rows in parallel.
    Zip::from(r.rows_mut())
        .and(g.rows_mut())
        .and(b.rows_mut())
        .and(rgb.outer_iter())
        .par_for_each(|mut r, mut g, mut b, px| {
            let lut = |v: u8| lut[usize::from(v)];
            match (
                px.as_slice(),
                r.as_slice_mut(),
                g.as_slice_mut(),
                b.as_slice_mut(),
            ) {
                (Some(px), Some(r), Some(g), Some(b)) => {
                    for (((p, r), g), b) in px.chunks_exact(3).zip(r).zip(g).zip(b) {
                        (*r, *g, *b) = (lut(p[0]), lut(p[1]), lut(p[2]));
                    }
                }
                _ => {
                    for (x, p) in px.outer_iter().enumerate() {
                        (r[x], g[x], b[x]) = (lut(p[0]), lut(p[1]), lut(p[2]));
                    }
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn percentile_matches_numpy_linear() {
        // np.percentile([1, 2, 3, 4], 50) = 2.5, 99 → 3.97, 0 → 1, 100 → 4.
        for (p, want) in [(50.0, 2.5), (99.0, 3.97), (0.0, 1.0), (100.0, 4.0)] {
            let mut v = vec![4.0, 1.0, 3.0, 2.0];
            let got = percentile_linear(&mut v, p).unwrap();
            assert!((got - want).abs() < 1e-6, "p{p}: {got} vs {want}");
        }
        assert_eq!(percentile_linear(&mut [], 50.0), None);
        // Above NARROW_MIN_VALUES the selection first narrows to the values above a sampled
        // threshold: the same result as sorting, at high and low percentiles, with ties and a
        // -0.0 beside 0.0, narrowed (`plain`) and falling back to all the values
        // (`adversarial`: the largest values all at the sampled places).
        let n = 100_003;
        let make = |adversarial: bool| -> Vec<f32> {
            (0..n)
                .map(|i| match i % 97 {
                    0 => -0.0,
                    1 => 0.0,
                    k if adversarial && i % (n / NARROW_SAMPLE) == 0 => 1000.0 + k as f32,
                    k => ((i * 7919) % 10_007) as f32 * 0.01 + k as f32 * 1e-4,
                })
                .collect()
        };
        for (adversarial, narrowed) in [(false, true), (true, false)] {
            let base = make(adversarial);
            let lo99 = (0.99 * (n - 1) as f64) as usize;
            let mut scratch = base.clone();
            let kept = narrow_to_rank(&mut scratch, lo99).0.len();
            assert_eq!(
                kept < n / 10,
                narrowed,
                "adversarial {adversarial}: {kept} kept"
            );
            let mut sorted = base.clone();
            sorted.sort_by(f32::total_cmp);
            for p in [99.0, 99.9, 50.0, 5.0, 100.0, 0.0, 97.3] {
                let rank = f64::from(p) / 100.0 * (n - 1) as f64;
                let lo = rank.floor() as usize;
                let frac = rank - lo as f64;
                let (lo_v, hi_v) = (sorted[lo], sorted[(lo + 1).min(n - 1)]);
                let want = if frac == 0.0 {
                    lo_v
                } else {
                    (f64::from(lo_v) + frac * (f64::from(hi_v) - f64::from(lo_v))) as f32
                };
                let got = percentile_linear(&mut base.clone(), p).unwrap();
                assert_eq!(
                    got.to_bits(),
                    want.to_bits(),
                    "p{p}, adversarial {adversarial}"
                );
            }
        }
        assert_eq!(percentile_linear(&mut [1.0, f32::NAN], 50.0), None);
    }

    #[test]
    fn amplitude_is_range_compensated_and_clipped() {
        // I·D² = [4, 4, 16, masked]; p100 of the valid ones = 16.
        let raw = array![[1.0f32, 4.0], [4.0, 100.0]];
        let depth = array![[2.0f32, 1.0], [2.0, 0.0]];
        let mut out = Array2::zeros((2, 2));
        let s = normalize_amplitude_into(
            raw.view(),
            depth.view(),
            100.0,
            &mut Vec::new(),
            out.view_mut(),
        );
        assert_eq!(s, Some(16.0));
        assert_eq!(out, array![[0.25, 0.25], [1.0, 0.0]]);
        // p50 of [4, 4, 16] = 4: the brightest pixel clips to 1.
        let s = normalize_amplitude_into(
            raw.view(),
            depth.view(),
            50.0,
            &mut Vec::new(),
            out.view_mut(),
        );
        assert_eq!(s, Some(4.0));
        assert_eq!(out, array![[1.0, 1.0], [1.0, 0.0]]);
        // No valid depth: all zero, no scale.
        let none = Array2::zeros((2, 2));
        let s = normalize_amplitude_into(
            raw.view(),
            none.view(),
            99.0,
            &mut Vec::new(),
            out.view_mut(),
        );
        assert_eq!(s, None);
        assert!(out.iter().all(|&v| v == 0.0));
    }
}
