//! The online calibration estimator: decides per frame whether to run the rough-flow network,
//! and filters the resulting measurements over time so that one bad frame cannot move the
//! published calibration.
//!
//! Per frame the caller asks [`OnlineCalibrator::begin_frame`] what to do, processes the frame
//! (`Full` when told to run the network, otherwise `Cached` with the current estimate), then
//! reports with [`OnlineCalibrator::end_frame`] the network frame's [`Measurement`] (if any)
//! and the frame's edge alignment check (if any; see [`crate::recalibration::residual`]).
//!
//! Filtering, in order:
//! 1. *Admission*: a flow fit that failed, used fewer than `min_pixels`, explains less than
//!    `min_inlier_fraction` of the flow or has an inlier RMS above `max_rms_px` is rejected; so
//!    is an edge fit whose edge correlation is below `min_edge_correlation`.
//! 2. *Innovation gate*: once the estimate is established, an admitted measurement whose
//!    predicted flow differs from the estimate's by more than `gate_px` anywhere in the depth
//!    range is held back. If `jump_confirmations` consecutive held-back measurements agree
//!    with each other, the calibration really jumped (an OIS step, a knock): they replace the
//!    history. One wild frame is therefore never enough.
//! 3. *Observability* (issue 32): a measurement that says how well its frame constrains each
//!    direction of `(t, c)` ([`Measurement::information`], [`crate::recalibration::observability`])
//!    moves the estimate only along the directions it knows to `max_direction_std_px`: it is
//!    replaced by `e + P (m − e)`, `e` the estimate and `P` the projector onto those
//!    eigenvectors of its information, before the gate and the median see it. A measurement
//!    that constrains no direction is [`Outcome::Unobservable`] and leaves the estimate where it
//!    is (it counts towards the warm-up, so a featureless room does not run the network on
//!    every frame, but it is neither accepted nor a rejection). Without an estimate there is
//!    nothing to project onto, so an estimator without a prior takes its first measurement
//!    whole; [`OnlineCalibrator::with_prior`] starts from a known (factory) calibration that
//!    the unconstrained directions keep.
//! 4. *Running median*: the estimate is the per-parameter median of the last `window` accepted
//!    measurements — bounded influence for anything the gate lets through, and a lag of about
//!    `window / 2` measurements on a drift.
//!
//! 5. *Principal-point tracking*: on frames without the network, the edge check's shift (the
//!    correction of `c` that best lines up RGB and warped-amplitude edges) moves the estimate's
//!    `c` by `track_gain` of it, at most `track_max_step_px` per frame, when its correlation
//!    peak is clear (`track_min_ncc`). The accepted measurements move with it: they are
//!    observations of a `c` that has since moved, and the median must not pull the estimate
//!    back to where `c` was. `t` (depth-dependent; slow thermal drift) is left to the network.
//!    Without this the estimate would lag OIS-like wander of the principal point (pixels per
//!    second) by about `interval_frames · window / 2` frames.
//!
//! **Network frames in the background** ([`crate::chain::BackgroundCalibrator`]): when the
//! network runs on a worker instead of inline, the caller answers a frame that asks for it with
//! [`OnlineCalibrator::defer_network`] (the worker took the frame; it is processed as an
//! ordinary frame meanwhile, and tracked) or [`OnlineCalibrator::network_busy`] (the worker is
//! still on an earlier frame; asked again next frame), and hands the result over with
//! [`OnlineCalibrator::deliver`] whenever it is ready. A late measurement observed `c` as it
//! was on its own frame, so the tracking applied since then is added to it before filtering,
//! exactly as it was added to the stored measurements. The residual baseline is taken on the
//! first frame after an accepted delivery, the first one aligned by the new estimate.
//!
//! The network runs when there is no established estimate yet, every `interval_frames`, sooner
//! (`retry_frames`) after a rejected measurement, and when the alignment residual has exceeded
//! the value measured on the last network frame by `residual_trigger_ratio` for
//! `residual_trigger_frames` consecutive frames.
//!
//! **Health** ([`OnlineCalibrator::health`], issue 32 item 3): good / can improve / needs
//! recalibration, from the correction the latest evidence proposes, the estimate's own
//! uncertainty and the held-back measurements; see [`CalibrationHealth`] and
//! docs/calibration-health.md.

use std::collections::VecDeque;

use dear_proto::CalibrationHealth;

use crate::recalibration::measurement::{Evidence, Measurement};
use crate::recalibration::observability::{Information, Observability};
use crate::recalibration::residual::EdgeAlignment;
use crate::recalibration::LsqError;
use dear_capture::calibration::Calibration;

/// Settings of [`OnlineCalibrator`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnlineConfig {
    /// Run the network at least every this many frames.
    pub interval_frames: u32,
    /// After a rejected measurement, retry after this many frames.
    pub retry_frames: u32,
    /// Accepted measurements before the estimate counts as established (until then the
    /// network runs every frame and the gate is off).
    pub warmup_measurements: usize,
    /// Number of accepted measurements the running median spans.
    pub window: usize,
    /// Innovation gate: largest flow change (px) a measurement may propose.
    pub gate_px: f32,
    /// Depth range (m) over which flows are compared for the gate.
    pub depth_range_m: (f32, f32),
    /// Consecutive, mutually consistent held-back measurements that are taken as a real jump.
    pub jump_confirmations: usize,
    /// Minimum inlier fraction of an admissible measurement.
    pub min_inlier_fraction: f32,
    /// Maximum inlier RMS residual (px) of an admissible measurement.
    pub max_rms_px: f32,
    /// Minimum usable pixels of an admissible measurement.
    pub min_pixels: usize,
    /// Minimum edge correlation of an admissible edge (direct) fit.
    pub min_edge_correlation: f32,
    /// Relative growth of the alignment residual over its post-estimate value that triggers
    /// the network.
    pub residual_trigger_ratio: f32,
    /// Absolute margin added to the trigger level (the residual is noisy near 0).
    pub residual_trigger_margin: f32,
    /// Consecutive frames above the trigger level before the network runs.
    pub residual_trigger_frames: u32,
    /// Fraction of the edge shift applied to `c` per frame (0 turns tracking off).
    pub track_gain: f32,
    /// Smallest peak NCC of an edge shift that is used.
    pub track_min_ncc: f32,
    /// Largest change of `c` per frame from tracking, px.
    pub track_max_step_px: f32,
    /// A measurement moves the estimate only along the directions of `(t, c)` it knows to at
    /// most this standard deviation (px of flow at about 1 m; eigenvalue of its information
    /// `≥ 1/σ²`). `f32::INFINITY` turns the projection off.
    pub max_direction_std_px: f32,
    /// The prior's ([`OnlineCalibrator::with_prior`]) standard deviation in every direction,
    /// px: how far a factory calibration is trusted before any frame confirmed it.
    pub prior_std_px: f32,
    /// Health: a proposed correction or an uncertainty of the estimate up to this many px of
    /// flow is "good".
    pub health_good_px: f32,
    /// Health: a proposed correction of at least this many px (or a held-back measurement
    /// beyond the gate) is "needs recalibration".
    pub health_recalibrate_px: f32,
    /// Health: a frame whose edge disagreement (`1 − NCC` of RGB and warped-amplitude edges at
    /// the published alignment) is at least this is "can improve": its edges barely line up.
    pub health_max_disagreement: f32,
}

