//! The capture-directory format (docs/design.md): one format for simulator output, recordings and
//! replay. [`manifest`] is `capture.json`; [`reader`] opens and validates a directory;
//! [`writer`] creates one; [`png`] and [`flo`] are the per-file codecs; [`layout`] names the
//! files. Every error names the file it is about ([`CaptureError::path`]).

pub mod error;
pub mod flo;
pub mod layout;
pub mod manifest;
pub mod png;
pub mod reader;
pub mod writer;

pub use error::CaptureError;
pub use layout::FramePaths;
pub use manifest::{CaptureManifest, FrameEntry, Intrinsics};
pub use reader::CaptureDir;
pub use writer::CaptureWriter;
