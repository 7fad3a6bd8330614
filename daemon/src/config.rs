//! `deard`'s configuration: a TOML file (every key optional, unknown keys rejected), then
//! command-line flags on top. `deard --print-config` prints the effective configuration, and
//! `daemon/deard.example.toml` documents every key with its default.

use std::path::{Path, PathBuf};

use dear_capture::Calibration;
use serde::{Deserialize, Serialize};

/// Why a configuration cannot be used. Every message names the file (when there is one) and
/// the key, and says what is allowed.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("{}: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The text is not TOML, or has an unknown key or a value of the wrong type.
    #[error("{0}")]
    Parse(#[from] toml::de::Error),
    /// A value parses but cannot work; the message names the key and the allowed values.
    #[error("{0}")]
    Invalid(String),
    /// One of the above in a file.
    #[error("{}: {source}", path.display())]
    InFile {
        path: PathBuf,
        #[source]
        source: Box<ConfigError>,
    },
}

/// Checks a log filter (`[runtime] log`, `RUST_LOG`): comma-separated directives, each a level
/// (`off`, `error`, `warn`, `info`, `debug`, `trace`) or `target=level` (a span filter
/// `target[span]=level` too). tracing's own parser takes a bare word that is not a level as a
/// *target* enabled at every level, so a misspelt level (`inof`) or junk (`[[[`) silently
/// turned every other log line off, errors included; here it is refused, naming the
/// directive. The error text starts with the filter in quotes.
pub fn validate_log_filter(filter: &str) -> Result<(), String> {
    use std::str::FromStr;
    use tracing_subscriber::filter::{Directive, LevelFilter};
    let levels = "off, error, warn, info, debug, trace";
    for directive in filter.split(',').map(str::trim).filter(|d| !d.is_empty()) {
        let bad = |why: String| Err(format!("{filter:?}: directive {directive:?} {why}"));
        match directive.rsplit_once('=') {
            None if LevelFilter::from_str(directive).is_ok() => {}
            None => {
                return bad(format!(
                    "is not a level ({levels}); a per-target level is written target=level"
                ))
            }
            Some((target, level)) => {
                if LevelFilter::from_str(level.trim()).is_err() {
                    return bad(format!("sets level {level:?}, expected one of {levels}"));
                }
                if target.trim().is_empty() {
                    return bad("has no target before '='".into());
                }
                if let Err(e) = Directive::from_str(directive) {
                    return bad(format!("is not a tracing filter directive: {e}"));
                }
            }
        }
    }
    Ok(())
}

/// Default `[capture] queue_depth`. A queue only fills while processing is behind, so its depth
/// adds no latency to a stream the daemon keeps up with; at 640×480 and 30 fps on two cores
/// (frame path, PNG decoding and the background measurement keep them about 90 % busy) bursts
/// of slow frames overflowed a queue of 2: `scripts/replay_drops.sh` dropped 6–15 of 3,000
/// frames with 2, 0–1 with 4 (docs/performance.md). Each waiting frame is a full RGB-D frame
/// (3.4 MB at 640×480).
pub const DEFAULT_QUEUE_DEPTH: usize = 4;
/// Largest `[capture] queue_depth`: a few frames absorb jitter; a longer queue only adds memory
/// and latency (each waiting frame is a full RGB-D frame).
pub const MAX_QUEUE_DEPTH: usize = 64;
/// Default `[service] max_subscribers_per_user`: two of the eight slots stay for other users.
pub const DEFAULT_SUBSCRIBERS_PER_USER: usize = dear_proto::service::QOS_MAX_SUBSCRIBERS - 2;
/// Largest `[service] max_shared_memory_mb`: 64 GiB.
pub const MAX_SHARED_MEMORY_MB: u64 = 65_536;
/// Longest `[runtime] stats_interval_s`: a day.
pub const MAX_STATS_INTERVAL_S: f64 = 86_400.0;
/// Shortest `[runtime] stats_interval_s`: a millisecond (a positive value below a nanosecond,
/// e.g. `5e-324`, became a zero `Duration` and a statistics line per frame).
pub const MIN_STATS_INTERVAL_S: f64 = 0.001;
/// Largest `|t_x|`, `|t_y|` of `[pipeline] static_calibration`, px·m: a 10 cm baseline at a
/// 10,000 px focal length. At start-up the bound tightens to the image size (see
/// [`check_calibration_fits`]).
pub const MAX_CALIBRATION_T: f32 = 1000.0;
/// Largest `|c_x|`, `|c_y|` of `[pipeline] static_calibration`, px: the largest image side a
/// capture may have. At start-up the bound tightens to the image size.
pub const MAX_CALIBRATION_C: f32 = 8192.0;

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
    /// Largest shared memory the frame service may take, MB (1..=[`MAX_SHARED_MEMORY_MB`]):
    /// the publisher's data segment holds `dear_proto::samples_in_shared_memory()` frames. A
    /// stream that needs more, or more than the transport's root directory has free, is refused
    /// at start.
    pub max_shared_memory_mb: u64,
    /// Subscriber slots one user other than the service's own (and root) may hold, of the
    /// service's [`dear_proto::service::QOS_MAX_SUBSCRIBERS`] (1..= that). Beyond it the
    /// daemon removes that user's newest subscribers every second, so that one member of the
    /// service's group cannot keep every other client out (issue 34).
    pub max_subscribers_per_user: usize,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        ServiceConfig {
            camera: dear_proto::DEFAULT_CAMERA.to_string(),
            name: None,
            max_shared_memory_mb: 1024,
            max_subscribers_per_user: DEFAULT_SUBSCRIBERS_PER_USER,
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
    /// Source kind: `"replay"` (a capture directory, `path`) or `"v4l"` (a live module's
    /// V4L2 nodes, `[capture.v4l]`).
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
    /// Frames waiting between capture and processing before the oldest is dropped
    /// (1..=[`MAX_QUEUE_DEPTH`]).
    pub queue_depth: usize,
    /// With `source = "v4l"`: the module's ToF and RGB nodes and its calibration file.
    pub v4l: Option<V4lConfig>,
    /// Write the source's frames to this new (or empty) directory as a capture directory while
    /// serving (`deard --record`); `deard --replay` processes them again bit for bit.
    pub record: Option<PathBuf>,
}

