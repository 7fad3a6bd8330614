//! `deard` command line: configuration file plus overriding flags.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use clap::Parser;
use deard::config::{CalibrationMode, Config, NetworkPlacement, Pacing, RefineMode};

// tract allocates every intermediate tensor per inference; with glibc's malloc each one above
// the mmap threshold (a 32-channel 640×480 map is 39 MB) comes back as fresh zeroed pages.
// mimalloc reuses them: fusion network 215 -> 137 ms per VGA frame (criterion dear_chain).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// DEAR daemon: aligned, refined ToF depth for every app on the machine, over shared memory.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    /// TOML configuration file (see daemon/deard.example.toml); flags below override it.
    #[arg(short, long)]
    config: Option<PathBuf>,
    /// Capture directory to replay ([capture] path; sets [capture] source = "replay").
    #[arg(long)]
    replay: Option<PathBuf>,
    /// Write the frames the source produces to this new (or empty) directory as a capture
    /// directory while serving: `deard --replay DIR` then processes them again, bit for bit
    /// ([capture] record).
    #[arg(long)]
    record: Option<PathBuf>,
    /// Camera name; the service is dear/<camera>/frames ([service] camera).
    #[arg(long)]
    camera: Option<String>,
    /// Explicit service name ([service] name).
    #[arg(long)]
    service: Option<String>,
    /// Replay pacing: timestamps or fast ([capture] pacing).
    #[arg(long, value_parser = parse_pacing)]
    pacing: Option<Pacing>,
    /// Loop the replay ([capture] loop).
    #[arg(long = "loop")]
    loop_: bool,
    /// First frame position ([capture] start).
    #[arg(long)]
    start: Option<usize>,
    /// One past the last frame position ([capture] end).
    #[arg(long)]
    end: Option<usize>,
    /// Refinement: dear, classical or none ([pipeline] refine).
    #[arg(long, value_parser = parse_refine)]
    refine: Option<RefineMode>,
    /// Model bundle directory for --refine dear ([pipeline] bundle).
    #[arg(long)]
    bundle: Option<PathBuf>,
    /// Calibration with a bundle: online or every-frame ([pipeline] calibration).
    #[arg(long)]
    calibration: Option<CalibrationMode>,
    /// Frames between rough-flow runs in online mode ([pipeline] online_interval_frames).
    #[arg(long)]
    online_interval: Option<u32>,
    /// Where online mode's network frames run: background or inline ([pipeline] online_network).
    #[arg(long)]
    online_network: Option<NetworkPlacement>,
    /// Exit when a non-looping replay ends ([runtime] exit_when_done).
    #[arg(long)]
    exit_when_done: bool,
    /// Seconds between statistics lines ([runtime] stats_interval_s).
    #[arg(long)]
    stats_interval: Option<f64>,
    /// Pin each frame-path thread to a CPU of its own ([runtime] pin_threads).
    #[arg(long)]
    pin_threads: bool,
    /// Print the effective configuration as TOML and exit.
    #[arg(long)]
    print_config: bool,
}

fn parse_pacing(s: &str) -> Result<Pacing, String> {
    match s {
        "timestamps" => Ok(Pacing::Timestamps),
        "fast" => Ok(Pacing::Fast),
        _ => Err(format!("{s:?}: expected \"timestamps\" or \"fast\"")),
    }
}

fn parse_refine(s: &str) -> Result<RefineMode, String> {
    match s {
        "dear" => Ok(RefineMode::Dear),
        "classical" => Ok(RefineMode::Classical),
        "none" => Ok(RefineMode::None),
        _ => Err(format!(
            "{s:?}: expected \"dear\", \"classical\" or \"none\""
        )),
    }
}

