//! The DEAR per-frame chain on device (feature `inference`): preprocessing, the three networks
//! of a [`ModelBundle`](crate::model::ModelBundle) and the geometry between them, writing
//! aligned refined depth and a confidence map into caller-provided views.
//!
//! - [`preprocess`]: amplitude and RGB normalisation as the bundle defines it;
//! - [`dear_chain`]: [`DearChain`], `Full` (the paper) and `Cached(calibration)` modes, a frame in
//!   two halves that consecutive frames can overlap;
//! - [`background`]: [`BackgroundCalibrator`], a `Full` frame's calibration measurement on a
//!   worker thread, so network frames do not stall the frame path, and [`DelayedCalibrator`],
//!   its deterministic stand-in for evaluation;
//! - [`confidence`]: the published per-pixel confidence and its definition;
//! - [`output_guard`]: [`OutputGuard`], the refinement network's output checked against
//!   physics; a frame it rejects is refined classically instead.

pub mod background;
pub mod confidence;
pub mod dear_chain;
pub mod output_guard;
pub mod preprocess;

pub use background::{BackgroundCalibrator, DelayedCalibrator, Delivered, Submit};
pub use dear_chain::{
    CachedFusion, ChainError, ChainInput, ChainMode, ChainOptions, ChainOutput, ChainReport,
    DearChain, MeasureReport, Prepared, StageTimings,
};
pub use output_guard::{OutputGuard, RefinementCheck};
