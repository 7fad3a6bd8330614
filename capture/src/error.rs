//! Errors of the capture-directory codecs. Every variant names the file it is about, so a user
//! (or the daemon's log) can go straight to the broken frame.

use std::path::{Path, PathBuf};

/// What went wrong reading or writing a capture directory.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: missing file")]
    Missing { path: PathBuf },
    #[error("{path}: cannot decode PNG: {message}")]
    Decode { path: PathBuf, message: String },
    #[error("{path}: expected {expected}, found {found}")]
    Format {
        path: PathBuf,
        expected: String,
        found: String,
    },
    #[error("{path}: image is {found_w}x{found_h}, the capture is {width}x{height}")]
    Resolution {
        path: PathBuf,
        width: u32,
        height: u32,
        found_w: u32,
        found_h: u32,
    },
    #[error("{path}: invalid manifest: {message}")]
    Manifest { path: PathBuf, message: String },
    #[error("{path}: cannot encode: {message}")]
    Encode { path: PathBuf, message: String },
}

impl CaptureError {
    /// The file this error is about.
    pub fn path(&self) -> &std::path::Path {
        match self {
            CaptureError::Io { path, .. }
            | CaptureError::Missing { path }
            | CaptureError::Decode { path, .. }
            | CaptureError::Format { path, .. }
            | CaptureError::Resolution { path, .. }
            | CaptureError::Manifest { path, .. }
            | CaptureError::Encode { path, .. } => path,
        }
    }

    /// `path` holds an image of `found` (width, height) where the capture is `expected`.
    pub(crate) fn resolution(path: &Path, expected: (u32, u32), found: (u32, u32)) -> Self {
        CaptureError::Resolution {
            path: path.to_owned(),
            width: expected.0,
            height: expected.1,
            found_w: found.0,
            found_h: found.1,
        }
    }

    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        let path = path.into();
        if source.kind() == std::io::ErrorKind::NotFound {
            CaptureError::Missing { path }
        } else {
            CaptureError::Io { path, source }
        }
    }
}
