//! `deard-bench`: the daemon's per-frame latency on this machine, measured on the code path
//! `deard` runs (`deard::processing::Processor`, the same configuration keys), without the
//! shared memory and the replay pacing around it.
//!
//! For each calibration mode (`online`, the daemon's default, and `every-frame`, the paper) it
//! replays a capture in order — looping until `--frames` frames were processed — after
//! `--warmup` frames, and prints per-frame latency (median, p95, mean), the frames on which the
//! rough-flow network ran, the median of each stage, and the resident memory after warm-up and
//! at the end. `--json` writes the same figures for `scripts/results.py`.
//!
//! ```sh
//! target/release/dear-synth sequence --frames 60 --width 640 --height 480 --seed 5 --out /tmp/vga
//! target/release/deard-bench --capture /tmp/vga --bundle models/edge
//! ```

mod machine;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::Parser;
use dear_capture::{CaptureDir, RgbdFrame};
use dear_proto::{flags, FrameHeader, Stage};
use deard::config::{CalibrationMode, NetworkPlacement, PipelineConfig, RefineMode};
use deard::processing::{FrameOutput, Processor};
use ndarray::{Array2, Array3};
use serde::Serialize;

// The daemon's allocator: the figures must be the daemon's.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Per-frame latency of deard's processing on a capture.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    /// Capture directory (any resolution; the figures are for its size).
    #[arg(long)]
    capture: PathBuf,
    /// Model bundle ([pipeline] bundle).
    #[arg(long, default_value = "models/edge")]
    bundle: PathBuf,
    /// Frames measured per mode (the capture is replayed in order, looping).
    #[arg(long, default_value_t = 120)]
    frames: usize,
    /// Frames processed before measuring (the online estimator's warm-up runs the network).
    #[arg(long, default_value_t = 10)]
    warmup: usize,
    /// Frames between rough-flow runs in online mode ([pipeline] online_interval_frames).
    #[arg(long, default_value_t = PipelineConfig::default().online_interval_frames)]
    online_interval: u32,
    /// Where online mode's network frames run: background (the daemon's default) or inline
    /// ([pipeline] online_network).
    #[arg(long, default_value = "background")]
    online_network: NetworkPlacement,
    /// Offer frames at this rate, as a camera does (0: back to back). A frame that took longer
    /// than its period is followed at once by the next.
    #[arg(long, default_value_t = 0.0)]
    fps: f64,
    /// Also measure this machine's memory bandwidth and f32 FMA peak (the physical-limit
    /// table's denominators; about two seconds).
    #[arg(long)]
    machine: bool,
    /// Modes to measure: online, every-frame (repeatable; default both).
    #[arg(long = "mode")]
    modes: Vec<CalibrationMode>,
    /// Also write the figures as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// Median, p95 and mean of a set of milliseconds.
#[derive(Debug, Clone, Copy, Serialize)]
struct Summary {
    count: usize,
    median_ms: f64,
    p95_ms: f64,
    mean_ms: f64,
}

impl Summary {
    /// Nearest-rank percentiles, the project's one definition (`dear_stats`): the median is
    /// the lower middle frame for an even count.
    fn of(values: &[f64]) -> Option<Summary> {
        let mut v = values.to_vec();
        let s = dear_stats::Summary::of(&mut v)?;
        Some(Summary {
            count: s.count,
            median_ms: s.p50,
            p95_ms: s.p95,
            mean_ms: s.mean,
        })
    }
}

/// The figures of one mode.
#[derive(Debug, Serialize)]
struct ModeReport {
    mode: &'static str,
    /// Every measured frame.
    all: Summary,
    /// Frames without the rough-flow network (online mode's steady state).
    without_network: Option<Summary>,
    /// Frames with it.
    with_network: Option<Summary>,
    /// Median ms of each stage over the frames without (online) / with (every-frame) the
    /// network, in `Stage` order: preprocess, flow (+ calibration), fuse, warp, refine (+ check).
    stage_median_ms: Vec<(String, f64)>,
    rss_after_warmup_mib: Option<f64>,
    rss_end_mib: Option<f64>,
}

