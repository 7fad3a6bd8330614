//! The paper's per-frame chain (docs/algorithm.md, "The equations and where they live") around the
//! three graphs of a bundle, writing its result into caller-provided views (the daemon passes views of
//! shared memory, so the published frame is never copied).
//!
//! `Full` mode is the paper: every frame runs the rough-flow network and re-solves the
//! calibration — and then, by default ([`ChainOptions::direct_fit`]), refines that calibration
//! by fitting it directly to the frame's RGB and amplitude edges ([`crate::recalibration::direct`]). The
//! networks' flow is a few pixels off on scenes unlike their training set, the direct fit a
//! fraction of a pixel when the edges agree (`dear eval`: AEPE at σ = 4 px 4.13 px for the
//! network chain, 2.07 px for the direct fit from the factory calibration), so when the direct
//! fit is confident the frame is aligned by its calibration alone, as a `Cached` frame is. `Cached(calibration)` is the on-device shortcut between network runs: the flow
//! is built from a known calibration and the depth itself (`D_rgb` by [`StaticAligner`]'s
//! forward splat, `W_convt` at `D_rgb`), and — by default, see [`CachedFusion`] — the fusion
//! network is skipped too. Either way the refiner gets the ToF depth warped with the final flow
//! by the same discontinuity-aware backward warp: that is what it was trained on. (Feeding it
//! the splatted `D_rgb` directly was measured worse: ToF-KPN MAE at the true calibration 12.78
//! vs 8.47 cm on a 200-frame drifting sequence, `dear eval --online`.)

use std::time::{Duration, Instant};

use ndarray::{Array2, ArrayView2, ArrayView3, ArrayViewMut2, Zip};

use crate::align::StaticAligner;
use crate::chain::confidence::{confidence_into, expected_error_confidence_into};
use crate::chain::output_guard::{OutputGuard, RefinementCheck};
use crate::chain::preprocess::{normalize_amplitude_into, rgb_planes_into};
use crate::filter::ClassicalRefiner;
use crate::geometry::{warp_depth, warp_depth_and_bilinear};
use crate::model::{
    BundleError, BundleRunner, ClassicalEstimate, ModelBundle, Normalisation, RunnerOptions,
};
use crate::recalibration::direct::{estimate_calibration_direct_against, DirectFitParams};
use crate::recalibration::residual::{EdgeAlignment, EdgeCheck};
use crate::recalibration::{LsqError, Measurement, RobustOptions};
use dear_capture::calibration::Calibration;
use dear_capture::frame::{Flow, RgbdFrame};

/// How one frame is aligned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ChainMode {
    /// Rough-flow network and least-squares calibration on this frame (the paper).
    Full,
    /// Skip the rough-flow network: the flow comes from this calibration and the depth.
    Cached(Calibration),
}

impl crate::recalibration::FrameDecision {
    /// The chain mode this decision calls for: `Cached` with the current estimate when the
    /// network does not run, `Full` otherwise (also before any estimate exists).
    pub fn chain_mode(&self) -> ChainMode {
        match (self.run_network, self.calibration) {
            (None, Some(estimate)) => ChainMode::Cached(estimate),
            _ => ChainMode::Full,
        }
    }
}

/// What `Cached` mode does about the fusion network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CachedFusion {
    /// Warp with `W_convt` directly (no network at all in the alignment). The default: the
    /// fusion net was trained to correct a *network* flow with the calibration flow; fed the
    /// calibration flow twice it has nothing to arbitrate, and on the edge tier it costs more
    /// than the flow net (1.1 GMAC at VGA). Measured (test `cached_fusion_choice_on_ground_truth`,
    /// untrained smoke bundle, true calibration, 64×96): AEPE 0.035 px skipped vs 0.27 px run,
    /// refined-depth MAE 2.44 vs 2.41 cm; VGA frame 140 ms vs 361 ms (`benches/dear_chain.rs`).
    /// Re-measure with a trained bundle before changing it.
    Skip,
    /// Run fusion with `W_rough := W_convt`.
    Run,
}

/// Settings of a [`DearChain`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChainOptions {
    /// The robust least squares of `Full` mode.
    pub robust: RobustOptions,
    /// Flow vectors with an end-point residual above this (px) count as outliers in the
    /// reported inlier fraction.
    pub inlier_threshold_px: f32,
    /// `Full` mode: refine the network's calibration by the direct fit to the frame's edges
    /// ([`crate::recalibration::direct`]); when it is confident, the frame is aligned by its calibration like
    /// a `Cached` frame. `None` runs the paper's chain as trained (rough flow, least squares,
    /// fusion).
    pub direct_fit: Option<DirectFitParams>,
    /// `Cached` mode (and `Full` frames aligned by the direct fit) and the fusion network.
    pub cached_fusion: CachedFusion,
    /// Compute [`ChainReport::alignment`] (about 1 ms at any resolution).
    pub alignment_check: bool,
    /// Largest principal-point correction the alignment check searches, px (0: only the
    /// disagreement, no edge shift).
    pub shift_search_px: usize,
    /// tract execution.
    pub runner: RunnerOptions,
    /// Checks the refinement network's output against physics; a frame it rejects is refined
    /// by the classical filter instead ([`ChainReport::rejected_refinement`]). `None` publishes
    /// whatever the network outputs (tests of the raw network only).
    pub output_guard: Option<OutputGuard>,
}

