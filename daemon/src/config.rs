//! `deard`'s configuration: a TOML file (every key optional, unknown keys rejected), then
//! command-line flags on top. `deard --print-config` prints the effective configuration, and
//! `daemon/deard.example.toml` documents every key with its default.

use std::path::{Path, PathBuf};

use dear_pipeline::Calibration;
use serde::{Deserialize, Serialize};

/// The whole configuration.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    pub service: ServiceConfig,
    pub capture: CaptureConfig,
    pub pipeline: PipelineConfig,
    pub runtime: RuntimeConfig,
}

/// Where frames are published.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServiceConfig {
    /// Camera name; the service is `dear/<camera>/frames` unless `name` is set.
    pub camera: String,
    /// Explicit iceoryx2 service name (overrides `camera`).
    pub name: Option<String>,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        ServiceConfig {
            camera: dear_proto::DEFAULT_CAMERA.to_string(),
            name: None,
        }
    }
}

impl ServiceConfig {
    /// The service name frames are published on.
    pub fn service_name(&self) -> String {
        self.name
            .clone()
            .unwrap_or_else(|| dear_proto::default_service_name(&self.camera))
    }
}

/// How replayed frames are paced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Pacing {
    /// At the recorded timestamps, like a live camera: if processing falls behind, the oldest
    /// waiting frame is dropped and counted.
    Timestamps,
    /// As fast as the pipeline goes, never dropping.
    Fast,
}

/// The frame source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CaptureConfig {
    /// Source kind. Only `"replay"` (a capture directory) exists so far.
    pub source: String,
    /// Capture directory to replay.
    pub path: PathBuf,
    pub pacing: Pacing,
    /// Start again at `start` after the last frame.
    #[serde(rename = "loop")]
    pub loop_: bool,
    /// First frame (position in the frame list, 0-based).
    pub start: usize,
    /// One past the last frame (position); none = to the end.
    pub end: Option<usize>,
    /// Frames waiting between capture and processing before the oldest is dropped.
    pub queue_depth: usize,
}

impl Default for CaptureConfig {
    fn default() -> Self {
        CaptureConfig {
            source: "replay".into(),
            path: PathBuf::from("samples/demo"),
            pacing: Pacing::Timestamps,
            loop_: false,
            start: 0,
            end: None,
            queue_depth: 2,
        }
    }
}

/// What the daemon does to each frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PipelineConfig {
    /// `"dear"` (the default): the DEAR chain with the model bundle `bundle`;
    /// `"classical"`: static calibration + the edge-aware filter, no networks;
    /// `"none"`: static calibration, alignment only.
    pub refine: RefineMode,
    /// Model bundle directory for `refine = "dear"`, relative to the working directory.
    pub bundle: PathBuf,
    /// With `refine = "dear"`: how the calibration is kept up to date.
    pub calibration: CalibrationMode,
    /// With `calibration = "online"`: frames between runs of the rough-flow network (it also
    /// runs early when the alignment residual grows).
    pub online_interval_frames: u32,
    /// With `calibration = "online"`: fraction of the per-frame edge-alignment correction of
    /// the principal point applied between network runs (0 turns tracking off; 0.7 default).
    pub online_track_gain: f32,
    /// Static calibration for `classical`/`none`, and the DEAR engine's fallback before its
    /// first estimate; none = the capture's `initial_calibration`.
    pub static_calibration: Option<Calibration>,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        PipelineConfig {
            refine: RefineMode::Dear,
            bundle: PathBuf::from("models/edge"),
            calibration: CalibrationMode::Online,
            online_interval_frames: 30,
            online_track_gain: 0.7,
            static_calibration: None,
        }
    }
}

/// Depth refinement choice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RefineMode {
    Dear,
    Classical,
    None,
}

/// How the DEAR engine estimates the calibration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CalibrationMode {
    /// Run the flow network every `online_interval_frames` (or when the residual grows) and
    /// align the frames between with the filtered estimate: real-time on small devices.
    Online,
    /// The paper's chain on every frame: flow network, least squares, fusion.
    EveryFrame,
}

/// Process-level behaviour.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RuntimeConfig {
    /// Seconds between statistics lines in the log.
    pub stats_interval_s: f64,
    /// Exit when a non-looping replay ends (otherwise keep the service up until signalled).
    pub exit_when_done: bool,
    /// Log filter (tracing `EnvFilter` syntax); `RUST_LOG` overrides it.
    pub log: String,
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        RuntimeConfig {
            stats_interval_s: 5.0,
            exit_when_done: false,
            log: "info".into(),
        }
    }
}

impl Config {
    /// Reads a TOML file; errors name the file and the offending key.
    pub fn from_file(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::from_toml(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Parses TOML text.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        let config: Config = toml::from_str(text).map_err(|e| e.to_string())?;
        config.validate()?;
        Ok(config)
    }

    /// Checks values serde cannot.
    pub fn validate(&self) -> Result<(), String> {
        dear_proto::validate_service_name(&self.service.service_name())
            .map_err(|e| format!("[service]: {e}"))?;
        if self.capture.source != "replay" {
            return Err(format!(
                "[capture] source = {:?}: supported sources: \"replay\"",
                self.capture.source
            ));
        }
        if self.capture.queue_depth == 0 {
            return Err("[capture] queue_depth must be at least 1".into());
        }
        if let Some(end) = self.capture.end {
            if end <= self.capture.start {
                return Err(format!(
                    "[capture] end = {end} must be greater than start = {}",
                    self.capture.start
                ));
            }
        }
        if self.pipeline.online_interval_frames == 0 {
            return Err("[pipeline] online_interval_frames must be at least 1".into());
        }
        let gain = self.pipeline.online_track_gain;
        if !(0.0..=1.0).contains(&gain) {
            return Err(format!(
                "[pipeline] online_track_gain = {gain} must be within 0..=1 (0 turns tracking off)"
            ));
        }
        if !(self.runtime.stats_interval_s > 0.0 && self.runtime.stats_interval_s.is_finite()) {
            return Err(format!(
                "[runtime] stats_interval_s = {} must be positive",
                self.runtime.stats_interval_s
            ));
        }
        Ok(())
    }
}
