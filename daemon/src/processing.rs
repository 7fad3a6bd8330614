//! What the daemon does to each frame, writing straight into the output planes it is given
//! (the loaned shared-memory sample).
//!
//! Two engines:
//! - **DEAR** (a model bundle is configured): the paper's chain from `dear_pipeline::dear`
//!   (rough flow → calibration → fusion → warp → ToF-KPN), with the calibration kept up to date
//!   online (`dear_pipeline::online`): the rough-flow network runs every N frames or when the
//!   alignment residual grows, and the filtered estimate aligns the frames in between;
//! - **static** (no bundle): align with the static calibration, then the classical edge-aware
//!   filter (`dear_pipeline::filter`).

use std::borrow::Borrow;
use std::time::{Duration, Instant};

use dear_capture::{Calibration, RgbdFrame};
use dear_pipeline::align::StaticAligner;
use dear_pipeline::dear::{
    BackgroundCalibrator, ChainError, ChainInput, ChainMode, ChainOutput, ChainReport, DearChain,
    Prepared, RefinementCheck, Submit,
};
use dear_pipeline::filter::ClassicalRefiner;
use dear_pipeline::geometry::LsqError;
use dear_pipeline::model::{BundleError, ModelBundle};
use dear_pipeline::online::{Measurement, NetworkTicket, OnlineCalibrator, OnlineConfig};
use dear_proto::{flags, CalibrationHealth, FrameHeader, Stage};
use ndarray::{Array2, ArrayViewMut2, ArrayViewMut3};

use crate::config::{CalibrationMode, NetworkPlacement, PipelineConfig, RefineMode};

/// Why the configured engine cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// The bundle does not load or verify.
    #[error("cannot load the model bundle {}: {source} (set [pipeline] bundle / --bundle, or run without networks: --refine classical)", dir.display())]
    Load {
        dir: std::path::PathBuf,
        #[source]
        source: BundleError,
    },
    /// The bundle's graphs cannot be prepared for the stream size.
    #[error("cannot prepare the model bundle {} for {width}x{height}: {source}", dir.display())]
    Prepare {
        dir: std::path::PathBuf,
        width: u32,
        height: u32,
        #[source]
        source: BundleError,
    },
    /// The background calibration worker cannot be started.
    #[error("cannot start the calibration worker thread: {0}")]
    Worker(#[source] std::io::Error),
}

/// Why one frame could not be processed (the daemon skips and counts it).
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// The frame's planes do not have the stream's size.
    #[error("frame {frame} is {width}x{height} (rgb {rgb:?}, amplitude {amplitude:?}), the stream is {stream_width}x{stream_height}")]
    Size {
        frame: u64,
        width: usize,
        height: usize,
        rgb: (usize, usize, usize),
        amplitude: (usize, usize),
        stream_width: usize,
        stream_height: usize,
    },
    /// The DEAR chain failed on the frame (a network error).
    #[error("frame {frame}: {source}")]
    Chain {
        frame: u64,
        #[source]
        source: ChainError,
    },
}

/// The output planes of one frame (views over the shared-memory payload).
pub struct FrameOutput<'a> {
    /// `(H, W)` metres, 0 = invalid.
    pub depth: ArrayViewMut2<'a, f32>,
    /// `(H, W, 3)`.
    pub rgb: ArrayViewMut3<'a, u8>,
    /// `(H, W)`, 0 = invalid … 255 = measured and kept.
    pub confidence: ArrayViewMut2<'a, u8>,
}

// The DEAR chain is boxed already; the static engine is the small common case.
#[allow(clippy::large_enum_variant)]
enum Engine {
    Static {
        aligner: StaticAligner,
        aligned: Array2<f32>,
        refiner: Option<ClassicalRefiner>,
    },
    Dear {
        chain: Box<DearChain>,
        online: Option<OnlineCalibrator>,
        /// Online mode with `online_network = "background"`: the network frames' worker.
        background: Option<BackgroundCalibrator<NetworkTicket>>,
        bundle_name: String,
        health: NetworkHealth,
    },
}

