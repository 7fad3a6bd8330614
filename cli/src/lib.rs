//! The `dear` command line: argument definitions and dispatch. One module per subcommand;
//! [`stats`] is the pure per-second aggregation behind `watch`.
//!
//! Its own crate so that the SDK (`dear-client`) stays thin: applications linking the SDK do
//! not pull clap, indicatif, the pipeline or tract, which `dear eval` needs.

#![forbid(unsafe_code)]

pub mod devices;
pub mod dump;
pub mod eval;
pub mod list;
pub mod reconnect;
pub mod record;
pub mod stats;
pub mod view;
pub mod watch;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::Context;
use clap::{Parser, Subcommand};

/// Command-line client of deard: find frame services, watch live statistics, dump frames,
/// record them to MCAP, evaluate the pipeline on captures with ground truth.
#[derive(Debug, Parser)]
#[command(name = "dear", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands. `record` writes MCAP (issue 15); `dump` writes the replayable capture format.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// List the DEAR frame services on this machine, with their publishers and subscribers.
    List,
    /// List the V4L2 capture devices (/dev/video*): driver, formats with sizes and frame
    /// rates, controls — what `[capture.v4l]` in deard's configuration can ask for.
    Devices,
    /// Print live statistics of a frame service once a second: rate, latency, calibration.
    Watch(watch::WatchArgs),
    /// Write received frames as a capture directory (the format `deard` replays).
    ///
    /// Files per frame: `frames/NNNNNN.rgb.png` (the frame's RGB), `.depth.png` (its aligned
    /// refined depth, 16-bit mm) and `.amp.png`, which holds the frame's CONFIDENCE × 257,
    /// because deard publishes no amplitude (`capture.json` says so under `source.amplitude`).
    /// Frame ids count from 0; timestamps are publish times relative to the first frame. Each
    /// frame's calibration estimate is in `source.calibration_estimates` (not `perturbation`,
    /// which is ground truth) and the daemon's own frame id and timestamps in
    /// `source.published_frames`.
    Dump(dump::DumpArgs),
    /// Record received frames to an MCAP file (Foxglove, Rerun, the `mcap` CLI open it).
    ///
    /// Channels `/dear/<camera>/depth` (foxglove.RawImage, 16UC1 mm or 32FC1 m, 0 = invalid),
    /// `/rgb` (rgb8), `/confidence` (mono8) and `/calibration` (foxglove.CameraCalibration;
    /// K, R, P and D from each frame header's intrinsics, or --intrinsics; zero, "uncalibrated",
    /// for a frame without any),
    /// protobuf-encoded. Log time = capture time, publish time = the frame's publish time.
    /// Stops after --count frames, --seconds seconds, or at Ctrl-C / SIGTERM; the file is
    /// finished (summary and index) in every case. Lost frames are counted and printed.
    Record(record::RecordArgs),
    /// Measure alignment and depth accuracy, and time per frame, on a capture with ground
    /// truth: the ToF input, the classical baselines (--baselines) and model bundles
    /// (--bundle), with the same pipeline code the daemon runs. Writes eval.json, eval.md and
    /// figures to --out.
    Eval(eval::EvalArgs),
    /// Serve a read-only web page showing the stream live: colourised depth, the RGB/depth
    /// blend, the confidence, the calibration over time and the frame rate (docs/view.md).
    ///
    /// GET and HEAD only; nothing a browser sends changes anything. One subscription however
    /// many browsers look; pictures are encoded at most --max-fps times a second.
    View(view::ViewArgs),
}

/// Runs the parsed command.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::List => list::run(),
        Command::Devices => devices::run(),
        Command::Watch(args) => watch::run(&args),
        Command::Dump(args) => dump::run(&args),
        Command::Record(args) => record::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::View(args) => view::run(&args),
    }
}

/// `RUST_LOG` controls our own diagnostics (default: warnings); iceoryx2's internal log is kept
/// to errors unless `IOX2_LOG_LEVEL` says otherwise, since every failure it reports also
/// reaches the user as an error naming the service.
pub fn init_logging() {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        // Colour only on a terminal: escape codes in a redirected log break every grep.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}

/// Writes `text` to stdout and flushes it. A write error (`> /dev/full`, a full disk) is an
/// error naming stdout, not a panic as from `print!`; a closed pipe (`dear list | head -1`)
/// ends the output quietly, as it does for `dear watch`.
pub fn write_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        Err(e) => Err(anyhow::Error::new(e).context("cannot write to stdout")),
    }
}