impl Default for ChainOptions {
    /// Huber δ = 1 px, outliers beyond 3 px, the direct fit on with its default settings,
    /// fusion skipped in `Cached` mode, alignment check
    /// on with a ±3 px shift search (the sequences' principal point moves < 0.5 px per frame).
    fn default() -> Self {
        ChainOptions {
            robust: RobustOptions::default(),
            inlier_threshold_px: 3.0,
            direct_fit: Some(DirectFitParams::default()),
            cached_fusion: CachedFusion::Skip,
            alignment_check: true,
            shift_search_px: 3,
            runner: RunnerOptions::default(),
            output_guard: Some(OutputGuard::default()),
        }
    }
}

/// One frame's sensor data; all on the RGB pixel grid's size `(H, W)`.
#[derive(Debug, Clone, Copy)]
pub struct ChainInput<'a> {
    /// RGB `(H, W, 3)`, 8-bit.
    pub rgb: ArrayView3<'a, u8>,
    /// Raw ToF amplitude `(H, W)` (sensor counts).
    pub amplitude: ArrayView2<'a, f32>,
    /// ToF depth `(H, W)`, metres, `0` = invalid, as delivered (weakly calibrated).
    pub depth: ArrayView2<'a, f32>,
}

impl<'a> From<&'a RgbdFrame> for ChainInput<'a> {
    /// A frame's planes as the chain takes them.
    fn from(frame: &'a RgbdFrame) -> Self {
        ChainInput {
            rgb: frame.rgb.view(),
            amplitude: frame.amplitude.view(),
            depth: frame.depth.view(),
        }
    }
}

impl ChainInput<'_> {
    /// `Ok` when every plane has the `(H, W)` (RGB `(H, W, 3)`) of a stream, else the
    /// [`ChainError::Shape`] naming the first plane that does not.
    pub(crate) fn check_shape(&self, (h, w): (usize, usize)) -> Result<(), ChainError> {
        shape_check("rgb", self.rgb.shape(), &[h, w, 3])?;
        shape_check("amplitude", self.amplitude.shape(), &[h, w])?;
        shape_check("depth", self.depth.shape(), &[h, w])
    }
}

/// Where the chain writes its result.
#[derive(Debug)]
pub struct ChainOutput<'a> {
    /// Aligned refined depth `(H, W)`, metres; `0` where no ToF measurement maps to the pixel.
    pub depth: ArrayViewMut2<'a, f32>,
    /// Confidence `(H, W)`, 0..=255 (see [`crate::chain::confidence`]).
    pub confidence: ArrayViewMut2<'a, u8>,
}

/// Wall time of each stage of one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimings {
    /// Amplitude normalisation and RGB planes.
    pub preprocess: Duration,
    /// Rough-flow network (zero in `Cached` mode).
    pub flow: Duration,
    /// `D_rgb`, least squares and `W_convt` (`Full`), or the splatted alignment (`Cached`).
    pub calibrate: Duration,
    /// Fusion network (zero when skipped).
    pub fuse: Duration,
    /// Warping depth and amplitude with the final flow.
    pub warp: Duration,
    /// Refinement network (with a hybrid refiner's classical filter), output masking and
    /// confidence, and the edge alignment check, which runs beside the refinement on the other
    /// core.
    pub refine: Duration,
}

impl StageTimings {
    /// Sum of the stages.
    pub fn total(&self) -> Duration {
        self.preprocess + self.flow + self.calibrate + self.fuse + self.warp + self.refine
    }
}

/// What happened on one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ChainReport {
    /// Whether the rough-flow network ran (`Full` mode).
    pub ran_flow_network: bool,
    /// Whether the direct fit to the frame's edges ran (`Full` mode with
    /// [`ChainOptions::direct_fit`], after a successful network fit).
    pub ran_direct_fit: bool,
    /// Whether the fusion network ran.
    pub ran_fusion_network: bool,
    /// The calibration behind `W_convt`: the fit (`Full`, when it succeeded) or the given one.
    pub calibration: Option<Calibration>,
    /// `Full` mode: the direct fit to the frame's edges when it ran and was confident,
    /// otherwise the robust fit of `W_rough` against `D_rgb` and its quality, or why it failed
    /// (then `W_convt = W_rough` everywhere). `None` in `Cached` mode.
    pub measurement: Option<Result<Measurement, LsqError>>,
    /// Fraction of pixels with a valid warped depth.
    pub valid_fraction: f32,
    /// The amplitude normalisation scale (`None`: no valid depth, amplitude input all zero).
    pub amplitude_scale: Option<f32>,
    /// Edge alignment between RGB and the warped amplitude (see [`EdgeCheck`]): the online
    /// estimator's trigger signal and its principal-point tracker.
    pub alignment: Option<EdgeAlignment>,
    /// `Some` when the output guard rejected the refinement network's output on this frame:
    /// the published depth and confidence are then the classical filter's.
    pub rejected_refinement: Option<RefinementCheck>,
    /// Whether the published confidence holds expected-error codes
    /// (`dear_proto::confidence`): a guarded refiner's output was published. Otherwise it is
    /// the heuristic score of [`confidence_into`].
    pub confidence_is_expected_error: bool,
    /// Stage timings.
    pub timings: StageTimings,
}