fn effective_config(cli: &Cli) -> Result<Config, deard::config::ConfigError> {
    let mut config = match &cli.config {
        Some(path) => Config::from_file(path)?,
        None => Config::default(),
    };
    if let Some(path) = &cli.replay {
        config.capture.source = "replay".into();
        config.capture.path = path.clone();
    }
    if let Some(path) = &cli.record {
        config.capture.record = Some(path.clone());
    }
    if let Some(camera) = &cli.camera {
        config.service.camera = camera.clone();
    }
    if let Some(name) = &cli.service {
        config.service.name = Some(name.clone());
    }
    if let Some(pacing) = cli.pacing {
        config.capture.pacing = pacing;
    }
    if cli.loop_ {
        config.capture.loop_ = true;
    }
    if let Some(start) = cli.start {
        config.capture.start = start;
    }
    if let Some(end) = cli.end {
        config.capture.end = Some(end);
    }
    if let Some(refine) = cli.refine {
        config.pipeline.refine = refine;
    }
    if let Some(bundle) = &cli.bundle {
        config.pipeline.bundle = bundle.clone();
    }
    if let Some(calibration) = cli.calibration {
        config.pipeline.calibration = calibration;
    }
    if let Some(n) = cli.online_interval {
        config.pipeline.online_interval_frames = n;
    }
    if let Some(placement) = cli.online_network {
        config.pipeline.online_network = placement;
    }
    if cli.exit_when_done {
        config.runtime.exit_when_done = true;
    }
    if let Some(s) = cli.stats_interval {
        config.runtime.stats_interval_s = s;
    }
    if cli.pin_threads {
        config.runtime.pin_threads = true;
    }
    config.validate()?;
    Ok(config)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let config = match effective_config(&cli) {
        Ok(config) => config,
        Err(e) => {
            eprintln!("deard: configuration error: {}", error_chain(&e));
            return ExitCode::from(2);
        }
    };
    if cli.print_config {
        use std::io::Write;
        let text = toml::to_string_pretty(&config).expect("config serialises");
        let mut out = std::io::stdout().lock();
        // A failed write (`> /dev/full`, a closed pipe) is an error, not a panic.
        if let Err(e) = out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
            eprintln!("deard: cannot write the configuration to stdout: {e}");
            return ExitCode::FAILURE;
        }
        return ExitCode::SUCCESS;
    }
    // RUST_LOG overrides [runtime] log, and is held to the same rules (a misspelt level would
    // turn every log line off).
    let rust_log = std::env::var("RUST_LOG")
        .ok()
        .filter(|v| !v.trim().is_empty());
    if let Some(value) = &rust_log {
        if let Err(e) = deard::config::validate_log_filter(value) {
            eprintln!("deard: configuration error: RUST_LOG = {e}");
            return ExitCode::from(2);
        }
    }
    let filter =
        tracing_subscriber::EnvFilter::new(rust_log.as_deref().unwrap_or(&config.runtime.log));
    // Colour only on a terminal: under systemd the log goes to the journal, in tests to a file,
    // and escape codes there break every `grep key=value`.
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        // A failed log write (stderr on a full disk) is dropped. By default tracing reports it
        // with `eprintln!`, which panics when stderr fails too: a full disk under the log
        // killed the daemon after 80,000 frames of a soak run.
        .log_internal_errors(false)
        .init();
    // iceoryx2's warnings (a client that cannot connect) into this log.
    deard::iceoryx_log::install();

    // Before anything uses rayon: its global pool is made once, by its first user.
    if config.runtime.pin_threads {
        match dear_pipeline::threads::pin_global_pool() {
            Ok(cpus) => tracing::info!(?cpus, "frame path's threads pinned, one per CPU"),
            Err(e) => {
                report_error(&format!("[runtime] pin_threads: {}", error_chain(&e)));
                return ExitCode::FAILURE;
            }
        }
    }

    let shutdown = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        if let Err(e) = signal_hook::flag::register(signal, shutdown.clone()) {
            eprintln!("deard: cannot install a handler for signal {signal}: {e}");
            return ExitCode::FAILURE;
        }
    }
    match deard::run::run(&config, shutdown) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            report_error(&error_chain(&e));
            ExitCode::FAILURE
        }
    }
}

/// A start-up or run error, said once: in the log when errors are logged (both go to stderr),
/// else on stderr.
fn report_error(message: &str) {
    if tracing::enabled!(tracing::Level::ERROR) {
        tracing::error!("{message}");
    } else {
        eprintln!("deard: {message}");
    }
}

/// `e` and its sources as one line (`a: b: c`), so the iceoryx2 or I/O reason under an error is
/// not lost; a source whose text the line already holds (most messages name their cause) is not
/// repeated.
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let more = s.to_string();
        if !text.contains(&more) {
            text.push_str(": ");
            text.push_str(&more);
        }
        source = s.source();
    }
    text
}