/// The error a command returns when Ctrl-C / SIGTERM stopped it before it finished; `main`
/// maps it to exit status 130 instead of a failure.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Interrupted(pub String);

/// Whether `e` is (or wraps) an [`Interrupted`].
pub fn is_interrupt(e: &anyhow::Error) -> bool {
    e.downcast_ref::<Interrupted>().is_some()
}

/// A flag set by SIGINT or SIGTERM. Commands poll it between short waits, so they finish
/// their output (a dump's manifest, the current line) instead of dying mid-write.
#[derive(Debug, Clone)]
pub struct StopFlag(Arc<AtomicBool>);

impl StopFlag {
    pub fn install() -> anyhow::Result<Self> {
        let flag = Arc::new(AtomicBool::new(false));
        for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
            signal_hook::flag::register(signal, Arc::clone(&flag))
                .with_context(|| format!("cannot install the handler of signal {signal}"))?;
        }
        Ok(StopFlag(flag))
    }

    pub fn is_set(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// How long one wait may block, bounding the reaction time to Ctrl-C and to `--seconds`.
const POLL: std::time::Duration = std::time::Duration::from_millis(100);

/// Waits for the next good frame (`dump` and `record`); malformed ones are skipped with a
/// warning. `Ok(None)` on timeout, at `end_at`, or when `stop` was set.
pub fn next_frame(
    client: &mut reconnect::ReconnectingClient,
    timeout: std::time::Duration,
    end_at: Option<std::time::Instant>,
    stop: &StopFlag,
) -> anyhow::Result<Option<dear_client::Frame>> {
    let mut deadline = std::time::Instant::now() + timeout;
    if let Some(end) = end_at {
        deadline = deadline.min(end);
    }
    loop {
        if stop.is_set() {
            return Ok(None);
        }
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        if left.is_zero() {
            return Ok(None);
        }
        match client.wait(left.min(POLL)) {
            Ok(Some(frame)) => return Ok(Some(frame)),
            Ok(None) => {}
            Err(dear_client::ReceiveError::BadFrame { service, source }) => {
                tracing::warn!(%service, error = %source, "skipping a malformed frame");
            }
            Err(e @ dear_client::ReceiveError::UntrustedPublisher { .. }) => {
                warn_untrusted_once(&e);
            }
            Err(_) if stop.is_set() => return Ok(None),
            Err(e) => return Err(e.into()),
        }
    }
}

/// Says once per process that frames of another user's publisher are refused (issue 34): the
/// command goes on with the service's own frames.
pub fn warn_untrusted_once(e: &dear_client::ReceiveError) {
    static WARNED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
    if !WARNED.swap(true, Ordering::Relaxed) {
        eprintln!("dear: warning: {e}");
    }
}

/// Waits for the first frame of a command that writes `out` (`dump`, `record`). When none comes,
/// the error says whether Ctrl-C or the timeout ended the wait, and that nothing was written.
pub fn first_frame(
    client: &mut reconnect::ReconnectingClient,
    service: &str,
    timeout_s: f64,
    out: &std::path::Path,
    stop: &StopFlag,
) -> anyhow::Result<dear_client::Frame> {
    let timeout = std::time::Duration::from_secs_f64(timeout_s);
    if let Some(frame) = next_frame(client, timeout, None, stop)? {
        return Ok(frame);
    }
    if stop.is_set() {
        return Err(Interrupted(format!(
            "interrupted before any frame arrived from {service:?}; nothing written"
        ))
        .into());
    }
    anyhow::bail!(
        "no frame arrived from service {service:?} within {timeout_s} s; nothing written to {} \
         (is deard running and publishing there? `dear list` shows the frame services)",
        out.display()
    )
}

/// `FX,FY,CX,CY`: the RGB camera's pinhole intrinsics given on the command line (`dump`,
/// `record`; clap value parser). Defined in dear-capture, next to `Intrinsics`, so the ROS 2
/// bridge (`dear-ros2`) parses `--intrinsics` by the same rules.
pub use dear_capture::parse_intrinsics;

/// Service name argument shared by the subcommands: the default camera's frame service.
pub fn default_service() -> String {
    dear_proto::default_service_name(dear_proto::DEFAULT_CAMERA)
}

/// Checks a service name given on the command line (clap value parser).
pub fn parse_service(name: &str) -> Result<String, dear_proto::ServiceNameError> {
    dear_proto::validate_service_name(name)?;
    Ok(name.to_string())
}