impl Default for OnlineConfig {
    /// Every 30 frames (1 s at 30 fps; drift is far slower), median of 5, gate 3 px over
    /// 0.3–5 m, jumps confirmed by 3 measurements, residual trigger +25 % for 3 frames;
    /// `c` tracked between network frames with gain 0.7, peaks with NCC ≥ 0.1, ≤ 1 px/frame;
    /// measurements applied along directions known to ≤ 0.5 px; a prior known to 0.5 px;
    /// health good up to 1 px, needs recalibration from 3 px (the gate), can improve from an
    /// edge disagreement of 0.9 (read off `dear eval --online` on the simulator's sets, see
    /// docs/calibration-health.md: aligned frames of six families are below it but for 1 in
    /// 40, most frames misaligned by σ = 2–3 px at 320×240 above 0.85).
    fn default() -> Self {
        OnlineConfig {
            interval_frames: 30,
            retry_frames: 5,
            warmup_measurements: 3,
            window: 5,
            gate_px: 3.0,
            depth_range_m: (0.3, 5.0),
            jump_confirmations: 3,
            min_inlier_fraction: 0.5,
            max_rms_px: 2.0,
            min_pixels: 500,
            min_edge_correlation: 0.2,
            residual_trigger_ratio: 0.25,
            residual_trigger_margin: 0.02,
            residual_trigger_frames: 3,
            track_gain: 0.7,
            track_min_ncc: 0.1,
            track_max_step_px: 1.0,
            max_direction_std_px: 0.5,
            prior_std_px: 0.5,
            health_good_px: 1.0,
            health_recalibrate_px: 3.0,
            health_max_disagreement: 0.9,
        }
    }
}

/// Why the network runs on a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trigger {
    /// No established estimate yet.
    Warmup,
    /// `interval_frames` since the last network frame.
    Interval,
    /// The last measurement was rejected; retrying early.
    Retry,
    /// The alignment residual grew.
    Residual,
}

/// What to do with the current frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameDecision {
    /// `Some(reason)`: run the rough-flow network (`Full` mode) on this frame.
    pub run_network: Option<Trigger>,
    /// The current estimate (use it for `Cached` mode when the network does not run).
    pub calibration: Option<Calibration>,
}

/// A network frame handed to a background worker ([`OnlineCalibrator::defer_network`]):
/// which frame it was and how far tracking had moved `c` by then.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetworkTicket {
    /// The frame number ([`OnlineCalibrator::frames`]) the measurement is of.
    pub frame: u64,
    /// [`OnlineCalibrator`]'s cumulative tracking correction of `c` at that frame.
    tracked: (f32, f32),
}

/// What became of a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// Entered the running median.
    Accepted,
    /// Far from the estimate; held back pending confirmation.
    Gated {
        /// Largest flow difference to the estimate, px.
        innovation_px: f32,
    },
    /// Confirmed a jump: the history was replaced by the consistent held-back measurements.
    Jump,
    /// Not admissible.
    Rejected(Rejection),
    /// Admissible, but its frame constrains no direction of `(t, c)` well enough
    /// (`max_direction_std_px`): the estimate is left alone.
    Unobservable,
}

/// Why a measurement was not admissible.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rejection {
    /// The fit failed.
    FitFailed,
    /// Fewer usable pixels than `min_pixels`.
    TooFewPixels(usize),
    /// Inlier fraction below `min_inlier_fraction`.
    FewInliers(f32),
    /// Inlier RMS above `max_rms_px`.
    LargeResidual(f32),
    /// Edge correlation below `min_edge_correlation`.
    LowEdgeCorrelation(f32),
    /// Non-finite parameters.
    NotFinite,
}

/// The online estimator (see the module docs).
#[derive(Debug, Clone)]
pub struct OnlineCalibrator {
    config: OnlineConfig,
    accepted: VecDeque<Measurement>,
    pending: Vec<Measurement>,
    /// Outcomes of the last `window` network frames: accepted or not.
    attempts: VecDeque<bool>,
    estimate: Option<Calibration>,
    frame: u64,
    last_network_frame: Option<u64>,
    last_estimate_frame: Option<u64>,
    last_rejected: bool,
    residual_baseline: Option<f32>,
    residual_high_frames: u32,
    residual_triggered: bool,
    this_frame_network: bool,
    /// Sum of every tracking step applied to `c` so far (`u`, `v`), for late measurements.
    tracked: (f32, f32),
    /// A delivered measurement was accepted: take the next frame's residual as the baseline.
    baseline_due: bool,
    /// The prior's information (`with_prior`), if any.
    prior: Option<Information>,
    /// Unobservable measurements so far (they count towards the warm-up), capped.
    unobservable: usize,
    /// What the last admitted measurement constrained.
    last_observability: Option<Observability>,
    /// The last frame's edge shift (`c` correction that best lines up its edges, relative to
    /// the calibration that aligned it), px, when its peak was clear; `INFINITY` when the
    /// peak was at the search window's border.
    frame_shift_px: Option<f32>,
    /// The last frame's edge check, as given.
    frame_alignment: Option<EdgeAlignment>,
}

impl OnlineCalibrator {
    /// A fresh estimator with no estimate (the network runs on the first frames).
    pub fn new(config: OnlineConfig) -> Self {
        let config = OnlineConfig {
            window: config.window.max(1),
            warmup_measurements: config.warmup_measurements.max(1),
            jump_confirmations: config.jump_confirmations.max(1),
            interval_frames: config.interval_frames.max(1),
            retry_frames: config.retry_frames.max(1),
            ..config
        };
        OnlineCalibrator {
            config,
            accepted: VecDeque::new(),
            pending: Vec::new(),
            attempts: VecDeque::new(),
            estimate: None,
            frame: 0,
            last_network_frame: None,
            last_estimate_frame: None,
            last_rejected: false,
            residual_baseline: None,
            residual_high_frames: 0,
            residual_triggered: false,
            this_frame_network: false,
            tracked: (0.0, 0.0),
            baseline_due: false,
            prior: None,
            unobservable: 0,
            last_observability: None,
            frame_shift_px: None,
            frame_alignment: None,
        }
    }

    /// An estimator that starts from a known calibration (the factory one), trusted to
    /// `prior_std_px` in every direction: the network still warms up, but measurements move
    /// it only along the directions their frames constrain, so a featureless scene leaves it
    /// where it is.
    pub fn with_prior(config: OnlineConfig, prior: Calibration) -> Self {
        let mut est = OnlineCalibrator::new(config);
        est.estimate = Some(prior);
        est.prior = Some(Information::isotropic(est.config.prior_std_px));
        est
    }

    /// The settings in use.
    pub fn config(&self) -> &OnlineConfig {
        &self.config
    }

    /// Starts a frame: whether to run the network, and the estimate to use otherwise.
    pub fn begin_frame(&mut self) -> FrameDecision {
        self.frame += 1;
        let since = self.last_network_frame.map(|f| self.frame - f);
        let reason = if self.accepted.len() + self.unobservable < self.config.warmup_measurements {
            Some(Trigger::Warmup)
        } else if self.last_rejected
            && since.is_none_or(|s| s >= u64::from(self.config.retry_frames))
        {
            Some(Trigger::Retry)
        } else if self.residual_triggered {
            Some(Trigger::Residual)
        } else if since.is_none_or(|s| s >= u64::from(self.config.interval_frames)) {
            Some(Trigger::Interval)
        } else {
            None
        };
        self.this_frame_network = reason.is_some();
        FrameDecision {
            run_network: reason,
            calibration: self.estimate,
        }
    }

    /// Ends a frame: the network frame's fit (`None` when the network did not run) and the
    /// frame's edge alignment check. Returns what became of the measurement.
    pub fn end_frame(
        &mut self,
        measurement: Option<Result<Measurement, LsqError>>,
        alignment: Option<EdgeAlignment>,
    ) -> Option<Outcome> {
        self.end_frame_aligned_with(measurement, alignment, None)
    }

