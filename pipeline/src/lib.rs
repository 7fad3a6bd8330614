//! `dear-pipeline`: the DEAR algorithm, independent of how frames are captured or published.
//!
//! - [`align`]: aligning ToF depth to RGB with a known calibration;
//! - [`calibration`]: the weak-calibration flow model `W = t / z + c`;
//! - [`frame`]: in-memory images of one RGB-D frame;
//! - [`capture`]: the capture-directory format (read, validate, write);
//! - [`geometry`]: warping, least-squares calibration, depth↔flow, forward splatting;
//! - [`metrics`]: AEPE and the paper's quantile-split depth MAE;
//! - [`filter`]: the classical edge-aware refinement baseline.

pub mod align;
pub mod calibration;
pub mod capture;
pub mod filter;
pub mod frame;
pub mod geometry;
pub mod metrics;

pub use calibration::Calibration;
pub use frame::{Flow, RgbdFrame};
