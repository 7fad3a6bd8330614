//! The online calibration estimate kept across restarts (`[runtime] state_file`): a module that
//! drifted away from its factory calibration starts the next run where the last one left off,
//! instead of re-learning it from the factory values.
//!
//! The daemon writes the estimate of its latest frame (when it came from the online estimator)
//! atomically at every statistics interval and at shutdown; at start it restores the file when
//! the stream has the same size, and logs the estimate's age. An explicit
//! `[pipeline] static_calibration` still wins: it is the user's override.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use dear_capture::Calibration;
use dear_proto::{flags, FrameHeader};
use serde::{Deserialize, Serialize};

/// The file's content.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationState {
    /// `"deard-calibration-state"`.
    pub format: String,
    pub width: u32,
    pub height: u32,
    pub calibration: Calibration,
    /// The estimator's quality in [0, 1] when it was saved.
    pub quality: f32,
    /// When it was saved, milliseconds since the Unix epoch. An integer: serde_json's default
    /// float parser can read a written f64 back one ulp off, and the file must read back as
    /// it was written.
    pub saved_unix_ms: u64,
    /// The source it was estimated on (for a reader; not checked).
    pub source: String,
}

const FORMAT: &str = "deard-calibration-state";

/// Why a state file could not be used or written.
#[derive(Debug, thiserror::Error)]
pub enum StateError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: not a calibration state file: {source}", path.display())]
    Parse {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },
}

impl CalibrationState {
    /// The estimate a published frame carries, if it came from the online estimator.
    pub fn from_header(header: &FrameHeader, source: &str) -> Option<Self> {
        if header.flags & flags::CALIBRATION_ONLINE == 0 {
            return None;
        }
        let calibration = Calibration {
            tx: header.calib_tx,
            ty: header.calib_ty,
            cx: header.calib_cx,
            cy: header.calib_cy,
        };
        if [
            calibration.tx,
            calibration.ty,
            calibration.cx,
            calibration.cy,
        ]
        .iter()
        .any(|v| !v.is_finite())
        {
            return None;
        }
        Some(CalibrationState {
            format: FORMAT.into(),
            width: header.width,
            height: header.height,
            calibration,
            quality: header.calib_quality,
            saved_unix_ms: unix_ms(SystemTime::now()),
            source: source.into(),
        })
    }

    /// Reads `path`: `Ok(None)` when there is no file yet.
    pub fn load(path: &Path) -> Result<Option<Self>, StateError> {
        let text =
            match dear_capture::input::read_text_limited(path, dear_capture::input::SETTINGS_LIMIT)
            {
                Ok(text) => text,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
                Err(source) => {
                    return Err(StateError::Io {
                        path: path.into(),
                        source,
                    })
                }
            };
        let state: CalibrationState =
            serde_json::from_str(&text).map_err(|source| StateError::Parse {
                path: path.into(),
                source,
            })?;
        let c = &state.calibration;
        if state.format != FORMAT || [c.tx, c.ty, c.cx, c.cy].iter().any(|v| !v.is_finite()) {
            return Err(StateError::Invalid {
                path: path.into(),
                message: format!("format {:?} or a non-finite calibration", state.format),
            });
        }
        Ok(Some(state))
    }

    /// Writes `path` through a temporary file and a rename (a crash leaves the old or the new
    /// file, never half of one).
    pub fn save(&self, path: &Path) -> Result<(), StateError> {
        let io = |source| StateError::Io {
            path: path.into(),
            source,
        };
        let tmp = path.with_extension("json.tmp");
        let text = serde_json::to_string_pretty(self).expect("plain data serialises");
        std::fs::write(&tmp, text).map_err(io)?;
        std::fs::rename(&tmp, path).map_err(io)
    }

    /// How long ago it was saved (zero for a clock that went back).
    pub fn age(&self) -> Duration {
        Duration::from_millis(unix_ms(SystemTime::now()).saturating_sub(self.saved_unix_ms))
    }
}

/// Milliseconds since the Unix epoch (0 for a clock set before it).
fn unix_ms(t: SystemTime) -> u64 {
    t.duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(online: bool) -> FrameHeader {
        let mut h = FrameHeader::new(3, 320, 240);
        h.calib_tx = -5.0;
        h.calib_ty = 0.5;
        h.calib_cx = 1.25;
        h.calib_cy = -0.75;
        h.calib_quality = 0.8;
        h.flags = if online {
            flags::CALIBRATION_ONLINE | flags::ALIGNED
        } else {
            flags::ALIGNED
        };
        h
    }

    #[test]
    fn an_online_estimate_round_trips_through_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("calibration.json");
        assert!(
            CalibrationState::load(&path).unwrap().is_none(),
            "no file yet"
        );
        let state = CalibrationState::from_header(&header(true), "replay x").unwrap();
        state.save(&path).unwrap();
        let back = CalibrationState::load(&path).unwrap().unwrap();
        assert_eq!(back, state);
        assert_eq!(back.calibration.cx, 1.25);
        assert!(back.age() < Duration::from_secs(60));
        assert!(!dir.path().join("calibration.json.tmp").exists());
    }

    #[test]
    fn a_static_calibration_is_not_an_estimate_to_keep() {
        assert!(CalibrationState::from_header(&header(false), "x").is_none());
    }

    #[test]
    fn a_damaged_file_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("calibration.json");
        std::fs::write(&path, "{\"format\": 3").unwrap();
        let err = CalibrationState::load(&path).unwrap_err().to_string();
        assert!(err.contains("calibration.json"), "{err}");
    }
}
