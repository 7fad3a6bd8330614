//! Direct alignment: fit the four calibration numbers `(t_x, t_y, c_x, c_y)` against every edge
//! pixel of the frame at once, instead of matching patches first and fitting a line to the
//! matches afterwards (the edge-matching baseline of `dear eval`, `dear_eval::edge_matching`).
//!
//! # Why
//!
//! The RGB→ToF flow of a frame is not a free field: it is `W = t / z + c`, four numbers, with
//! the depth `z` known at every ToF pixel. Patch matching (or a dense optical flow) estimates a
//! free displacement per patch, throws away the ones it is unsure of, and only then imposes the
//! model; a straight edge, a weak edge or a repeated pattern gives nothing or an outlier. Fitting
//! the four numbers directly lets every edge pixel vote — a straight edge constrains the flow
//! across itself, and edges in different directions and at different depths together pin all
//! four parameters — and needs no match to be unambiguous on its own.
//!
//! # How
//!
//! - **Edge maps.** RGB and near-infrared intensities differ, object boundaries do not, so both
//!   sides are compared as gradient magnitudes (as in the edge matcher): of the RGB grey image
//!   on the RGB grid, and of `log amplitude` on the ToF grid. The logarithm makes an edge's
//!   strength independent of distance; with `√amplitude` (the edge matcher's choice) the
//!   nearest, brightest objects own most of the edge energy, and their flow is the largest and
//!   the least reliable (measured on the tuning set below: mean AEPE 3.3 → 2.3 px at σ = 2).
//!   Depth-discontinuity edges can be added (`depth_edge_weight`); they did not help.
//! - **Mapping.** A ToF pixel `q` with depth `z` lands in the RGB view at `p(q) = q − t/z − c`
//!   (the inverse of "RGB pixel `p` sees ToF pixel `p + W`", the rule
//!   [`synthesize_view`](crate::geometry::synthesize_view) and the
//!   [`StaticAligner`](crate::align::StaticAligner) splat with; checked by a unit test).
//! - **Objective.** The correlation (zero-normalised cross-correlation) between the ToF edge map
//!   `T(q)` and the RGB edge map sampled bilinearly at `p(q)` (zero outside the image, so the
//!   pixel set never shrinks and a small overlap cannot win by chance), over the ToF pixels with
//!   valid depth: invariant to the different contrasts of the two modalities. It is maximised
//!   as the equivalent least squares `min Σ (α·I(p(q; θ)) + β − T(q))²` over `θ = (t, c)` and
//!   the photometric gain/offset `(α, β)` (at the optimal `α, β` the residual is
//!   `‖T − T̄‖²·(1 − ρ²)`), by Gauss–Newton with a halving step.
//! - **Coarse to fine.** Both edge maps are blurred and reduced to a Gaussian pyramid, which
//!   widens the basin. At the coarsest level (at most 160 px wide) an exhaustive search over
//!   whole-pixel offsets of `c` (`t` held; a candidate costs four multiply-adds per pixel, as
//!   the bilinear weights of a pixel do not change with a whole-pixel shift) scores all pixels
//!   and, in the same pass, six layers of inverse depth separately. The correlation along `t`
//!   is sharply peaked (near objects move by `t/z`, tens of pixels, for a small change of `t`),
//!   and `t` held at its initial value is a local maximum, so Gauss–Newton alone cannot find
//!   `t`: lines `flow = t/z + c` through the layers' peaks (every pair tried, each scored by
//!   the layers' correlations at the offsets it predicts) give start points that have it.
//!   The best global offsets and the best few distinct lines are refined by Gauss–Newton at
//!   the coarsest level, the one with the highest correlation then level by level up to full
//!   resolution. The search runs around the start (the rough-flow network's calibration) and
//!   around the calibration in use, whose fits must beat the start's by a handicap
//!   ([`DirectFitParams::search_from_reference`]): a poor network start cannot lose the basin
//!   the calibration in use leads to.
//! - **When `t` is not observable.** If the edges' inverse depths barely spread (a wall facing
//!   the camera), `t` and `c` cannot be told apart and `t` is held at its initial value; only
//!   `c` is fitted.
//! - **Fallback.** If the final correlation is low, or not better than the initial
//!   calibration's, the initial (factory) calibration is returned and flagged.
//!
//! **Cost.** A fit is a few hundred passes over its levels, most at the coarsest and most only
//! judging a step that is then rejected. So a pass that judges a step skips the normal
//! equations (`PassKind::Residuals`), the samples at the landing points are computed once per
//! calibration tried (`Samples`), the sums no calibration changes once per level
//! (`Level::fixed`), and the offset search runs eight offsets per pass over the points
//! (`offset_lane_sums`); every one of these gives the sums of the plain scan bit for bit (their
//! tests), so the fit's path and result do not depend on them. About 250 ms of one core for
//! the whole 640×480 measurement with the rough-flow network, 60 ms for a 320×240 fit
//! (docs/performance.md).
//!
//! The blurs are tuned on simulated sets whose RGB views are rendered from the RGB camera
//! (`dear-synth perturb`), as a camera sees them: see [`DirectFitParams::blur_sigma`]. Sets
//! that splatted the aligned RGB instead left disocclusions black, a band beside every
//! occluding contour that no camera shows; the earlier settings (one 1 px blur) were tuned on
//! those.

use ndarray::{Array2, ArrayView2, ArrayView3};

use crate::geometry::surface::is_valid_depth;
use crate::recalibration::edges::{gradient_magnitude, normalise_by_p99, rgb_to_gray};
use crate::recalibration::observability::{Information, EDGE_PIXELS_PER_SAMPLE};
use dear_capture::calibration::Calibration;

/// Settings of [`estimate_calibration_direct`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectFitParams {
    /// The coarsest pyramid level is the first at most twice this wide, px (160 px for
    /// 320×240; 40 here, a 80 px search level, was 4× faster and clearly less accurate on the
    /// tuning set).
    pub coarse_width: usize,
    /// Half size of the exhaustive search of `c` at the coarsest level, full-resolution px.
    pub search_radius_px: f32,
    /// Local maxima of the search refined at the coarsest level before one is kept.
    pub search_candidates: usize,
    /// Lines `flow = t/z + c` through the depth layers' peaks refined at the coarsest level
    /// (the best-scoring distinct ones) before one is kept.
    pub search_lines: usize,
    /// Search around the reference calibration as well as around the start
    /// ([`estimate_calibration_direct_against`]), and refine the best of both searches'
    /// candidates. The rough-flow network's start is better than the calibration in use on
    /// some frames and worse on others (it helped at σ = 2 and 6 px and cost 23 % of AEPE at
    /// σ = 4 and 37 % on a dual-frequency module); searching from both, a poor network start
    /// no longer loses the basin the calibration in use already leads to. Tuning sets (40
    /// frames each, `dear-synth generate --seed 9101` and `family` seeds 9102–9105 for
    /// held-out / clean / empty / wide, `perturb --sigma 2 --seed 11`; mean AEPE at σ = 4 px,
    /// default / held-out / clean / empty / wide) without: 1.14 / 1.85 / 0.51 / 1.11 / 0.81;
    /// with, no handicap: 1.13 / 1.83 / 0.74 / 1.11 / 0.81 (on bright single-bounce scenes a
    /// wrong basin correlates better); with `reference_handicap` 0.01: 1.14 / 1.89 / 0.73 /
    /// 1.17 / 0.81; 0.03: 1.14 / 1.85 / 0.59 / 1.11 / 0.81. Cost: the coarsest level's
    /// search and its Gauss–Newton run twice; the fits carried to full resolution stay at most
    /// [`carried_fits`](Self::carried_fits).
    pub search_from_reference: bool,
    /// The reference search's fits are ranked by their correlation less this, so they win
    /// only where they explain the frame clearly better than the start's fits (above).
    pub reference_handicap: f32,
    /// Distinct fits of the coarsest level (best correlation first, flows at least 1 px apart)
    /// refined down to the finest level, where the best is kept. Choosing at the coarsest level
    /// alone kept the wrong basin on cluttered, noisy frames. Tuning sets as `blur_sigma`'s
    /// (mean AEPE without the network, px; σ = 2 / 4 on the default family, then σ = 4 on
    /// clean / wide / empty / held-out), one fit carried: 0.93 / 1.67, 1.26 / 0.62 / 1.07 /
    /// 1.14; three, within `carry_margin` 0.05: 1.01 / 1.12, 1.06 / 0.61 / 0.95 / 0.85 (margin
    /// 0.02: 1.31 on default σ = 4 and 1.01 held-out; 0.1 or no margin: within 0.02 of 0.05).
    /// Aligned tuning frames stay at 0. Cost: 640×480 frames of a drifting sequence, one core,
    /// 170 → 235 ms a fit; the worst case refines three fits at full resolution (about 490 ms).
    /// Searching at full resolution instead (`coarse_width` 160 on 320×240) fitted about as
    /// well (0.57 / 1.24, 1.10 / 0.49 / 0.98 / 0.77) but took 555 ms a 640×480 fit.
    pub carried_fits: usize,
    /// Only fits whose coarsest-level correlation is within this of the best one's are carried
    /// (a clear winner is refined alone, which keeps the usual fit's cost down).
    pub carry_margin: f32,
    /// The carried fits are refined down to the first level at most this wide (never past
    /// the finest: `choice_level`) and compared there; only those within
    /// [`choice_margin`](Self::choice_margin) of the best go on through the finer levels. 320:
    /// a 320×240 frame (the tuning sets, every `RESULTS.md` set) compares them at full
    /// resolution as [`carried_fits`](Self::carried_fits) was tuned, bit for bit as before;
    /// a 640×480 frame at the same 320 px width, instead of refining every carried fit at
    /// 640 px, whose passes were two thirds of a 640×480 fit's pixel work.
    pub choice_width: usize,
    /// Fits whose correlation at the choice level is within this of the best one's are all
    /// refined through the finer levels, where the best is kept. Measured on 640×480 tuning
    /// sets no table reports (24 frames each: `dear-synth generate --seed 9201` at σ = 4 px,
    /// `perturb --seed 12`; the held-out family, `--seed 9202`, `perturb --seed 13`; near-empty
    /// rooms aligned, `--seed 9203`; `dear eval --baselines`, two cores; AEPE of the direct
    /// fit without the network, px, and its ms per frame): every carried fit refined at 640
    /// px 3.32 / 5.38 / 0.00 px at 308 / 338 / 182 ms; margin 0 (the best at 320 px alone)
    /// 3.33 / 5.42 / 0.00 at 212 / 198 / 156 ms, and the chain's final flow on the held-out
    /// set 5.37 → 5.44 px; 0.01 every AEPE as with all fits refined (3.32 / 5.38 / 0.00, the
    /// chain's too) at 237 / 278 / 154 ms; 0.03 the same AEPE at 264 / 273 ms.
    pub choice_margin: f32,
    /// Gaussian blur of both edge maps at every level, in that level's px; the coarser levels
    /// are made from the blurred finer ones. Tuned on rendered views (`dear-synth perturb
    /// --seed 11` of the 40-frame tuning sets of five families, which no table reports; mean
    /// AEPE of the fit without the network, px; σ = 2 / 4 px of 640×480 on the default family,
    /// then σ = 4 on clean / wide / empty / held-out): the previous settings (0.5 px, 1 px at
    /// full resolution, contour radius 0) 1.89 / 2.67, 2.82 / 1.36 / 1.28 / 1.32; 0.4 px
    /// everywhere with contour radius 1 0.93 / 1.67, 1.26 / 0.62 / 1.07 / 1.14 (0.3: 0.98 /
    /// 1.78, 1.26 / 0.59 / 1.04 / 1.08; 0.5: 1.40 / 1.64, 1.30 / 0.79 / 1.15 / 1.26; 0.7 or a
    /// 1 px finest level worse on every set). Aligned tuning frames of every family stay at 0.
    pub blur_sigma: f32,
    /// Blur of the full-resolution level, where the fit ends, instead of `blur_sigma` (`None`:
    /// the same). A 1 px finest blur was needed while the correlation was normalised by the
    /// samples' own variance (see `Corr`): with less, an aligned frame with sharp edges seen
    /// in RGB only (the unit tests' striped wall) gained more than `min_gain` by moving half
    /// a pixel. With the map's variance it stays, and the sharper level fits better (above).
    pub finest_blur_sigma: Option<f32>,
    /// Weight of the depth-discontinuity edges in the ToF edge map (0 = amplitude only).
    pub depth_edge_weight: f32,
    /// A ToF pixel moves with the nearest valid surface within this radius (level px): the
    /// blurred edge of an occluding contour spreads onto the background, but the contour moves
    /// with the foreground. 0: each pixel moves with its own depth, which is right only for
    /// views that leave disocclusions black (splatted). On rendered views radius 1 fitted
    /// every tuning family better (with the previous blurs, σ = 4: default 2.67 → 1.86,
    /// clean 2.82 → 1.55, wide 1.36 → 0.97, empty 1.28 → 1.12, held-out 1.32 → 1.35 px);
    /// 2 was no better and worse on the held-out family (1.85).
    pub contour_radius: usize,
    /// Edges of `log amplitude` (else of `√amplitude`).
    pub log_amplitude: bool,
    /// Zero the RGB edges around black bands connected to the image border (the border a
    /// synthesised view moved away from). Off: on the tuning set it helped the median frame
    /// and hurt the mean.
    pub suppress_border_holes: bool,
    /// Gauss–Newton iterations per level (at most; stops once the flow moves < 0.01 px).
    pub iterations: usize,
    /// Scale of the Cauchy loss on the residual of the edge maps, in units of the RMS residual
    /// at the start of each level (0 = plain least squares): edges seen in one modality only
    /// count less. Off: it made every tried scene worse (the largest residuals are the edges
    /// that do match, with a gain mismatch).
    pub robust_k: f32,
    /// Finest level refined (0 = full resolution).
    pub finest_level: usize,
    /// Smallest edge-weighted relative spread `std(1/z) / mean(1/z)` for which `t` is fitted;
    /// below it `t` stays at its initial value.
    pub min_rel_inv_depth_spread: f32,
    /// Smallest final correlation for the fit to be used.
    pub min_correlation: f32,
    /// The fit must beat the reference calibration's correlation (the one in use: see
    /// [`estimate_calibration_direct_against`]) by this much to be used. A correct
    /// calibration is a local maximum of the correlation, but rarely the global one: the RGB
    /// and amplitude edges of a scene never coincide exactly, and on the tuning sets a fit
    /// from an aligned frame gained a median 0.003–0.006 of correlation by moving 0.1–0.5 px
    /// (1–3 px on bright single-bounce scenes), where a fit that corrects a misalignment of
    /// σ = 2–4 px gains a median 0.17–0.29. 0.03 left every aligned tuning frame where it was
    /// and changed the misaligned sets' mean AEPE by at most 0.01 px (docs/daemon.md, "Leaving a correct calibration alone").
    pub min_gain: f32,
    /// The fit may move the flow of the reference calibration by at most this much on average
    /// over the valid ToF pixels (px of the full-resolution image) to be used: in near-empty
    /// rooms a line `flow = t/z + c` through two walls can win the search with a flow tens of
    /// pixels off, which no module that was calibrated once does. Three quarters of the
    /// search radius (tuning sets: the empty-room fits beyond it were all wrong).
    pub max_mean_flow_change_px: f32,
}

