//! The per-frame engine: what `deard` does to every frame when it runs a model bundle, kept in
//! the library so that the evaluation (`dear eval --online`) runs the daemon's code and not a
//! re-creation of it.
//!
//! [`FrameEngine`] holds the [`DearChain`], the online estimator ([`OnlineCalibrator`]), the
//! measurement of the frames on which the estimator asks for the rough-flow network, and the
//! record of the output guard's verdicts. Per frame it decides how the frame is aligned,
//! hands a finished measurement to the estimator, runs the chain (whole, or in two halves that
//! consecutive frames overlap), ends the frame in the estimator and says in a [`FrameReport`]
//! what the frame header publishes. The daemon (`daemon/src/processing.rs`) converts its
//! `[pipeline]` configuration into an [`EngineConfig`], fills the header from the report, and
//! runs the static engine (no bundle) itself.
//!
//! **When a measurement arrives** ([`MeasurementSchedule`]) is the one thing that differs
//! between the daemon and the evaluation:
//! - [`Background`](MeasurementSchedule::Background) (deard's default): the measurement runs on
//!   a worker thread ([`BackgroundCalibrator`]) and reaches the estimator on the first frame
//!   after it is ready, so how many frames later depends on the machine and its load;
//! - [`Delayed`](MeasurementSchedule::Delayed) (`dear eval --online`): the same measurement,
//!   of the same frame, made at once on the caller's thread ([`DelayedCalibrator`]) and handed
//!   to the estimator exactly `n` frames after the frame that asked for it, so evaluation
//!   results are reproducible bit for bit and are what the daemon computes when its worker
//!   takes `n` frame intervals. [`typical_delay_frames`] is the `n` that matches the daemon's
//!   measured latency;
//! - [`Inline`](MeasurementSchedule::Inline): on the frame that asked for it (`Full` mode), as
//!   deard's `online_network = "inline"`; that frame takes the network's time.
//!
//! With an off-path measurement (background or delayed) every frame is aligned by a
//! calibration and its first half runs no network, so the engine [overlaps
//! frames](FrameEngine::overlaps_frames): [`prepare`](FrameEngine::prepare) aligns a frame with
//! the estimate as it is then, [`finish`](FrameEngine::finish) refines it, beside the next
//! frame's first half when the caller has that frame already (docs/daemon.md, "Overlapping
//! frames"). The evaluation prepares each frame and finishes it alone, as deard does when it
//! keeps up with the camera.

use std::num::NonZeroU32;

use dear_proto::CalibrationHealth;
use ndarray::{Array2, Array3};

use crate::chain::{
    BackgroundCalibrator, ChainError, ChainInput, ChainMode, ChainOutput, ChainReport, DearChain,
    DelayedCalibrator, Delivered, MeasureReport, Prepared, RefinementCheck, Submit,
};
use crate::model::{BundleError, ModelBundle};
use crate::recalibration::LsqError;
use crate::recalibration::{Measurement, NetworkTicket, OnlineCalibrator, OnlineConfig};
use dear_capture::calibration::Calibration;

/// The worker thread's name (`top -H`, debuggers): the daemon is the engine's one user of it.
const WORKER_THREAD_NAME: &str = "deard-calibrate";

/// Consecutive frames whose refinement the output guard rejected before the network is
/// reported as broken (one bad frame can be a freak input; ten in a row is the model).
const BROKEN_NETWORK_FRAMES: u32 = 10;

/// How the engine keeps the calibration (deard's `[pipeline] calibration`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CalibrationPolicy {
    /// The paper's chain on every frame: rough flow, least squares, direct fit, fusion.
    EveryFrame,
    /// The online estimator: the rough-flow network every `config.interval_frames` (or when
    /// the alignment residual grows), the filtered estimate aligning the frames between.
    Online {
        /// The estimator's settings (deard exposes `interval_frames` and `track_gain`).
        config: OnlineConfig,
        /// When the measurement of a network frame reaches the estimator.
        schedule: MeasurementSchedule,
    },
}

/// When the measurement of a network frame reaches the online estimator (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeasurementSchedule {
    /// On a worker thread; delivered on the first frame after it is ready (deard's default).
    Background,
    /// Made at once, delivered exactly this many frames after the frame that asked for it
    /// (the evaluation: reproducible).
    Delayed(NonZeroU32),
    /// On the frame that asked for it, which then runs the whole chain (`Full` mode).
    Inline,
}