/// Why a frame could not be processed.
#[derive(Debug, thiserror::Error)]
pub enum ChainError {
    /// An input or output image does not have the chain's shape.
    #[error("{what} has shape {found:?}, the chain runs at {expected:?}")]
    Shape {
        /// Which image.
        what: &'static str,
        /// The chain's `(H, W)` (`(H, W, 3)` for RGB).
        expected: Vec<usize>,
        /// What was passed.
        found: Vec<usize>,
    },
    /// A network failed.
    #[error(transparent)]
    Model(#[from] BundleError),
}

/// The DEAR chain for one stream resolution, with every intermediate buffer preallocated.
///
/// A frame is processed in two halves: [`prepare`](Self::prepare) (preprocessing, alignment,
/// the warps and, for `hybrid` refiners, the classical filter) and [`finish`](Self::finish)
/// (the refine graph and its tail, the edge check, the output guard and the confidence).
/// [`process`](Self::process) runs one after the other. The refine graph runs on one core, so
/// a caller that has the next frame already can [`finish_and_prepare`](Self::finish_and_prepare):
/// this frame's second half beside the next frame's first half, on the other core. The halves
/// write separate buffers (`Staged` is double-buffered), so the output is the same bits
/// either way.
#[derive(Debug)]
pub struct DearChain {
    runner: BundleRunner,
    norm: Normalisation,
    options: ChainOptions,
    front: FrontEnd,
    /// The refinement's inputs of the last prepared frame (what `finish` reads).
    staged: Staged,
    edge_check: EdgeCheck,
    refined: Array2<f32>,
    /// The classical refiner frames fall back to when the output guard rejects the network's
    /// output (other refiners than `hybrid`); made on the first rejection.
    fallback: Option<ClassicalRefiner>,
    /// Frames prepared so far: ties a [`Prepared`] to the staged buffers it describes.
    prepared_count: u64,
}

/// The first half's state: everything up to the refinement's inputs.
#[derive(Debug)]
struct FrontEnd {
    aligner: StaticAligner,
    scratch: Vec<f32>,
    amplitude: Array2<f32>,
    flow_rough: Flow,
    depth_rgb: Array2<f32>,
    flow_convt: Flow,
    flow_refined: Flow,
    /// Where the last frame's flows are: a frame aligned by a calibration reads `W_convt` (and
    /// with fusion skipped `W_refn`) from the aligner instead of copying it (5 MB at 640×480).
    flows: FlowSource,
    /// `hybrid` refiners: the classical refiner they build on.
    classical: Option<ClassicalRefiner>,
    /// The refinement's inputs being written by `prepare`.
    staged: Staged,
    /// The calibration in use that a `Full` frame's direct fit must clearly beat
    /// ([`DearChain::set_reference`]).
    reference: Option<Calibration>,
}

/// Where a frame's `W_convt` and final flow `W_refn` are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FlowSource {
    /// The paper's steps: `flow_convt` and the fused `flow_refined`.
    Buffers,
    /// Aligned by a calibration, fusion skipped: both are the aligner's flow.
    Aligner,
    /// Aligned by a calibration, fusion run: `W_convt` is the aligner's, `W_refn` fused.
    AlignerFused,
}

impl FlowSource {
    /// `W_convt`, given its buffer and the aligner's flow.
    fn convt<'a>(self, buffer: &'a Flow, aligners: &'a Flow) -> &'a Flow {
        match self {
            FlowSource::Buffers => buffer,
            FlowSource::Aligner | FlowSource::AlignerFused => aligners,
        }
    }

    /// `W_refn`, given the fused-flow buffer and the aligner's flow.
    fn refined<'a>(self, fused: &'a Flow, aligners: &'a Flow) -> &'a Flow {
        match self {
            FlowSource::Buffers | FlowSource::AlignerFused => fused,
            FlowSource::Aligner => aligners,
        }
    }
}

/// What the second half reads of a prepared frame.
#[derive(Debug)]
struct Staged {
    rgb: [Array2<f32>; 3],
    depth_warped: Array2<f32>,
    amplitude_warped: Array2<f32>,
    /// `hybrid` refiners: the classical refiner's depth and confidence on the warped depth.
    classical: Option<(Array2<f32>, Array2<u8>)>,
}

impl Staged {
    fn new(height: usize, width: usize, classical: bool) -> Self {
        let plane = || Array2::zeros((height, width));
        Staged {
            rgb: [plane(), plane(), plane()],
            depth_warped: plane(),
            amplitude_warped: plane(),
            classical: classical.then(|| (plane(), Array2::zeros((height, width)))),
        }
    }
}

/// A frame whose first half ([`DearChain::prepare`]) is done: what it found, handed to
/// [`DearChain::finish`]. Only the latest prepared frame can be finished.
#[derive(Debug)]
#[must_use = "a prepared frame is published by `finish`"]
pub struct Prepared {
    /// The [`DearChain::prepared_count`] it was made at.
    id: u64,
    ran_flow_network: bool,
    ran_direct_fit: bool,
    ran_fusion_network: bool,
    calibration: Option<Calibration>,
    measurement: Option<Result<Measurement, LsqError>>,
    amplitude_scale: Option<f32>,
    timings: StageTimings,
}