impl Default for DirectFitParams {
    fn default() -> Self {
        DirectFitParams {
            coarse_width: 80,
            search_radius_px: 32.0,
            search_candidates: 3,
            search_lines: 6,
            search_from_reference: true,
            reference_handicap: 0.03,
            carried_fits: 3,
            carry_margin: 0.05,
            choice_width: 320,
            choice_margin: 0.01,
            blur_sigma: 0.4,
            finest_blur_sigma: None,
            depth_edge_weight: 0.0,
            contour_radius: 1,
            log_amplitude: true,
            suppress_border_holes: false,
            iterations: 10,
            robust_k: 0.0,
            finest_level: 0,
            min_rel_inv_depth_spread: 0.1,
            min_correlation: 0.2,
            min_gain: 0.03,
            max_mean_flow_change_px: 24.0,
        }
    }
}

/// The result of [`estimate_calibration_direct`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectFit {
    /// The calibration to align with: the fit, or the initial one when [`fell_back`](Self::fell_back).
    pub calibration: Calibration,
    /// Edge-map correlation of the returned calibration at the finest level refined.
    pub correlation: f32,
    /// Edge-map correlation of the reference calibration at the same level (the initial one
    /// for [`estimate_calibration_direct`]).
    pub initial_correlation: f32,
    /// Whether the fit was rejected and `calibration` is the reference one.
    pub fell_back: bool,
    /// Whether `t` was fitted (false: held at its initial value, too little depth spread).
    pub baseline_fitted: bool,
    /// How well the frame's edges constrain each direction of `(t, c)` at the returned
    /// calibration ([`crate::recalibration::observability`]): the Gauss–Newton normal matrix at the
    /// finest level, `(α, β)` eliminated (Schur complement), over the residual variance and
    /// [`EDGE_PIXELS_PER_SAMPLE`]. When `t` was held, only the flow at the edges' mean inverse
    /// depth `ā` was fitted: the information is that of `t·ā + c` alone (rank 2). Zero when the
    /// fit fell back.
    pub information: Information,
}

/// One pyramid level: the ToF side (edge map, inverse depth of the nearest surface, 0 =
/// invalid) and the RGB side (edge map and its x/y derivatives, interleaved).
struct Level {
    scale: f32,
    tof_w: usize,
    tof_h: usize,
    t: Vec<f32>,
    inv_depth: Vec<f32>,
    rgb_w: usize,
    rgb_h: usize,
    rgb: Vec<[f32; 4]>,
    /// The correlation sums no calibration changes (`n`, `Σt`, `Σt²` over the valid ToF
    /// pixels, the rest 0), summed once in the order every pass would (see
    /// [`Level::with_fixed_sums`]).
    fixed: Corr,
}

impl Level {
    /// The level with its [`fixed`](Self::fixed) sums: every valid ToF pixel (inverse depth
    /// above 0) counts in every pass, sampled inside the RGB view or not, so these sums are
    /// the same in every pass over the level; summed here in row-major order, as the passes
    /// summed them, they are those sums bit for bit.
    fn with_fixed_sums(mut self) -> Self {
        let mut fixed = Corr::default();
        for (&a, &t) in self.inv_depth.iter().zip(&self.t) {
            if a > 0.0 {
                fixed.add_fixed(t as f64);
            }
        }
        self.fixed = fixed;
        self
    }
}

/// Fits the calibration directly to the edges of one frame; see the module docs.
///
/// `rgb` is `(H, W, 3)` on the RGB grid; `amplitude` and `depth` (metres, 0 = invalid) share the
/// ToF grid. `initial` is the starting point, the reference the fit must beat and the fallback
/// ([`estimate_calibration_direct_against`] with `initial` as both).
pub fn estimate_calibration_direct(
    rgb: ArrayView3<u8>,
    amplitude: ArrayView2<f32>,
    depth: ArrayView2<f32>,
    initial: Calibration,
    params: &DirectFitParams,
) -> DirectFit {
    estimate_calibration_direct_against(rgb, amplitude, depth, initial, initial, params)
}

/// [`estimate_calibration_direct`] started from `start` (e.g. the rough-flow network's
/// calibration) and judged against `reference`, the calibration in use (the factory one or
/// the online estimate): the fit replaces it only when it raises the edge correlation by
/// [`DirectFitParams::min_gain`] and moves the flow by at most
/// [`DirectFitParams::max_mean_flow_change_px`] on average; otherwise `reference` is
/// returned, flagged [`DirectFit::fell_back`]. A frame that does not clearly show the
/// calibration to be wrong leaves it alone.
pub fn estimate_calibration_direct_against(
    rgb: ArrayView3<u8>,
    amplitude: ArrayView2<f32>,
    depth: ArrayView2<f32>,
    start: Calibration,
    reference: Calibration,
    params: &DirectFitParams,
) -> DirectFit {
    let fallback = |correlation: f32| DirectFit {
        calibration: reference,
        correlation,
        initial_correlation: correlation,
        fell_back: true,
        baseline_fitted: false,
        information: Information::ZERO,
    };
    assert_eq!(
        amplitude.dim(),
        depth.dim(),
        "estimate_calibration_direct: amplitude and depth shapes differ"
    );
    let (th, tw) = depth.dim();
    let (rh, rw, _) = rgb.dim();
    if th < 8 || tw < 8 || rh < 8 || rw < 8 {
        return fallback(0.0);
    }
    let pyramid = build_pyramid(rgb, amplitude, depth, params);
    let coarsest = pyramid.len() - 1;
    let finest = params.finest_level.min(coarsest);

    let initial_theta = Theta::from(start);
    let fine = &pyramid[finest];
    let reference_theta = Theta::from(reference);
    // The reference's correlation: a pass that only judges (its corr does not depend on the
    // gain, offset or robust scale).
    let initial_correlation = normal_equations(
        fine,
        &reference_theta,
        0.0,
        PassKind::Residuals,
        Samples::Compute,
    )
    .corr
    .value()
    .unwrap_or(0.0);

    // Is t observable? Edge-weighted spread of the inverse depth at the finest level.
    let fit_t = rel_inv_depth_spread(fine) >= params.min_rel_inv_depth_spread as f64;

    // Exhaustive search of c at the coarsest level, t held, around the start and (see
    // `search_from_reference`) around the reference, whose fits carry `reference_handicap`.
    let top = &pyramid[coarsest];
    let mut starts = vec![(initial_theta, 0.0)];
    if params.search_from_reference && reference_theta.p != initial_theta.p {
        starts.push((reference_theta, params.reference_handicap as f64));
    }
    let mut refined: Vec<Candidate> = starts
        .iter()
        .flat_map(|&(start, handicap)| {
            search_offsets(top, &start, params)
                .into_iter()
                .map(move |c| (c, handicap))
        })
        .map(|(c, handicap)| {
            let (theta, correlation) =
                gauss_newton(top, c, fit_t, params.iterations, params.robust_k);
            Candidate {
                theta,
                correlation,
                handicap,
            }
        })
        .filter(|c| c.correlation.is_finite())
        .collect();
    refined.sort_by(|a, b| b.score().total_cmp(&a.score()));
    let carried = distinct_fits(
        top,
        refined,
        params.carried_fits.max(1),
        params.carry_margin,
    );
    let widths: Vec<usize> = pyramid.iter().map(|l| l.tof_w).collect();
    let choice = choice_level(&widths, finest, params.choice_width);
    let refine_through = |fit: &mut Candidate, levels: &[Level]| {
        for level in levels.iter().rev() {
            (fit.theta, fit.correlation) =
                gauss_newton(level, fit.theta, fit_t, params.iterations, params.robust_k);
        }
    };
    let mut fits: Vec<Candidate> = carried
        .into_iter()
        .map(|mut fit| {
            refine_through(&mut fit, &pyramid[choice..coarsest]);
            fit
        })
        .collect();
    let lead = fits
        .iter()
        .map(Candidate::score)
        .fold(f64::NEG_INFINITY, f64::max);
    fits.retain(|f| f.score() >= lead - params.choice_margin as f64);
    let mut best: Option<Candidate> = None;
    for mut fit in fits {
        refine_through(&mut fit, &pyramid[finest..choice]);
        if best.is_none_or(|b| fit.score() > b.score()) {
            best = Some(fit);
        }
    }
    let Some(Candidate {
        theta,
        correlation: corr,
        ..
    }) = best
    else {
        return fallback(initial_correlation as f32);
    };
    let corr = corr as f32;
    if !corr.is_finite()
        || corr < params.min_correlation
        || corr <= initial_correlation as f32 + params.min_gain
        || mean_flow_change(fine, &theta, &reference_theta) > params.max_mean_flow_change_px as f64
    {
        let mut f = fallback(initial_correlation as f32);
        f.baseline_fitted = false;
        return f;
    }
    DirectFit {
        calibration: theta.into(),
        correlation: corr,
        initial_correlation: initial_correlation as f32,
        fell_back: false,
        baseline_fitted: fit_t,
        information: information_at(fine, &theta, fit_t),
    }
}

