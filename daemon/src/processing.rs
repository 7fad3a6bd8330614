//! What the daemon does to each frame, writing straight into the output planes it is given
//! (the loaned shared-memory sample).
//!
//! Two engines:
//! - **DEAR** (a model bundle is configured): [`dear_pipeline::engine::FrameEngine`], the
//!   library's per-frame engine (the paper's chain, the online estimator with its measurement
//!   on a background worker, overlapped frames, the output guard), which `dear eval --online`
//!   evaluates too; this module converts the `[pipeline]` configuration into its
//!   [`EngineConfig`] and fills the frame header from its [`FrameReport`];
//! - **static** (no bundle): align with the static calibration, then the classical edge-aware
//!   filter (`dear_pipeline::filter`).

use std::borrow::Borrow;
use std::time::{Duration, Instant};

use dear_capture::{Calibration, RgbdFrame};
use dear_pipeline::align::StaticAligner;
use dear_pipeline::chain::{ChainError, ChainInput, ChainOutput, Prepared};
use dear_pipeline::engine::{
    CalibrationPolicy, EngineConfig, FrameEngine, FrameReport, MeasurementSchedule,
};
use dear_pipeline::filter::ClassicalRefiner;
use dear_pipeline::model::{BundleError, ModelBundle};
use dear_pipeline::recalibration::OnlineConfig;
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

// One per stream, made once; the DEAR engine is boxed.
#[allow(clippy::large_enum_variant)]
enum Engine {
    Static {
        aligner: StaticAligner,
        aligned: Array2<f32>,
        refiner: Option<ClassicalRefiner>,
    },
    Dear(Box<FrameEngine>),
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
        let manifest = bundle.manifest();
        let engine = FrameEngine::new(
            &bundle,
            width as usize,
            height as usize,
            calibration,
            engine_config(config, format!("{}/{}", manifest.tier, manifest.variant)),
        )
        .map_err(|e| match e {
            dear_pipeline::engine::EngineError::Prepare(source) => EngineError::Prepare {
                dir: dir.clone(),
                width,
                height,
                source,
            },
            dear_pipeline::engine::EngineError::Worker(e) => EngineError::Worker(e),
        })?;
        Ok(Processor {
            width: width as usize,
            height: height as usize,
            calibration,
            engine: Engine::Dear(Box::new(engine)),
        })
    }

    /// Frames whose network refinement the output guard rejected since start (published with
    /// the classical filter, flagged `NETWORK_OUTPUT_REJECTED`); 0 without networks.
    pub fn network_output_rejected(&self) -> u64 {
        match &self.engine {
            Engine::Dear(engine) => engine.network_output_rejected(),
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
    /// before its refinement ([`FrameEngine::overlaps_frames`]).
    pub fn overlaps_frames(&self) -> bool {
        matches!(&self.engine, Engine::Dear(engine) if engine.overlaps_frames())
    }

    /// Runs the frame path once on a synthetic frame before the first camera frame
    /// ([`FrameEngine::warm_up`]), so that frame is not slowed by first-use costs (about
    /// 190 ms at 640×480 with the edge bundle: the queue dropped frames at start). The static
    /// engines have nothing worth warming. Returns how long it took.
    ///
    /// # Errors
    /// As [`FrameEngine::warm_up`]: the chain failed on the synthetic frame.
    pub fn warm_up(&mut self) -> Result<Duration, ChainError> {
        let start = Instant::now();
        if let Engine::Dear(engine) = &mut self.engine {
            engine.warm_up()?;
        }
        Ok(start.elapsed())
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
            Engine::Dear(engine) => {
                let f = frame.borrow();
                engine
                    .prepare(ChainInput::from(f))
                    .map_err(|source| ProcessError::Chain {
                        frame: f.index,
                        source,
                    })?
            }
            Engine::Static { .. } => None,
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
        let Engine::Dear(engine) = &mut self.engine else {
            unreachable!("only the DEAR engine prepares frames");
        };
        let output = ChainOutput {
            depth: out.depth.view_mut(),
            confidence: out.confidence.view_mut(),
        };
        let next_input = match &next {
            Some(Ok(n)) => Some(ChainInput::from(n.borrow())),
            _ => None,
        };
        let (finished, next_prepared) = engine.finish(
            frame.index,
            prepared,
            ChainInput::from(frame),
            output,
            next_input,
        );
        let next_prepared = match (next, next_prepared) {
            (Some(Ok(n)), Some(p)) => {
                let index = n.borrow().index;
                Some(
                    p.map(|p| PreparedFrame {
                        frame: n,
                        prepared: Some(p),
                    })
                    .map_err(|source| ProcessError::Chain {
                        frame: index,
                        source,
                    }),
                )
            }
            (Some(Err(e)), _) => Some(Err(e)),
            (Some(Ok(_)), None) | (None, _) => None,
        };
        let result = finished
            .map(|report| fill_header(header, &report, engine.label()))
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
            Engine::Dear(engine) => {
                let output = ChainOutput {
                    depth: out.depth.view_mut(),
                    confidence: out.confidence.view_mut(),
                };
                let report = engine
                    .process(frame.index, ChainInput::from(frame), output)
                    .map_err(|source| ProcessError::Chain {
                        frame: frame.index,
                        source,
                    })?;
                fill_header(header, &report, engine.label());
            }
        }
        Ok(())
    }
}