/// What the engine is made with.
#[derive(Debug, Clone, PartialEq)]
pub struct EngineConfig {
    /// How the calibration is kept.
    pub calibration: CalibrationPolicy,
    /// Names the bundle in logs and frame headers (deard: `tier/variant` of the manifest).
    pub label: String,
}

/// Why the engine cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// The bundle's graphs cannot be prepared for the stream size.
    #[error(transparent)]
    Prepare(#[from] BundleError),
    /// The background measurement's worker thread cannot be started.
    #[error("cannot start the calibration worker thread: {0}")]
    Worker(#[source] std::io::Error),
}

/// `n` for [`MeasurementSchedule::Delayed`]: the frames of a `fps` stream of `width × height`
/// that pass while deard's background worker measures one frame, at least 1 — the
/// measurement's latency times the frame rate, rounded up, since a result reaches the
/// estimator on the first frame after it is ready.
///
/// The latency is interpolated linearly in the pixel count between two measured points (and
/// extrapolated beyond them), each the median of deard's own warm measurements on the 2-core
/// reference machine of RESULTS.md's speed tables, replaying at 30 fps with the defaults
/// (`RUST_LOG=warn,dear_pipeline::engine=debug deard --replay SEQ --pacing timestamps
/// --bundle models/edge`, the `elapsed_ms` of each "background calibration delivered" line):
/// 124 ms on RESULTS.md's 300-frame 320×240 sequence (11 measurements, 110–147 ms; the first,
/// cold, 204 ms) and 360 ms on its 640×480 drifting sequence repeated (`vga_sequence-x50`, 24
/// measurements, 272–485 ms: about 300 when the step is rejected, 430 when it is accepted;
/// the first, cold, 676 ms). The worker runs at the lowest priority beside the frame path, so
/// at 640×480 it takes longer than the same measurement alone on one core (about 250 ms). So
/// 4 frames at 30 fps for 320×240 (2 at 15 fps) and 11 for 640×480; during the warm-up, which
/// asks again on the frame a measurement is delivered, the 320×240 run measured frame 8 and
/// then frame 12.
pub fn typical_delay_frames(width: usize, height: usize, fps: f64) -> NonZeroU32 {
    const SMALL: (f64, f64) = (320.0 * 240.0, 0.124);
    const LARGE: (f64, f64) = (640.0 * 480.0, 0.360);
    let pixels = (width * height) as f64;
    let slope = (LARGE.1 - SMALL.1) / (LARGE.0 - SMALL.0);
    let latency_s = (SMALL.1 + slope * (pixels - SMALL.0)).max(0.0);
    let frames = (latency_s * fps).ceil();
    let frames = if frames.is_finite() {
        frames.clamp(1.0, f64::from(u32::MAX)) as u32
    } else {
        1
    };
    NonZeroU32::new(frames).unwrap_or(NonZeroU32::MIN)
}

/// Where the measurement of a network frame runs when it is off the frame path.
// One per engine, made once: the delayed variant holds a whole chain inline.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
enum OffPath {
    Worker(BackgroundCalibrator<NetworkTicket>),
    Delayed(DelayedCalibrator<NetworkTicket>),
}

impl OffPath {
    fn is_unavailable(&self) -> bool {
        match self {
            OffPath::Worker(w) => w.is_busy() || w.is_stopped(),
            OffPath::Delayed(d) => d.is_busy(),
        }
    }

    fn try_submit(
        &mut self,
        input: ChainInput<'_>,
        ticket: NetworkTicket,
    ) -> Result<Submit, ChainError> {
        match self {
            OffPath::Worker(w) => w.try_submit(input, ticket),
            OffPath::Delayed(d) => d.try_submit(input, ticket),
        }
    }

    /// The calibration in use, that the next submitted measurement must clearly beat.
    fn set_reference(&mut self, reference: Calibration) {
        match self {
            OffPath::Worker(w) => w.set_reference(Some(reference)),
            OffPath::Delayed(d) => d.set_reference(Some(reference)),
        }
    }

    /// A frame begins: the finished measurement, if one is due.
    fn poll(&mut self) -> Option<Delivered<NetworkTicket>> {
        match self {
            OffPath::Worker(w) => w.poll(),
            OffPath::Delayed(d) => d.poll(),
        }
    }
}

/// The refinement network's output as the chain's output guard judged it, over the stream.
#[derive(Debug, Default)]
struct NetworkHealth {
    /// Frames published with the classical filter because the network's output was rejected.
    rejected_total: u64,
    /// Rejected frames in a row, up to the current one.
    consecutive: u32,
}

impl NetworkHealth {
    /// Logs the first rejection of a run of them, the point where the run says the network is
    /// broken, and the recovery; every frame is counted.
    fn record(&mut self, frame: u64, bundle: &str, rejected: Option<&RefinementCheck>) {
        match rejected {
            Some(check) => {
                self.rejected_total += 1;
                self.consecutive += 1;
                if self.consecutive == 1 {
                    tracing::warn!(
                        frame,
                        bundle,
                        "refinement network output rejected ({check}); the frame is published \
                         refined by the classical filter"
                    );
                } else if self.consecutive == BROKEN_NETWORK_FRAMES {
                    tracing::error!(
                        frame,
                        bundle,
                        rejected_total = self.rejected_total,
                        "the refinement network's output was implausible on {BROKEN_NETWORK_FRAMES} \
                         frames in a row ({check}): the bundle looks broken; frames are refined \
                         by the classical filter until its output is plausible again"
                    );
                }
            }
            None if self.consecutive > 0 => {
                tracing::info!(
                    frame,
                    bundle,
                    after_frames = self.consecutive,
                    "refinement network output plausible again"
                );
                self.consecutive = 0;
            }
            None => {}
        }
    }
}

/// What one frame did, and what its header publishes about the calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameReport {
    /// The chain's report (flags, stage timings, the inline measurement, the edge check).
    pub chain: ChainReport,
    /// Whether this frame's planes went to the rough-flow network: on the frame (`Full`), or
    /// handed to the off-path measurement.
    pub measured: bool,
    /// An off-path measurement handed to the estimator at this frame's start (`Err`: its fit
    /// failed); `None` when none was delivered, or the network failed on its frame.
    pub delivered: Option<Result<Measurement, LsqError>>,
    /// The calibration to publish: online, the estimate after this frame's update (before any
    /// estimate, what aligned the frame); every frame, this frame's fit; else the static one.
    pub calibration: Calibration,
    /// Whether the calibration comes from the online estimator.
    pub online: bool,
    /// Online, [`OnlineCalibrator::quality`]; every frame, the fit's
    /// [`Measurement::fit_quality`] (0 if it failed).
    pub quality: f32,
    /// The calibration's health (docs/calibration-health.md).
    pub health: CalibrationHealth,
    /// How many of `(t_x, t_y, c_x, c_y)` are known well (bit field of the header's
    /// `calib_constrained`).
    pub constrained: u8,
    /// Frames since the last accepted estimate (online; `None` before any), 0 every frame.
    pub age_frames: Option<u64>,
    /// The inlier RMS of this frame's flow fit, inline or delivered (`None`: no fit, a failed
    /// one, or a direct fit, which has no end-point residual).
    pub residual_px: Option<f32>,
}

