//! The guided filter (He, Sun, Tang, "Guided Image Filtering", TPAMI 2013) with a validity mask.
//!
//! Within every `(2r+1)²` window the output is modelled as an affine function of the guide,
//! `q = a·I + b`; `a = cov(I, p) / (var(I) + ε)`, `b = mean(p) − a·mean(I)`; each pixel averages
//! the models of the windows covering it. Where the guide is flat the filter averages depth
//! (denoising); where the guide has an edge much stronger than `√ε`, `a` follows the depth
//! across it and the edge survives. Every statistic is computed over the *valid* pixels only
//! (masked box sums divided by the box sum of the mask), so holes neither pull depth towards
//! zero nor need filling first. All box sums are O(N) ([`box_sum`]).

use ndarray::{Array2, ArrayView2, ArrayViewMut2, Zip};

use crate::filter::boxsum::box_sum;

/// Buffers of [`guided_filter_masked`], reused across frames.
#[derive(Debug, Clone)]
pub struct GuidedScratch {
    tmp: Array2<f32>,
    prod: [Array2<f32>; 5],
    sums: [Array2<f32>; 5],
}

impl GuidedScratch {
    /// Buffers for `(h, w)` images.
    pub fn new(h: usize, w: usize) -> Self {
        let z = || Array2::zeros((h, w));
        GuidedScratch {
            tmp: z(),
            prod: [z(), z(), z(), z(), z()],
            sums: [z(), z(), z(), z(), z()],
        }
    }

    /// `(h, w)` the buffers are sized for.
    pub fn dim(&self) -> (usize, usize) {
        self.tmp.dim()
    }
}