impl Prepared {
    /// The calibration the frame was aligned with (`None`: a `Full` frame whose fit failed).
    pub fn calibration(&self) -> Option<Calibration> {
        self.calibration
    }
}

/// Whether preparing a frame in `mode` runs a network (the runner is then busy, so the frame
/// cannot be prepared beside another's refinement).
fn prepare_runs_network(mode: ChainMode, options: &ChainOptions) -> bool {
    matches!(mode, ChainMode::Full) || options.cached_fusion == CachedFusion::Run
}

impl DearChain {
    /// A chain running `bundle` on `width × height` frames with default options.
    ///
    /// # Errors
    /// As [`BundleRunner::new`].
    pub fn new(bundle: &ModelBundle, width: usize, height: usize) -> Result<Self, BundleError> {
        Self::with_options(bundle, width, height, ChainOptions::default())
    }

    /// [`new`](Self::new) with explicit options.
    ///
    /// # Errors
    /// As [`BundleRunner::with_options`].
    pub fn with_options(
        bundle: &ModelBundle,
        width: usize,
        height: usize,
        options: ChainOptions,
    ) -> Result<Self, BundleError> {
        let runner = BundleRunner::with_options(bundle, width, height, options.runner)?;
        let plane = || Array2::zeros((height, width));
        let uses_classical = runner.refine_uses_classical();
        let flow = || Flow::zeros(height, width);
        Ok(DearChain {
            runner,
            norm: bundle.normalisation(),
            options,
            front: FrontEnd {
                aligner: StaticAligner::new(height, width),
                scratch: Vec::with_capacity(height * width),
                amplitude: plane(),
                flow_rough: flow(),
                depth_rgb: plane(),
                flow_convt: flow(),
                flow_refined: flow(),
                flows: FlowSource::Buffers,
                classical: uses_classical.then(ClassicalRefiner::default),
                staged: Staged::new(height, width, uses_classical),
                reference: None,
            },
            staged: Staged::new(height, width, uses_classical),
            edge_check: EdgeCheck::new(options.shift_search_px),
            refined: plane(),
            fallback: None,
            prepared_count: 0,
        })
    }

    /// `(height, width)` of the stream.
    pub fn dim(&self) -> (usize, usize) {
        self.runner.dim()
    }

    /// The options in use.
    pub fn options(&self) -> &ChainOptions {
        &self.options
    }

    /// Changes how `Cached` frames treat the fusion network.
    pub fn set_cached_fusion(&mut self, cached_fusion: CachedFusion) {
        self.options.cached_fusion = cached_fusion;
    }

    /// The calibration in use (the factory calibration, or the online estimate): a `Full`
    /// frame's direct fit, started from the network's calibration, replaces it only when the
    /// frame clearly shows it wrong ([`estimate_calibration_direct_against`]); otherwise the
    /// frame is aligned by it and its measurement constrains nothing (zero information: the
    /// online estimator leaves its estimate). `None` (the paper's protocol, and the default):
    /// the network's calibration is the reference.
    pub fn set_reference(&mut self, reference: Option<Calibration>) {
        self.front.reference = reference;
    }

    /// The graphs, for running a single network (tests, benches).
    pub fn runner_mut(&mut self) -> &mut BundleRunner {
        &mut self.runner
    }

    /// Processes one frame and writes the aligned refined depth and its confidence:
    /// [`prepare`](Self::prepare), then [`finish`](Self::finish).
    ///
    /// # Errors
    /// [`ChainError::Shape`] when an image does not have the chain's shape (nothing is
    /// written), [`ChainError::Model`] when a network fails.
    pub fn process(
        &mut self,
        input: ChainInput<'_>,
        mode: ChainMode,
        output: ChainOutput<'_>,
    ) -> Result<ChainReport, ChainError> {
        self.check_output_shape(&output)?;
        let prepared = self.prepare(input, mode)?;
        self.finish(prepared, input.rgb, output)
    }

    /// The first half of a frame: preprocessing, the alignment `mode` asks for, the warps of
    /// the refinement's inputs and (for `hybrid` refiners) the classical filter on them.
    ///
    /// # Errors
    /// [`ChainError::Shape`] when an input does not have the chain's shape,
    /// [`ChainError::Model`] when a network fails.
    pub fn prepare(
        &mut self,
        input: ChainInput<'_>,
        mode: ChainMode,
    ) -> Result<Prepared, ChainError> {
        input.check_shape(self.dim())?;
        self.prepared_count += 1;
        let prepared = self.front.prepare(
            Some(&mut self.runner),
            self.norm,
            &self.options,
            input,
            mode,
            self.prepared_count,
        )?;
        std::mem::swap(&mut self.front.staged, &mut self.staged);
        Ok(prepared)
    }

