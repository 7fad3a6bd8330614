//! Errors of model-bundle loading and running. Every variant names the file or the graph it is
//! about, so a log line is enough to find what is broken in a bundle.

use std::path::PathBuf;

/// What is wrong with a model bundle, or with running one.
#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    /// The bundle directory or one of its files is missing.
    #[error("{path}: missing (a model bundle is a directory with model.json, flow.onnx, fuse.onnx and refine.onnx)")]
    Missing {
        /// The missing path.
        path: PathBuf,
    },
    /// The bundle path is not a directory (a file, a FIFO).
    #[error("{path}: not a directory (a model bundle is a directory with model.json, flow.onnx, fuse.onnx and refine.onnx)")]
    NotADirectory {
        /// The path given as the bundle.
        path: PathBuf,
    },
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// `model.json` is not valid JSON or lacks a required field.
    #[error("{path}: invalid manifest: {message}")]
    Manifest {
        /// Path of `model.json`.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A graph file does not have the SHA-256 that `model.json` records: tampered, truncated
    /// or from another export.
    #[error(
        "{path}: SHA-256 mismatch: model.json records {expected}, the file hashes to {actual}"
    )]
    Checksum {
        /// The graph file.
        path: PathBuf,
        /// Hex digest recorded in `model.json`.
        expected: String,
        /// Hex digest of the file on disk.
        actual: String,
    },
    /// A graph file's size differs from the size `model.json` records.
    #[error("{path}: size mismatch: model.json records {expected} bytes, the file has {actual}")]
    Size {
        /// The graph file.
        path: PathBuf,
        /// Bytes recorded in `model.json`.
        expected: u64,
        /// Bytes on disk.
        actual: u64,
    },
    /// A graph's inputs or outputs do not match what the DEAR chain feeds it / reads from it
    /// (names, count, channels), in `model.json` or in the ONNX file itself.
    #[error("{path}: graph `{graph}` breaks the I/O contract: {message}")]
    Contract {
        /// The graph file (or `model.json` when the manifest itself is at fault).
        path: PathBuf,
        /// `flow`, `fuse` or `refine`.
        graph: &'static str,
        /// What is wrong.
        message: String,
    },
    /// tract could not parse, type or optimise an ONNX file.
    #[error("{path}: cannot load ONNX graph `{graph}`: {message}")]
    Onnx {
        /// The graph file.
        path: PathBuf,
        /// `flow`, `fuse` or `refine`.
        graph: &'static str,
        /// tract's error chain.
        message: String,
    },
    /// A stream resolution the runner cannot serve (zero, or too large to pad).
    #[error("unsupported stream resolution {width}x{height}: {message}")]
    Resolution {
        /// Requested width.
        width: usize,
        /// Requested height.
        height: usize,
        /// Why.
        message: String,
    },
    /// Running a graph failed, or its output has an unexpected shape.
    #[error("running graph `{graph}` failed: {message}")]
    Run {
        /// `flow`, `fuse` or `refine`.
        graph: &'static str,
        /// tract's error chain or the shape problem.
        message: String,
    },
    /// An input handed to the runner does not have the stream's shape.
    #[error("input `{input}` of graph `{graph}` has shape {found:?}, expected {expected:?}")]
    InputShape {
        /// `flow`, `fuse` or `refine`.
        graph: &'static str,
        /// The input's name.
        input: &'static str,
        /// Expected `(height, width)`.
        expected: (usize, usize),
        /// Shape received.
        found: (usize, usize),
    },
}

impl BundleError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        let path = path.into();
        if source.kind() == std::io::ErrorKind::NotFound {
            BundleError::Missing { path }
        } else {
            BundleError::Io { path, source }
        }
    }
}