/// Guided filter of `p` with guide `guide` over the pixels where `p > 0`; writes `0` where no
/// valid pixel lies within the radius.
///
/// # Panics
/// If the shapes differ from each other or from the scratch's.
pub fn guided_filter_masked(
    guide: ArrayView2<f32>,
    p: ArrayView2<f32>,
    radius: usize,
    eps: f32,
    scratch: &mut GuidedScratch,
    mut out: ArrayViewMut2<f32>,
) {
    let dim = p.dim();
    assert_eq!(
        guide.dim(),
        dim,
        "guided_filter_masked: guide shape differs from the input"
    );
    assert_eq!(
        out.dim(),
        dim,
        "guided_filter_masked: output shape differs from the input"
    );
    assert_eq!(
        scratch.dim(),
        dim,
        "guided_filter_masked: scratch sized for another shape"
    );
    let GuidedScratch { tmp, prod, sums } = scratch;

    // Masked products: m, m·I, m·p, m·I·p, m·I².
    {
        let [m, mi, mp, mip, mii] = prod;
        Zip::from(&mut *m)
            .and(&mut *mi)
            .and(&mut *mp)
            .and(&guide)
            .and(&p)
            .par_for_each(|m, mi, mp, &g, &d| {
                let valid = d > 0.0 && d.is_finite();
                (*m, *mi, *mp) = if valid { (1.0, g, d) } else { (0.0, 0.0, 0.0) };
            });
        Zip::from(mip)
            .and(mii)
            .and(&*mi)
            .and(&*mp)
            .and(&guide)
            .par_for_each(|mip, mii, &mi, &mp, &g| {
                *mip = g * mp;
                *mii = g * mi;
            });
    }
    for (src, dst) in prod.iter().zip(sums.iter_mut()) {
        box_sum(src.view(), radius, tmp.view_mut(), dst.view_mut());
    }

    // Per-window affine models (a, b) and whether the window saw any valid pixel (ma), stored
    // in prod[1], prod[2] and prod[0]; ma holds var(I) in between.
    {
        let [n, si, sp, sip, sii] = &*sums;
        let [ma, a, b, _, _] = prod;
        let means = |n: f32, si: f32, sp: f32| {
            let n = f64::from(n);
            (f64::from(si) / n, f64::from(sp) / n)
        };
        Zip::from(&mut *ma)
            .and(n)
            .and(si)
            .and(sii)
            .par_for_each(|var, &n, &si, &sii| {
                let mi = f64::from(si) / f64::from(n);
                *var = if n < 0.5 {
                    -1.0
                } else {
                    (f64::from(sii) / f64::from(n) - mi * mi).max(0.0) as f32
                };
            });
        Zip::from(&mut *ma)
            .and(&mut *a)
            .and(n)
            .and(si)
            .and(sp)
            .and(sip)
            .par_for_each(|ma, a, &n, &si, &sp, &sip| {
                if *ma < 0.0 {
                    (*ma, *a) = (0.0, 0.0);
                    return;
                }
                let (mi, mp) = means(n, si, sp);
                let cov = f64::from(sip) / f64::from(n) - mi * mp;
                *a = (cov / (f64::from(*ma) + f64::from(eps))) as f32;
                *ma = 1.0;
            });
        Zip::from(b)
            .and(&*a)
            .and(&*ma)
            .and(n)
            .and(si)
            .and(sp)
            .par_for_each(|b, &a, &ma, &n, &si, &sp| {
                *b = if ma > 0.0 {
                    let (mi, mp) = means(n, si, sp);
                    (mp - f64::from(a) * mi) as f32
                } else {
                    0.0
                };
            });
    }
    for k in 0..3 {
        box_sum(prod[k].view(), radius, tmp.view_mut(), sums[k].view_mut());
    }
    let [n_models, sa, sb, _, _] = &*sums;
    Zip::from(&mut out)
        .and(n_models)
        .and(sa)
        .and(sb)
        .and(&guide)
        .par_for_each(|o, &n, &sa, &sb, &g| {
            *o = if n < 0.5 { 0.0 } else { (sa * g + sb) / n };
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(guide: &Array2<f32>, p: &Array2<f32>, r: usize, eps: f32) -> Array2<f32> {
        let (h, w) = p.dim();
        let mut s = GuidedScratch::new(h, w);
        let mut out = Array2::zeros((h, w));
        guided_filter_masked(guide.view(), p.view(), r, eps, &mut s, out.view_mut());
        out
    }

    #[test]
    fn flat_guide_gives_the_masked_box_mean() {
        // Constant guide → a = 0, b = window mean; averaging b over windows is a box of a box.
        let guide = Array2::from_elem((1, 5), 0.5f32);
        let p = Array2::from_shape_vec((1, 5), vec![1.0f32, 2.0, 0.0, 4.0, 5.0]).unwrap();
        let out = run(&guide, &p, 1, 1e-3);
        // Window means (valid only): [1.5, 1.5, 3.0, 4.5, 4.5]; then the mean over the windows
        // covering each pixel: x=0 → (1.5+1.5)/2, x=2 → (1.5+3+4.5)/3.
        let want = [1.5f32, 2.0, 3.0, 4.0, 4.5];
        for (x, &wv) in want.iter().enumerate() {
            assert!(
                (out[(0, x)] - wv).abs() < 1e-5,
                "x={x}: {} vs {wv}",
                out[(0, x)]
            );
        }
    }

    #[test]
    fn depth_that_is_affine_in_the_guide_passes_unchanged() {
        // p = 2·I + 1 exactly, with a strong guide edge: with ε → 0 every window's model is exact.
        let guide = Array2::from_shape_fn(
            (6, 10),
            |(y, x)| if x < 5 { 0.1 } else { 0.9 + 0.01 * y as f32 },
        );
        let p = guide.mapv(|g| 2.0 * g + 1.0);
        let out = run(&guide, &p, 2, 1e-9);
        for (o, w) in out.iter().zip(&p) {
            assert!((o - w).abs() < 1e-3, "{o} vs {w}");
        }
    }

    #[test]
    fn no_valid_pixel_in_reach_gives_zero() {
        let guide = Array2::from_elem((1, 8), 0.5f32);
        let mut p = Array2::zeros((1, 8));
        p[(0, 0)] = 2.0;
        let out = run(&guide, &p, 1, 1e-3);
        assert!((out[(0, 0)] - 2.0).abs() < 1e-6 && (out[(0, 1)] - 2.0).abs() < 1e-6);
        assert_eq!(out[(0, 3)], 0.0);
    }
}