    /// The second half of the frame `prepared` describes (the latest one prepared): the refine
    /// graph beside the edge alignment check, the output guard, and the published depth and
    /// confidence. `rgb` is that frame's RGB image.
    ///
    /// # Errors
    /// [`ChainError::Shape`] when `rgb` or an output does not have the chain's shape,
    /// [`ChainError::Model`] when the refine graph fails.
    ///
    /// # Panics
    /// If `prepared` is not the latest frame this chain prepared.
    pub fn finish(
        &mut self,
        prepared: Prepared,
        rgb: ArrayView3<'_, u8>,
        output: ChainOutput<'_>,
    ) -> Result<ChainReport, ChainError> {
        self.check_finish(&prepared, rgb, &output)?;
        let (_, mut back, _) = self.halves();
        back.finish(prepared, rgb, output)
    }

    /// [`finish`](Self::finish) of `prepared` beside [`prepare`](Self::prepare) of `next`: the
    /// refine graph runs on one thread, and the next frame's alignment, warps and classical
    /// filter take the other core meanwhile. The results are those of the two calls in turn
    /// (which is what runs when preparing `next` needs a network: the graphs are busy).
    ///
    /// # Errors
    /// Each half's, as [`finish`](Self::finish) and [`prepare`](Self::prepare) say.
    ///
    /// # Panics
    /// As [`finish`](Self::finish).
    pub fn finish_and_prepare(
        &mut self,
        prepared: Prepared,
        rgb: ArrayView3<'_, u8>,
        output: ChainOutput<'_>,
        next: ChainInput<'_>,
        next_mode: ChainMode,
    ) -> (
        Result<ChainReport, ChainError>,
        Result<Prepared, ChainError>,
    ) {
        if prepare_runs_network(next_mode, &self.options) {
            let finished = self.finish(prepared, rgb, output);
            return (finished, self.prepare(next, next_mode));
        }
        if let Err(e) = self.check_finish(&prepared, rgb, &output) {
            return (Err(e), self.prepare(next, next_mode));
        }
        if let Err(e) = next.check_shape(self.dim()) {
            return (self.finish(prepared, rgb, output), Err(e));
        }
        let next_id = self.prepared_count + 1;
        let (front, mut back, norm) = self.halves();
        let options = back.options;
        let (finished, next_prepared) = rayon::join(
            || back.finish(prepared, rgb, output),
            || front.prepare(None, norm, options, next, next_mode, next_id),
        );
        self.prepared_count = next_id;
        if next_prepared.is_ok() {
            std::mem::swap(&mut self.front.staged, &mut self.staged);
        }
        (finished, next_prepared)
    }

    /// The calibration measurement of a `Full` frame alone — preprocessing, the rough-flow
    /// network, its robust least-squares fit and (by default) the direct fit to the frame's
    /// edges — without aligning or refining anything. This is what a background worker runs
    /// so that network frames never hold up the frame path (`DearChain::process` in `Cached`
    /// mode does the rest); the measurement is the one [`ChainReport::measurement`] would carry.
    ///
    /// # Errors
    /// As [`process`](Self::process) (no output is written, so only the inputs are checked).
    pub fn measure(&mut self, input: ChainInput<'_>) -> Result<MeasureReport, ChainError> {
        input.check_shape(self.dim())?;
        let mut t = StageTimings::default();
        let mut clock = Stopwatch::start();
        let front = &mut self.front;
        front.preprocess(self.norm, input, &mut t, &mut clock);
        let NetworkFit { fit, direct } =
            front.network_fit(&mut self.runner, &self.options, input, &mut t, &mut clock)?;
        clock.lap(&mut t.calibrate);
        let ran_direct_fit = direct.is_some();
        let measurement = match direct.flatten() {
            Some(direct) => Ok(direct),
            None => fit,
        };
        Ok(MeasureReport {
            measurement,
            ran_direct_fit,
            timings: t,
        })
    }

    /// What [`finish`](Self::finish) checks before it starts.
    ///
    /// # Panics
    /// If `prepared` is not the latest frame this chain prepared.
    fn check_finish(
        &self,
        prepared: &Prepared,
        rgb: ArrayView3<'_, u8>,
        output: &ChainOutput<'_>,
    ) -> Result<(), ChainError> {
        self.check_output_shape(output)?;
        shape_check("rgb", rgb.shape(), &[self.dim().0, self.dim().1, 3])?;
        assert_eq!(
            prepared.id, self.prepared_count,
            "DearChain::finish: only the latest prepared frame can be finished"
        );
        Ok(())
    }

    /// The chain's two halves, borrowed apart so that they can run side by side, and the
    /// bundle's normalisation.
    fn halves(&mut self) -> (&mut FrontEnd, BackEnd<'_>, Normalisation) {
        let back = BackEnd {
            runner: &mut self.runner,
            options: &self.options,
            staged: &self.staged,
            edge_check: &mut self.edge_check,
            refined: &mut self.refined,
            fallback: &mut self.fallback,
        };
        (&mut self.front, back, self.norm)
    }

    fn check_output_shape(&self, output: &ChainOutput<'_>) -> Result<(), ChainError> {
        let (h, w) = self.dim();
        shape_check("output depth", output.depth.shape(), &[h, w])?;
        shape_check("output confidence", output.confidence.shape(), &[h, w])
    }