    /// [`end_frame`](Self::end_frame) of a frame that was aligned with `aligned_with` rather
    /// than with the current estimate: a caller that overlaps frames aligns the next frame
    /// before this one has ended, with the estimate as it was then. The edge check's shift
    /// says where `c` is relative to the calibration that aligned the frame, so the tracking
    /// moves the estimate towards `aligned_with`'s `c` plus that shift (with `None`, or the
    /// estimate itself, this is the plain [`end_frame`](Self::end_frame)).
    pub fn end_frame_aligned_with(
        &mut self,
        measurement: Option<Result<Measurement, LsqError>>,
        alignment: Option<EdgeAlignment>,
        aligned_with: Option<Calibration>,
    ) -> Option<Outcome> {
        let residual = alignment.map(|a| a.disagreement);
        self.frame_alignment = alignment;
        self.frame_shift_px = alignment.and_then(|a| a.shift).and_then(|shift| {
            let clear = shift.peak_ncc >= self.config.track_min_ncc;
            let px = shift.du.hypot(shift.dv);
            (clear && px.is_finite()).then_some(if shift.at_limit { f32::INFINITY } else { px })
        });
        let outcome = measurement.map(|m| self.observe(m));
        if !self.this_frame_network {
            self.track(alignment, aligned_with);
        }
        if self.baseline_due && !self.this_frame_network {
            if let Some(r) = residual.filter(|r| r.is_finite()) {
                self.residual_baseline = Some(r);
                self.baseline_due = false;
            }
        }
        if self.this_frame_network {
            self.last_network_frame = Some(self.frame);
            self.residual_triggered = false;
            self.residual_high_frames = 0;
            // The residual right after a network estimate is this scene's "aligned" level.
            if matches!(outcome, Some(Outcome::Accepted | Outcome::Jump)) {
                self.residual_baseline = residual.filter(|r| r.is_finite());
            }
        } else if let (Some(r), Some(base)) = (residual, self.residual_baseline) {
            let level = base * (1.0 + self.config.residual_trigger_ratio)
                + self.config.residual_trigger_margin;
            if r > level {
                self.residual_high_frames += 1;
                if self.residual_high_frames >= self.config.residual_trigger_frames {
                    self.residual_triggered = true;
                }
            } else {
                self.residual_high_frames = 0;
            }
        }
        self.this_frame_network = false;
        outcome
    }

    /// The frame that [`begin_frame`](Self::begin_frame) asked the network for was handed to
    /// a background worker: it is processed and ended like a frame without the network
    /// (tracked, its residual watched), while the interval and the residual trigger restart
    /// from it as from a network frame. Returns the ticket to [`deliver`](Self::deliver) the
    /// result with.
    pub fn defer_network(&mut self) -> NetworkTicket {
        self.this_frame_network = false;
        self.last_network_frame = Some(self.frame);
        self.residual_triggered = false;
        self.residual_high_frames = 0;
        NetworkTicket {
            frame: self.frame,
            tracked: self.tracked,
        }
    }

    /// The network was asked for on this frame but the background worker is still busy: the
    /// frame is an ordinary one, and the next frame asks again.
    pub fn network_busy(&mut self) {
        self.this_frame_network = false;
    }

    /// A background measurement of the frame `ticket` names, delivered between frames (before
    /// [`begin_frame`](Self::begin_frame)). The tracking steps applied since that frame are
    /// added to its `c` first, then it is filtered like an inline one. Returns what became of
    /// it.
    pub fn deliver(
        &mut self,
        ticket: NetworkTicket,
        measurement: Result<Measurement, LsqError>,
    ) -> Outcome {
        let (du, dv) = (
            self.tracked.0 - ticket.tracked.0,
            self.tracked.1 - ticket.tracked.1,
        );
        let measurement = measurement.map(|mut m| {
            m.calibration.cx += du;
            m.calibration.cy += dv;
            m
        });
        let outcome = self.observe(measurement);
        if matches!(outcome, Outcome::Accepted | Outcome::Jump) {
            self.baseline_due = true;
        }
        outcome
    }

    /// A background measurement that could not be made at all (the network failed on its
    /// frame): counted as a rejected attempt, so the network is retried after
    /// `retry_frames` and the quality's acceptance drops.
    pub fn deliver_failure(&mut self) {
        self.record(Outcome::Rejected(Rejection::FitFailed));
    }

    /// Moves `c` (estimate, accepted and held-back measurements) by the edge shift.
    fn track(&mut self, alignment: Option<EdgeAlignment>, aligned_with: Option<Calibration>) {
        let Some(shift) = alignment.and_then(|a| a.shift) else {
            return;
        };
        let Some(estimate) = self.estimate.as_mut() else {
            return;
        };
        if self.config.track_gain <= 0.0
            || shift.peak_ncc.is_nan()
            || shift.peak_ncc < self.config.track_min_ncc
            || !(shift.du.is_finite() && shift.dv.is_finite())
        {
            return;
        }
        // Where the edges put `c`, relative to the estimate.
        let (lag_u, lag_v) = aligned_with.map_or((0.0, 0.0), |used| {
            (estimate.cx - used.cx, estimate.cy - used.cy)
        });
        let (mut du, mut dv) = (
            (shift.du - lag_u) * self.config.track_gain,
            (shift.dv - lag_v) * self.config.track_gain,
        );
        let step = du.hypot(dv);
        if step > self.config.track_max_step_px {
            let k = self.config.track_max_step_px / step;
            du *= k;
            dv *= k;
        }
        estimate.cx += du;
        estimate.cy += dv;
        self.tracked.0 += du;
        self.tracked.1 += dv;
        for m in self.accepted.iter_mut().chain(self.pending.iter_mut()) {
            m.calibration.cx += du;
            m.calibration.cy += dv;
        }
    }

    fn observe(&mut self, m: Result<Measurement, LsqError>) -> Outcome {
        let outcome = match m {
            Err(_) => Outcome::Rejected(Rejection::FitFailed),
            Ok(m) => match self.admit(&m) {
                Err(why) => Outcome::Rejected(why),
                Ok(()) => match self.project(m) {
                    None => Outcome::Unobservable,
                    Some(m) => self.gate(m),
                },
            },
        };
        if outcome == Outcome::Unobservable {
            // Neither accepted nor rejected: no retry, the acceptance is unchanged.
            self.last_rejected = false;
            self.unobservable = (self.unobservable + 1).min(self.config.warmup_measurements);
        } else {
            self.record(outcome);
        }
        if matches!(outcome, Outcome::Accepted | Outcome::Jump) {
            self.estimate = Some(median(&self.accepted));
            self.last_estimate_frame = Some(self.frame);
        }
        outcome
    }

    /// The measurement moved from the estimate only along the directions its frame
    /// constrains (unchanged without an estimate or without information); `None` when it
    /// constrains none.
    fn project(&mut self, mut m: Measurement) -> Option<Measurement> {
        let Some(info) = m.information else {
            self.last_observability = None;
            return Some(m);
        };
        let obs = info.observability(self.config.max_direction_std_px);
        self.last_observability = Some(obs);
        if obs.constrained == 0 {
            return None;
        }
        if let Some(e) = self.estimate {
            if !obs.complete() {
                m.calibration = obs.step(&e, &m.calibration);
            }
        }
        Some(m)
    }

    /// Counts a network attempt's outcome: the acceptance window and the retry trigger.
    fn record(&mut self, outcome: Outcome) {
        self.last_rejected = matches!(outcome, Outcome::Rejected(_));
        self.attempts
            .push_back(matches!(outcome, Outcome::Accepted | Outcome::Jump));
        while self.attempts.len() > self.config.window {
            self.attempts.pop_front();
        }
    }

    fn admit(&self, m: &Measurement) -> Result<(), Rejection> {
        let c = m.calibration;
        if ![c.tx, c.ty, c.cx, c.cy].iter().all(|v| v.is_finite()) {
            return Err(Rejection::NotFinite);
        }
        // The comparisons are written to reject NaN too.
        match m.evidence {
            Evidence::Flow {
                rms_residual_px,
                inlier_fraction,
                pixels_used,
            } => {
                if pixels_used < self.config.min_pixels {
                    return Err(Rejection::TooFewPixels(pixels_used));
                }
                if inlier_fraction.is_nan() || inlier_fraction < self.config.min_inlier_fraction {
                    return Err(Rejection::FewInliers(inlier_fraction));
                }
                if rms_residual_px.is_nan() || rms_residual_px > self.config.max_rms_px {
                    return Err(Rejection::LargeResidual(rms_residual_px));
                }
            }
            Evidence::Edges { correlation, .. } => {
                if correlation.is_nan() || correlation < self.config.min_edge_correlation {
                    return Err(Rejection::LowEdgeCorrelation(correlation));
                }
            }
        }
        Ok(())
    }