impl CaptureConfig {
    /// The live module's tables when the source is `"v4l"` (validation made sure they exist).
    pub fn live(&self) -> Option<&V4lConfig> {
        self.v4l.as_ref().filter(|_| self.source == "v4l")
    }
}

/// A live ToF RGB-D module: two V4L2 capture nodes paired by timestamp, registered onto the RGB
/// grid with the module's calibration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct V4lConfig {
    /// The module's calibration (TOML: both cameras' intrinsics, the ToF → RGB rotation and
    /// translation, the depth scale; `daemon/module.example.toml` documents it).
    pub calibration: PathBuf,
    pub tof: TofNodeConfig,
    pub rgb: NodeConfig,
    /// With a depth format (`Z16 `/`Y16 `): the node of the same sensor's amplitude / IR image
    /// (`GREY`, `Y16 `; RealSense's infrared node), paired with the depth by timestamp. Without
    /// it, amplitude is 1 wherever depth is valid.
    pub amplitude: Option<NodeConfig>,
    /// Largest timestamp difference of a ToF and an RGB frame that are paired, milliseconds;
    /// none = half the slower node's frame period.
    pub pair_tolerance_ms: Option<f64>,
}

/// One V4L2 capture node and the format to stream it in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeConfig {
    /// Device node, e.g. `/dev/video0` (or a stable `/dev/v4l/by-id/…` link).
    pub device: PathBuf,
    /// FourCC, four characters (`"YUYV"`, `"Z16 "` with its trailing space). `dear devices`
    /// lists what each node offers.
    pub format: String,
    pub width: u32,
    pub height: u32,
    /// Frames per second to ask for; none = the node's current rate.
    pub fps: Option<u32>,
    /// V4L2 controls by name as `dear devices` prints them (`exposure_time_absolute = 100`).
    #[serde(default)]
    pub controls: std::collections::BTreeMap<String, i64>,
}

/// The ToF node: a depth format (`Z16 `, `Y16 `: depth units times the calibration's
/// `depth_scale_m`) or raw 4-phase frames demodulated in the daemon (`Y12 `: four consecutive
/// buffers; `Y12P`: the four phases stacked in one buffer of 4 × `height` rows).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TofNodeConfig {
    #[serde(flatten)]
    pub node: NodeConfig,
    /// 4-phase formats: the modulation frequency, Hz (Arducam ToF: 75e6 for its 2 m range,
    /// 37.5e6 for 4 m). Any format: depth beyond its unambiguous range `c / 2f` is invalid.
    pub modulation_hz: Option<f64>,
    /// 4-phase formats: `"standard"` (Q = D1 − D3) or `"inverted"` (Q = D3 − D1, Arducam).
    #[serde(default)]
    pub q_sign: QSignConfig,
    /// 4-phase formats: amplitude (raw units) below which a pixel's depth is invalid.
    #[serde(default)]
    pub min_amplitude: f32,
}