/// The information of the fit at `theta` on `level` (see [`DirectFit::information`]).
// Small dense linear algebra reads best with indices.
#[allow(clippy::needless_range_loop)]
fn information_at(level: &Level, theta: &Theta, fit_t: bool) -> Information {
    let pass = normal_equations(
        level,
        theta,
        0.0,
        PassKind::NormalEquations,
        Samples::Compute,
    );
    let h = pass.hm;
    // Schur complement of the photometric (α, β) block.
    let (a, b, d) = (h[4][4], h[4][5], h[5][5]);
    let det = a * d - b * b;
    if !(det.is_finite() && det > 0.0) {
        return Information::ZERO;
    }
    let inv = [[d / det, -b / det], [-b / det, a / det]];
    let mut s = [[0.0f64; 4]; 4];
    for i in 0..4 {
        for j in 0..4 {
            let mut x = h[i][j];
            for k in 0..2 {
                for l in 0..2 {
                    x -= h[i][4 + k] * inv[k][l] * h[4 + l][j];
                }
            }
            s[i][j] = x;
        }
    }
    let n = pass.corr.n.max(1.0);
    let variance = pass.sse / n;
    if !fit_t {
        // Only the flow at the edges' mean inverse depth ā was fitted: the c block's
        // information, moved onto the direction (ā, 1) of each axis.
        let (mut sw, mut sa) = (0.0f64, 0.0f64);
        for (&t, &a) in level.t.iter().zip(&level.inv_depth) {
            if a > 0.0 {
                sw += t as f64;
                sa += (t * a) as f64;
            }
        }
        let abar = if sw > 0.0 { sa / sw } else { 0.0 };
        let w = [abar, abar, 1.0, 1.0];
        let idx = [2usize, 3, 2, 3];
        let mut m = [[0.0f64; 4]; 4];
        for i in 0..4 {
            for j in 0..4 {
                m[i][j] = w[i] * w[j] * s[idx[i]][idx[j]];
            }
        }
        s = m;
    }
    Information::from_normal_matrix(s, variance, EDGE_PIXELS_PER_SAMPLE)
}

/// `(t_x, t_y, c_x, c_y, α, β)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Theta {
    p: [f64; 6],
}

impl From<Calibration> for Theta {
    fn from(c: Calibration) -> Self {
        Theta {
            p: [c.tx as f64, c.ty as f64, c.cx as f64, c.cy as f64, 1.0, 0.0],
        }
    }
}

impl From<Theta> for Calibration {
    fn from(t: Theta) -> Self {
        Calibration {
            tx: t.p[0] as f32,
            ty: t.p[1] as f32,
            cx: t.p[2] as f32,
            cy: t.p[3] as f32,
        }
    }
}

fn build_pyramid(
    rgb: ArrayView3<u8>,
    amplitude: ArrayView2<f32>,
    depth: ArrayView2<f32>,
    params: &DirectFitParams,
) -> Vec<Level> {
    let (th, tw) = depth.dim();
    let (rh, rw, _) = rgb.dim();
    // RGB side.
    let gray = rgb_to_gray(rgb);
    let mut e_rgb = gradient_magnitude(gray.view());
    if params.suppress_border_holes {
        suppress_border_holes(rgb, &mut e_rgb);
    }
    // ToF side: amplitude edges, depth edges.
    // log: an edge's strength does not depend on the distance (sqrt would still weigh the
    // nearest objects, the brightest, most).
    let amp = if params.log_amplitude {
        amplitude.mapv(|a| (a.max(0.0) + 1.0).ln())
    } else {
        amplitude.mapv(|a| a.max(0.0).sqrt())
    };
    let mut e_tof = gradient_magnitude(amp.view());
    if params.depth_edge_weight > 0.0 {
        let e_depth = depth_edges(depth);
        let k = params.depth_edge_weight;
        e_tof.zip_mut_with(&e_depth, |a, &d| *a = a.max(k * d));
    }
    let inv = inverse_depth(depth);

    let mut levels = Vec::new();
    let mut t_img = into_vec(e_tof);
    let mut a_img = inv;
    let mut i_img = into_vec(e_rgb);
    let (mut tw_l, mut th_l, mut rw_l, mut rh_l) = (tw, th, rw, rh);
    let mut scale = 1.0f32;
    loop {
        let t_blur = blur(&t_img, tw_l, th_l, params.blur_sigma);
        let i_blur = blur(&i_img, rw_l, rh_l, params.blur_sigma);
        // The full-resolution maps the fit ends on get their own blur (see
        // `finest_blur_sigma`); the coarser levels are made from the `blur_sigma` ones.
        let (t_level, i_level) = match params.finest_blur_sigma {
            Some(sigma) if levels.is_empty() && sigma != params.blur_sigma => (
                blur(&t_img, tw_l, th_l, sigma),
                blur(&i_img, rw_l, rh_l, sigma),
            ),
            _ => (t_blur.clone(), i_blur.clone()),
        };
        levels.push(
            Level {
                scale,
                tof_w: tw_l,
                tof_h: th_l,
                t: t_level,
                inv_depth: nearest_surface(&a_img, tw_l, th_l, params.contour_radius),
                rgb_w: rw_l,
                rgb_h: rh_l,
                rgb: with_gradient(&i_level, rw_l, rh_l),
                fixed: Corr::default(),
            }
            .with_fixed_sums(),
        );
        if tw_l <= 2 * params.coarse_width.max(8) || th_l < 16 || rh_l < 16 || rw_l < 16 {
            break;
        }
        t_img = downsample(&t_blur, tw_l, th_l, |v| 0.25 * (v[0] + v[1] + v[2] + v[3]));
        a_img = downsample(&a_img, tw_l, th_l, |v| v[0].max(v[1]).max(v[2]).max(v[3]));
        i_img = downsample(&i_blur, rw_l, rh_l, |v| 0.25 * (v[0] + v[1] + v[2] + v[3]));
        (tw_l, th_l, rw_l, rh_l) = (tw_l / 2, th_l / 2, rw_l / 2, rh_l / 2);
        scale *= 2.0;
    }
    levels
}

fn into_vec(a: Array2<f32>) -> Vec<f32> {
    if a.is_standard_layout() {
        a.into_raw_vec_and_offset().0
    } else {
        a.iter().copied().collect()
    }
}

/// A synthesised view (the simulator's misaligned test sets) is black (every channel 0) along
/// the border it moved away from; the edge of that band is not a scene edge, and a camera has
/// no such band. Zero the edges around the black pixels connected to the image border (holes
/// inside the image, disocclusions, are left: their far side is where the background next to
/// an occluding contour lands).
fn suppress_border_holes(rgb: ArrayView3<u8>, edges: &mut Array2<f32>) {
    let (h, w, _) = rgb.dim();
    let black = |y: usize, x: usize| (0..rgb.dim().2).all(|k| rgb[[y, x, k]] == 0);
    let mut seen = vec![false; h * w];
    let mut stack = Vec::new();
    for y in 0..h {
        for x in 0..w {
            if (y == 0 || x == 0 || y == h - 1 || x == w - 1) && black(y, x) {
                seen[y * w + x] = true;
                stack.push((y, x));
            }
        }
    }
    if stack.is_empty() {
        return;
    }
    while let Some((y, x)) = stack.pop() {
        for yy in y.saturating_sub(1)..(y + 2).min(h) {
            for xx in x.saturating_sub(1)..(x + 2).min(w) {
                edges[[yy, xx]] = 0.0;
                if !seen[yy * w + xx] && black(yy, xx) {
                    seen[yy * w + xx] = true;
                    stack.push((yy, xx));
                }
            }
        }
    }
}

/// Sobel gradient magnitude of `log z` where the whole 3×3 neighbourhood is valid (0
/// elsewhere), normalised like [`gradient_magnitude`] (99th percentile → 1, clipped).
fn depth_edges(depth: ArrayView2<f32>) -> Array2<f32> {
    let (h, w) = depth.dim();
    let logz = depth.mapv(|z| if is_valid_depth(z) { z.ln() } else { f32::NAN });
    let mut g = Array2::<f32>::zeros((h, w));
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let p = |dy: usize, dx: usize| logz[[y + dy - 1, x + dx - 1]];
            let gx = (p(0, 2) + 2.0 * p(1, 2) + p(2, 2)) - (p(0, 0) + 2.0 * p(1, 0) + p(2, 0));
            let gy = (p(2, 0) + 2.0 * p(2, 1) + p(2, 2)) - (p(0, 0) + 2.0 * p(0, 1) + p(0, 2));
            let m = (gx * gx + gy * gy).sqrt();
            g[[y, x]] = if m.is_finite() { m } else { 0.0 };
        }
    }
    normalise_by_p99(&mut g, 3);
    g
}

