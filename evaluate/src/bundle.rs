//! A model bundle as rows of an evaluation (feature `inference`), run through the same
//! [`DearChain`] the daemon runs.
//!
//! One run of the paper's chain on a frame yields two rows: the depth aligned with the refined
//! flow before refinement ("aligned"), and the chain's output ("refined"), so alignment and
//! refinement are measured separately without running the networks twice. A third row runs the
//! refinement alone on depth aligned with the frame's *true* calibration: the protocol of the
//! paper's Tables 2 and 3, which evaluate refinement on already-aligned input. A fourth,
//! [`OnlineBundleMethod`], is the daemon's online recalibration over frames in order: the
//! library's per-frame engine that deard runs ([`FrameEngine`]), with the measurement of
//! network frames delivered a fixed number of frames later instead of by a worker thread, so
//! that the rows are reproducible.

use ndarray::Array2;

use crate::methods::MethodOutput;
use dear_capture::Sample;
use dear_capture::{Calibration, RgbdFrame};
use dear_pipeline::chain::{
    ChainError, ChainInput, ChainMode, ChainOutput, ChainReport, DearChain,
};
use dear_pipeline::engine::{
    CalibrationPolicy, EngineConfig, EngineError, FrameEngine, FrameReport, MeasurementSchedule,
};
use dear_pipeline::model::{BundleError, ModelBundle};
use dear_pipeline::recalibration::OnlineConfig;

/// The outputs of one chain run.
#[derive(Debug, Clone)]
pub struct BundleOutputs {
    /// Depth warped with the refined flow, before the refinement network.
    pub aligned: MethodOutput,
    /// The chain's output (aligned and refined).
    pub refined: MethodOutput,
    /// What the chain reported (calibration fit, stage timings).
    pub report: ChainReport,
}

/// A bundle's chain for one frame size, with output buffers kept between frames.
#[derive(Debug)]
pub struct BundleMethod {
    name: String,
    chain: DearChain,
    depth: Array2<f32>,
    confidence: Array2<u8>,
}

impl BundleMethod {
    /// The chain of `bundle` for `(height, width)` frames; `name` labels its rows.
    ///
    /// # Errors
    /// As [`DearChain::new`].
    pub fn new(
        bundle: &ModelBundle,
        name: impl Into<String>,
        height: usize,
        width: usize,
    ) -> Result<Self, BundleError> {
        Ok(BundleMethod {
            name: name.into(),
            chain: DearChain::new(bundle, width, height)?,
            depth: Array2::zeros((height, width)),
            confidence: Array2::zeros((height, width)),
        })
    }

    /// The calibration in use (the capture's static calibration) that the chain's direct fit
    /// must clearly beat ([`DearChain::set_reference`]); without it the network's
    /// calibration is the reference (the paper's protocol).
    pub fn with_reference(mut self, reference: Option<Calibration>) -> Self {
        self.chain.set_reference(reference);
        self
    }

    /// The label of this bundle's rows.
    pub fn name(&self) -> &str {
        &self.name
    }

    fn process(&mut self, frame: &RgbdFrame, mode: ChainMode) -> Result<ChainReport, ChainError> {
        self.chain.process(
            ChainInput::from(frame),
            mode,
            ChainOutput {
                depth: self.depth.view_mut(),
                confidence: self.confidence.view_mut(),
            },
        )
    }

    /// The frame's published confidence when it holds expected-error codes.
    fn expected_error_code(&self, report: &ChainReport) -> Option<Array2<u8>> {
        report
            .confidence_is_expected_error
            .then(|| self.confidence.clone())
    }

    /// The paper's chain (rough flow and calibration solved on this frame).
    ///
    /// # Errors
    /// As [`DearChain::process`].
    pub fn run(&mut self, frame: &RgbdFrame) -> Result<BundleOutputs, ChainError> {
        let report = self.process(frame, ChainMode::Full)?;
        let t = report.timings;
        let flow = Some(self.chain.flow_refined().clone());
        let flow_rough = Some(self.chain.flow_rough().clone());
        let aligned = MethodOutput {
            depth: self.chain.depth_warped().clone(),
            flow: flow.clone(),
            flow_rough: flow_rough.clone(),
            calibration: report.calibration,
            seconds: (t.preprocess + t.flow + t.calibrate + t.fuse + t.warp).as_secs_f64(),
            expected_error_code: None,
        };
        let refined = MethodOutput {
            depth: self.depth.clone(),
            flow,
            flow_rough,
            calibration: report.calibration,
            seconds: t.total().as_secs_f64(),
            expected_error_code: self.expected_error_code(&report),
        };
        Ok(BundleOutputs {
            aligned,
            refined,
            report,
        })
    }