#[derive(Debug, Serialize)]
struct Report {
    capture: PathBuf,
    bundle: PathBuf,
    width: u32,
    height: u32,
    threads_available: usize,
    /// `background` or `inline`.
    online_network: &'static str,
    /// Frames offered per second (0: back to back).
    fps: f64,
    /// `--machine`: this machine's measured limits.
    machine: Option<machine::MachineLimits>,
    modes: Vec<ModeReport>,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(&cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("deard-bench: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: &Cli) -> Result<(), String> {
    if cli.frames == 0 {
        return Err("--frames must be at least 1".into());
    }
    let capture = CaptureDir::open(&cli.capture)
        .map_err(|e| format!("cannot open the capture {}: {e}", cli.capture.display()))?;
    let (width, height) = capture.size();
    // Keep the frames in memory: the figures are processing, not PNG decoding.
    let mut frames = Vec::new();
    for position in 0..capture.len() {
        match capture.read_frame(position) {
            Ok(f) => frames.push(f),
            Err(e) => eprintln!("deard-bench: skipping frame {position}: {e}"),
        }
    }
    if frames.is_empty() {
        return Err(format!("no readable frame in {}", cli.capture.display()));
    }
    let calibration = capture.manifest().initial_calibration;
    let modes = if cli.modes.is_empty() {
        vec![CalibrationMode::Online, CalibrationMode::EveryFrame]
    } else {
        cli.modes.clone()
    };
    println!(
        "deard-bench: {} at {width}x{height} ({} frames, looped), bundle {}, {} measured + {} warm-up frames per mode, online network {}, {}",
        cli.capture.display(),
        frames.len(),
        cli.bundle.display(),
        cli.frames,
        cli.warmup,
        match cli.online_network {
            NetworkPlacement::Background => "in the background",
            NetworkPlacement::Inline => "inline",
        },
        if cli.fps > 0.0 { format!("frames offered at {} fps", cli.fps) } else { "frames back to back".to_owned() }
    );
    let limits = cli.machine.then(|| {
        let m = machine::measure();
        println!(
            "machine: copy bandwidth {:.1} GB/s on one thread, {:.1} GB/s on {}; f32 FMA {:.1} GFLOP/s on one thread, {:.1} GFLOP/s on {}",
            m.bandwidth_gbs_one, m.bandwidth_gbs_all, m.threads, m.fma_gflops_one, m.fma_gflops_all, m.threads
        );
        m
    });
    let mut reports = Vec::new();
    for mode in modes {
        let config = PipelineConfig {
            refine: RefineMode::Dear,
            bundle: cli.bundle.clone(),
            calibration: mode,
            online_interval_frames: cli.online_interval,
            online_network: cli.online_network,
            ..PipelineConfig::default()
        };
        let mut processor = Processor::from_config(width, height, calibration, &config)
            .map_err(|e| e.to_string())?;
        let period = (cli.fps > 0.0).then(|| std::time::Duration::from_secs_f64(1.0 / cli.fps));
        let report = measure(
            &mut processor,
            &frames,
            mode,
            cli.warmup,
            cli.frames,
            period,
        )?;
        print_report(&report);
        reports.push(report);
    }
    if let Some(path) = &cli.json {
        let report = Report {
            capture: cli.capture.clone(),
            bundle: cli.bundle.clone(),
            width,
            height,
            threads_available: std::thread::available_parallelism().map_or(1, |n| n.get()),
            online_network: cli.online_network.name(),
            fps: cli.fps,
            machine: limits,
            modes: reports,
        };
        let text = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?;
        std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn measure(
    processor: &mut Processor,
    frames: &[RgbdFrame],
    mode: CalibrationMode,
    warmup: usize,
    measured: usize,
    period: Option<std::time::Duration>,
) -> Result<ModeReport, String> {
    let (h, w) = frames[0].dim();
    let mut depth = Array2::<f32>::zeros((h, w));
    let mut rgb = Array3::<u8>::zeros((h, w, 3));
    let mut confidence = Array2::<u8>::zeros((h, w));
    let stages = [
        Stage::Preprocess,
        Stage::Flow,
        Stage::Fuse,
        Stage::Warp,
        Stage::Refine,
    ];
    let (mut with, mut without) = (Vec::new(), Vec::new());
    let mut stage_ms: Vec<Vec<f64>> = vec![Vec::new(); stages.len()];
    let mut rss_after_warmup = None;
    let mut next_frame = Instant::now();
    for i in 0..warmup + measured {
        if let Some(period) = period {
            let now = Instant::now();
            if next_frame > now {
                std::thread::sleep(next_frame - now);
            }
            next_frame = next_frame.max(now) + period;
        }
        if i == warmup {
            rss_after_warmup = resident_mib();
        }
        let frame = &frames[i % frames.len()];
        let mut header = FrameHeader::new(frame.index, w as u32, h as u32);
        let out = FrameOutput {
            depth: depth.view_mut(),
            rgb: rgb.view_mut(),
            confidence: confidence.view_mut(),
        };
        let start = Instant::now();
        processor
            .process_into(frame, &mut header, out)
            .map_err(|e| e.to_string())?;
        let ms = start.elapsed().as_secs_f64() * 1e3;
        if i < warmup {
            continue;
        }
        let network = header.flags & flags::CALIBRATION_ESTIMATED != 0;
        if network { &mut with } else { &mut without }.push(ms);
        // Stage breakdown of the frames that make the headline figure.
        let typical = match mode {
            CalibrationMode::Online => !network,
            CalibrationMode::EveryFrame => network,
        };
        if typical {
            for (k, s) in stages.iter().enumerate() {
                stage_ms[k].push(f64::from(header.stage_latency_us[*s as usize]) / 1e3);
            }
        }
    }
    let all: Vec<f64> = with.iter().chain(&without).copied().collect();
    Ok(ModeReport {
        mode: mode.name(),
        all: Summary::of(&all).expect("at least one measured frame"),
        without_network: Summary::of(&without),
        with_network: Summary::of(&with),
        stage_median_ms: stages
            .iter()
            .zip(&stage_ms)
            .filter_map(|(s, v)| Some((format!("{s:?}").to_lowercase(), Summary::of(v)?.median_ms)))
            .collect(),
        rss_after_warmup_mib: rss_after_warmup,
        rss_end_mib: resident_mib(),
    })
}

fn print_report(r: &ModeReport) {
    let line = |label: &str, s: &Option<Summary>| match s {
        Some(s) => println!(
            "  {label:<26} {:>5} frames  median {:>7.1} ms  p95 {:>7.1} ms  mean {:>7.1} ms",
            s.count, s.median_ms, s.p95_ms, s.mean_ms
        ),
        None => println!("  {label:<26}     0 frames"),
    };
    println!("{}:", r.mode);
    line("all frames", &Some(r.all));
    line("without the flow network", &r.without_network);
    line("with the flow network", &r.with_network);
    let stages: Vec<String> = r
        .stage_median_ms
        .iter()
        .map(|(s, ms)| format!("{s} {ms:.1}"))
        .collect();
    println!("  stage medians (ms): {}", stages.join(", "));
    if let (Some(a), Some(b)) = (r.rss_after_warmup_mib, r.rss_end_mib) {
        println!("  resident memory: {a:.1} MiB after warm-up, {b:.1} MiB at the end");
    }
}

/// This process's resident set (VmRSS), MiB; `None` where `/proc` does not say.
fn resident_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}