/// `1 / z`, 0 where the depth is invalid.
fn inverse_depth(depth: ArrayView2<f32>) -> Vec<f32> {
    depth
        .iter()
        .map(|&z| if is_valid_depth(z) { 1.0 / z } else { 0.0 })
        .collect()
}

/// The largest inverse depth (nearest surface) within `r` px (a square window) of every valid
/// pixel; 0 where the pixel itself is invalid.
fn nearest_surface(inv: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    if r == 0 {
        return inv.to_vec();
    }
    let mut tmp = vec![0.0f32; w * h];
    for y in 0..h {
        let row = &inv[y * w..(y + 1) * w];
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(r), (x + r).min(w - 1));
            tmp[y * w + x] = row[x0..=x1].iter().copied().fold(0.0, f32::max);
        }
    }
    let mut out = vec![0.0f32; w * h];
    for y in 0..h {
        let (y0, y1) = (y.saturating_sub(r), (y + r).min(h - 1));
        for x in 0..w {
            if inv[y * w + x] > 0.0 {
                out[y * w + x] = (y0..=y1).map(|yy| tmp[yy * w + x]).fold(0.0, f32::max);
            }
        }
    }
    out
}

/// Separable Gaussian blur with clamped borders.
fn blur(img: &[f32], w: usize, h: usize, sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 {
        return img.to_vec();
    }
    let r = (3.0 * sigma).ceil() as usize;
    let mut k: Vec<f32> = (0..=2 * r)
        .map(|i| {
            let d = i as f32 - r as f32;
            (-0.5 * d * d / (sigma * sigma)).exp()
        })
        .collect();
    let s: f32 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    let mut tmp = vec![0.0f32; w * h];
    for y in 0..h {
        let row = &img[y * w..(y + 1) * w];
        let out = &mut tmp[y * w..(y + 1) * w];
        for x in 0..w {
            let mut acc = 0.0;
            if x >= r && x + r < w {
                for (i, &kv) in k.iter().enumerate() {
                    acc += kv * row[x + i - r];
                }
            } else {
                for (i, &kv) in k.iter().enumerate() {
                    let xx = (x as isize + i as isize - r as isize).clamp(0, w as isize - 1);
                    acc += kv * row[xx as usize];
                }
            }
            out[x] = acc;
        }
    }
    let mut out = vec![0.0f32; w * h];
    for y in 0..h {
        let dst = &mut out[y * w..(y + 1) * w];
        for (i, &kv) in k.iter().enumerate() {
            let yy = (y as isize + i as isize - r as isize).clamp(0, h as isize - 1) as usize;
            let src = &tmp[yy * w..(yy + 1) * w];
            for (d, &s) in dst.iter_mut().zip(src) {
                *d += kv * s;
            }
        }
    }
    out
}

/// 2×2 reduction with `f` over the block `[(0,0), (0,1), (1,0), (1,1)]`: coarse pixel `i` is
/// centred on fine `2i + 0.5`.
fn downsample(img: &[f32], w: usize, h: usize, f: impl Fn([f32; 4]) -> f32) -> Vec<f32> {
    let (w2, h2) = (w / 2, h / 2);
    let mut out = Vec::with_capacity(w2 * h2);
    for y in 0..h2 {
        let (r0, r1) = (&img[2 * y * w..], &img[(2 * y + 1) * w..]);
        for x in 0..w2 {
            out.push(f([r0[2 * x], r0[2 * x + 1], r1[2 * x], r1[2 * x + 1]]));
        }
    }
    out
}

/// The image and its central-difference derivatives, interleaved.
fn with_gradient(img: &[f32], w: usize, h: usize) -> Vec<[f32; 4]> {
    let mut out = vec![[0.0f32; 4]; w * h];
    for y in 0..h {
        let (ym, yp) = (y.saturating_sub(1), (y + 1).min(h - 1));
        for x in 0..w {
            let (xm, xp) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let gx = (img[y * w + xp] - img[y * w + xm]) / (xp - xm).max(1) as f32;
            let gy = (img[yp * w + x] - img[ym * w + x]) / (yp - ym).max(1) as f32;
            let v = img[y * w + x];
            out[y * w + x] = [v, gx, gy, v * v];
        }
    }
    out
}

/// Bilinear sample of the interleaved RGB side at `(x, y)` (level px), `None` outside the
/// convex hull of the pixel centres.
#[inline(always)]
fn sample(level: &Level, x: f32, y: f32) -> Option<[f32; 4]> {
    let (w, h) = (level.rgb_w, level.rgb_h);
    if !(x >= 0.0 && y >= 0.0 && x <= (w - 1) as f32 && y <= (h - 1) as f32) {
        return None;
    }
    let x0 = (x as usize).min(w - 2);
    let y0 = (y as usize).min(h - 2);
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let i = y0 * w + x0;
    let (a, b, c, d) = (
        level.rgb[i],
        level.rgb[i + 1],
        level.rgb[i + w],
        level.rgb[i + w + 1],
    );
    let (w00, w01, w10, w11) = (
        (1.0 - fx) * (1.0 - fy),
        fx * (1.0 - fy),
        (1.0 - fx) * fy,
        fx * fy,
    );
    let mut out = [0.0f32; 4];
    for k in 0..4 {
        out[k] = w00 * a[k] + w01 * b[k] + w10 * c[k] + w11 * d[k];
    }
    Some(out)
}

/// Where ToF pixel `(x, y)` of `level` with inverse depth `a` lands in the RGB view, level px.
#[inline]
fn landing(level: &Level, theta: &Theta, x: usize, y: usize, a: f32) -> (f32, f32) {
    // The scale is a power of two, so multiplying by its inverse is exactly the division (two
    // f64 divisions per pixel and pass were a sixth of the fit's time).
    let inv_s = 1.0 / level.scale as f64;
    let u = (theta.p[0] * a as f64 + theta.p[2]) * inv_s;
    let v = (theta.p[1] * a as f64 + theta.p[3]) * inv_s;
    (x as f32 - u as f32, y as f32 - v as f32)
}

/// Running sums for a correlation.
///
/// The RGB side is sampled bilinearly between pixels, which smooths it: at a half-pixel
/// offset the samples of a map with detail the ToF side lacks (texture seen in RGB only) vary
/// less, and a correlation normalised by the samples' own variance *rises* there — an aligned
/// frame gained more than `min_gain` by moving half a pixel. So the correlation is normalised
/// by the variance of the map itself around the landing points: the bilinear sample of the
/// squared map (`sii_map`), which at a whole-pixel offset is the samples' own and between
/// pixels does not shrink. The regression of the Gauss–Newton residual (`gain_offset`) keeps
/// the samples' variance (`sii`).
#[derive(Default, Clone, Copy)]
struct Corr {
    n: f64,
    st: f64,
    stt: f64,
    si: f64,
    sii: f64,
    sii_map: f64,
    sti: f64,
}

impl Corr {
    /// A sample `i` taken at a pixel (no interpolation): what the offset search adds per
    /// point and offset, [`offset_lane_sums`] for several offsets at once (the tests'
    /// reference).
    #[cfg(test)]
    fn add(&mut self, t: f64, i: f64) {
        self.add_sampled(t, i, i * i);
    }

    /// A sample `i` interpolated between pixels, with `i_sq` the squared map interpolated with
    /// the same weights: every sum. The passes over a level add only the sums that depend on
    /// the sample ([`add_varying`](Self::add_varying)) and take the rest
    /// ([`add_fixed`](Self::add_fixed)) from [`Level::fixed`]; this is the tests' reference
    /// for both.
    #[cfg(test)]
    fn add_sampled(&mut self, t: f64, i: f64, i_sq: f64) {
        self.add_fixed(t);
        self.add_varying(t, i, i_sq);
    }

    /// The part of [`add_sampled`](Self::add_sampled) that does not depend on the sample:
    /// the count, `Σt` and `Σt²`.
    #[inline]
    fn add_fixed(&mut self, t: f64) {
        self.n += 1.0;
        self.st += t;
        self.stt += t * t;
    }

    /// The part of [`add_sampled`](Self::add_sampled) that depends on the sample: a pass
    /// over a level takes `n`, `Σt` and `Σt²` from [`Level::fixed`].
    #[inline]
    fn add_varying(&mut self, t: f64, i: f64, i_sq: f64) {
        self.si += i;
        self.sii += i * i;
        self.sii_map += i_sq;
        self.sti += t * i;
    }

    fn merge(&mut self, o: &Corr) {
        self.n += o.n;
        self.st += o.st;
        self.stt += o.stt;
        self.si += o.si;
        self.sii += o.sii;
        self.sii_map += o.sii_map;
        self.sti += o.sti;
    }

    fn value(&self) -> Option<f64> {
        if self.n < 16.0 {
            return None;
        }
        let vt = self.stt - self.st * self.st / self.n;
        let vi = self.sii_map - self.si * self.si / self.n;
        let c = self.sti - self.st * self.si / self.n;
        (vt > 1e-9 && vi > 1e-9).then(|| c / (vt * vi).sqrt())
    }

    /// Least-squares gain and offset of `T ≈ α·I + β`.
    fn gain_offset(&self) -> (f64, f64) {
        let vi = self.sii - self.si * self.si / self.n;
        let c = self.sti - self.st * self.si / self.n;
        let alpha = if vi > 1e-12 { c / vi } else { 0.0 };
        (alpha, (self.st - alpha * self.si) / self.n)
    }
}

