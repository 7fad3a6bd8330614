//! `dear-pipeline`: the DEAR algorithm, independent of how frames are captured or published.
//! The frame, flow and calibration types it works on (and the capture-directory format) are
//! the `dear-capture` crate's: [`dear_capture::RgbdFrame`], [`dear_capture::Flow`],
//! [`dear_capture::Calibration`] (the weak-calibration flow model `W = t / z + c`).
//!
//! - [`align`]: aligning ToF depth to RGB with a known calibration;
//! - [`geometry`]: warping, depth↔flow, forward splatting, registration of a live ToF image;
//! - [`recalibration`]: estimating the weak calibration from the frames — the least-squares
//!   fit of a flow, the edge maps and the direct fit to them, and online re-estimation of the
//!   drifting calibration (estimator, observability and health, the per-frame edge check);
//! - [`filter`]: the classical edge-aware refinement baseline;
//! - [`model`]: model bundles (ONNX graphs + manifest) run by tract (feature `inference`);
//! - [`chain`]: the paper's per-frame chain of networks and geometry, and its calibration
//!   measurement off the frame path (feature `inference`);
//! - [`engine`]: the per-frame engine deard runs with a bundle (chain, online estimator,
//!   measurement off the frame path, output guard) and `dear eval --online` evaluates
//!   (feature `inference`);
//! - [`simd`]: the instruction sets the hot loops are compiled for, and which one runs;
//! - [`threads`]: the frame path's thread pool, optionally pinned one thread per CPU.
//!
//! The evaluation behind `dear eval` (metrics, methods and baselines, reports) is the
//! `dear-eval` crate, which depends on this one; the runtime does not.

pub mod align;
#[cfg(feature = "inference")]
pub mod chain;
#[cfg(feature = "inference")]
pub mod engine;
pub mod filter;
pub mod geometry;
#[cfg(feature = "inference")]
pub mod model;
pub mod recalibration;
pub mod simd;
pub mod threads;
mod vector_math;