/// The library engine's settings for deard's `[pipeline]` configuration; `label` names the
/// bundle in logs and headers.
fn engine_config(config: &PipelineConfig, label: String) -> EngineConfig {
    let calibration = match config.calibration {
        CalibrationMode::Online => CalibrationPolicy::Online {
            config: OnlineConfig {
                interval_frames: config.online_interval_frames,
                track_gain: config.online_track_gain,
                ..OnlineConfig::default()
            },
            schedule: match config.online_network {
                NetworkPlacement::Background => MeasurementSchedule::Background,
                NetworkPlacement::Inline => MeasurementSchedule::Inline,
            },
        },
        CalibrationMode::EveryFrame => CalibrationPolicy::EveryFrame,
    };
    EngineConfig { calibration, label }
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

/// Fills `header` from the DEAR engine's `report` of a frame of the bundle `bundle_name`.
fn fill_header(header: &mut FrameHeader, report: &FrameReport, bundle_name: &str) {
    let chain = &report.chain;
    header.flags = match &chain.rejected_refinement {
        None => flags::ALIGNED | flags::REFINED_NETWORK,
        Some(_) => flags::ALIGNED | flags::REFINED_CLASSICAL | flags::NETWORK_OUTPUT_REJECTED,
    };
    if chain.confidence_is_expected_error {
        header.flags |= flags::CONFIDENCE_EXPECTED_ERROR;
    }
    if report.calibration_estimated() {
        header.flags |= flags::CALIBRATION_ESTIMATED;
    }
    if report.online {
        header.flags |= flags::CALIBRATION_ONLINE;
    }
    header.set_bundle_name(bundle_name);
    set_calibration(header, report.calibration);
    header.calib_quality = report.quality;
    header.calib_health = report.health.code();
    header.calib_constrained = report.constrained;
    header.calib_age_frames = report
        .age_frames
        .map_or(u32::MAX, |f| f.min(u32::MAX as u64) as u32);
    header.calib_residual_px = report.residual_px.unwrap_or(f32::NAN);
    let t = &chain.timings;
    let us = |d: Duration| d.as_micros().min(u32::MAX as u128) as u32;
    header.stage_latency_us[Stage::Preprocess as usize] = us(t.preprocess);
    header.stage_latency_us[Stage::Flow as usize] = us(t.flow + t.calibrate);
    header.stage_latency_us[Stage::Fuse as usize] = us(t.fuse);
    header.stage_latency_us[Stage::Warp as usize] = us(t.warp);
    header.stage_latency_us[Stage::Refine as usize] = us(t.refine);
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