/// Mean end-point distance between the flows of `a` and `b` over the valid ToF pixels of
/// `level`, full-resolution px (0 without valid pixels).
fn mean_flow_change(level: &Level, a: &Theta, b: &Theta) -> f64 {
    let d: [f64; 4] = std::array::from_fn(|i| a.p[i] - b.p[i]);
    let (mut sum, mut n) = (0.0f64, 0usize);
    for &inv in level.inv_depth.iter().filter(|&&inv| inv > 0.0) {
        let inv = inv as f64;
        sum += (d[0] * inv + d[2]).hypot(d[1] * inv + d[3]);
        n += 1;
    }
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

/// A fit on its way down the pyramid, with the handicap of the search that found it
/// ([`DirectFitParams::reference_handicap`] for the reference's search, else 0).
#[derive(Debug, Clone, Copy)]
struct Candidate {
    theta: Theta,
    correlation: f64,
    handicap: f64,
}

impl Candidate {
    /// What fits are ranked and chosen by: the correlation less the handicap.
    fn score(&self) -> f64 {
        self.correlation - self.handicap
    }
}

/// The best `keep` of `fits` (sorted best first by [`Candidate::score`]) within `margin` of
/// the best score whose flows differ on average by more than 1 px (full resolution) from
/// every better one kept: fits that converged to one basin are refined once.
fn distinct_fits(level: &Level, fits: Vec<Candidate>, keep: usize, margin: f32) -> Vec<Candidate> {
    let mut kept: Vec<Candidate> = Vec::with_capacity(keep);
    let best = fits.first().map_or(f64::NEG_INFINITY, Candidate::score);
    for fit in fits {
        if kept.len() >= keep || fit.score() < best - margin as f64 {
            break;
        }
        if kept
            .iter()
            .all(|k| mean_flow_change(level, &k.theta, &fit.theta) > 1.0)
        {
            kept.push(fit);
        }
    }
    kept
}

/// `std(1/z) / mean(1/z)` over the valid ToF pixels, weighted by their edge strength.
fn rel_inv_depth_spread(level: &Level) -> f64 {
    let (mut sw, mut sa, mut saa) = (0.0f64, 0.0f64, 0.0f64);
    for (&t, &a) in level.t.iter().zip(&level.inv_depth) {
        if a > 0.0 {
            let (t, a) = (t as f64, a as f64);
            sw += t;
            sa += t * a;
            saa += t * a * a;
        }
    }
    if sw <= 0.0 {
        return 0.0;
    }
    let mean = sa / sw;
    let var = (saa / sw - mean * mean).max(0.0);
    var.sqrt() / mean
}

/// Best local maxima (3×3) of a `side × side` score grid, best first: `(score, i, j)`.
fn local_maxima(scores: &[f64], side: usize, keep: usize) -> Vec<(f64, usize, usize)> {
    let mut peaks = Vec::new();
    for j in 0..side {
        for i in 0..side {
            let s = scores[j * side + i];
            if !s.is_finite() {
                continue;
            }
            let mut is_max = true;
            'n: for jj in j.saturating_sub(1)..(j + 2).min(side) {
                for ii in i.saturating_sub(1)..(i + 2).min(side) {
                    let o = scores[jj * side + ii];
                    if (jj, ii) != (j, i) && (o > s || (o == s && (jj, ii) < (j, i))) {
                        is_max = false;
                        break 'n;
                    }
                }
            }
            if is_max {
                peaks.push((s, i, j));
            }
        }
    }
    peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
    peaks.truncate(keep);
    peaks
}