/// Sign of the quadrature term of a 4-phase module.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum QSignConfig {
    #[default]
    Standard,
    Inverted,
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
            queue_depth: DEFAULT_QUEUE_DEPTH,
            v4l: None,
            record: None,
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
    /// With `calibration = "online"`: where the rough-flow network runs. `"background"` (the
    /// default): on a worker thread of lower priority, so no frame waits for it (its
    /// calibration applies from the first frame after it is ready); `"inline"`: on the frame
    /// that asked for it, which then takes the network's time (deterministic; `dear eval
    /// --online` runs the background schedule made deterministic, `dear_pipeline::engine`).
    pub online_network: NetworkPlacement,
    /// Static calibration for `classical`/`none`, and the DEAR engine's fallback before its
    /// first estimate; none = the capture's `initial_calibration`. Finite, `|t| ≤`
    /// [`MAX_CALIBRATION_T`] px·m and `|c| ≤` [`MAX_CALIBRATION_C`] px here; at start-up
    /// within the image size ([`check_calibration_fits`]).
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
            online_network: NetworkPlacement::Background,
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

impl CalibrationMode {
    /// The name used in the configuration file and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            CalibrationMode::Online => "online",
            CalibrationMode::EveryFrame => "every-frame",
        }
    }
}

impl std::str::FromStr for CalibrationMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        [CalibrationMode::Online, CalibrationMode::EveryFrame]
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("{s:?}: expected \"online\" or \"every-frame\""))
    }
}

/// Where the online mode's network frames run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NetworkPlacement {
    /// On a background worker; frames never wait for it.
    Background,
    /// On the frame that asked for it.
    Inline,
}

impl NetworkPlacement {
    /// The name used in the configuration file and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            NetworkPlacement::Background => "background",
            NetworkPlacement::Inline => "inline",
        }
    }
}

impl std::str::FromStr for NetworkPlacement {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        [NetworkPlacement::Background, NetworkPlacement::Inline]
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("{s:?}: expected \"background\" or \"inline\""))
    }
}

/// Process-level behaviour.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RuntimeConfig {
    /// Seconds between statistics lines in the log
    /// ([`MIN_STATS_INTERVAL_S`] ≤ s ≤ [`MAX_STATS_INTERVAL_S`]).
    pub stats_interval_s: f64,
    /// Exit when a non-looping replay ends (otherwise keep the service up until signalled).
    pub exit_when_done: bool,
    /// Log filter (tracing `EnvFilter` syntax); `RUST_LOG` overrides it.
    pub log: String,
    /// Where the online calibration estimate is kept across restarts (written at every
    /// statistics line and at shutdown, restored at start for a stream of the same size unless
    /// `[pipeline] static_calibration` is set); none = not kept.
    pub state_file: Option<PathBuf>,
    /// Pin each of the frame path's threads to a CPU of its own, one per CPU the daemon may
    /// run on (or `RAYON_NUM_THREADS` of them, the first ones): steadier frame times on CPUs
    /// the daemon has to itself, much slower frames when another process keeps one of them
    /// busy (`dear_pipeline::threads` has the measurements).
    pub pin_threads: bool,
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        RuntimeConfig {
            stats_interval_s: 5.0,
            exit_when_done: false,
            log: "info".into(),
            state_file: None,
            pin_threads: false,
        }
    }
}