    /// RGB planes in `[0, 1]` of the last prepared frame.
    pub fn rgb_planes(&self) -> &[Array2<f32>; 3] {
        &self.staged.rgb
    }
    /// Normalised amplitude of the last frame (ToF grid).
    pub fn amplitude(&self) -> &Array2<f32> {
        &self.front.amplitude
    }
    /// `W_rough` of the last `Full` frame.
    pub fn flow_rough(&self) -> &Flow {
        &self.front.flow_rough
    }
    /// `D_rgb`: ToF depth warped by `W_rough` (`Full`) or aligned by the calibration (`Cached`).
    pub fn depth_rgb(&self) -> &Array2<f32> {
        &self.front.depth_rgb
    }
    /// `W_convt` of the last frame.
    pub fn flow_convt(&self) -> &Flow {
        self.front.convt()
    }
    /// The flow the depth was finally warped with (`W_refn`, or `W_convt` when fusion was
    /// skipped).
    pub fn flow_refined(&self) -> &Flow {
        self.front.refined()
    }
    /// The refinement's depth input (metres) of the last prepared frame.
    pub fn depth_warped(&self) -> &Array2<f32> {
        &self.staged.depth_warped
    }
    /// The refinement's amplitude input of the last prepared frame.
    pub fn amplitude_warped(&self) -> &Array2<f32> {
        &self.staged.amplitude_warped
    }
    /// The refinement's raw output (metres), before masking, of the last finished frame.
    pub fn refined_raw(&self) -> &Array2<f32> {
        &self.refined
    }
}

impl FrontEnd {
    /// The first half of a frame (see [`DearChain::prepare`]) into `self.staged`. `runner` is
    /// `None` only where `mode` runs no network ([`prepare_runs_network`]).
    fn prepare(
        &mut self,
        runner: Option<&mut BundleRunner>,
        norm: Normalisation,
        options: &ChainOptions,
        input: ChainInput<'_>,
        mode: ChainMode,
        id: u64,
    ) -> Result<Prepared, ChainError> {
        let mut t = StageTimings::default();
        let mut clock = Stopwatch::start();

        // 1. Preprocess.
        let amplitude_scale = self.preprocess(norm, input, &mut t, &mut clock);

        let mut measurement = None;
        let calibration;
        let ran_fusion;
        let mut ran_direct_fit = false;
        let needs_runner = "the caller passes the runner when the mode runs a network";
        match mode {
            ChainMode::Full => {
                let runner = runner.expect(needs_runner);
                let NetworkFit { fit, direct } =
                    self.network_fit(runner, options, input, &mut t, &mut clock)?;
                ran_direct_fit = direct.is_some();
                let direct = direct.flatten();
                if let Some(direct) = direct {
                    // Aligned by a calibration, exactly as a `Cached` frame.
                    calibration = Some(direct.calibration);
                    measurement = Some(Ok(direct));
                    ran_fusion = self.align_with_calibration(
                        Some(runner),
                        options,
                        input.depth,
                        &direct.calibration,
                        &mut t,
                        &mut clock,
                    )?;
                } else {
                    calibration = fit.as_ref().ok().map(|m| m.calibration);
                    self.flows = FlowSource::Buffers;
                    self.flow_convt.u.assign(&self.flow_rough.u);
                    self.flow_convt.v.assign(&self.flow_rough.v);
                    if let Some(c) = calibration {
                        convt_flow_into(&c, self.depth_rgb.view(), &mut self.flow_convt);
                    }
                    measurement = Some(fit);
                    clock.lap(&mut t.calibrate);
                    // 6. Fusion.
                    runner.fuse(&self.flow_rough, &self.flow_convt, &mut self.flow_refined)?;
                    ran_fusion = true;
                    clock.lap(&mut t.fuse);
                    // 7. Warp depth and amplitude.
                    self.warp_inputs(input.depth);
                    clock.lap(&mut t.warp);
                }
            }
            ChainMode::Cached(c) => {
                calibration = Some(c);
                ran_fusion = self.align_with_calibration(
                    runner,
                    options,
                    input.depth,
                    &c,
                    &mut t,
                    &mut clock,
                )?;
            }
        }

        // 8a. A hybrid refiner's classical filter (an input of its graph), counted as
        // refinement.
        if let (Some(refiner), Some((depth, confidence))) =
            (&mut self.classical, &mut self.staged.classical)
        {
            refiner.refine_into(
                self.staged.depth_warped.view(),
                input.rgb,
                depth.view_mut(),
                confidence.view_mut(),
            );
        }
        clock.lap(&mut t.refine);
        Ok(Prepared {
            id,
            ran_flow_network: matches!(mode, ChainMode::Full),
            ran_direct_fit,
            ran_fusion_network: ran_fusion,
            calibration,
            measurement,
            amplitude_scale,
            timings: t,
        })
    }

    /// Step 1: the RGB planes and the normalised amplitude. Returns the amplitude scale.
    fn preprocess(
        &mut self,
        norm: Normalisation,
        input: ChainInput<'_>,
        t: &mut StageTimings,
        clock: &mut Stopwatch,
    ) -> Option<f32> {
        rgb_planes_into(input.rgb, &mut self.staged.rgb);
        let scale = normalize_amplitude_into(
            input.amplitude,
            input.depth,
            norm.amplitude_percentile,
            &mut self.scratch,
            self.amplitude.view_mut(),
        );
        clock.lap(&mut t.preprocess);
        scale
    }