/// Sub-pixel offset of a peak along one axis from its two neighbours (parabola), in [−½, ½].
fn parabola(m: f64, c: f64, p: f64) -> f64 {
    let denom = m - 2.0 * c + p;
    if denom < 0.0 && m.is_finite() && p.is_finite() {
        (0.5 * (m - p) / denom).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

/// A valid ToF pixel of [`search_offsets`]: the whole-pixel part of its landing point (at the
/// centre of the search), the bilinear weights (the same for every whole-pixel shift), T and
/// its depth layer.
struct SearchPoint {
    x0: i32,
    y0: i32,
    w: [f32; 4],
    t: f32,
    layer: u8,
}

/// Offsets along x whose sums [`offset_lane_sums`] accumulates side by side.
const SEARCH_LANES: usize = 8;

/// The sums of [`Corr`] that depend on the offset, one lane per offset.
struct LaneCorr {
    si: [f64; SEARCH_LANES],
    sii: [f64; SEARCH_LANES],
    sti: [f64; SEARCH_LANES],
}

/// For the offsets `(dx, dy)`, `dx = dx_lo + SEARCH_LANES − 1 − l` in lane `l`: over `points`
/// in order, the sample `v` of `plane` (`w × h`) at each point's landing moved by `−(dx, dy)`
/// (bilinear, 0 where its 2×2 cell is not inside) added as [`Corr::add`] adds it. In lane
/// order the cells of a point are consecutive pixels, so where all are inside (nearly every
/// point) the samples are contiguous loads. Compiled for AVX-512 and AVX2 as well, chosen at
/// run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn offset_lane_sums(
    points: &[SearchPoint],
    plane: &[f32],
    (w, h): (i32, i32),
    dy: i32,
    dx_lo: i32,
) -> LaneCorr {
    const L: usize = SEARCH_LANES;
    let wi = w as usize;
    let (mut si, mut sii, mut sti) = ([0.0f64; L], [0.0f64; L], [0.0f64; L]);
    let mut v = [0.0f32; L];
    for p in points {
        // Lane 0's cell; lane l's is l pixels to the right.
        let (xb, y0) = (p.x0 - dx_lo - (L as i32 - 1), p.y0 - dy);
        if xb >= 0 && y0 >= 0 && xb + (L as i32) < w && y0 + 1 < h {
            let i = (y0 * w + xb) as usize;
            let (r0, r1) = (&plane[i..i + L + 1], &plane[i + wi..i + wi + L + 1]);
            for l in 0..L {
                v[l] = p.w[0] * r0[l] + p.w[1] * r0[l + 1] + p.w[2] * r1[l] + p.w[3] * r1[l + 1];
            }
        } else {
            for (l, v) in v.iter_mut().enumerate() {
                let x0 = xb + l as i32;
                *v = if x0 < 0 || y0 < 0 || x0 + 1 >= w || y0 + 1 >= h {
                    // Zero padding: the pixel set stays fixed (a small overlap must not win
                    // by chance).
                    0.0
                } else {
                    let i = (y0 * w + x0) as usize;
                    p.w[0] * plane[i]
                        + p.w[1] * plane[i + 1]
                        + p.w[2] * plane[i + wi]
                        + p.w[3] * plane[i + wi + 1]
                };
            }
        }
        let t = p.t as f64;
        for l in 0..L {
            let i = v[l] as f64;
            si[l] += i;
            sii[l] += i * i;
            sti[l] += t * i;
        }
    }
    LaneCorr { si, sii, sti }
}

/// Exhaustive search of a whole-pixel offset of `c` around `initial` (t held) at `level`,
/// scored over all pixels and, in the same pass, separately over layers of inverse depth.
/// Returns the starting points for Gauss–Newton: the best local maxima of the global score,
/// and the robust line `flow = t·(1/z) + c` through the layers' best offsets (which finds `t`
/// where the global search, `t` held, cannot: near objects move far from the rest).
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn search_offsets(level: &Level, initial: &Theta, params: &DirectFitParams) -> Vec<Theta> {
    const LAYERS: usize = 6;
    let r = (params.search_radius_px / level.scale).round().max(0.0) as i32;
    let side = (2 * r + 1) as usize;
    let (w, h) = (level.rgb_w as i32, level.rgb_h as i32);
    // Layer bounds: quantiles of the inverse depth over the edge pixels.
    let mut edge_a: Vec<f32> = level
        .t
        .iter()
        .zip(&level.inv_depth)
        .filter(|(&t, &a)| a > 0.0 && t > 0.1)
        .map(|(_, &a)| a)
        .collect();
    edge_a.sort_by(f32::total_cmp);
    let bounds: Vec<f32> = if edge_a.len() >= 10 * LAYERS {
        (1..LAYERS)
            .map(|k| edge_a[k * edge_a.len() / LAYERS])
            .collect()
    } else {
        Vec::new()
    };
    let layers = bounds.len() + 1;
    let mut points = Vec::new();
    for y in 0..level.tof_h {
        for x in 0..level.tof_w {
            let i = y * level.tof_w + x;
            let a = level.inv_depth[i];
            if a <= 0.0 {
                continue;
            }
            let (px, py) = landing(level, initial, x, y, a);
            if !(px.is_finite() && py.is_finite()) {
                continue;
            }
            let (fx0, fy0) = (px.floor(), py.floor());
            let (fx, fy) = (px - fx0, py - fy0);
            points.push(SearchPoint {
                x0: fx0 as i32,
                y0: fy0 as i32,
                w: [
                    (1.0 - fx) * (1.0 - fy),
                    fx * (1.0 - fy),
                    (1.0 - fx) * fy,
                    fx * fy,
                ],
                t: level.t[i],
                layer: bounds.iter().filter(|&&b| a >= b).count() as u8,
            });
        }
    }
    let mut scores = vec![f64::NEG_INFINITY; side * side];
    let mut layer_scores = vec![f64::NEG_INFINITY; layers * side * side];
    // Each layer's points together, each layer in row-major order (a stable sort), which is
    // the order its sums always ran in; and the sums no offset changes (the count and T's),
    // once per layer. Every offset's sums are then those of one scan over the points (bit
    // for bit), but `offset_lane_sums` runs SEARCH_LANES offsets per pass over a layer with
    // its sums in registers: one offset at a time into a layer picked per point was most of
    // the search's cost.
    points.sort_by_key(|p| p.layer);
    let mut fixed = vec![Corr::default(); layers];
    for p in &points {
        fixed[p.layer as usize].add_fixed(p.t as f64);
    }
    let layer_points: Vec<&[SearchPoint]> = (0..layers)
        .map(|k| {
            let lo = points.partition_point(|p| (p.layer as usize) < k);
            let hi = points.partition_point(|p| (p.layer as usize) <= k);
            &points[lo..hi]
        })
        .collect();
    let plane: Vec<f32> = level.rgb.iter().map(|v| v[0]).collect();
    for dy in -r..=r {
        for dx_lo in (-r..=r).step_by(SEARCH_LANES) {
            let sums: Vec<LaneCorr> = layer_points
                .iter()
                .map(|points| offset_lane_sums(points, &plane, (w, h), dy, dx_lo))
                .collect();
            // Lane `l` is the offset `dx_lo + SEARCH_LANES − 1 − l`.
            for l in 0..SEARCH_LANES {
                let dx = dx_lo + (SEARCH_LANES - 1 - l) as i32;
                if dx > r {
                    continue;
                }
                let cell = ((dy + r) as usize) * side + (dx + r) as usize;
                let mut all = Corr::default();
                for (k, (lanes, fixed)) in sums.iter().zip(&fixed).enumerate() {
                    let c = Corr {
                        si: lanes.si[l],
                        sii: lanes.sii[l],
                        sii_map: lanes.sii[l],
                        sti: lanes.sti[l],
                        ..*fixed
                    };
                    all.merge(&c);
                    if let Some(v) = c.value() {
                        layer_scores[k * side * side + cell] = v;
                    }
                }
                if let Some(v) = all.value() {
                    scores[cell] = v;
                }
            }
        }
    }
    let scale = level.scale as f64;
    let mut out: Vec<Theta> = local_maxima(&scores, side, params.search_candidates.max(1))
        .into_iter()
        .map(|(_, i, j)| {
            let mut theta = *initial;
            theta.p[2] += (i as f64 - r as f64) * scale;
            theta.p[3] += (j as f64 - r as f64) * scale;
            theta
        })
        .collect();
    // The layers' line: through every pair of layer peaks (the best two of each layer), scored
    // by the sum over the layers of their correlation at the offset the line predicts (a layer
    // the line moves out of the search window adds nothing). Robust to layers whose own best
    // offset is wrong, as near layers are when their flow exceeds the window.
    if layers >= 2 {
        let layer_a: Vec<f64> = (0..layers)
            .map(|k| {
                let lo = k * edge_a.len() / LAYERS;
                let hi = ((k + 1) * edge_a.len() / LAYERS).min(edge_a.len());
                edge_a[(lo + hi) / 2] as f64
            })
            .collect();
        let grid = |k: usize| &layer_scores[k * side * side..(k + 1) * side * side];
        // Peaks as offsets from the initial flow, level px.
        let mut peaks: Vec<(usize, f64, f64)> = Vec::new();
        for k in 0..layers {
            let g = grid(k);
            for (best, i, j) in local_maxima(g, side, 2) {
                let at = |i: isize, j: isize| -> f64 {
                    if i < 0 || j < 0 || i >= side as isize || j >= side as isize {
                        f64::NEG_INFINITY
                    } else {
                        g[j as usize * side + i as usize]
                    }
                };
                let (ii, jj) = (i as isize, j as isize);
                let sx = parabola(at(ii - 1, jj), best, at(ii + 1, jj));
                let sy = parabola(at(ii, jj - 1), best, at(ii, jj + 1));
                peaks.push((k, i as f64 - r as f64 + sx, j as f64 - r as f64 + sy));
            }
        }
        let score_line = |tu: f64, tv: f64, cu: f64, cv: f64| -> f64 {
            (0..layers)
                .map(|k| {
                    let (du, dv) = (tu * layer_a[k] + cu, tv * layer_a[k] + cv);
                    let (i, j) = ((du + r as f64).round(), (dv + r as f64).round());
                    if i < 0.0 || j < 0.0 || i >= side as f64 || j >= side as f64 {
                        return 0.0;
                    }
                    let v = grid(k)[j as usize * side + i as usize];
                    if v.is_finite() {
                        v.max(0.0)
                    } else {
                        0.0
                    }
                })
                .sum()
        };
        let mut lines: Vec<(f64, [f64; 4])> = Vec::new();
        for (n1, &(k1, u1, v1)) in peaks.iter().enumerate() {
            for &(k2, u2, v2) in &peaks[n1 + 1..] {
                let da = layer_a[k2] - layer_a[k1];
                if k1 == k2 || da.abs() < 1e-3 {
                    continue;
                }
                let (tu, tv) = ((u2 - u1) / da, (v2 - v1) / da);
                let (cu, cv) = (u1 - tu * layer_a[k1], v1 - tv * layer_a[k1]);
                lines.push((score_line(tu, tv, cu, cv), [tu, tv, cu, cv]));
            }
        }
        lines.sort_by(|a, b| b.0.total_cmp(&a.0));
        // The best few lines that predict different offsets (by more than a level px at some
        // layer) all go on to Gauss–Newton, and the global correlation decides: the layers'
        // own scores do not always rank the true line first, because an occluding contour
        // correlates both with its own offset and with the background's (the best line alone:
        // mean AEPE 2.01 px at σ = 4 on the RESULTS set, six lines 1.53 px).
        let mut kept: Vec<[f64; 4]> = Vec::new();
        for (_, line) in lines {
            if kept.len() >= params.search_lines.max(1) {
                break;
            }
            let distinct = kept.iter().all(|k| {
                layer_a.iter().any(|&a| {
                    ((line[0] - k[0]) * a + line[2] - k[2]).abs() > 1.0
                        || ((line[1] - k[1]) * a + line[3] - k[3]).abs() > 1.0
                })
            });
            if distinct {
                kept.push(line);
            }
        }
        for [tu, tv, cu, cv] in kept {
            // Offsets (level px, relative to the initial flow) → calibration (full px).
            let mut theta = *initial;
            theta.p[0] += tu * scale;
            theta.p[1] += tv * scale;
            theta.p[2] += cu * scale;
            theta.p[3] += cv * scale;
            out.push(theta);
        }
    }
    out
}

/// The level the carried fits are compared at, of a pyramid whose levels are `widths` wide
/// (finest first, the last the coarsest, where the search ran): the finest level from
/// `finest` on at most `choice_width` wide, short of the coarsest; `finest` when none is.
fn choice_level(widths: &[usize], finest: usize, choice_width: usize) -> usize {
    let coarsest = widths.len().saturating_sub(1);
    (finest..coarsest)
        .find(|&l| widths[l] <= choice_width)
        .unwrap_or(finest)
}

/// What one pass over a level at some `θ` gives.
struct Pass {
    /// Correlation sums (unweighted).
    corr: Corr,
    /// Gauss–Newton normal matrix `Σ w JᵀJ` in `(t_x, t_y, c_x, c_y, α, β)`.
    hm: [[f64; 6]; 6],
    /// Gradient `Σ w Jᵀ r`.
    g: [f64; 6],
    /// Robust cost `Σ ρ(r)` (`Σ r²/2` without a robust scale).
    cost: f64,
    /// `Σ r²`.
    sse: f64,
}

/// Where a pass gets each valid ToF pixel's sample of the RGB maps at its landing point.
enum Samples<'a> {
    /// Computed.
    Compute,
    /// Computed and kept (in the order of the valid pixels) for passes at the same `t` and
    /// `c`.
    Store(&'a mut Vec<[f32; 4]>),
    /// Kept by an earlier pass at the same `t` and `c` (bit for bit what it would compute).
    Stored(&'a [[f32; 4]]),
}

/// What a pass computes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PassKind {
    /// The correlation sums, the costs and the residuals' squares.
    Residuals,
    /// These and the normal equations (`hm`, `g`; zero otherwise).
    NormalEquations,
}

/// One pass at `theta`: the correlation and (with [`PassKind::NormalEquations`]) the
/// Gauss–Newton normal equations of `Σ ρ(α·I(p(q)) + β − T(q))`, with `ρ` the Cauchy loss of
/// scale `k` (least squares if `k ≤ 0`). A `Residuals` pass computes every other sum with the
/// same operations in the same order, so they are those of the full pass bit for bit, at
/// about half its cost: the passes whose normal equations are never solved (the start's gain
/// and robust scale, every step tried before it is accepted) run it.
// Small dense linear algebra reads best with indices.
#[allow(clippy::needless_range_loop)]
// Compiled for wider register files too: the 27 running sums of a pixel spill on the baseline
// x86-64 target's 16 registers (no FMA contraction happens, so every version gives the same bits).
#[multiversion::multiversion(targets("x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"))]
fn normal_equations(
    level: &Level,
    theta: &Theta,
    k_robust: f32,
    kind: PassKind,
    mut samples: Samples<'_>,
) -> Pass {
    let jacobian = kind == PassKind::NormalEquations;
    let mut valid = 0;
    let mut corr = Corr::default();
    let mut hm = [[0.0f64; 6]; 6];
    let mut g = [0.0f64; 6];
    let (mut cost, mut sse) = (0.0f64, 0.0f64);
    let (alpha, beta) = (theta.p[4] as f32, theta.p[5] as f32);
    let inv_s = 1.0 / level.scale;
    let inv_k2 = if k_robust > 0.0 {
        1.0 / (k_robust * k_robust)
    } else {
        0.0
    };
    // f32 accumulation per row, f64 across rows.
    let mut hr = [[0.0f32; 6]; 6];
    let mut gr = [0.0f32; 6];
    let (mut cost_r, mut sse_r) = (0.0f32, 0.0f32);
    for y in 0..level.tof_h {
        for x in 0..level.tof_w {
            let i = y * level.tof_w + x;
            let a = level.inv_depth[i];
            if a <= 0.0 {
                continue;
            }
            let [iv, ix, iy, iv_sq] = match &mut samples {
                Samples::Stored(stored) => stored[valid],
                _ => {
                    let (px, py) = landing(level, theta, x, y, a);
                    let s = sample(level, px, py).unwrap_or([0.0; 4]);
                    if let Samples::Store(store) = &mut samples {
                        store.push(s);
                    }
                    s
                }
            };
            valid += 1;
            let t = level.t[i];
            corr.add_varying(t as f64, iv as f64, iv_sq as f64);
            let r = alpha * iv + beta - t;
            let r2 = r * r;
            sse_r += r2;
            let wgt = if inv_k2 > 0.0 {
                let u = r2 * inv_k2;
                cost_r += 0.5 * (1.0 + u).ln() / inv_k2;
                1.0 / (1.0 + u)
            } else {
                cost_r += 0.5 * r2;
                1.0
            };
            if !jacobian {
                continue;
            }
            // p = q − (t·a + c)/s: ∂p/∂t = −a/s, ∂p/∂c = −1/s.
            let gx = -alpha * ix * inv_s;
            let gy = -alpha * iy * inv_s;
            let j = [gx * a, gy * a, gx, gy, iv, 1.0];
            for k in 0..6 {
                let wj = wgt * j[k];
                gr[k] += wj * r;
                for l in k..6 {
                    hr[k][l] += wj * j[l];
                }
            }
        }
        for k in 0..6 {
            g[k] += gr[k] as f64;
            gr[k] = 0.0;
            for l in k..6 {
                hm[k][l] += hr[k][l] as f64;
                hr[k][l] = 0.0;
            }
        }
        cost += cost_r as f64;
        sse += sse_r as f64;
        (cost_r, sse_r) = (0.0, 0.0);
    }
    for k in 0..6 {
        for l in 0..k {
            hm[k][l] = hm[l][k];
        }
    }
    (corr.n, corr.st, corr.stt) = (level.fixed.n, level.fixed.st, level.fixed.stt);
    Pass {
        corr,
        hm,
        g,
        cost,
        sse,
    }
}

/// Solves `H δ = −g` on the parameters `idx` (Cholesky with a tiny ridge); `None` if singular.
// Small dense linear algebra reads best with indices.
#[allow(clippy::needless_range_loop)]
fn solve(hm: &[[f64; 6]; 6], g: &[f64; 6], idx: &[usize]) -> Option<[f64; 6]> {
    let n = idx.len();
    let mut a = [[0.0f64; 6]; 6];
    let mut b = [0.0f64; 6];
    for (r, &i) in idx.iter().enumerate() {
        for (c, &j) in idx.iter().enumerate() {
            a[r][c] = hm[i][j];
        }
        a[r][r] *= 1.0 + 1e-6;
        b[r] = -g[i];
    }
    // Cholesky.
    let mut l = [[0.0f64; 6]; 6];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                if s <= 1e-12 * a[i][i].abs().max(1e-30) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut z = [0.0f64; 6];
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i][k] * z[k];
        }
        z[i] = s / l[i][i];
    }
    let mut x = [0.0f64; 6];
    for i in (0..n).rev() {
        let mut s = z[i];
        for k in i + 1..n {
            s -= l[k][i] * x[k];
        }
        x[i] = s / l[i][i];
    }
    let mut delta = [0.0f64; 6];
    for (r, &i) in idx.iter().enumerate() {
        delta[i] = x[r];
    }
    Some(delta)
}

/// Largest change of the flow a parameter step makes over the level's inverse-depth range,
/// level px.
fn flow_change(level: &Level, delta: &[f64; 6], a_range: (f64, f64)) -> f64 {
    [a_range.0, a_range.1]
        .iter()
        .map(|&a| {
            let du = delta[0] * a + delta[2];
            let dv = delta[1] * a + delta[3];
            du.hypot(dv) / level.scale as f64
        })
        .fold(0.0, f64::max)
}