impl Config {
    /// Reads a TOML file; errors name the file and the offending key.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let limit = dear_capture::input::SETTINGS_LIMIT;
        let text = dear_capture::input::read_text_limited(path, limit).map_err(|source| {
            ConfigError::Read {
                path: path.to_path_buf(),
                source,
            }
        })?;
        Self::from_toml(&text).map_err(|e| ConfigError::InFile {
            path: path.to_path_buf(),
            source: Box::new(e),
        })
    }

    /// Parses TOML text.
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        let config: Config = toml::from_str(text)?;
        config.validate()?;
        Ok(config)
    }

    /// Checks values serde cannot. Errors name the key and the allowed values.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.check().map_err(ConfigError::Invalid)
    }

    /// [`validate`](Self::validate)'s checks, with the message of the first that fails.
    fn check(&self) -> Result<(), String> {
        self.validate_service()?;
        let shm = self.service.max_shared_memory_mb;
        if !(1..=MAX_SHARED_MEMORY_MB).contains(&shm) {
            return Err(format!(
                "[service] max_shared_memory_mb = {shm} must be within 1..={MAX_SHARED_MEMORY_MB}"
            ));
        }
        let per_user = self.service.max_subscribers_per_user;
        let slots = dear_proto::service::QOS_MAX_SUBSCRIBERS;
        if !(1..=slots).contains(&per_user) {
            return Err(format!(
                "[service] max_subscribers_per_user = {per_user} must be within 1..={slots} (the service's subscriber slots)"
            ));
        }
        match (self.capture.source.as_str(), &self.capture.v4l) {
            ("replay", _) => {}
            ("v4l", Some(v4l)) => check_v4l(v4l)?,
            ("v4l", None) => {
                return Err(
                    "[capture] source = \"v4l\" needs a [capture.v4l] table (calibration, \
                     [capture.v4l.tof], [capture.v4l.rgb]; see daemon/deard.example.toml)"
                        .into(),
                )
            }
            (other, _) => {
                return Err(format!(
                    "[capture] source = {other:?}: supported sources: \"replay\", \"v4l\""
                ))
            }
        }
        let depth = self.capture.queue_depth;
        if !(1..=MAX_QUEUE_DEPTH).contains(&depth) {
            return Err(format!(
                "[capture] queue_depth = {depth} must be within 1..={MAX_QUEUE_DEPTH}"
            ));
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
        if let Some(calibration) = &self.pipeline.static_calibration {
            check_calibration(
                "[pipeline] static_calibration",
                calibration,
                (MAX_CALIBRATION_T, MAX_CALIBRATION_T),
                (MAX_CALIBRATION_C, MAX_CALIBRATION_C),
                "",
            )?;
        }
        validate_log_filter(&self.runtime.log).map_err(|e| format!("[runtime] log = {e}"))?;
        let stats = self.runtime.stats_interval_s;
        // Written so that NaN fails too.
        if !(MIN_STATS_INTERVAL_S..=MAX_STATS_INTERVAL_S).contains(&stats) {
            return Err(format!(
                "[runtime] stats_interval_s = {stats} must be within {MIN_STATS_INTERVAL_S} <= s <= {MAX_STATS_INTERVAL_S} seconds"
            ));
        }
        Ok(())
    }

    /// The camera name is one segment of `dear/<camera>/frames`; an explicit name has no empty
    /// segment; either way the result is a valid service name.
    fn validate_service(&self) -> Result<(), String> {
        let camera = &self.service.camera;
        if camera.is_empty() {
            return Err(format!("[service] camera = \"\" is empty; {SEGMENT_RULE}"));
        }
        if let Some(c) = camera
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || "_-.".contains(*c)))
        {
            return Err(format!(
                "[service] camera = {camera:?} contains {c:?}; {SEGMENT_RULE}"
            ));
        }
        let key = match &self.service.name {
            Some(name) => {
                if name.split('/').any(str::is_empty) {
                    return Err(format!(
                        "[service] name = {name:?} has an empty segment (a leading, trailing or doubled '/')"
                    ));
                }
                "name"
            }
            None => "camera",
        };
        dear_proto::validate_service_name(&self.service.service_name())
            .map_err(|e| format!("[service] {key}: {e}"))
    }
}