impl FrameReport {
    /// Whether a measurement of the calibration ran on this frame or reached the estimator on
    /// it (the header's `CALIBRATION_ESTIMATED`).
    pub fn calibration_estimated(&self) -> bool {
        self.chain.ran_flow_network || self.delivered.is_some()
    }
}

/// The per-frame engine with a model bundle (see the module docs).
#[derive(Debug)]
pub struct FrameEngine {
    chain: DearChain,
    online: Option<OnlineCalibrator>,
    /// Online mode with an off-path measurement.
    off_path: Option<OffPath>,
    /// The static calibration: the estimator's prior and the fallback before its estimate.
    static_calibration: Calibration,
    label: String,
    health: NetworkHealth,
}

impl FrameEngine {
    /// The engine of `bundle` for `width × height` frames whose static (factory) calibration
    /// is `static_calibration`.
    ///
    /// # Errors
    /// [`EngineError::Prepare`] when a graph cannot be prepared for the size,
    /// [`EngineError::Worker`] when the background worker cannot be started.
    pub fn new(
        bundle: &ModelBundle,
        width: usize,
        height: usize,
        static_calibration: Calibration,
        config: EngineConfig,
    ) -> Result<Self, EngineError> {
        let mut chain = DearChain::new(bundle, width, height)?;
        let (online, off_path) = match config.calibration {
            CalibrationPolicy::EveryFrame => (None, None),
            CalibrationPolicy::Online { config, schedule } => {
                // The static calibration is the prior: measurements move it only along the
                // directions their frames constrain (issue 32).
                let online = OnlineCalibrator::with_prior(config, static_calibration);
                // The measurement's own chain: its buffers and tract states are its own.
                let off_path = match schedule {
                    MeasurementSchedule::Inline => None,
                    MeasurementSchedule::Background => Some(OffPath::Worker(
                        BackgroundCalibrator::spawn(
                            DearChain::new(bundle, width, height)?,
                            WORKER_THREAD_NAME,
                        )
                        .map_err(EngineError::Worker)?,
                    )),
                    MeasurementSchedule::Delayed(frames) => Some(OffPath::Delayed(
                        DelayedCalibrator::new(DearChain::new(bundle, width, height)?, frames),
                    )),
                };
                (Some(online), off_path)
            }
        };
        // Every frame measured (no estimator): the factory calibration is the one in use.
        if online.is_none() {
            chain.set_reference(Some(static_calibration));
        }
        Ok(FrameEngine {
            chain,
            online,
            off_path,
            static_calibration,
            label: config.label,
            health: NetworkHealth::default(),
        })
    }