/// Consecutive frames whose refinement the output guard rejected before the network is
/// reported as broken (one bad frame can be a freak input; ten in a row is the model).
const BROKEN_NETWORK_FRAMES: u32 = 10;

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

/// Per-stream processing state (scratch buffers sized for the stream).
pub struct Processor {
    width: usize,
    height: usize,
    /// The static calibration (and the DEAR engine's fallback before its first estimate).
    calibration: Calibration,
    engine: Engine,
}

impl Processor {
    /// The static engine for `width`×`height` frames aligned with `calibration`, refined with
    /// the classical filter or not at all.
    fn new_static(
        width: u32,
        height: u32,
        calibration: Calibration,
        classical_filter: bool,
    ) -> Self {
        let (w, h) = (width as usize, height as usize);
        Processor {
            width: w,
            height: h,
            calibration,
            engine: Engine::Static {
                aligner: StaticAligner::new(h, w),
                aligned: Array2::zeros((h, w)),
                refiner: classical_filter.then(ClassicalRefiner::default),
            },
        }
    }

    /// The engine the configuration asks for. Loading a bundle verifies it (checksums, graph
    /// inputs) and optimises its graphs for the stream size; any problem is a start-up error.
    pub fn from_config(
        width: u32,
        height: u32,
        calibration: Calibration,
        config: &PipelineConfig,
    ) -> Result<Self, EngineError> {
        match config.refine {
            RefineMode::Classical => return Ok(Self::new_static(width, height, calibration, true)),
            RefineMode::None => return Ok(Self::new_static(width, height, calibration, false)),
            RefineMode::Dear => {}
        }
        let dir = &config.bundle;
        let bundle = ModelBundle::load(dir).map_err(|source| EngineError::Load {
            dir: dir.clone(),
            source,
        })?;
        let prepare = || {
            DearChain::new(&bundle, width as usize, height as usize).map_err(|source| {
                EngineError::Prepare {
                    dir: dir.clone(),
                    width,
                    height,
                    source,
                }
            })
        };
        let chain = prepare()?;
        let online = match config.calibration {
            // The static calibration is the prior: measurements move it only along the
            // directions their frames constrain (issue 32).
            CalibrationMode::Online => Some(OnlineCalibrator::with_prior(
                OnlineConfig {
                    interval_frames: config.online_interval_frames,
                    track_gain: config.online_track_gain,
                    ..OnlineConfig::default()
                },
                calibration,
            )),
            CalibrationMode::EveryFrame => None,
        };
        let background = match (&online, config.online_network) {
            (Some(_), NetworkPlacement::Background) => {
                // The worker's own chain: its buffers and tract states are its own.
                let worker = BackgroundCalibrator::spawn(prepare()?, "deard-calibrate")
                    .map_err(EngineError::Worker)?;
                Some(worker)
            }
            _ => None,
        };
        let manifest = bundle.manifest();
        let bundle_name = format!("{}/{}", manifest.tier, manifest.variant);
        Ok(Processor {
            width: width as usize,
            height: height as usize,
            calibration,
            engine: Engine::Dear {
                chain: Box::new(chain),
                online,
                background,
                bundle_name,
                health: NetworkHealth::default(),
            },
        })
    }

    /// Frames whose network refinement the output guard rejected since start (published with
    /// the classical filter, flagged `NETWORK_OUTPUT_REJECTED`); 0 without networks.
    pub fn network_output_rejected(&self) -> u64 {
        match &self.engine {
            Engine::Dear { health, .. } => health.rejected_total,
            Engine::Static { .. } => 0,
        }
    }

    /// The static calibration.
    pub fn calibration(&self) -> Calibration {
        self.calibration
    }