    /// The refinement network alone, on depth aligned with the frame's true calibration.
    /// `None` when the capture does not record the frame's perturbation.
    ///
    /// # Errors
    /// As [`DearChain::process`].
    pub fn run_refine_only(&mut self, sample: &Sample) -> Option<Result<MethodOutput, ChainError>> {
        let truth = sample.truth.perturbation?;
        Some(
            self.process(&sample.frame, ChainMode::Cached(truth))
                .map(|report| {
                    let t = report.timings;
                    MethodOutput {
                        depth: self.depth.clone(),
                        flow: None,
                        flow_rough: None,
                        calibration: Some(truth),
                        seconds: t.total().as_secs_f64(),
                        expected_error_code: self.expected_error_code(&report),
                    }
                }),
        )
    }
}

/// A bundle in the daemon's online mode over the frames of a sequence (see the module docs).
#[derive(Debug)]
pub struct OnlineBundleMethod {
    engine: FrameEngine,
    depth: Array2<f32>,
    confidence: Array2<u8>,
}

impl OnlineBundleMethod {
    /// The engine deard runs with `bundle` in online mode for `(height, width)` frames, the
    /// estimator set up by `config` and starting from `static_calibration`, the measurement of
    /// network frames delivered as `schedule` says (`Delayed` for reproducible rows, `Inline`
    /// for deard's `online_network = "inline"`; `Background` would make the rows depend on
    /// the machine's speed). `name` labels its rows.
    ///
    /// # Errors
    /// As [`FrameEngine::new`].
    pub fn new(
        bundle: &ModelBundle,
        name: impl Into<String>,
        (height, width): (usize, usize),
        static_calibration: Calibration,
        config: OnlineConfig,
        schedule: MeasurementSchedule,
    ) -> Result<Self, EngineError> {
        let engine = FrameEngine::new(
            bundle,
            width,
            height,
            static_calibration,
            EngineConfig {
                calibration: CalibrationPolicy::Online { config, schedule },
                label: name.into(),
            },
        )?;
        Ok(OnlineBundleMethod {
            engine,
            depth: Array2::zeros((height, width)),
            confidence: Array2::zeros((height, width)),
        })
    }

    /// The label of this bundle's rows.
    pub fn name(&self) -> &str {
        self.engine.label()
    }

    /// The engine (its online estimator's health, for the tracking table).
    pub fn engine(&self) -> &FrameEngine {
        &self.engine
    }

    /// The next frame of the sequence (frames must come in capture order), as deard processes
    /// it when it keeps up with the camera: prepared with the estimate as it is, then finished.
    /// The output's flow is the one the frame was aligned with, its calibration the published
    /// one, its time the frame path's (an off-path measurement is not in it; an inline one is).
    ///
    /// # Errors
    /// As [`FrameEngine::process`].
    pub fn run(&mut self, frame: &RgbdFrame) -> Result<(MethodOutput, FrameReport), ChainError> {
        let input = ChainInput::from(frame);
        let output = ChainOutput {
            depth: self.depth.view_mut(),
            confidence: self.confidence.view_mut(),
        };
        let report = match self.engine.prepare(input)? {
            Some(prepared) => {
                self.engine
                    .finish(frame.index, prepared, input, output, None)
                    .0?
            }
            None => self.engine.process(frame.index, input, output)?,
        };
        let output = MethodOutput {
            depth: self.depth.clone(),
            flow: Some(self.engine.chain().flow_refined().clone()),
            flow_rough: None,
            calibration: Some(report.calibration),
            seconds: report.chain.timings.total().as_secs_f64(),
            expected_error_code: report
                .chain
                .confidence_is_expected_error
                .then(|| self.confidence.clone()),
        };
        Ok((output, report))
    }
}