    fn gate(&mut self, m: Measurement) -> Outcome {
        let established = self.accepted.len() >= self.config.warmup_measurements;
        let innovation = self
            .estimate
            .map_or(0.0, |e| self.flow_distance(&e, &m.calibration));
        if !established || innovation <= self.config.gate_px {
            self.pending.clear();
            self.push_accepted(m);
            return Outcome::Accepted;
        }
        // Held back. Keep only the run of held-back measurements consistent with this one.
        let consistent = self.pending.last().is_none_or(|p| {
            self.flow_distance(&p.calibration, &m.calibration) <= self.config.gate_px
        });
        if !consistent {
            self.pending.clear();
        }
        self.pending.push(m);
        if self.pending.len() >= self.config.jump_confirmations {
            self.accepted.clear();
            for p in std::mem::take(&mut self.pending) {
                self.push_accepted(p);
            }
            return Outcome::Jump;
        }
        Outcome::Gated {
            innovation_px: innovation,
        }
    }

    fn push_accepted(&mut self, m: Measurement) {
        self.accepted.push_back(m);
        while self.accepted.len() > self.config.window {
            self.accepted.pop_front();
        }
    }

    /// Largest end-point difference of the flows two calibrations predict over the depth
    /// range (the flow is affine in 1/z, so the extremes are at the range's ends).
    fn flow_distance(&self, a: &Calibration, b: &Calibration) -> f32 {
        let (z0, z1) = self.config.depth_range_m;
        [z0, z1]
            .iter()
            .map(|&z| {
                let du = (a.tx - b.tx) / z + (a.cx - b.cx);
                let dv = (a.ty - b.ty) / z + (a.cy - b.cy);
                du.hypot(dv)
            })
            .fold(0.0, f32::max)
    }

    /// The current filtered calibration, if any measurement was accepted.
    pub fn estimate(&self) -> Option<Calibration> {
        self.estimate
    }

    /// Quality of the estimate in `[0, 1]`:
    /// `fit · acceptance · freshness` where
    /// - `fit` is the median over the window of [`Measurement::fit_quality`] (a flow fit's
    ///   `inlier_fraction / (1 + rms²)`, an edge fit's edge correlation);
    /// - `acceptance` is the fraction of the last `window` network frames that were accepted
    ///   (rejected and held-back ones lower it);
    /// - `freshness` is 1 up to `2 · interval_frames` frames since the last accepted estimate and
    ///   decays exponentially (time constant `4 · interval_frames`) after.
    ///
    /// 0 without an estimate.
    pub fn quality(&self) -> f32 {
        if self.estimate.is_none() || self.accepted.is_empty() {
            return 0.0;
        }
        let mut fits: Vec<f32> = self.accepted.iter().map(Measurement::fit_quality).collect();
        let fit = dear_stats::upper_median(&mut fits).expect("accepted is not empty");
        let acceptance = if self.attempts.is_empty() {
            1.0
        } else {
            self.attempts.iter().filter(|&&a| a).count() as f32 / self.attempts.len() as f32
        };
        let n = self.config.interval_frames as f32;
        let age = self.frames_since_estimate().unwrap_or(u64::MAX) as f32;
        let freshness = (-(age - 2.0 * n).max(0.0) / (4.0 * n)).exp();
        (fit * acceptance * freshness).clamp(0.0, 1.0)
    }

    /// What the last admitted measurement's frame constrained (`None` before any, or when it
    /// carried no information).
    pub fn last_observability(&self) -> Option<Observability> {
        self.last_observability
    }

    /// The information behind the estimate: the prior's plus that of every measurement in the
    /// window (a measurement without information counts as knowing every direction to
    /// 0.1 px). A heuristic for "has every direction been seen": the measurements of one
    /// scene are not independent, and the estimate is their median, not their weighted mean.
    pub fn information(&self) -> Information {
        let mut info = self.prior.unwrap_or(Information::ZERO);
        for m in &self.accepted {
            info = info.add(&m.information.unwrap_or(Information::isotropic(0.1)));
        }
        info
    }

    /// The calibration's health (docs/calibration-health.md):
    /// - **unknown** without an estimate;
    /// - **needs recalibration** while `≥ 2` mutually consistent measurements beyond the gate
    ///   are held back (a jump half confirmed; one wild frame is never enough), or when the
    ///   recent evidence or the frame's own edge check proposes a correction of
    ///   `health_recalibrate_px` or more (an edge shift at the border of its search window
    ///   counts as beyond it);
    /// - **can improve** when it proposes `health_good_px` or more, when the frame's edges line
    ///   up best at the border of the shift search (however weakly) or barely at all
    ///   (disagreement ≥ `health_max_disagreement`), when some direction of the estimate is
    ///   known only to worse than `health_good_px` (no prior and no frame constrained it yet),
    ///   or while the alignment residual is above its trigger level;
    /// - **good** otherwise.
    ///
    /// The *proposed correction* is the larger of the flow distance from the estimate to the
    /// per-parameter median of the last three accepted (projected) measurements — what the
    /// recent evidence says, robust to one wild measurement as the estimate is, and ahead of
    /// the estimate (the median of the whole window) when the calibration moves — and the
    /// last frame's edge shift ([`crate::recalibration::EdgeShift`], when its peak is clear: NCC ≥
    /// `track_min_ncc`): how far that frame's own edges say its alignment is off in `c`.
    pub fn health(&self) -> HealthReport {
        let info = self.information();
        let uncertainty_px = info.observability(self.config.health_good_px).worst_std_px;
        let recent: VecDeque<Measurement> = self
            .accepted
            .iter()
            .skip(self.accepted.len().saturating_sub(RECENT_MEASUREMENTS))
            .copied()
            .collect();
        let proposed_px = match (self.estimate, recent.is_empty()) {
            (Some(e), false) => self.flow_distance(&e, &median(&recent)),
            _ => 0.0,
        };
        let held_back_px = match (self.estimate, self.pending.last()) {
            (Some(e), Some(p)) if self.pending.len() >= 2 => {
                Some(self.flow_distance(&e, &p.calibration))
            }
            _ => None,
        };
        let frame_px = self.frame_shift_px.unwrap_or(0.0);
        let correction_px = proposed_px.max(held_back_px.unwrap_or(0.0)).max(frame_px);
        let state = if self.estimate.is_none() {
            CalibrationHealth::Unknown
        } else if held_back_px.is_some() || correction_px >= self.config.health_recalibrate_px {
            CalibrationHealth::NeedsRecalibration
        } else if correction_px >= self.config.health_good_px
            || self.frame_disagrees()
            || uncertainty_px.is_nan()
            || uncertainty_px > self.config.health_good_px
            || self.residual_high_frames >= self.config.residual_trigger_frames
        {
            CalibrationHealth::CanImprove
        } else {
            CalibrationHealth::Good
        };
        HealthReport {
            state,
            correction_px,
            uncertainty_px,
            constrained: self.last_observability.map_or(4, |o| o.constrained),
            held_back: self.pending.len(),
            frame_alignment: self.frame_alignment,
        }
    }

    /// Whether the last frame's own edges say its alignment is off without saying by how
    /// much: they line up best at the border of the shift search however weakly (beyond the
    /// window), or they barely line up at all (`health_max_disagreement`).
    fn frame_disagrees(&self) -> bool {
        self.frame_alignment.is_some_and(|a| {
            a.disagreement >= self.config.health_max_disagreement
                || a.shift.is_some_and(|s| s.at_limit)
        })
    }

    /// Frames since the estimate last changed (0 on the frame it changed), `None` before any.
    pub fn frames_since_estimate(&self) -> Option<u64> {
        self.last_estimate_frame.map(|f| self.frame - f)
    }

    /// Whether the current frame (between `begin_frame` and `end_frame`) runs the network.
    pub fn runs_network_this_frame(&self) -> bool {
        self.this_frame_network
    }

    /// Frames started so far.
    pub fn frames(&self) -> u64 {
        self.frame
    }
}

/// Accepted measurements whose median is the "recent evidence" of [`OnlineCalibrator::health`].
const RECENT_MEASUREMENTS: usize = 3;