/// Gauss–Newton (IRLS with the Cauchy loss when `robust_k > 0`, its scale `robust_k` times
/// the RMS residual at the start) from `start` at `level`, α and β refitted first; each step is
/// halved until the cost does not grow. Returns the parameters and their correlation.
// Small dense linear algebra reads best with indices.
#[allow(clippy::needless_range_loop)]
fn gauss_newton(
    level: &Level,
    start: Theta,
    fit_t: bool,
    iterations: usize,
    robust_k: f32,
) -> (Theta, f64) {
    // The inverse-depth range the flow is checked over: 2nd to 98th percentile (a few flying
    // pixels near the camera must not throttle every step).
    let mut inv: Vec<f32> = level
        .inv_depth
        .iter()
        .copied()
        .filter(|&a| a > 0.0)
        .collect();
    if inv.is_empty() {
        return (start, f64::NEG_INFINITY);
    }
    let lo = inv.len() / 50;
    let hi = (inv.len() * 49 / 50).min(inv.len() - 1);
    let a_min = *inv.select_nth_unstable_by(lo, f32::total_cmp).1 as f64;
    let a_max = *inv.select_nth_unstable_by(hi, f32::total_cmp).1 as f64;
    let idx: &[usize] = if fit_t {
        &[0, 1, 2, 3, 4, 5]
    } else {
        &[2, 3, 4, 5]
    };
    let mut theta = start;
    // Photometric gain/offset of the start point.
    // The start's three passes differ only in gain, offset and robust scale, and a step's
    // normal equations are computed where its cost was: the samples (the landing and the
    // bilinear sample, much of a pass) are computed once for each `t` and `c`.
    let mut stored = Vec::new();
    let p0 = normal_equations(
        level,
        &theta,
        0.0,
        PassKind::Residuals,
        Samples::Store(&mut stored),
    );
    let (alpha, beta) = p0.corr.gain_offset();
    theta.p[4] = alpha;
    theta.p[5] = beta;
    let k = if robust_k > 0.0 {
        let p = normal_equations(
            level,
            &theta,
            0.0,
            PassKind::Residuals,
            Samples::Stored(&stored),
        );
        robust_k * (p.sse / p.corr.n.max(1.0)).sqrt() as f32
    } else {
        0.0
    };
    let mut pass = normal_equations(
        level,
        &theta,
        k,
        PassKind::NormalEquations,
        Samples::Stored(&stored),
    );
    let Some(mut corr) = pass.corr.value() else {
        return (theta, f64::NEG_INFINITY);
    };
    // Pixels leave the image as the flow changes: compare mean costs.
    let mean_cost = |p: &Pass| p.cost / p.corr.n.max(1.0);
    for iteration in 0..iterations {
        let Some(mut delta) = solve(&pass.hm, &pass.g, idx) else {
            break;
        };
        // At most 2 level px of flow change per step (the basin's width).
        let mut change = flow_change(level, &delta, (a_min, a_max));
        if change > 2.0 {
            let s = 2.0 / change;
            delta.iter_mut().for_each(|d| *d *= s);
            change = 2.0;
        }
        let mut accepted = false;
        for _ in 0..4 {
            let mut cand = theta;
            for i in 0..6 {
                cand.p[i] += delta[i];
            }
            // A step is judged on its cost alone (most are rejected: a level usually ends
            // with four halvings that all fail); the normal equations at an accepted step are
            // computed only if they will be solved, i.e. unless the step ends the level (too
            // small, or the last).
            stored.clear();
            let next = normal_equations(
                level,
                &cand,
                k,
                PassKind::Residuals,
                Samples::Store(&mut stored),
            );
            if let Some(c) = next.corr.value() {
                if mean_cost(&next) <= mean_cost(&pass) {
                    let ends_level = change < 0.01 || iteration + 1 == iterations;
                    pass = if ends_level {
                        next
                    } else {
                        normal_equations(
                            level,
                            &cand,
                            k,
                            PassKind::NormalEquations,
                            Samples::Stored(&stored),
                        )
                    };
                    (theta, corr) = (cand, c);
                    accepted = true;
                    break;
                }
            }
            delta.iter_mut().for_each(|d| *d *= 0.5);
            change *= 0.5;
        }
        if !accepted || change < 0.01 {
            break;
        }
    }
    (theta, corr)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recalibration::edges::test_scene::{fit_textured_scene, textured_scene};

    /// The calibration the tests' scenes are seen through: a baseline and a principal-point
    /// offset, both a few pixels at the scenes' depths.
    const TRUTH: Calibration = Calibration {
        tx: 6.0,
        ty: -2.0,
        cx: 3.0,
        cy: 1.5,
    };

    /// 320×240 compares the carried fits at full resolution (as tuned), 640×480 at 320 px, a
    /// frame with no level that narrow short of the coarsest at its finest level.
    #[test]
    fn carried_fits_are_compared_at_the_finest_level_at_most_choice_width_wide() {
        assert_eq!(choice_level(&[320, 160], 0, 320), 0);
        assert_eq!(choice_level(&[640, 320, 160], 0, 320), 1);
        assert_eq!(choice_level(&[1280, 640, 320, 160], 0, 320), 2);
        assert_eq!(choice_level(&[400, 200], 0, 320), 0);
        assert_eq!(choice_level(&[640, 320, 160], 1, 320), 1);
        assert_eq!(choice_level(&[640, 320, 160], 0, 640), 0);
        assert_eq!(choice_level(&[160], 0, 320), 0);
    }

    fn max_flow_error(c: Calibration, truth: Calibration, depths: &[f32]) -> f32 {
        depths
            .iter()
            .map(|&z| {
                let (a, b) = (c.flow_at(z).unwrap(), truth.flow_at(z).unwrap());
                (a.0 - b.0).hypot(a.1 - b.1)
            })
            .fold(0.0, f32::max)
    }

    /// The landing rule matches the splatting convention: a ToF pixel at depth z lands at
    /// `q − W(z)` in the view `synthesize_view` makes.
    #[test]
    fn direct_landing_matches_the_splatting_convention() {
        let truth = TRUTH;
        let (h, w) = (40, 60);
        // One bright ToF pixel at (20, 30), depth 1.5 m, on a 3 m wall.
        let depth =
            Array2::from_shape_fn((h, w), |(y, x)| if (y, x) == (20, 30) { 1.5 } else { 3.0 });
        let rgb =
            ndarray::Array3::from_shape_fn(
                (h, w, 1),
                |(y, x, _)| {
                    if (y, x) == (20, 30) {
                        255u8
                    } else {
                        0
                    }
                },
            );
        let view = crate::geometry::synthesize_view(rgb.view(), depth.view(), &truth);
        // W(1.5) = (4 + 3, −4/3 + 1.5) = (7, 1/6): lands at (30 − 7, 20 − 1/6).
        let level = Level {
            scale: 1.0,
            tof_w: w,
            tof_h: h,
            t: vec![0.0; w * h],
            inv_depth: vec![0.0; w * h],
            rgb_w: w,
            rgb_h: h,
            rgb: vec![[0.0; 4]; w * h],
            fixed: Corr::default(),
        };
        let (px, py) = landing(&level, &Theta::from(truth), 30, 20, 1.0 / 1.5);
        assert!((px - 23.0).abs() < 1e-5 && (py - (20.0 - 1.0 / 6.0)).abs() < 1e-5);
        // The splatted view's brightest pixel is the nearest to the landing point.
        let (mut best, mut at) = (0u8, (0, 0));
        for ((y, x, _), &v) in view.rgb.indexed_iter() {
            if v > best {
                best = v;
                at = (y, x);
            }
        }
        assert_eq!(at, (20, 23));
    }

    /// A synthetic scene (discs at several depths before a wall, RGB and amplitude sharing the
    /// boundaries but not the interior pattern) seen through a known calibration, with the
    /// disocclusions filled as a real camera sees them: the direct fit, with the real-camera
    /// settings (contours move with the nearer surface, depth edges added), recovers the flow
    /// to within a pixel at every depth that has edges in both modalities (the discs; the wall
    /// behind has only RGB stripes).
    #[test]
    fn direct_recovers_a_known_calibration_on_a_textured_scene() {
        let truth = TRUTH;
        let fit = fit_textured_scene(&truth);
        assert!(!fit.fell_back, "{fit:?}");
        assert!(fit.baseline_fitted, "{fit:?}");
        let err = max_flow_error(fit.calibration, truth, &[0.8, 1.0, 1.2, 1.5, 1.8]);
        assert!(err < 1.0, "flow error {err} px: {fit:?}");
        // Far from the factory calibration's error.
        let before = max_flow_error(Calibration::IDENTITY, truth, &[0.8, 1.0, 1.2, 1.5, 1.8]);
        assert!(before > 6.0, "{before}");
    }

    /// Already aligned input: the fit stays at the identity (the project's aligned target is
    /// AEPE ≤ 0.3 px).
    #[test]
    fn direct_keeps_aligned_input_aligned() {
        let (rgb, amplitude, depth) = textured_scene(&Calibration::IDENTITY);
        let fit = estimate_calibration_direct(
            rgb.view(),
            amplitude.view(),
            depth.view(),
            Calibration::IDENTITY,
            &DirectFitParams::default(),
        );
        let err = max_flow_error(
            fit.calibration,
            Calibration::IDENTITY,
            &[0.8, 1.2, 1.8, 3.0],
        );
        assert!(err < 0.3, "flow error {err} px: {fit:?}");
    }

    /// An aligned frame and a search started far off (as from a poor network estimate): the
    /// fit climbs back to about the calibration in use, gains less correlation over it than
    /// [`DirectFitParams::min_gain`], and the calibration in use comes back unchanged, flagged.
    #[test]
    fn aligned_frame_leaves_the_calibration_in_use_alone() {
        let (rgb, amplitude, depth) = textured_scene(&Calibration::IDENTITY);
        let start = Calibration {
            tx: 3.0,
            ty: -1.0,
            cx: -2.0,
            cy: 1.0,
        };
        let fit = estimate_calibration_direct_against(
            rgb.view(),
            amplitude.view(),
            depth.view(),
            start,
            Calibration::IDENTITY,
            &DirectFitParams::default(),
        );
        assert!(fit.fell_back, "{fit:?}");
        assert_eq!(fit.calibration, Calibration::IDENTITY);
        assert_eq!(fit.information, Information::ZERO);
    }

    /// A drifted calibration in use and a rough-flow start further off than the search reaches
    /// (a poor network estimate): searching around the calibration in use as well finds the
    /// frame's calibration; searching around the start alone cannot, and keeps the drifted one.
    #[test]
    fn a_start_beyond_the_search_is_rescued_by_searching_from_the_reference() {
        let truth = TRUTH;
        let (rgb, amplitude, depth) = textured_scene(&truth);
        let reference = Calibration {
            cx: truth.cx - 4.0,
            cy: truth.cy + 3.0,
            ..truth
        };
        let start = Calibration {
            cx: truth.cx + 45.0,
            cy: truth.cy - 40.0,
            ..truth
        };
        let fit = |search_from_reference: bool| {
            let params = DirectFitParams {
                search_from_reference,
                ..DirectFitParams::default()
            };
            estimate_calibration_direct_against(
                rgb.view(),
                amplitude.view(),
                depth.view(),
                start,
                reference,
                &params,
            )
        };
        let depths = [0.8, 1.0, 1.2, 1.5, 1.8];
        let both = fit(true);
        assert!(!both.fell_back, "{both:?}");
        let err = max_flow_error(both.calibration, truth, &depths);
        assert!(err < 1.0, "flow error {err} px: {both:?}");
        let start_only = fit(false);
        let err = max_flow_error(start_only.calibration, truth, &depths);
        assert!(err > 3.0, "flow error {err} px: {start_only:?}");
    }

    /// A near-empty room (a wall and a floor, smooth shading, few edges) seen through a
    /// correct calibration: nothing in it shows that calibration wrong, so it stays, bit for
    /// bit.
    #[test]
    fn aligned_low_texture_room_leaves_the_calibration_alone() {
        let reference = Calibration::IDENTITY;
        let (h, w) = (120, 160);
        // Floor below row 80 (depth falling towards the camera), wall 3 m behind, a door frame.
        let tof_depth = Array2::from_shape_fn((h, w), |(y, _)| {
            if y >= 80 {
                3.0 - 0.04 * (y - 80) as f32
            } else {
                3.0
            }
        });
        let shade = |y: usize, x: usize| {
            let door = (50..70).contains(&x) && y < 80;
            let floor = y >= 80;
            if door {
                90.0
            } else if floor {
                140.0 + 0.3 * x as f32
            } else {
                180.0 - 0.2 * y as f32
            }
        };
        let rgb_aligned = ndarray::Array3::from_shape_fn((h, w, 3), |(y, x, _)| shade(y, x) as u8);
        let amplitude = Array2::from_shape_fn((h, w), |(y, x)| {
            4.0 * shade(y, x) / (tof_depth[[y, x]].powi(2))
        });
        let fit = estimate_calibration_direct_against(
            rgb_aligned.view(),
            amplitude.view(),
            tof_depth.view(),
            reference,
            reference,
            &DirectFitParams::default(),
        );
        assert!(fit.fell_back, "{fit:?}");
        assert_eq!(fit.calibration, reference);
    }

    /// The offset search's lanes give every offset the sums of one scan over the points,
    /// `Corr::add` per point, bit for bit: inside the image, across its borders (zero
    /// padding), and in lanes past the last offset.
    #[test]
    fn offset_lanes_give_each_offset_the_sums_of_one_scan_bit_for_bit() {
        let (w, h) = (37, 23);
        let plane: Vec<f32> = (0..w * h)
            .map(|i| ((i * 7919) % 101) as f32 / 100.0)
            .collect();
        // Points all over the image, the borders included, in no particular order.
        let points: Vec<SearchPoint> = (0..300)
            .map(|k| {
                let f = (k * 37 % 97) as f32 / 97.0;
                SearchPoint {
                    x0: (k * 13 % (w + 6)) as i32 - 3,
                    y0: (k * 7 % (h + 4)) as i32 - 2,
                    w: [(1.0 - f) * 0.7, f * 0.7, (1.0 - f) * 0.3, f * 0.3],
                    t: (k % 17) as f32 / 16.0,
                    layer: 0,
                }
            })
            .collect();
        for dy in [-3, 0, 2] {
            for dx_lo in [-9, -1, 4] {
                let lanes = offset_lane_sums(&points, &plane, (w as i32, h as i32), dy, dx_lo);
                for l in 0..SEARCH_LANES {
                    let dx = dx_lo + (SEARCH_LANES - 1 - l) as i32;
                    let mut one = Corr::default();
                    for p in &points {
                        let (x0, y0) = (p.x0 - dx, p.y0 - dy);
                        let inside = x0 >= 0 && y0 >= 0 && x0 + 1 < w as i32 && y0 + 1 < h as i32;
                        let v = if inside {
                            let i = (y0 * w as i32 + x0) as usize;
                            p.w[0] * plane[i]
                                + p.w[1] * plane[i + 1]
                                + p.w[2] * plane[i + w]
                                + p.w[3] * plane[i + w + 1]
                        } else {
                            0.0
                        };
                        one.add(p.t as f64, v as f64);
                    }
                    let got = [lanes.si[l], lanes.sii[l], lanes.sii[l], lanes.sti[l]];
                    let want = [one.si, one.sii, one.sii_map, one.sti];
                    assert_eq!(
                        got.map(f64::to_bits),
                        want.map(f64::to_bits),
                        "({dx}, {dy})"
                    );
                }
            }
        }
    }

    /// A pass that only judges a step gives the sums of the full pass bit for bit (the fit's
    /// path, and so its result, does not depend on which passes skip the normal equations),
    /// and both give the correlation sums of one scan adding every sum per pixel.
    #[test]
    fn a_residuals_pass_gives_the_full_pass_sums_bit_for_bit() {
        let (rgb, amplitude, depth) = textured_scene(&TRUTH);
        let levels = build_pyramid(
            rgb.view(),
            amplitude.view(),
            depth.view(),
            &DirectFitParams::default(),
        );
        let mut theta = Theta::from(Calibration {
            tx: 4.5,
            cx: 2.0,
            ..TRUTH
        });
        (theta.p[4], theta.p[5]) = (0.8, 0.05);
        let bits = |p: &Pass| {
            let c = p.corr;
            [
                c.n, c.st, c.stt, c.si, c.sii, c.sii_map, c.sti, p.cost, p.sse,
            ]
            .map(f64::to_bits)
        };
        for level in &levels {
            for k in [0.0, 0.05] {
                let full = normal_equations(
                    level,
                    &theta,
                    k,
                    PassKind::NormalEquations,
                    Samples::Compute,
                );
                let mut stored = Vec::new();
                let residuals = normal_equations(
                    level,
                    &theta,
                    k,
                    PassKind::Residuals,
                    Samples::Store(&mut stored),
                );
                // Passes reading the samples an earlier one kept: the same sums.
                let again = normal_equations(
                    level,
                    &theta,
                    k,
                    PassKind::NormalEquations,
                    Samples::Stored(&stored),
                );
                assert_eq!(bits(&again), bits(&full));
                assert_eq!(
                    again.hm.map(|r| r.map(f64::to_bits)),
                    full.hm.map(|r| r.map(f64::to_bits))
                );
                assert_eq!(again.g.map(f64::to_bits), full.g.map(f64::to_bits));
                assert!(full.corr.n > 100.0 && full.hm[0][0] > 0.0);
                assert_eq!(
                    bits(&residuals),
                    bits(&full),
                    "level {}, k {k}",
                    level.tof_w
                );
                assert_eq!(residuals.hm, [[0.0; 6]; 6]);
                assert_eq!(residuals.g, [0.0; 6]);
                // The level's fixed sums and the pass's varying ones are those of one scan
                // adding every sum per pixel.
                let mut one = Corr::default();
                for y in 0..level.tof_h {
                    for x in 0..level.tof_w {
                        let i = y * level.tof_w + x;
                        let a = level.inv_depth[i];
                        if a > 0.0 {
                            let (px, py) = landing(level, &theta, x, y, a);
                            let s = sample(level, px, py).unwrap_or([0.0; 4]);
                            one.add_sampled(level.t[i] as f64, s[0] as f64, s[3] as f64);
                        }
                    }
                }
                let scan = Pass {
                    corr: one,
                    ..residuals
                };
                assert_eq!(bits(&scan), bits(&residuals), "level {}", level.tof_w);
            }
        }
    }

    /// Fits carried from the coarsest level: best first, one per basin, none beyond the
    /// margin, at most `keep`.
    #[test]
    fn fits_carried_down_the_pyramid_are_distinct_and_close_to_the_best() {
        let level = Level {
            scale: 1.0,
            tof_w: 4,
            tof_h: 4,
            t: vec![0.0; 16],
            inv_depth: vec![0.5; 16],
            rgb_w: 4,
            rgb_h: 4,
            rgb: vec![[0.0; 4]; 16],
            fixed: Corr::default(),
        };
        let at = |cx: f32, corr: f64| {
            let c = Calibration {
                cx,
                ..Calibration::IDENTITY
            };
            Candidate {
                theta: Theta::from(c),
                correlation: corr,
                handicap: 0.0,
            }
        };
        // Best first: the best basin, a second start that converged into it (0.3 px away), a
        // distinct basin within the margin, and one beyond it.
        let fits = vec![at(0.0, 0.60), at(0.3, 0.59), at(3.0, 0.58), at(-4.0, 0.50)];
        let cx = |kept: Vec<Candidate>| kept.iter().map(|c| c.theta.p[2]).collect::<Vec<_>>();
        assert_eq!(cx(distinct_fits(&level, fits.clone(), 3, 0.05)), [0.0, 3.0]);
        assert_eq!(
            cx(distinct_fits(&level, fits.clone(), 3, 1.0)),
            [0.0, 3.0, -4.0]
        );
        assert_eq!(cx(distinct_fits(&level, fits, 1, 1.0)), [0.0]);
        // A handicapped fit (from the reference's search) is judged by its correlation less
        // the handicap: 0.62 − 0.03 is within 0.05 of the best but not within 0.005.
        let handicapped = Candidate {
            handicap: 0.03,
            ..at(3.0, 0.62)
        };
        let fits = vec![at(0.0, 0.60), handicapped, at(-4.0, 0.50)];
        assert_eq!(cx(distinct_fits(&level, fits.clone(), 3, 0.05)), [0.0, 3.0]);
        assert_eq!(cx(distinct_fits(&level, fits, 3, 0.005)), [0.0]);
    }

    /// A fit that explains the frame better but moves the flow further than
    /// [`DirectFitParams::max_mean_flow_change_px`] is refused; within it, taken.
    #[test]
    fn a_fit_beyond_the_flow_change_limit_is_refused() {
        let truth = TRUTH;
        let (rgb, amplitude, depth) = textured_scene(&truth);
        let fit = |max_mean_flow_change_px: f32| {
            let params = DirectFitParams {
                max_mean_flow_change_px,
                ..DirectFitParams::default()
            };
            estimate_calibration_direct(
                rgb.view(),
                amplitude.view(),
                depth.view(),
                Calibration::IDENTITY,
                &params,
            )
        };
        let taken = fit(24.0);
        assert!(!taken.fell_back, "{taken:?}");
        let refused = fit(1.0);
        assert!(refused.fell_back, "{refused:?}");
        assert_eq!(refused.calibration, Calibration::IDENTITY);
    }

    /// Nothing to fit on a flat image: the initial calibration comes back, flagged.
    #[test]
    fn direct_falls_back_on_a_flat_image() {
        let initial = Calibration {
            tx: 1.0,
            ty: 0.5,
            cx: -2.0,
            cy: 0.25,
        };
        let rgb = ndarray::Array3::from_elem((100, 120, 3), 128u8);
        let amp = Array2::from_elem((100, 120), 500.0f32);
        let depth = Array2::from_shape_fn((100, 120), |(_, x)| 1.0 + 0.01 * x as f32);
        let fit = estimate_calibration_direct(
            rgb.view(),
            amp.view(),
            depth.view(),
            initial,
            &DirectFitParams::default(),
        );
        assert!(fit.fell_back, "{fit:?}");
        assert_eq!(fit.calibration, initial);
    }
}