    /// The label given at construction.
    pub fn label(&self) -> &str {
        &self.label
    }

    /// Runs the frame path once on a synthetic frame (a slanted wall under an RGB and an
    /// amplitude gradient), aligned with the static calibration, and discards the result,
    /// so that the first camera frame does not pay the first-use costs: tract's and the
    /// filters' buffers, the geometry's scratch, their pages. In deard at 640×480 the first
    /// frame took about 190 ms more than the next ones, six periods of a 30 fps camera, and
    /// the queue dropped frames at start. The estimator, the measurement and the network
    /// health are not touched, so what the engine does with real frames is the same, bit for
    /// bit (`pipeline/tests/engine.rs`).
    ///
    /// # Errors
    /// As [`DearChain::process`].
    pub fn warm_up(&mut self) -> Result<(), ChainError> {
        let (h, w) = self.chain.dim();
        let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, c)| {
            ((x * 3 + y * 5 + c * 40) % 256) as u8
        });
        let amplitude =
            Array2::from_shape_fn((h, w), |(y, x)| 200.0 + ((x * 7 + y * 11) % 800) as f32);
        let depth =
            Array2::from_shape_fn((h, w), |(y, x)| 1.5 + 0.002 * x as f32 + 0.001 * y as f32);
        let mut refined = Array2::zeros((h, w));
        let mut confidence = Array2::zeros((h, w));
        let input = ChainInput {
            rgb: rgb.view(),
            amplitude: amplitude.view(),
            depth: depth.view(),
        };
        let output = ChainOutput {
            depth: refined.view_mut(),
            confidence: confidence.view_mut(),
        };
        self.chain
            .process(input, ChainMode::Cached(self.static_calibration), output)
            .map(|_| ())
    }

    /// The chain (its intermediate images describe the last frame prepared).
    pub fn chain(&self) -> &DearChain {
        &self.chain
    }

    /// The online estimator (online mode).
    pub fn online(&self) -> Option<&OnlineCalibrator> {
        self.online.as_ref()
    }

    /// The static calibration.
    pub fn static_calibration(&self) -> Calibration {
        self.static_calibration
    }

    /// Frames whose network refinement the output guard rejected since start (published with
    /// the classical filter).
    pub fn network_output_rejected(&self) -> u64 {
        self.health.rejected_total
    }

    /// Whether frames are processed in two halves ([`prepare`](Self::prepare),
    /// [`finish`](Self::finish)) that consecutive frames can overlap: online mode with the
    /// measurement off the frame path, so that every frame is aligned by a calibration and
    /// runs no network before its refinement.
    pub fn overlaps_frames(&self) -> bool {
        self.online.is_some() && self.off_path.is_some()
    }

    /// The first half of a frame (alignment, warps, a hybrid refiner's classical stage),
    /// aligned with the online estimate as it is now, when the engine [overlaps
    /// frames](Self::overlaps_frames); `None` otherwise ([`process`](Self::process) the frame
    /// whole).
    ///
    /// # Errors
    /// As [`DearChain::prepare`].
    pub fn prepare(&mut self, input: ChainInput<'_>) -> Result<Option<Prepared>, ChainError> {
        if !self.overlaps_frames() {
            return Ok(None);
        }
        let calibration = self.current_calibration();
        self.chain
            .prepare(input, ChainMode::Cached(calibration))
            .map(Some)
    }

    /// The estimate, or the static calibration before the first.
    fn current_calibration(&self) -> Calibration {
        self.online
            .as_ref()
            .and_then(OnlineCalibrator::estimate)
            .unwrap_or(self.static_calibration)
    }

    /// The second half of the frame `prepared` describes (its planes `input`, its number
    /// `index` for the log) into `output`; when `next` is given, that frame's first half
    /// beside it, returned. A measurement that became ready is handed to the estimator first,
    /// and this frame is submitted for measurement when the estimator asks for the network.
    /// `next` is aligned with the estimate as it is before this frame ends: the estimator
    /// tracks one frame late, and is told so.
    ///
    /// # Panics
    /// When the engine does not [overlap frames](Self::overlaps_frames) (no [`Prepared`] comes
    /// from it then), or `prepared` is not the latest frame prepared.
    pub fn finish(
        &mut self,
        index: u64,
        prepared: Prepared,
        input: ChainInput<'_>,
        output: ChainOutput<'_>,
        next: Option<ChainInput<'_>>,
    ) -> (
        Result<FrameReport, ChainError>,
        Option<Result<Prepared, ChainError>>,
    ) {
        let (Some(online), Some(off_path)) = (self.online.as_mut(), self.off_path.as_mut()) else {
            panic!("FrameEngine::finish: only an engine that overlaps frames prepares them");
        };
        let delivered = deliver(off_path, online);
        let decision = online.begin_frame();
        let measured = decision.run_network.is_some()
            && submit(off_path, online, input, self.static_calibration);
        let aligned_with = prepared.calibration();
        let next_calibration = online.estimate().unwrap_or(self.static_calibration);
        let (finished, next_prepared) = match next {
            Some(next) => {
                let (finished, next_prepared) = self.chain.finish_and_prepare(
                    prepared,
                    input.rgb,
                    output,
                    next,
                    ChainMode::Cached(next_calibration),
                );
                (finished, Some(next_prepared))
            }
            None => (self.chain.finish(prepared, input.rgb, output), None),
        };
        let report =
            finished.map(|report| self.end_frame(index, report, measured, delivered, aligned_with));
        (report, next_prepared)
    }

    /// One frame whole (its planes `input`, its number `index` for the log) into `output`:
    /// the chain mode the calibration policy asks for, a delivered measurement handed to the
    /// estimator first (an off-path measurement submitted when the estimator asks for one).
    ///
    /// # Errors
    /// As [`DearChain::process`].
    pub fn process(
        &mut self,
        index: u64,
        input: ChainInput<'_>,
        output: ChainOutput<'_>,
    ) -> Result<FrameReport, ChainError> {
        // A measurement that finished since the last frame goes to the estimator before this
        // frame's decision, so this frame already uses it.
        let delivered = match (self.off_path.as_mut(), self.online.as_mut()) {
            (Some(off_path), Some(online)) => deliver(off_path, online),
            _ => None,
        };
        let mut measured = false;
        let mode = match (self.online.as_mut(), self.off_path.as_mut()) {
            (None, _) => ChainMode::Full,
            (Some(online), None) => {
                // The measurement must clearly beat the estimate in use to move it.
                let reference = online.estimate().unwrap_or(self.static_calibration);
                self.chain.set_reference(Some(reference));
                online.begin_frame().chain_mode()
            }
            (Some(online), Some(off_path)) => {
                let decision = online.begin_frame();
                if decision.run_network.is_some() {
                    measured = submit(off_path, online, input, self.static_calibration);
                }
                // Before the first estimate: the static calibration.
                ChainMode::Cached(decision.calibration.unwrap_or(self.static_calibration))
            }
        };
        let report = self.chain.process(input, mode, output)?;
        let measured = measured || report.ran_flow_network;
        Ok(self.end_frame(index, report, measured, delivered, None))
    }

    /// Ends frame `index` in the estimator and the output guard's record and says what its
    /// header publishes; `delivered` is a measurement handed over before it, `aligned_with`
    /// the calibration that aligned it when that was not the estimate at the frame's start
    /// (overlapped frames).
    fn end_frame(
        &mut self,
        index: u64,
        chain: ChainReport,
        measured: bool,
        delivered: Option<Result<Measurement, LsqError>>,
        aligned_with: Option<Calibration>,
    ) -> FrameReport {
        // This frame's measurement: inline, or delivered off the frame path.
        let fit = chain
            .measurement
            .as_ref()
            .or(delivered.as_ref())
            .and_then(|m| m.as_ref().ok())
            .copied();
        self.health
            .record(index, &self.label, chain.rejected_refinement.as_ref());
        let residual_px = fit.and_then(|m| m.residual_px());
        match self.online.as_mut() {
            Some(online) => {
                online.end_frame_aligned_with(
                    chain.measurement.clone(),
                    chain.alignment,
                    aligned_with,
                );
                // Until the first estimate is established, publish what aligned this frame.
                let calibration = online
                    .estimate()
                    .or(chain.calibration)
                    .unwrap_or(self.static_calibration);
                let health = online.health();
                FrameReport {
                    calibration,
                    online: true,
                    quality: online.quality(),
                    health: health.state,
                    constrained: health.constrained,
                    age_frames: online.frames_since_estimate(),
                    residual_px,
                    measured,
                    delivered,
                    chain,
                }
            }
            None => {
                // Every frame is fitted on its own: good when its frame constrains every
                // direction, can improve when it does not (some of the published calibration
                // is then the fit's starting point, not a measurement).
                let observability = fit.map(|m| {
                    m.observability(OnlineConfig::default().max_direction_std_px)
                        .constrained
                });
                FrameReport {
                    calibration: chain.calibration.unwrap_or(self.static_calibration),
                    online: false,
                    quality: fit.map_or(0.0, |m| m.fit_quality()),
                    health: match observability {
                        None => CalibrationHealth::Unknown,
                        Some(4) => CalibrationHealth::Good,
                        Some(_) => CalibrationHealth::CanImprove,
                    },
                    constrained: observability.unwrap_or(0),
                    age_frames: Some(0),
                    residual_px,
                    measured,
                    delivered,
                    chain,
                }
            }
        }
    }
}

