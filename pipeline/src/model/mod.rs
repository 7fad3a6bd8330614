//! Model bundles: the three ONNX graphs of DEAR (rough flow, flow fusion, depth refinement)
//! with their manifest, verified and run by `tract` (crate feature `inference`).
//!
//! - [`manifest`]: `model.json` and the graphs' I/O contract;
//! - [`bundle`]: [`ModelBundle::load`], checksum and contract checks;
//! - [`kernel_apply`]: the full-resolution tail of a format-2 (`gated`) refiner, in Rust;
//! - [`runner`]: [`BundleRunner`], the graphs optimised for one stream resolution, with
//!   replicate padding to the bundle's size multiple;
//! - [`error`]: the error type, [`BundleError`].
//!
//! The warps, the least-squares calibration and the normalisation are not in the graphs: they
//! run in Rust ([`crate::chain`]) between the three networks.

pub mod bundle;
pub mod error;
pub mod kernel_apply;
pub mod manifest;
pub mod runner;
mod stacked_input;

pub use bundle::{hex_sha256, ModelBundle};
pub use error::BundleError;
pub use kernel_apply::ClassicalEstimate;
pub use manifest::{GraphRole, Manifest, Normalisation, RefineApply};
pub use runner::{BundleRunner, RunnerOptions};