    /// Whether consecutive frames overlap in [`finish_into`](Self::finish_into): the DEAR
    /// engine with online calibration whose network frames run on the background worker, so
    /// that every frame on the frame path is aligned by a calibration and runs no network
    /// before its refinement.
    pub fn overlaps_frames(&self) -> bool {
        matches!(
            &self.engine,
            Engine::Dear {
                online: Some(_),
                background: Some(_),
                ..
            }
        )
    }

    /// A frame of the wrong size is an error (the caller skips and counts it).
    fn check_size(&self, frame: &RgbdFrame) -> Result<(), ProcessError> {
        let (h, w) = frame.dim();
        if (h, w) != (self.height, self.width)
            || frame.rgb.dim() != (h, w, 3)
            || frame.amplitude.dim() != (h, w)
        {
            return Err(ProcessError::Size {
                frame: frame.index,
                width: w,
                height: h,
                rgb: frame.rgb.dim(),
                amplitude: frame.amplitude.dim(),
                stream_width: self.width,
                stream_height: self.height,
            });
        }
        Ok(())
    }

    /// The first half of `frame` (alignment, warps, the classical stage) when the engine
    /// [overlaps frames](Self::overlaps_frames), aligned with the online estimate as it is now;
    /// otherwise the frame is only held, and [`finish_into`](Self::finish_into) processes it
    /// whole as [`process_into`](Self::process_into) does.
    ///
    /// # Errors
    /// As [`process_into`](Self::process_into): the frame is skipped.
    pub fn prepare<F: Borrow<RgbdFrame>>(
        &mut self,
        frame: F,
    ) -> Result<PreparedFrame<F>, ProcessError> {
        self.check_size(frame.borrow())?;
        let prepared = match &mut self.engine {
            Engine::Dear {
                chain,
                online: Some(online),
                background: Some(_),
                ..
            } => {
                let calibration = online.estimate().unwrap_or(self.calibration);
                let f = frame.borrow();
                let prepared = chain
                    .prepare(chain_input(f), ChainMode::Cached(calibration))
                    .map_err(|source| ProcessError::Chain {
                        frame: f.index,
                        source,
                    })?;
                Some(prepared)
            }
            _ => None,
        };
        Ok(PreparedFrame { frame, prepared })
    }

    /// Processes `pending` into `out` and fills `header` as [`process_into`](Self::process_into)
    /// does; when `next` is given, prepares it meanwhile (on the other core, while this frame's
    /// refine graph runs on one) and returns it. `next` is aligned with the estimate as it is
    /// before `pending` ends: the online estimator tracks one frame late, and is told so.
    ///
    /// # Errors
    /// As [`process_into`](Self::process_into), for each of the two frames.
    pub fn finish_into<F: Borrow<RgbdFrame>>(
        &mut self,
        pending: PreparedFrame<F>,
        next: Option<F>,
        header: &mut FrameHeader,
        mut out: FrameOutput<'_>,
    ) -> Finished<F> {
        let PreparedFrame { frame, prepared } = pending;
        let frame = frame.borrow();
        let Some(prepared) = prepared else {
            let result = self.process_into(frame, header, out);
            return Finished {
                result,
                next: next.map(|n| self.prepare(n)),
            };
        };
        // A next frame of the wrong size is refused here; the held frame is finished alone.
        let next = next.map(|n| self.check_size(n.borrow()).map(|()| n));
        out.rgb.assign(&frame.rgb);
        let Engine::Dear {
            chain,
            online: Some(online),
            background: Some(worker),
            bundle_name,
            health,
        } = &mut self.engine
        else {
            unreachable!("only an overlapping engine prepares frames");
        };
        let input = chain_input(frame);
        let delivered = deliver_background(worker, online);
        let decision = online.begin_frame();
        if decision.run_network.is_some() {
            submit_network(worker, online, input);
        }
        let aligned_with = prepared.calibration();
        let output = ChainOutput {
            depth: out.depth.view_mut(),
            confidence: out.confidence.view_mut(),
        };
        let next_calibration = online.estimate().unwrap_or(self.calibration);
        let (finished, next_prepared) = match next {
            Some(Ok(n)) => {
                let (finished, next_prepared) = chain.finish_and_prepare(
                    prepared,
                    input.rgb,
                    output,
                    chain_input(n.borrow()),
                    ChainMode::Cached(next_calibration),
                );
                let index = n.borrow().index;
                let next_prepared = next_prepared
                    .map(|p| PreparedFrame {
                        frame: n,
                        prepared: Some(p),
                    })
                    .map_err(|source| ProcessError::Chain {
                        frame: index,
                        source,
                    });
                (finished, Some(next_prepared))
            }
            Some(Err(e)) => (chain.finish(prepared, input.rgb, output), Some(Err(e))),
            None => (chain.finish(prepared, input.rgb, output), None),
        };
        let result = finished
            .map(|report| {
                let mut publish = Publish {
                    online: Some(online),
                    health,
                    bundle_name,
                    static_calibration: self.calibration,
                };
                publish.report(frame.index, &report, delivered, aligned_with, header);
            })
            .map_err(|source| ProcessError::Chain {
                frame: frame.index,
                source,
            });
        Finished {
            result,
            next: next_prepared,
        }
    }

