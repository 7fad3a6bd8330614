//! The methods an evaluation compares. Every one is a configuration of code the daemon runs.

use std::time::Instant;

use ndarray::Array2;

use crate::edge_matching::{estimate_calibration_or, EdgeMatchParams};
use dear_capture::frame::Flow;
use dear_capture::Calibration;
use dear_capture::{RgbdFrame, Sample};
use dear_pipeline::align::StaticAligner;
use dear_pipeline::filter::ClassicalRefiner;
use dear_pipeline::recalibration::direct::{estimate_calibration_direct, DirectFitParams};

/// One row of the comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// The ToF depth as delivered (no alignment, no refinement): the input.
    RawTof,
    /// Aligned with the static (factory) calibration.
    StaticCalibration,
    /// Static calibration + the classical edge-aware filter (the daemon without a model).
    StaticClassical,
    /// Calibration estimated per frame by classical RGB↔amplitude edge matching + robust LS.
    EdgeMatching,
    /// Edge matching + the classical filter.
    EdgeMatchingClassical,
    /// Calibration fitted per frame directly to all edge pixels (edge-map correlation,
    /// coarse-to-fine; [`dear_pipeline::recalibration::direct`]), the factory calibration when
    /// the fit is not confident.
    DirectFit,
    /// Direct fit + the classical filter.
    DirectFitClassical,
    /// Aligned with the frame's *true* calibration (an upper bound for alignment, needs the
    /// capture's per-frame `perturbation`).
    OracleCalibration,
}

impl Method {
    /// Every classical method, in table order.
    pub const CLASSICAL: [Method; 8] = [
        Method::RawTof,
        Method::StaticCalibration,
        Method::StaticClassical,
        Method::EdgeMatching,
        Method::EdgeMatchingClassical,
        Method::DirectFit,
        Method::DirectFitClassical,
        Method::OracleCalibration,
    ];

    /// Stable name used in tables and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Method::RawTof => "raw-tof",
            Method::StaticCalibration => "static-calibration",
            Method::StaticClassical => "static+classical-filter",
            Method::EdgeMatching => "edge-matching",
            Method::EdgeMatchingClassical => "edge-matching+classical-filter",
            Method::DirectFit => "direct-fit",
            Method::DirectFitClassical => "direct-fit+classical-filter",
            Method::OracleCalibration => "oracle-calibration",
        }
    }
}

/// What a method produced for one frame.
#[derive(Debug, Clone)]
pub struct MethodOutput {
    /// Depth on the RGB grid, metres, 0 = invalid.
    pub depth: Array2<f32>,
    /// The RGB→ToF flow the method aligned with, when it has one.
    pub flow: Option<Flow>,
    /// The network's rough flow `W_rough`, for methods that have one (DEAR bundles).
    pub flow_rough: Option<Flow>,
    /// The calibration it used, when it has one.
    pub calibration: Option<Calibration>,
    /// Wall time of the method on this frame, seconds.
    pub seconds: f64,
    /// The published confidence, when it holds expected-error codes
    /// (`dear_proto::confidence`; a guarded refiner's rows).
    pub expected_error_code: Option<Array2<u8>>,
}

impl MethodOutput {
    /// The measurement itself as a method's output: the "ToF input" row (`raw-tof`).
    pub fn measurement(frame: &RgbdFrame) -> Self {
        MethodOutput {
            depth: frame.depth.clone(),
            flow: None,
            flow_rough: None,
            calibration: None,
            seconds: 0.0,
            expected_error_code: None,
        }
    }
}

/// Runs methods over frames, keeping scratch buffers between frames.
pub struct MethodRunner {
    initial: Calibration,
    aligner: StaticAligner,
    refiner: ClassicalRefiner,
    edge_params: EdgeMatchParams,
    direct_params: DirectFitParams,
}

impl MethodRunner {
    /// A runner for `(height, width)` frames whose factory calibration is `initial`.
    pub fn new(height: usize, width: usize, initial: Calibration) -> Self {
        MethodRunner {
            initial,
            aligner: StaticAligner::new(height, width),
            refiner: ClassicalRefiner::default(),
            edge_params: EdgeMatchParams::default(),
            direct_params: DirectFitParams::default(),
        }
    }

    /// Runs `method` on `frame`. `None` when the method cannot apply (the oracle without a
    /// known perturbation).
    pub fn run(&mut self, method: Method, sample: &Sample) -> Option<MethodOutput> {
        let frame = &sample.frame;
        let start = Instant::now();
        let (calibration, refine) = match method {
            Method::RawTof => {
                return Some(MethodOutput {
                    seconds: start.elapsed().as_secs_f64(),
                    ..MethodOutput::measurement(frame)
                })
            }
            Method::StaticCalibration => (self.initial, false),
            Method::StaticClassical => (self.initial, true),
            Method::EdgeMatching | Method::EdgeMatchingClassical => {
                let c = estimate_calibration_or(
                    frame.rgb.view(),
                    frame.amplitude.view(),
                    frame.depth.view(),
                    &self.edge_params,
                    self.initial,
                );
                (c, method == Method::EdgeMatchingClassical)
            }
            Method::DirectFit | Method::DirectFitClassical => {
                let fit = estimate_calibration_direct(
                    frame.rgb.view(),
                    frame.amplitude.view(),
                    frame.depth.view(),
                    self.initial,
                    &self.direct_params,
                );
                (fit.calibration, method == Method::DirectFitClassical)
            }
            Method::OracleCalibration => (sample.truth.perturbation?, false),
        };
        let mut aligned = Array2::zeros(frame.dim());
        self.aligner
            .align_into(frame.depth.view(), &calibration, aligned.view_mut());
        let depth = if refine {
            self.refiner.refine(aligned.view(), frame.rgb.view()).0
        } else {
            aligned
        };
        Some(MethodOutput {
            depth,
            flow: Some(self.aligner.flow().clone()),
            flow_rough: None,
            calibration: Some(calibration),
            seconds: start.elapsed().as_secs_f64(),
            expected_error_code: None,
        })
    }
}