/// The node tables of `[capture.v4l]`: four-character formats the daemon decodes for each
/// role, sizes within the capture limits, 4-phase parameters where the format needs them.
fn check_v4l(v4l: &V4lConfig) -> Result<(), String> {
    use dear_v4l2::pixel::PixelFormat as P;
    let mut roles: Vec<(&str, &NodeConfig, &[P])> = vec![
        ("tof", &v4l.tof.node, &[P::Z16, P::Y16, P::Y12, P::Y12P]),
        ("rgb", &v4l.rgb, &[P::Yuyv, P::Nv12, P::Rgb3, P::Mjpg]),
    ];
    if let Some(amplitude) = &v4l.amplitude {
        roles.push(("amplitude", amplitude, &[P::Grey, P::Y16]));
        if matches!(node_format(&v4l.tof.node), Ok(P::Y12 | P::Y12P)) {
            return Err(
                "[capture.v4l.amplitude] is for depth formats: a 4-phase ToF node's amplitude comes from its phases"
                    .into(),
            );
        }
        if (amplitude.width, amplitude.height) != (v4l.tof.node.width, v4l.tof.node.height) {
            return Err(format!(
                "[capture.v4l.amplitude] {}x{} must be the ToF node's {}x{} (one sensor, one grid)",
                amplitude.width, amplitude.height, v4l.tof.node.width, v4l.tof.node.height
            ));
        }
    }
    for (role, node, allowed) in roles {
        let key = format!("[capture.v4l.{role}]");
        let format = node_format(node).map_err(|e| format!("{key} {e}"))?;
        if !allowed.contains(&format) {
            let names: Vec<String> = allowed
                .iter()
                .map(|f| format!("{:?}", f.to_string()))
                .collect();
            return Err(format!(
                "{key} format = {:?} is not one the daemon decodes for the {role} node: {}",
                node.format,
                names.join(", ")
            ));
        }
        let max = dear_capture::manifest::MAX_SIDE;
        if !(1..=max).contains(&node.width) || !(1..=max).contains(&node.height) {
            return Err(format!(
                "{key} width = {}, height = {} must be within 1..={max}",
                node.width, node.height
            ));
        }
        if node.fps == Some(0) {
            return Err(format!(
                "{key} fps = 0: leave it out to keep the node's rate"
            ));
        }
    }
    let tof = &v4l.tof;
    // Any format: a depth module's frequency bounds its depth (capture::DepthLimit).
    if let Some(f) = tof.modulation_hz {
        if !(f.is_finite() && f > 0.0) {
            return Err(format!(
                "[capture.v4l.tof] modulation_hz = {f} must be a positive frequency"
            ));
        }
    }
    if matches!(node_format(&tof.node), Ok(P::Y12 | P::Y12P)) {
        if tof.modulation_hz.is_none() {
            return Err(format!(
                "[capture.v4l.tof] format = {:?} is raw 4-phase data: modulation_hz is needed to turn phase into distance",
                tof.node.format
            ));
        }
        if tof.node.format == "Y12P" && !tof.node.height.is_multiple_of(4) {
            return Err(format!(
                "[capture.v4l.tof] height = {} must be 4 × the image height (four stacked phases)",
                tof.node.height
            ));
        }
    }
    if !(tof.min_amplitude.is_finite() && tof.min_amplitude >= 0.0) {
        return Err(format!(
            "[capture.v4l.tof] min_amplitude = {} must be finite and ≥ 0",
            tof.min_amplitude
        ));
    }
    if let Some(ms) = v4l.pair_tolerance_ms {
        if !(ms.is_finite() && ms > 0.0 && ms <= 1000.0) {
            return Err(format!(
                "[capture.v4l] pair_tolerance_ms = {ms} must be within (0, 1000]"
            ));
        }
    }
    Ok(())
}

/// A node's `format` as a pixel format (an error names a FourCC that is not four characters or
/// not one the daemon knows).
pub fn node_format(node: &NodeConfig) -> Result<dear_v4l2::pixel::PixelFormat, String> {
    let bytes: [u8; 4] = node.format.as_bytes().try_into().map_err(|_| {
        format!(
            "format = {:?} must be a four-character code (pad with spaces: \"Z16 \")",
            node.format
        )
    })?;
    dear_v4l2::pixel::PixelFormat::from_fourcc(&bytes).ok_or_else(|| {
        format!(
            "format = {:?} is not a format the daemon decodes",
            node.format
        )
    })
}

/// What a camera name may be.
const SEGMENT_RULE: &str =
    "it must be one segment of the service name: letters, digits and _ - . only";

/// Checks that `calibration` can align a `width`×`height` stream: finite, `|t_x| ≤ width` and
/// `|t_y| ≤ height` px·m (a flow of at most the image size at 1 m), `|c_x| ≤ width` and
/// `|c_y| ≤ height` px. Beyond that no pixel of the depth lands in the image and every frame
/// would be published without valid depth. `what` names the calibration in the error (e.g.
/// `"[pipeline] static_calibration"`).
pub fn check_calibration_fits(
    what: &str,
    calibration: &Calibration,
    width: u32,
    height: u32,
) -> Result<(), ConfigError> {
    let (w, h) = (width as f32, height as f32);
    check_calibration(
        what,
        calibration,
        (w, h),
        (w, h),
        &format!(" for the {width}x{height} image"),
    )
    .map_err(ConfigError::Invalid)
}

/// `calibration` finite with `|t_x| ≤ t.0`, `|t_y| ≤ t.1`, `|c_x| ≤ c.0`, `|c_y| ≤ c.1`; the
/// error names `what.<field>`, its value and the bound (`context` is appended to it).
fn check_calibration(
    what: &str,
    calibration: &Calibration,
    t: (f32, f32),
    c: (f32, f32),
    context: &str,
) -> Result<(), String> {
    let fields = [
        ("tx", calibration.tx, t.0, "px·m"),
        ("ty", calibration.ty, t.1, "px·m"),
        ("cx", calibration.cx, c.0, "px"),
        ("cy", calibration.cy, c.1, "px"),
    ];
    for (field, value, bound, unit) in fields {
        if !value.is_finite() || value.abs() > bound {
            return Err(format!(
                "{what}.{field} = {value} must be finite and within ±{bound} {unit}{context}"
            ));
        }
    }
    Ok(())
}