    /// Processes `frame` into `out` and fills the header's calibration, flags and stage
    /// latencies. A frame of the wrong size is an error (the caller skips and counts it).
    pub fn process_into(
        &mut self,
        frame: &RgbdFrame,
        header: &mut FrameHeader,
        mut out: FrameOutput<'_>,
    ) -> Result<(), ProcessError> {
        self.check_size(frame)?;
        out.rgb.assign(&frame.rgb);
        match &mut self.engine {
            Engine::Static {
                aligner,
                aligned,
                refiner,
            } => {
                set_calibration(header, self.calibration);
                header.calib_residual_px = f32::NAN;
                header.calib_quality = 0.0;
                header.calib_age_frames = 0;
                header.calib_health = CalibrationHealth::Unknown.code();
                header.calib_constrained = 0;
                header.flags = flags::ALIGNED;
                let t = Instant::now();
                match refiner {
                    Some(refiner) => {
                        aligner.align_into(
                            frame.depth.view(),
                            &self.calibration,
                            aligned.view_mut(),
                        );
                        header.stage_latency_us[Stage::Warp as usize] = micros(t);
                        let t = Instant::now();
                        refiner.refine_into(
                            aligned.view(),
                            frame.rgb.view(),
                            out.depth.view_mut(),
                            out.confidence.view_mut(),
                        );
                        header.stage_latency_us[Stage::Refine as usize] = micros(t);
                        header.flags |= flags::REFINED_CLASSICAL;
                    }
                    None => {
                        aligner.align_into(
                            frame.depth.view(),
                            &self.calibration,
                            out.depth.view_mut(),
                        );
                        out.confidence
                            .zip_mut_with(&out.depth, |c, &z| *c = if z > 0.0 { 255 } else { 0 });
                        header.stage_latency_us[Stage::Warp as usize] = micros(t);
                    }
                }
            }
            Engine::Dear {
                chain,
                online,
                background,
                bundle_name,
                health,
            } => {
                let input = chain_input(frame);
                // A background measurement that finished since the last frame goes to the
                // estimator before this frame's decision, so this frame already uses it.
                let delivered = match (background.as_mut(), online.as_mut()) {
                    (Some(worker), Some(online)) => deliver_background(worker, online),
                    _ => None,
                };
                let mode = match (online.as_mut(), background.as_mut()) {
                    (None, _) => ChainMode::Full,
                    (Some(online), None) => online.begin_frame().chain_mode(),
                    (Some(online), Some(worker)) => {
                        let decision = online.begin_frame();
                        if decision.run_network.is_some() {
                            submit_network(worker, online, input);
                        }
                        // Before the first estimate: the static calibration.
                        ChainMode::Cached(decision.calibration.unwrap_or(self.calibration))
                    }
                };
                let output = ChainOutput {
                    depth: out.depth.view_mut(),
                    confidence: out.confidence.view_mut(),
                };
                let report =
                    chain
                        .process(input, mode, output)
                        .map_err(|source| ProcessError::Chain {
                            frame: frame.index,
                            source,
                        })?;
                let mut publish = Publish {
                    online: online.as_mut(),
                    health,
                    bundle_name,
                    static_calibration: self.calibration,
                };
                publish.report(frame.index, &report, delivered, None, header);
            }
        }
        Ok(())
    }
}

