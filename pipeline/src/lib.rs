//! `dear-pipeline`: the DEAR algorithm, independent of how frames are captured or published.
//!
//! - [`align`]: aligning ToF depth to RGB with a known calibration;
//! - [`calibration`]: the weak-calibration flow model `W = t / z + c`;
//! - [`frame`]: in-memory images of one RGB-D frame;
//! - [`crossmodal`]: classical RGB↔amplitude edge matching (a baseline);
//! - [`direct`]: direct fit of the calibration to all edge pixels at once (edge correlation);
//! - [`capture`]: the capture-directory format (read, validate, write);
//! - [`geometry`]: warping, least-squares calibration, depth↔flow, forward splatting;
//! - [`metrics`]: AEPE and the paper's quantile-split depth MAE;
//! - [`evaluate`]: methods and metric accumulation behind `dear eval` (feature `evaluate`, not in
//!   the daemon's build);
//! - [`filter`]: the classical edge-aware refinement baseline;
//! - [`model`]: model bundles (ONNX graphs + manifest) run by tract (feature `inference`);
//! - [`dear`]: the paper's per-frame chain of networks and geometry (feature `inference`);
//! - [`online`]: online re-estimation of the drifting calibration.

pub mod align;
pub mod calibration;
pub mod capture;
pub mod crossmodal;
#[cfg(feature = "inference")]
pub mod dear;
pub mod direct;
#[cfg(feature = "evaluate")]
pub mod evaluate;
pub mod filter;
pub mod frame;
pub mod geometry;
pub mod metrics;
#[cfg(feature = "inference")]
pub mod model;
pub mod online;

pub use calibration::Calibration;
pub use frame::{Flow, RgbdFrame};
pub use geometry::is_valid_depth;