/// [`OnlineCalibrator::health`]'s state and the numbers behind it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HealthReport {
    /// Good / can improve / needs recalibration (unknown without an estimate).
    pub state: CalibrationHealth,
    /// The largest of the correction the recent evidence proposes (the median of the last
    /// three accepted measurements against the estimate), the last frame's clear edge shift
    /// (∞ at the search window's border) and, with two or more held back, the last held-back
    /// measurement's distance from the estimate; px of flow over the depth range.
    pub correction_px: f32,
    /// Standard deviation of the estimate along its worst-known direction, px (∞ when some
    /// direction has never been constrained).
    pub uncertainty_px: f32,
    /// Directions the last admitted measurement's frame constrained, 0–4 (4 when it carried
    /// no information, or before any).
    pub constrained: u8,
    /// Measurements held back by the gate, waiting for the confirmation of a jump.
    pub held_back: usize,
    /// The last frame's edge check (diagnostics).
    pub frame_alignment: Option<EdgeAlignment>,
}

/// Per-parameter median of the measurements (upper median for an even count,
/// [`dear_stats::upper_median`]).
///
/// # Panics
/// If `ms` is empty.
fn median(ms: &VecDeque<Measurement>) -> Calibration {
    let pick = |f: fn(&Calibration) -> f32| {
        let mut v: Vec<f32> = ms.iter().map(|m| f(&m.calibration)).collect();
        dear_stats::upper_median(&mut v).expect("median of no measurements")
    };
    Calibration {
        tx: pick(|c| c.tx),
        ty: pick(|c| c.ty),
        cx: pick(|c| c.cx),
        cy: pick(|c| c.cy),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TRUE: Calibration = Calibration {
        tx: 6.0,
        ty: -2.0,
        cx: 3.0,
        cy: 1.0,
    };

    fn flow_fit(c: Calibration, rms_residual_px: f32, inlier_fraction: f32) -> Measurement {
        Measurement {
            calibration: c,
            information: None,
            evidence: Evidence::Flow {
                rms_residual_px,
                inlier_fraction,
                pixels_used: 10_000,
            },
        }
    }

    fn good(c: Calibration) -> Measurement {
        flow_fit(c, 0.3, 0.95)
    }

    fn edge_fit(c: Calibration, correlation: f32) -> Measurement {
        Measurement {
            calibration: c,
            information: None,
            evidence: Evidence::Edges {
                correlation,
                initial_correlation: 0.1,
            },
        }
    }

    #[test]
    fn edge_fits_are_admitted_by_their_correlation_and_it_is_their_quality() {
        let mut est = OnlineCalibrator::new(OnlineConfig::default());
        for weak in [0.1, f32::NAN] {
            est.begin_frame();
            let outcome = est.end_frame(Some(Ok(edge_fit(TRUE, weak))), None);
            assert!(
                matches!(
                    outcome,
                    Some(Outcome::Rejected(Rejection::LowEdgeCorrelation(_)))
                ),
                "{outcome:?}"
            );
        }
        assert_eq!(est.estimate(), None);
        est.begin_frame();
        let outcome = est.end_frame(Some(Ok(edge_fit(TRUE, 0.6))), None);
        assert_eq!(outcome, Some(Outcome::Accepted));
        assert_eq!(est.estimate(), Some(TRUE));
        // fit 0.6 (the correlation) × acceptance 1/3 × freshness 1.
        assert!((est.quality() - 0.2).abs() < 1e-6, "{}", est.quality());
    }

    /// Deterministic small noise in [-a, a].
    fn noise(i: u64, a: f32) -> f32 {
        let x = (i.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as f32 / (1u64 << 24) as f32;
        a * (2.0 * x - 1.0)
    }

    fn noisy(c: Calibration, i: u64) -> Calibration {
        Calibration {
            tx: c.tx + noise(4 * i, 0.1),
            ty: c.ty + noise(4 * i + 1, 0.1),
            cx: c.cx + noise(4 * i + 2, 0.05),
            cy: c.cy + noise(4 * i + 3, 0.05),
        }
    }

    /// Runs `frames` frames; `measure(frame)` gives the network's measurement when it runs.
    fn drive(
        est: &mut OnlineCalibrator,
        frames: u64,
        mut measure: impl FnMut(u64) -> Measurement,
        mut each: impl FnMut(u64, &OnlineCalibrator, Option<Outcome>),
    ) {
        for _ in 0..frames {
            let d = est.begin_frame();
            let m = d.run_network.map(|_| Ok(measure(est.frames())));
            let outcome = est.end_frame(m, None);
            each(est.frames(), est, outcome);
        }
    }

    /// Largest parameter difference.
    fn dist(a: Calibration, b: Calibration) -> f32 {
        [a.tx - b.tx, a.ty - b.ty, a.cx - b.cx, a.cy - b.cy]
            .iter()
            .fold(0.0, |m, d| m.max(d.abs()))
    }

    #[test]
    fn warms_up_then_runs_the_network_every_interval() {
        let config = OnlineConfig {
            interval_frames: 10,
            ..OnlineConfig::default()
        };
        let mut est = OnlineCalibrator::new(config);
        assert_eq!(est.estimate(), None);
        assert_eq!(est.quality(), 0.0);
        let mut runs = Vec::new();
        for f in 1..=40u64 {
            let d = est.begin_frame();
            if let Some(why) = d.run_network {
                runs.push((f, why));
            }
            assert_eq!(est.runs_network_this_frame(), d.run_network.is_some());
            let m = d.run_network.map(|_| Ok(good(noisy(TRUE, f))));
            est.end_frame(m, None);
        }
        assert_eq!(
            runs,
            vec![
                (1, Trigger::Warmup),
                (2, Trigger::Warmup),
                (3, Trigger::Warmup),
                (13, Trigger::Interval),
                (23, Trigger::Interval),
                (33, Trigger::Interval)
            ]
        );
        assert!(dist(est.estimate().unwrap(), TRUE) < 0.2);
        assert!(est.quality() > 0.8, "{}", est.quality());
    }

    #[test]
    fn one_wildly_wrong_frame_does_not_move_the_estimate() {
        let mut est = OnlineCalibrator::new(OnlineConfig {
            interval_frames: 1,
            ..OnlineConfig::default()
        });
        let wild = Calibration {
            tx: -40.0,
            ty: 30.0,
            cx: -25.0,
            cy: 18.0,
        };
        let mut before = None;
        drive(
            &mut est,
            30,
            |f| {
                if f == 20 {
                    good(wild)
                } else {
                    good(noisy(TRUE, f))
                }
            },
            |f, est, outcome| {
                if f == 19 {
                    before = est.estimate();
                }
                if f == 20 {
                    assert!(
                        matches!(outcome, Some(Outcome::Gated { .. })),
                        "{outcome:?}"
                    );
                    assert_eq!(est.estimate(), before, "the wild frame moved the estimate");
                }
                if f > 3 {
                    let e = est.estimate().unwrap();
                    assert!(dist(e, TRUE) < 0.5, "frame {f}: {e:?}");
                }
            },
        );
        // Also a wild frame that the gate cannot see (during warm-up, no gate yet): the median
        // of the window bounds it.
        let mut est = OnlineCalibrator::new(OnlineConfig::default());
        drive(
            &mut est,
            5,
            |f| {
                if f == 2 {
                    good(wild)
                } else {
                    good(noisy(TRUE, f))
                }
            },
            |_, _, _| {},
        );
        assert!(
            dist(est.estimate().unwrap(), TRUE) < 0.5,
            "{:?}",
            est.estimate()
        );
    }

    #[test]
    fn a_slow_drift_is_tracked_with_bounded_lag() {
        let interval = 10u32;
        let mut est = OnlineCalibrator::new(OnlineConfig {
            interval_frames: interval,
            ..OnlineConfig::default()
        });
        // c_x drifts by 0.01 px/frame (OIS creep), t_x by 0.005 px·m/frame.
        let at = |f: u64| Calibration {
            tx: TRUE.tx + 0.005 * f as f32,
            cx: TRUE.cx + 0.01 * f as f32,
            ..TRUE
        };
        let window = est.config().window as f32;
        // Median of `window` measurements taken every `interval` frames lags by about
        // window/2 measurements; plus up to one interval since the last one; plus the noise.
        let max_lag_frames = (window / 2.0 + 1.0) * interval as f32;
        let bound = 0.01 * max_lag_frames + 0.06;
        drive(
            &mut est,
            600,
            |f| good(noisy(at(f), f)),
            |f, est, _| {
                if f > 60 {
                    let e = est.estimate().unwrap();
                    let err = (e.cx - at(f).cx).abs();
                    assert!(
                        err <= bound,
                        "frame {f}: c_x {} vs {} (bound {bound})",
                        e.cx,
                        at(f).cx
                    );
                }
            },
        );
        // And it does follow: the drift is 6 px over the run, far above the bound.
        assert!(est.estimate().unwrap().cx > TRUE.cx + 5.0);
    }

    #[test]
    fn a_real_jump_is_taken_after_confirmation() {
        let mut est = OnlineCalibrator::new(OnlineConfig {
            interval_frames: 1,
            ..OnlineConfig::default()
        });
        let jumped = Calibration {
            cx: TRUE.cx + 8.0,
            ..TRUE
        };
        let mut outcomes = Vec::new();
        drive(
            &mut est,
            20,
            |f| good(noisy(if f > 10 { jumped } else { TRUE }, f)),
            |f, _, o| {
                if f > 10 {
                    outcomes.push(o.unwrap());
                }
            },
        );
        assert!(matches!(outcomes[0], Outcome::Gated { .. }));
        assert!(matches!(outcomes[1], Outcome::Gated { .. }));
        assert_eq!(outcomes[2], Outcome::Jump);
        assert!(dist(est.estimate().unwrap(), jumped) < 0.5);
    }

    #[test]
    fn quality_falls_when_fits_are_bad() {
        let mut est = OnlineCalibrator::new(OnlineConfig {
            interval_frames: 1,
            ..OnlineConfig::default()
        });
        drive(&mut est, 10, |f| good(noisy(TRUE, f)), |_, _, _| {});
        let q_good = est.quality();
        assert!(q_good > 0.8, "{q_good}");
        // Fits that explain little of the flow are rejected: acceptance drops, and so does
        // the quality, while the estimate stays where it was.
        let kept = est.estimate();
        drive(
            &mut est,
            3,
            |_| flow_fit(TRUE, 0.3, 0.2),
            |_, _, o| {
                assert!(
                    matches!(o, Some(Outcome::Rejected(Rejection::FewInliers(_)))),
                    "{o:?}"
                )
            },
        );
        let q_rejected = est.quality();
        assert!(q_rejected < 0.5 * q_good, "{q_rejected} vs {q_good}");
        assert_eq!(est.estimate(), kept);
        // Admissible but mediocre fits (1.5 px RMS) also lower it.
        let mut est2 = OnlineCalibrator::new(OnlineConfig::default());
        drive(
            &mut est2,
            5,
            |f| flow_fit(noisy(TRUE, f), 1.5, 0.7),
            |_, _, _| {},
        );
        assert!(est2.quality() < 0.3, "{}", est2.quality());
        // Failed fits count as rejections too, and trigger an early retry.
        let mut est3 = OnlineCalibrator::new(OnlineConfig {
            interval_frames: 30,
            retry_frames: 5,
            ..OnlineConfig::default()
        });
        drive(&mut est3, 3, |f| good(noisy(TRUE, f)), |_, _, _| {});
        for _ in 0..29 {
            est3.begin_frame();
            est3.end_frame(None, None);
        }
        let d = est3.begin_frame();
        assert_eq!(d.run_network, Some(Trigger::Interval));
        est3.end_frame(Some(Err(LsqError::ZeroWeight)), None);
        let frames_before = est3.frames();
        let retry_at = loop {
            if est3.begin_frame().run_network.is_some() {
                break est3.frames();
            }
            est3.end_frame(None, None);
        };
        assert_eq!(retry_at - frames_before, 5);
        // Staleness: no estimate for a long time lowers the quality.
        let q = est3.quality();
        est3.end_frame(Some(Err(LsqError::ZeroWeight)), None);
        for _ in 0..300 {
            est3.begin_frame();
            est3.end_frame(None, None);
        }
        assert!(est3.quality() < 0.2 * q, "{} vs {q}", est3.quality());
    }

    /// An edge check with this disagreement and no shift.
    fn residual(r: f32) -> Option<EdgeAlignment> {
        Some(EdgeAlignment {
            disagreement: r,
            shift: None,
        })
    }

    /// An edge check that says `c` must move by `(du, dv)`.
    fn shifted(du: f32, dv: f32, peak_ncc: f32) -> Option<EdgeAlignment> {
        Some(EdgeAlignment {
            disagreement: 0.5,
            shift: Some(crate::recalibration::residual::EdgeShift {
                du,
                dv,
                peak_ncc,
                gain: 0.1,
                at_limit: false,
            }),
        })
    }

    /// An estimator established on exact measurements of `TRUE`.
    fn warmed_up(config: OnlineConfig) -> OnlineCalibrator {
        let mut est = OnlineCalibrator::new(config);
        for _ in 0..config.warmup_measurements {
            est.begin_frame();
            est.end_frame(Some(Ok(good(TRUE))), None);
        }
        est
    }

    #[test]
    fn the_edge_shift_tracks_the_principal_point_between_network_frames() {
        let config = OnlineConfig {
            interval_frames: 1000,
            ..OnlineConfig::default()
        };
        let mut est = warmed_up(config);
        // c_x wanders 0.3 px per frame; the edge check measures what is left over.
        let mut truth = TRUE;
        for _ in 0..40 {
            truth.cx += 0.3;
            let d = est.begin_frame();
            assert_eq!(d.run_network, None);
            let e = d.calibration.unwrap();
            est.end_frame(None, shifted(truth.cx - e.cx, truth.cy - e.cy, 0.4));
        }
        let e = est.estimate().unwrap();
        // Steady-state lag of a gain-0.7 tracker: 0.3 · 0.3 / 0.7 ≈ 0.13 px.
        assert!((e.cx - truth.cx).abs() < 0.2, "{e:?} vs {truth:?}");
        assert_eq!((e.tx, e.ty, e.cy), (TRUE.tx, TRUE.ty, TRUE.cy));
        // The next network measurement agrees with the tracked estimate: the history moved
        // along, so the median does not drag c back 12 px to where it was.
        est.begin_frame();
        est.end_frame(Some(Ok(good(truth))), None);
        assert!((est.estimate().unwrap().cx - truth.cx).abs() < 0.2);

        // Unclear peaks, and steps above the limit, are not taken whole.
        let before = est.estimate().unwrap();
        est.begin_frame();
        est.end_frame(None, shifted(2.0, 0.0, 0.05));
        assert_eq!(est.estimate().unwrap(), before, "peak below track_min_ncc");
        est.begin_frame();
        est.end_frame(None, shifted(5.0, 0.0, 0.5));
        let moved = est.estimate().unwrap().cx - before.cx;
        assert!((moved - config.track_max_step_px).abs() < 1e-5, "{moved}");

        // Tracking off: the estimate stays put.
        let mut off = warmed_up(OnlineConfig {
            track_gain: 0.0,
            ..config
        });
        off.begin_frame();
        off.end_frame(None, shifted(1.0, 1.0, 0.5));
        assert_eq!(off.estimate(), Some(TRUE));
    }

    /// Overlapped frames: each frame is aligned with the estimate as it was before the previous
    /// frame ended. Told which calibration aligned the frame, the tracker converges as without
    /// the overlap; treating the late shift as relative to the current estimate (the plain
    /// `end_frame`) counts the previous frame's step twice and rings.
    #[test]
    fn tracking_a_frame_aligned_one_frame_late_measures_from_its_own_calibration() {
        let config = OnlineConfig {
            interval_frames: 1000,
            ..OnlineConfig::default()
        };
        // A 2 px step of c_x, then 12 overlapped frames.
        let run = |aware: bool| {
            let mut est = warmed_up(config);
            let truth = Calibration {
                cx: TRUE.cx + 2.0,
                ..TRUE
            };
            let mut aligned_with = est.estimate().unwrap();
            let mut errors = Vec::new();
            for _ in 0..12 {
                // The next frame is aligned now, before this one ends.
                let next = est.estimate().unwrap();
                let d = est.begin_frame();
                assert_eq!(d.run_network, None);
                let shift = shifted(truth.cx - aligned_with.cx, 0.0, 0.4);
                if aware {
                    est.end_frame_aligned_with(None, shift, Some(aligned_with));
                } else {
                    est.end_frame(None, shift);
                }
                aligned_with = next;
                errors.push((est.estimate().unwrap().cx - truth.cx).abs());
            }
            errors
        };
        let aware = run(true);
        let naive = run(false);
        // Geometric convergence at the tracker's rate (0.3 per frame) from the 2 px step.
        assert!(aware[11] < 1e-3, "{aware:?}");
        assert!(
            aware.windows(2).all(|w| w[1] <= w[0] + 1e-6),
            "monotone: {aware:?}"
        );
        // The naive tracker overshoots (its error grows again after shrinking).
        assert!(naive.windows(2).any(|w| w[1] > w[0] + 1e-3), "{naive:?}");
        // Aligned with the estimate itself, it is the plain end_frame.
        let mut a = warmed_up(config);
        let mut b = warmed_up(config);
        a.begin_frame();
        b.begin_frame();
        a.end_frame(None, shifted(0.7, -0.2, 0.4));
        b.end_frame_aligned_with(None, shifted(0.7, -0.2, 0.4), b.estimate());
        assert_eq!(a.estimate(), b.estimate());
    }

    /// The background protocol: a network frame handed to a worker is processed (and tracked)
    /// like any other, the interval restarts from it, the result arrives frames later with the
    /// tracking applied since its frame, and a busy worker means "ask again next frame".
    #[test]
    fn a_late_measurement_gets_the_tracking_applied_since_its_frame() {
        let config = OnlineConfig {
            interval_frames: 5,
            ..OnlineConfig::default()
        };
        let mut est = warmed_up(config);
        // Frames until the interval asks for the network; they are tracked: c moves 0.5 px.
        let mut asked = None;
        for _ in 0..10 {
            let d = est.begin_frame();
            if d.run_network.is_some() {
                asked = Some(est.defer_network());
                // Handed to the worker: an ordinary frame, tracked like the others.
                est.end_frame(None, shifted(0.5 / 0.7, 0.0, 0.5));
                break;
            }
            est.end_frame(None, None);
        }
        let ticket = asked.expect("the interval asks for the network");
        assert!((est.estimate().unwrap().cx - (TRUE.cx + 0.5)).abs() < 1e-5);
        // While the worker is busy the next frames ask again (interval restarted at the
        // ticket's frame: they do not), and they keep being tracked.
        for _ in 0..3 {
            let d = est.begin_frame();
            assert_eq!(
                d.run_network, None,
                "the interval restarts at the deferred frame"
            );
            est.end_frame(None, shifted(0.5 / 0.7, 0.0, 0.5));
        }
        let truth_now = TRUE.cx + 2.0;
        assert!((est.estimate().unwrap().cx - truth_now).abs() < 1e-4);
        // The measurement of the ticket's frame saw c as it was then, before that frame's own
        // tracking step: TRUE. Delivered now, it is moved by the 2 px tracked since and agrees
        // with the tracked estimate instead of dragging it back.
        let outcome = est.deliver(ticket, Ok(good(TRUE)));
        assert_eq!(outcome, Outcome::Accepted);
        assert!(
            (est.estimate().unwrap().cx - truth_now).abs() < 1e-4,
            "{:?}",
            est.estimate()
        );
        // A busy worker: the frame is an ordinary one and the next frame asks again.
        let mut busy_est = warmed_up(config);
        let mut asked_frames = 0;
        for _ in 0..20 {
            if busy_est.begin_frame().run_network.is_some() {
                asked_frames += 1;
                busy_est.network_busy();
            }
            busy_est.end_frame(None, None);
        }
        assert_eq!(
            asked_frames,
            20 - 4,
            "asked on every frame from the interval on"
        );
        // A failed background frame counts as a rejected attempt: retried, quality lower.
        let before = busy_est.quality();
        busy_est.deliver_failure();
        assert!(busy_est.quality() < before);
    }

    #[test]
    fn a_growing_residual_triggers_the_network() {
        let mut est = OnlineCalibrator::new(OnlineConfig {
            interval_frames: 1000,
            ..OnlineConfig::default()
        });
        // Warm-up frames with a residual of 0.4 set the baseline.
        for f in 0..3 {
            assert!(est.begin_frame().run_network.is_some());
            est.end_frame(Some(Ok(good(noisy(TRUE, f)))), residual(0.4));
        }
        // Small fluctuations do not trigger.
        for r in [0.41, 0.45, 0.39, 0.5, 0.42] {
            assert_eq!(est.begin_frame().run_network, None);
            est.end_frame(None, residual(r));
        }
        // Three frames above 0.4·1.25 + 0.02 = 0.52 do.
        for _ in 0..3 {
            assert_eq!(est.begin_frame().run_network, None);
            est.end_frame(None, residual(0.7));
        }
        assert_eq!(est.begin_frame().run_network, Some(Trigger::Residual));
        est.end_frame(Some(Ok(good(TRUE))), residual(0.4));
        assert_eq!(est.begin_frame().run_network, None);
    }

    /// A flow fit whose frame has edges at the inverse depths `layers` only (1000 samples
    /// each, 0.1 px noise): one layer constrains `t/z + c` at its depth, two or more all four.
    fn observed(c: Calibration, layers: &[f32]) -> Measurement {
        let mut info = Information::ZERO;
        for &a in layers {
            let n = 1000.0;
            let a = f64::from(a);
            info = info.add(&Information::of_flow_fit(n, a * n, a * a * n, 0.01, 1.0));
        }
        Measurement {
            information: Some(info),
            ..good(c)
        }
    }

    /// Issue 32: a frame that constrains only some directions moves the estimate only along
    /// them. With edges at 2 m only (a wall), a measurement that got `t` and `c` wrong along
    /// the direction that keeps the flow at 2 m (what a fit of a wall does) leaves a correct
    /// calibration where it is, frame after frame; a frame with no information at all is
    /// `Unobservable`, and neither retries the network nor counts against the acceptance.
    #[test]
    fn a_frame_that_cannot_improve_the_estimate_leaves_it_alone() {
        let config = OnlineConfig {
            interval_frames: 1,
            ..OnlineConfig::default()
        };
        let mut est = OnlineCalibrator::with_prior(config, TRUE);
        assert_eq!(est.estimate(), Some(TRUE));
        // t off by +3 px·m, c by −1.5 px: the same flow at 2 m (a = 0.5), 3.8 px off at 0.3 m.
        let wrong = Calibration {
            tx: TRUE.tx + 3.0,
            cx: TRUE.cx - 1.5,
            ty: TRUE.ty - 2.0,
            cy: TRUE.cy + 1.0,
        };
        for f in 0..20 {
            assert!(est.begin_frame().run_network.is_some());
            let outcome = est.end_frame(Some(Ok(observed(wrong, &[0.5]))), None);
            assert_eq!(outcome, Some(Outcome::Accepted), "frame {f}");
            assert_eq!(est.last_observability().unwrap().constrained, 2);
            let e = est.estimate().unwrap();
            assert!(dist(e, TRUE) < 1e-4, "frame {f}: {e:?}");
        }
        // The same measurement without observability moves it (the old behaviour).
        let mut blind = OnlineCalibrator::with_prior(config, TRUE);
        blind.begin_frame();
        blind.end_frame(Some(Ok(good(wrong))), None);
        assert!(dist(blind.estimate().unwrap(), TRUE) > 1.0);
        // Nothing constrained at all: unobservable, no retry, acceptance unchanged.
        let before = est.quality();
        est.begin_frame();
        let outcome = est.end_frame(Some(Ok(observed(wrong, &[]))), None);
        assert_eq!(outcome, Some(Outcome::Unobservable));
        assert!(dist(est.estimate().unwrap(), TRUE) < 1e-4);
        assert_eq!(est.quality(), before);
        assert_ne!(est.begin_frame().run_network, Some(Trigger::Retry));
    }

    /// The other half: frames that constrain every direction (edges at several depths) move a
    /// wrong prior to the truth; frames that constrain only the flow at one depth correct
    /// exactly that flow and leave the rest of the prior.
    #[test]
    fn constrained_frames_still_converge() {
        let config = OnlineConfig {
            interval_frames: 1,
            ..OnlineConfig::default()
        };
        let off = Calibration {
            tx: TRUE.tx - 4.0,
            ty: TRUE.ty + 2.0,
            cx: TRUE.cx + 2.0,
            cy: TRUE.cy - 1.0,
        };
        let mut est = OnlineCalibrator::with_prior(config, off);
        for _ in 0..3 {
            est.begin_frame();
            est.end_frame(Some(Ok(observed(TRUE, &[0.3, 0.6, 1.2]))), None);
        }
        assert!(dist(est.estimate().unwrap(), TRUE) < 1e-4);
        // Edges at 2 m only: the flow at 2 m becomes the truth's, the flow elsewhere is
        // neither the truth's nor the prior's.
        let mut est = OnlineCalibrator::with_prior(config, off);
        for _ in 0..5 {
            est.begin_frame();
            est.end_frame(Some(Ok(observed(TRUE, &[0.5]))), None);
        }
        let e = est.estimate().unwrap();
        let flow = |c: Calibration, z: f32| c.flow_at(z).unwrap();
        let at = |z: f32| {
            let (p, q) = (flow(e, z), flow(TRUE, z));
            (p.0 - q.0).hypot(p.1 - q.1)
        };
        assert!(at(2.0) < 1e-4, "{e:?}");
        assert!(at(0.3) > 1.0, "{e:?}");
    }

    /// The health states (docs/calibration-health.md) on constructed measurements.
    #[test]
    fn health_states() {
        let config = OnlineConfig {
            interval_frames: 1,
            ..OnlineConfig::default()
        };
        // No estimate: unknown.
        let est = OnlineCalibrator::new(config);
        assert_eq!(est.health().state, CalibrationHealth::Unknown);
        // A prior confirmed by agreeing measurements: good.
        let mut est = OnlineCalibrator::with_prior(config, TRUE);
        assert_eq!(
            est.health().state,
            CalibrationHealth::Good,
            "{:?}",
            est.health()
        );
        for _ in 0..3 {
            est.begin_frame();
            est.end_frame(Some(Ok(observed(TRUE, &[0.3, 0.6, 1.2]))), None);
        }
        let h = est.health();
        assert_eq!(h.state, CalibrationHealth::Good, "{h:?}");
        assert!(h.correction_px < 1e-3 && h.uncertainty_px < 0.5, "{h:?}");
        assert_eq!(h.constrained, 4);
        // c_x moves by 1.5 px. The first measurement of it is outvoted (one wild frame is
        // never enough); after the second the last three measurements say 1.5 px while the
        // estimate, the median of five, has not moved yet: can improve; the third moves it.
        let moved_cx = |d: f32| Calibration {
            cx: TRUE.cx + d,
            ..TRUE
        };
        let at = |d: f32| Some(Ok(observed(moved_cx(d), &[0.3, 0.6, 1.2])));
        let mut states = Vec::new();
        for _ in 0..3 {
            est.begin_frame();
            est.end_frame(at(1.5), None);
            states.push(est.health());
        }
        assert_eq!(states[0].state, CalibrationHealth::Good, "{states:?}");
        assert_eq!(states[1].state, CalibrationHealth::CanImprove, "{states:?}");
        assert!((states[1].correction_px - 1.5).abs() < 1e-3, "{states:?}");
        assert_eq!(states[2].state, CalibrationHealth::Good, "{states:?}");
        assert!(dist(est.estimate().unwrap(), moved_cx(1.5)) < 1e-4);
        // A jump of 5 px: the first measurement beyond the gate is held back and changes
        // nothing; the second, consistent with it, says needs recalibration; the third
        // confirms the jump, the estimate takes it, and the health is good again.
        for k in 0..3 {
            est.begin_frame();
            let outcome = est.end_frame(at(6.5), None);
            let h = est.health();
            match k {
                0 => {
                    assert!(
                        matches!(outcome, Some(Outcome::Gated { .. })),
                        "{outcome:?}"
                    );
                    assert_eq!((h.state, h.held_back), (CalibrationHealth::Good, 1));
                }
                1 => {
                    assert!(
                        matches!(outcome, Some(Outcome::Gated { .. })),
                        "{outcome:?}"
                    );
                    assert_eq!(h.state, CalibrationHealth::NeedsRecalibration, "{h:?}");
                    assert!((h.correction_px - 5.0).abs() < 1e-3, "{h:?}");
                }
                _ => {
                    assert_eq!(outcome, Some(Outcome::Jump));
                    assert_eq!(h.state, CalibrationHealth::Good, "{h:?}");
                }
            }
        }
        // Without a prior, frames that constrain only two directions leave the estimate's
        // other two unknown: can improve, however well the seen directions agree.
        let mut est = OnlineCalibrator::new(config);
        for _ in 0..3 {
            est.begin_frame();
            est.end_frame(Some(Ok(observed(TRUE, &[0.5]))), None);
        }
        let h = est.health();
        assert_eq!(h.state, CalibrationHealth::CanImprove, "{h:?}");
        assert!(h.uncertainty_px > 1.0, "{h:?}");
        assert_eq!(h.constrained, 2);
        // A growing alignment residual: can improve until the network re-measures.
        let mut est = OnlineCalibrator::with_prior(
            OnlineConfig {
                interval_frames: 1000,
                ..config
            },
            TRUE,
        );
        for _ in 0..3 {
            est.begin_frame();
            est.end_frame(Some(Ok(observed(TRUE, &[0.3, 0.6, 1.2]))), residual(0.4));
        }
        assert_eq!(est.health().state, CalibrationHealth::Good);
        for _ in 0..3 {
            est.begin_frame();
            est.end_frame(None, residual(0.8));
        }
        assert_eq!(est.health().state, CalibrationHealth::CanImprove);
        // The frame's own edges: a clear 1.5 px shift says can improve, one at the border of
        // the search window needs recalibration, an unclear peak says nothing.
        let mut est = OnlineCalibrator::with_prior(
            OnlineConfig {
                interval_frames: 1000,
                track_gain: 0.0,
                ..config
            },
            TRUE,
        );
        for _ in 0..3 {
            est.begin_frame();
            est.end_frame(Some(Ok(observed(TRUE, &[0.3, 0.6, 1.2]))), None);
        }
        let frame = |est: &mut OnlineCalibrator, a: Option<EdgeAlignment>| {
            est.begin_frame();
            est.end_frame(None, a);
            est.health().state
        };
        assert_eq!(
            frame(&mut est, shifted(0.3, 0.2, 0.5)),
            CalibrationHealth::Good
        );
        assert_eq!(
            frame(&mut est, shifted(1.5, 0.0, 0.5)),
            CalibrationHealth::CanImprove
        );
        assert_eq!(
            frame(&mut est, shifted(1.5, 0.0, 0.05)),
            CalibrationHealth::Good
        );
        let mut at_limit = shifted(3.0, 0.0, 0.5);
        if let Some(s) = at_limit.as_mut().and_then(|a| a.shift.as_mut()) {
            s.at_limit = true;
        }
        assert_eq!(
            frame(&mut est, at_limit),
            CalibrationHealth::NeedsRecalibration
        );
        // At the border with an unclear peak, or edges that barely line up: can improve.
        let mut weak_limit = shifted(3.0, 0.0, 0.02);
        if let Some(s) = weak_limit.as_mut().and_then(|a| a.shift.as_mut()) {
            s.at_limit = true;
        }
        assert_eq!(frame(&mut est, weak_limit), CalibrationHealth::CanImprove);
        let mut uncorrelated = shifted(0.2, 0.0, 0.5);
        if let Some(a) = uncorrelated.as_mut() {
            a.disagreement = 0.95;
        }
        assert_eq!(frame(&mut est, uncorrelated), CalibrationHealth::CanImprove);
        assert_eq!(
            frame(&mut est, shifted(0.2, 0.0, 0.5)),
            CalibrationHealth::Good
        );
    }
}