/// A frame on which the online estimator asks for the network, with the measurement off the
/// frame path: hands the frame over (`true`), or tells the estimator the measurement is busy.
fn submit(
    off_path: &mut OffPath,
    online: &mut OnlineCalibrator,
    input: ChainInput<'_>,
    static_calibration: Calibration,
) -> bool {
    if off_path.is_unavailable() {
        online.network_busy();
        return false;
    }
    // The measurement must clearly beat the estimate in use to move it.
    off_path.set_reference(online.estimate().unwrap_or(static_calibration));
    let ticket = online.defer_network();
    // A frame of the wrong shape fails the chain too.
    match off_path.try_submit(input, ticket) {
        Ok(Submit::Started) => true,
        Ok(Submit::Stopped) => {
            tracing::error!(
                "the calibration worker stopped; the calibration is now tracked from the edges only"
            );
            false
        }
        Ok(Submit::Busy) | Err(_) => false,
    }
}

/// A frame begins: hands a finished off-path measurement, if any, to the estimator; returns it
/// (or `None` when none finished, or the network failed on its frame, which is logged and
/// counted as a rejected attempt).
fn deliver(
    off_path: &mut OffPath,
    online: &mut OnlineCalibrator,
) -> Option<Result<Measurement, LsqError>> {
    let delivered = off_path.poll()?;
    match delivered.report {
        Ok(MeasureReport { measurement, .. }) => {
            let outcome = online.deliver(delivered.ticket, measurement.clone());
            tracing::debug!(
                frame = delivered.ticket.frame,
                elapsed_ms = delivered.elapsed.as_secs_f64() * 1e3,
                ?outcome,
                "background calibration delivered"
            );
            Some(measurement)
        }
        Err(e) => {
            tracing::warn!(frame = delivered.ticket.frame, error = %e, "background calibration failed");
            online.deliver_failure();
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_typical_delay_is_the_measurement_latency_in_frames_rounded_up() {
        let frames = |w, h, fps| typical_delay_frames(w, h, fps).get();
        // 124 ms and 360 ms (the module's reference points) at 30 and 15 fps.
        assert_eq!(frames(320, 240, 30.0), 4);
        assert_eq!(frames(320, 240, 15.0), 2);
        assert_eq!(frames(640, 480, 30.0), 11);
        // In between, linear in the pixel count: 202.7 ms, 8.11 frames at 40 fps.
        assert_eq!(frames(480, 320, 40.0), 9);
        // At least one frame: a result cannot reach the frame that asked for it.
        assert_eq!(frames(16, 16, 1.0), 1);
        assert_eq!(frames(320, 240, f64::NAN), 1);
        assert_eq!(frames(320, 240, 0.0), 1);
    }
}