    /// Steps 2–4 of a `Full` frame on the preprocessed planes: rough flow, `D_rgb`, the robust
    /// fit of `W_rough`, then the direct fit started from it (when configured and the network
    /// fit succeeded). Leaves `W_rough` and `D_rgb` in their buffers.
    fn network_fit(
        &mut self,
        runner: &mut BundleRunner,
        options: &ChainOptions,
        input: ChainInput<'_>,
        t: &mut StageTimings,
        clock: &mut Stopwatch,
    ) -> Result<NetworkFit, ChainError> {
        // 2. Rough flow.
        let [r, g, b] = &self.staged.rgb;
        runner.flow(
            [r.view(), g.view(), b.view()],
            self.amplitude.view(),
            &mut self.flow_rough,
        )?;
        clock.lap(&mut t.flow);
        // 3.–4. D_rgb and the robust least squares.
        warp_depth(input.depth, &self.flow_rough, self.depth_rgb.view_mut());
        let fit = Measurement::from_flow(
            &self.flow_rough,
            self.depth_rgb.view(),
            options.robust,
            options.inlier_threshold_px,
        );
        // The direct fit to the frame's edges, started from the network's calibration and
        // judged against the calibration in use.
        let direct = match (&options.direct_fit, &fit) {
            (Some(params), Ok(network)) => {
                let (reference, params) = match self.reference {
                    Some(reference) => (reference, *params),
                    // Without a calibration in use there is nothing to protect: the fit only
                    // has to beat the network's start (the paper's protocol).
                    None => (
                        network.calibration,
                        DirectFitParams {
                            min_gain: 0.0,
                            max_mean_flow_change_px: f32::INFINITY,
                            ..*params
                        },
                    ),
                };
                let direct = estimate_calibration_direct_against(
                    input.rgb,
                    input.amplitude,
                    input.depth,
                    network.calibration,
                    reference,
                    &params,
                );
                Some(if direct.fell_back && self.reference.is_some() {
                    Some(Measurement::keeping_reference(&direct))
                } else {
                    Measurement::from_direct_fit(&direct)
                })
            }
            _ => None,
        };
        Ok(NetworkFit { fit, direct })
    }

    /// Aligns the frame by a calibration (`Cached` frames, and `Full` frames whose direct fit
    /// succeeded): `D_rgb` by the forward splat, `W_convt` that calibration's flow at `D_rgb`,
    /// the fusion network as [`ChainOptions::cached_fusion`] says, then the warp of the
    /// refiner's inputs. Returns whether the fusion network ran.
    fn align_with_calibration(
        &mut self,
        runner: Option<&mut BundleRunner>,
        options: &ChainOptions,
        depth: ArrayView2<'_, f32>,
        calibration: &Calibration,
        t: &mut StageTimings,
        clock: &mut Stopwatch,
    ) -> Result<bool, ChainError> {
        self.aligner
            .align_into(depth, calibration, self.depth_rgb.view_mut());
        clock.lap(&mut t.calibrate);
        let ran_fusion = match options.cached_fusion {
            CachedFusion::Skip => {
                self.flows = FlowSource::Aligner;
                false
            }
            CachedFusion::Run => {
                self.flows = FlowSource::AlignerFused;
                let runner = runner.expect("the caller passes the runner when fusion runs");
                let convt = self.aligner.flow();
                runner.fuse(convt, convt, &mut self.flow_refined)?;
                clock.lap(&mut t.fuse);
                true
            }
        };
        self.warp_inputs(depth);
        clock.lap(&mut t.warp);
        Ok(ran_fusion)
    }

    /// `W_convt` of the last frame.
    fn convt(&self) -> &Flow {
        self.flows.convt(&self.flow_convt, self.aligner.flow())
    }

    /// The flow the last frame was warped with.
    fn refined(&self) -> &Flow {
        self.flows.refined(&self.flow_refined, self.aligner.flow())
    }

    /// Warps the refiner's inputs, depth and normalised amplitude, with `W_refn`.
    fn warp_inputs(&mut self, depth: ArrayView2<'_, f32>) {
        let flow = self.flows.refined(&self.flow_refined, self.aligner.flow());
        warp_depth_and_bilinear(
            depth,
            self.amplitude.view(),
            flow,
            self.staged.depth_warped.view_mut(),
            self.staged.amplitude_warped.view_mut(),
        );
    }
}

/// The second half's state, borrowed from the chain beside a [`FrontEnd`] at work.
struct BackEnd<'a> {
    runner: &'a mut BundleRunner,
    options: &'a ChainOptions,
    staged: &'a Staged,
    edge_check: &'a mut EdgeCheck,
    refined: &'a mut Array2<f32>,
    fallback: &'a mut Option<ClassicalRefiner>,
}

