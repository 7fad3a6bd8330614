//! `dear-capture`: the capture-directory format (docs/capture-format.md),
//! one format for simulator output, recordings, replay, evaluation and training.
//!
//! - [`manifest`]: `capture.json`, its types and the rules it is validated by;
//! - [`schema`]: the JSON Schema of `capture.json`, generated from those types (checked in as
//!   `schema/capture.schema.json`, what the Python reader validates against);
//! - [`reader`] opens and validates a directory, [`writer`] creates one;
//! - [`prefetch`] reads a capture's frames ahead on a thread of its own (the daemon's replay);
//! - [`png`] and [`flo`] are the per-file codecs, [`layout`] names the files;
//! - [`frame`]: the in-memory sensor frame, its ground truth and the two together (a
//!   [`Sample`]), and [`calibration`] the weak-calibration model the ground truth is given in.
//!
//! Every error names the file it is about ([`CaptureError::path`]). The crate knows nothing of
//! the algorithm; every crate that reads frames, flows or calibrations names them here
//! (`dear_capture::RgbdFrame`, not through `dear-pipeline`).

pub mod calibration;
pub mod error;
pub mod flo;
pub mod frame;
pub mod input;
pub mod layout;
pub mod manifest;
pub mod png;
pub mod prefetch;
pub mod reader;
pub mod schema;
pub mod writer;

pub use calibration::Calibration;
pub use error::CaptureError;
pub use frame::{is_valid_depth, Flow, GroundTruth, RgbdFrame, Sample};
pub use layout::FramePaths;
pub use manifest::{parse_intrinsics, CaptureManifest, FrameEntry, Intrinsics};
pub use prefetch::{FramePrefetch, PrefetchOptions, Prefetched};
pub use reader::CaptureDir;
pub use writer::CaptureWriter;