/// A frame held between [`Processor::prepare`] and [`Processor::finish_into`].
pub struct PreparedFrame<F> {
    frame: F,
    /// The chain's first half, when the engine overlaps frames.
    prepared: Option<Prepared>,
}

impl<F: Borrow<RgbdFrame>> PreparedFrame<F> {
    /// The frame.
    pub fn frame(&self) -> &RgbdFrame {
        self.frame.borrow()
    }
}

/// What [`Processor::finish_into`] did.
pub struct Finished<F> {
    /// The finished frame's outcome (on `Err` it was not published: skip and count it).
    pub result: Result<(), ProcessError>,
    /// The next frame, prepared (or why it cannot be: skip and count it), when one was given.
    pub next: Option<Result<PreparedFrame<F>, ProcessError>>,
}

/// A frame's planes as the chain takes them.
fn chain_input(frame: &RgbdFrame) -> ChainInput<'_> {
    ChainInput {
        rgb: frame.rgb.view(),
        amplitude: frame.amplitude.view(),
        depth: frame.depth.view(),
    }
}

/// A frame on which the online estimator asks for the network, with the network on the
/// background worker: hands the frame over, or tells the estimator the worker is busy.
fn submit_network(
    worker: &mut BackgroundCalibrator<NetworkTicket>,
    online: &mut OnlineCalibrator,
    input: ChainInput<'_>,
) {
    if worker.is_busy() || worker.is_stopped() {
        online.network_busy();
        return;
    }
    let ticket = online.defer_network();
    // A frame of the wrong shape fails the chain too.
    if let Ok(Submit::Stopped) = worker.try_submit(input, ticket) {
        tracing::error!(
            "the calibration worker stopped; the calibration is now tracked from the edges only"
        );
    }
}

/// What a DEAR frame's report does to the header, the network's health and the estimator.
struct Publish<'a> {
    online: Option<&'a mut OnlineCalibrator>,
    health: &'a mut NetworkHealth,
    bundle_name: &'a str,
    static_calibration: Calibration,
}