impl BackEnd<'_> {
    /// The second half of a frame (see [`DearChain::finish`]); shapes are checked.
    fn finish(
        &mut self,
        prepared: Prepared,
        rgb_u8: ArrayView3<'_, u8>,
        output: ChainOutput<'_>,
    ) -> Result<ChainReport, ChainError> {
        let mut t = prepared.timings;
        let classical_time = t.refine;
        let mut clock = Stopwatch::start();
        let staged = self.staged;
        // 8b. Refinement, beside the edge alignment check: the check reads only the warped
        // inputs, and the refine graph runs on one thread, so the check takes the other core
        // instead of adding its time after the refinement.
        let [r, g, b] = &staged.rgb;
        let rgb = self
            .runner
            .refine_uses_rgb()
            .then(|| [r.view(), g.view(), b.view()]);
        let (runner, refined) = (&mut *self.runner, &mut *self.refined);
        let (depth_warped, amplitude_warped) = (&staged.depth_warped, &staged.amplitude_warped);
        let edge_check = &mut *self.edge_check;
        let check = self.options.alignment_check;
        let (refine_result, alignment) = rayon::join(
            || {
                runner.refine(
                    amplitude_warped.view(),
                    depth_warped.view(),
                    rgb,
                    staged
                        .classical
                        .as_ref()
                        .map(|(depth, confidence)| ClassicalEstimate {
                            depth: depth.view(),
                            confidence: confidence.view(),
                        }),
                    refined.view_mut(),
                )
            },
            || {
                check
                    .then(|| {
                        edge_check.measure(rgb_u8, amplitude_warped.view(), depth_warped.view())
                    })
                    .flatten()
            },
        );
        refine_result?;
        let ChainOutput {
            depth: mut out_depth,
            confidence: mut out_confidence,
        } = output;
        // The guard's pass writes the published depth and counts the measured pixels too
        // (`valid_fraction`); a rejected frame's depth is overwritten below.
        // (Without a guard the counts only give `valid_fraction`.)
        let guard = self.options.output_guard.unwrap_or_default();
        let check = guard.check_into(
            depth_warped.view(),
            self.refined.view(),
            out_depth.view_mut(),
        );
        let valid = check.measured;
        let rejected_refinement = self
            .options
            .output_guard
            .is_some_and(|guard| guard.rejects(&check))
            .then_some(check);
        let expected_error = self.runner.expected_log_error();
        let confidence_is_expected_error =
            rejected_refinement.is_none() && expected_error.is_some();
        match (rejected_refinement, &staged.classical) {
            (None, _) => match expected_error {
                Some(log_error) => {
                    expected_error_confidence_into(out_depth.view(), log_error, out_confidence)
                }
                None => confidence_into(depth_warped.view(), self.refined.view(), out_confidence),
            },
            // A hybrid refiner's classical stage already filtered this frame.
            (Some(_), Some((depth, confidence))) => {
                out_depth.assign(depth);
                out_confidence.assign(confidence);
            }
            (Some(_), None) => self
                .fallback
                .get_or_insert_with(ClassicalRefiner::default)
                .refine_into(
                    depth_warped.view(),
                    rgb_u8,
                    out_depth.view_mut(),
                    out_confidence.view_mut(),
                ),
        }
        clock.lap(&mut t.refine);
        t.refine += classical_time;
        let (h, w) = depth_warped.dim();
        Ok(ChainReport {
            ran_flow_network: prepared.ran_flow_network,
            ran_direct_fit: prepared.ran_direct_fit,
            ran_fusion_network: prepared.ran_fusion_network,
            calibration: prepared.calibration,
            measurement: prepared.measurement,
            valid_fraction: valid as f32 / (h * w) as f32,
            amplitude_scale: prepared.amplitude_scale,
            alignment,
            rejected_refinement,
            confidence_is_expected_error,
            timings: t,
        })
    }
}

/// `Ok` when `found` is `expected`, else the [`ChainError::Shape`] naming `what`.
fn shape_check(what: &'static str, found: &[usize], expected: &[usize]) -> Result<(), ChainError> {
    if found == expected {
        Ok(())
    } else {
        Err(ChainError::Shape {
            what,
            expected: expected.to_vec(),
            found: found.to_vec(),
        })
    }
}

/// The two fits of a `Full` frame.
struct NetworkFit {
    /// The robust fit of `W_rough` against `D_rgb`.
    fit: Result<Measurement, LsqError>,
    /// `Some` when the direct fit ran: its measurement, `None` inside when it fell back.
    direct: Option<Option<Measurement>>,
}

/// What [`DearChain::measure`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasureReport {
    /// The direct fit when it ran and was confident, otherwise the robust fit of `W_rough`
    /// (or why it failed).
    pub measurement: Result<Measurement, LsqError>,
    /// Whether the direct fit ran.
    pub ran_direct_fit: bool,
    /// Preprocess, flow (rough-flow network) and calibrate (the fits).
    pub timings: StageTimings,
}

/// Wall-clock laps for [`StageTimings`].
struct Stopwatch(Instant);

impl Stopwatch {
    fn start() -> Self {
        Stopwatch(Instant::now())
    }

    /// Stores the time since the last lap in `slot`.
    fn lap(&mut self, slot: &mut Duration) {
        let now = Instant::now();
        *slot = now - self.0;
        self.0 = now;
    }
}

/// `W_convt = t / D + c` where `D` is valid; leaves `flow` (holding `W_rough`) elsewhere.
fn convt_flow_into(calib: &Calibration, depth: ArrayView2<f32>, flow: &mut Flow) {
    Zip::from(&mut flow.u)
        .and(&mut flow.v)
        .and(&depth)
        .par_for_each(|u, v, &z| {
            if let Some((fu, fv)) = calib.flow_at(z) {
                *u = fu;
                *v = fv;
            }
        });
}