impl Publish<'_> {
    /// Fills `header` from the chain's `report` of frame `index` and ends the frame in the
    /// estimator; `delivered` is a background measurement handed over before it, and
    /// `aligned_with` the calibration that aligned it when that was not the estimate at the
    /// frame's start (overlapped frames).
    fn report(
        &mut self,
        index: u64,
        report: &ChainReport,
        delivered: Option<Result<Measurement, LsqError>>,
        aligned_with: Option<Calibration>,
        header: &mut FrameHeader,
    ) {
        // This frame's network measurement: inline, or delivered by the worker.
        let network_measurement = report.measurement.as_ref().or(delivered.as_ref());
        let fit = network_measurement.and_then(|m| m.as_ref().ok()).copied();
        header.flags = match &report.rejected_refinement {
            None => flags::ALIGNED | flags::REFINED_NETWORK,
            Some(_) => flags::ALIGNED | flags::REFINED_CLASSICAL | flags::NETWORK_OUTPUT_REJECTED,
        };
        if report.confidence_is_expected_error {
            header.flags |= flags::CONFIDENCE_EXPECTED_ERROR;
        }
        self.health
            .record(index, self.bundle_name, report.rejected_refinement.as_ref());
        if report.ran_flow_network || delivered.is_some() {
            header.flags |= flags::CALIBRATION_ESTIMATED;
        }
        header.set_bundle_name(self.bundle_name);
        match self.online.as_mut() {
            Some(online) => {
                online.end_frame_aligned_with(
                    report.measurement.clone(),
                    report.alignment,
                    aligned_with,
                );
                header.flags |= flags::CALIBRATION_ONLINE;
                // Until the first estimate is established, publish what aligned this frame.
                let calibration = online
                    .estimate()
                    .or(report.calibration)
                    .unwrap_or(self.static_calibration);
                set_calibration(header, calibration);
                header.calib_quality = online.quality();
                let health = online.health();
                header.calib_health = health.state.code();
                header.calib_constrained = health.constrained;
                header.calib_age_frames = online
                    .frames_since_estimate()
                    .map_or(u32::MAX, |f| f.min(u32::MAX as u64) as u32);
            }
            None => {
                set_calibration(
                    header,
                    report.calibration.unwrap_or(self.static_calibration),
                );
                header.calib_quality = fit.map_or(0.0, |m| m.fit_quality());
                header.calib_age_frames = 0;
                // Every frame is fitted on its own: good when its frame constrains every
                // direction, can improve when it does not (some of the published calibration
                // is then the fit's starting point, not a measurement).
                let observability = fit.map(|m| {
                    m.observability(OnlineConfig::default().max_direction_std_px)
                        .constrained
                });
                header.calib_constrained = observability.unwrap_or(0);
                header.calib_health = match observability {
                    None => CalibrationHealth::Unknown,
                    Some(4) => CalibrationHealth::Good,
                    Some(_) => CalibrationHealth::CanImprove,
                }
                .code();
            }
        }
        header.calib_residual_px = fit.and_then(|m| m.residual_px()).unwrap_or(f32::NAN);
        let t = &report.timings;
        let us = |d: Duration| d.as_micros().min(u32::MAX as u128) as u32;
        header.stage_latency_us[Stage::Preprocess as usize] = us(t.preprocess);
        header.stage_latency_us[Stage::Flow as usize] = us(t.flow + t.calibrate);
        header.stage_latency_us[Stage::Fuse as usize] = us(t.fuse);
        header.stage_latency_us[Stage::Warp as usize] = us(t.warp);
        header.stage_latency_us[Stage::Refine as usize] = us(t.refine);
    }
}

/// Hands a finished background measurement, if any, to the estimator; returns it (or `None`
/// when none finished, or the network failed on its frame, which is logged and counted as a
/// rejected attempt).
fn deliver_background(
    worker: &mut BackgroundCalibrator<NetworkTicket>,
    online: &mut OnlineCalibrator,
) -> Option<Result<Measurement, LsqError>> {
    let delivered = worker.poll()?;
    match delivered.report {
        Ok(report) => {
            let outcome = online.deliver(delivered.ticket, report.measurement.clone());
            tracing::debug!(
                frame = delivered.ticket.frame,
                elapsed_ms = delivered.elapsed.as_secs_f64() * 1e3,
                ?outcome,
                "background calibration delivered"
            );
            Some(report.measurement)
        }
        Err(e) => {
            tracing::warn!(frame = delivered.ticket.frame, error = %e, "background calibration failed");
            online.deliver_failure();
            None
        }
    }
}

fn set_calibration(header: &mut FrameHeader, c: Calibration) {
    header.calib_tx = c.tx;
    header.calib_ty = c.ty;
    header.calib_cx = c.cx;
    header.calib_cy = c.cy;
}

/// Microseconds since `t`, saturating.
pub fn micros(t: Instant) -> u32 {
    t.elapsed().as_micros().min(u32::MAX as u128) as u32
}
