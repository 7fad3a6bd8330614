//! `deard-bench`: the daemon's time per frame and latency on this machine, measured on the
//! code path `deard` runs (`deard::processing::Processor`, the same configuration keys),
//! without the shared memory and the replay pacing around it.
//!
//! For each calibration mode (`online`, the daemon's default, and `every-frame`, the paper) it
//! replays a capture in order — looping until `--frames` frames were processed — after
//! `--warmup` frames, and prints the processing time per frame (median, p95, mean), the frames
//! on which the rough-flow network ran, the latency from a frame's first stage to its
//! publication, the median of each stage, and the resident memory after warm-up and at the
//! end. `--json` writes the same figures for `scripts/results.py`.
//!
//! As in `deard`, a frame that is waiting when the previous one reaches its refinement is
//! prepared beside it (`Processor::finish_into`; online mode with the network in the
//! background): back to back, every frame overlaps, so the time per frame is the throughput
//! interval and the latency is longer than it. `--sequential` processes each frame whole.
//!
//! `--pin-cpu 0` runs the whole bench on one core (one rayon thread; the background worker
//! at nice +19 on the same core), and `--hog-cpu 1` keeps another core busy with a spinning
//! process for the whole measurement: a board whose other cores belong to the apps
//! (`cores`). `--pin-threads` pins each frame-path thread to a CPU of its own, as deard's
//! `[runtime] pin_threads` (`dear_pipeline::threads` says when that pays).
//!
//! ```sh
//! cargo build --release -p dear-synth -p dear-tools --bin dear-synth --bin deard-bench
//! target/release/dear-synth sequence --frames 60 --width 640 --height 480 --seed 5 --out /tmp/vga
//! target/release/deard-bench --capture /tmp/vga --bundle models/edge
//! target/release/deard-bench --capture /tmp/vga --mode online --pin-cpu 0 --hog-cpu 1
//! ```
// The options' help texts name configuration sections as `[pipeline]`, which rustdoc would
// read as links.
#![allow(rustdoc::broken_intra_doc_links)]

mod cores;
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
    /// Process each frame whole, never overlapping two (`Processor::process_into`).
    #[arg(long)]
    sequential: bool,
    /// Run on this one CPU only (every thread, the background worker included; one rayon
    /// thread): the one-core figures. As `taskset -c CPU` with `RAYON_NUM_THREADS=1`.
    #[arg(long)]
    pin_cpu: Option<usize>,
    /// Pin each frame-path thread to a CPU of its own, one per CPU (or RAYON_NUM_THREADS), as
    /// deard's `[runtime] pin_threads` does.
    #[arg(long, conflicts_with = "pin_cpu")]
    pin_threads: bool,
    /// Keep this CPU busy with a spinning process while measuring (repeatable): the figures of
    /// a board whose other cores run the apps.
    #[arg(long = "hog-cpu")]
    hog_cpus: Vec<usize>,
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
    /// Every measured frame: the processor's time on it (for overlapped frames, the interval
    /// between two publications).
    all: Summary,
    /// From the start of a frame's first stage to its publication.
    latency: Summary,
    /// Measured frames prepared beside the previous one's refinement.
    overlapped_frames: usize,
    /// Frames without the rough-flow network (online mode's steady state).
    without_network: Option<Summary>,
    /// Frames with it.
    with_network: Option<Summary>,
    /// Median ms of each stage over the frames without (online) / with (every-frame) the
    /// network, in `Stage` order: preprocess, flow (+ calibration), fuse, warp, refine (+ check).
    stage_median_ms: Vec<(String, f64)>,
    rss_after_warmup_mib: Option<f64>,
    rss_end_mib: Option<f64>,
    /// CPU time of the whole process (every thread: the frame path, the pool, the background
    /// worker) over the measured frames, per frame: the work a frame costs, whatever else
    /// the machine runs.
    cpu_ms_per_frame: Option<f64>,
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
    /// `--pin-cpu`: the one CPU every thread ran on.
    pinned_cpu: Option<usize>,
    /// `--pin-threads`: the CPUs the frame path's threads were pinned to, one each.
    pinned_threads: Option<Vec<usize>>,
    /// `--hog-cpu`: the CPUs kept busy by a spinning process.
    hog_cpus: Vec<usize>,
    modes: Vec<ModeReport>,
}

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    if args.next().as_deref() == Some(cores::SPIN_FLAG) {
        return match cores::spin(args.next()) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("deard-bench: {e}");
                ExitCode::FAILURE
            }
        };
    }
    let cli = Cli::parse();
    // Before any other thread exists, so that every later one inherits the CPU.
    if let Some(cpu) = cli.pin_cpu {
        let pinned = cores::pin_to(cpu).and_then(|()| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build_global()
                .map_err(|e| format!("cannot make the one-thread pool: {e}"))
        });
        if let Err(e) = pinned {
            eprintln!("deard-bench: {e}");
            return ExitCode::FAILURE;
        }
    }
    let pinned_threads = if cli.pin_threads {
        match dear_pipeline::threads::pin_global_pool() {
            Ok(cpus) => Some(cpus),
            Err(e) => {
                eprintln!("deard-bench: --pin-threads: {e}");
                return ExitCode::FAILURE;
            }
        }
    } else {
        None
    };
    match run(&cli, pinned_threads) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("deard-bench: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: &Cli, pinned_threads: Option<Vec<usize>>) -> Result<(), String> {
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
    if cli.pin_cpu.is_some_and(|cpu| cli.hog_cpus.contains(&cpu)) {
        return Err("--hog-cpu names the CPU the bench is pinned to (--pin-cpu)".into());
    }
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
    if let Some(cpu) = cli.pin_cpu {
        println!(
            "pinned to CPU {cpu}: every thread ({} rayon thread, the background worker at nice +19)",
            rayon::current_num_threads()
        );
    }
    if let Some(cpus) = &pinned_threads {
        println!("frame-path threads pinned, one per CPU: {cpus:?}");
    }
    let hogs = cores::Hogs::start(&cli.hog_cpus)?;
    if !cli.hog_cpus.is_empty() {
        println!("busy board: a spinning process on {}", hogs.describe());
    }
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
            Schedule {
                warmup: cli.warmup,
                measured: cli.frames,
                period,
                sequential: cli.sequential,
            },
        )?;
        print_report(&report);
        reports.push(report);
    }
    drop(hogs);
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
            pinned_cpu: cli.pin_cpu,
            pinned_threads,
            hog_cpus: cli.hog_cpus.clone(),
            modes: reports,
        };
        let text = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?;
        std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// Which frames are offered when, and how they are processed.
struct Schedule {
    warmup: usize,
    measured: usize,
    /// Time between offered frames (`None`: back to back).
    period: Option<std::time::Duration>,
    sequential: bool,
}

fn measure(
    processor: &mut Processor,
    frames: &[RgbdFrame],
    mode: CalibrationMode,
    schedule: Schedule,
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
    let (mut with, mut without, mut latency) = (Vec::new(), Vec::new(), Vec::new());
    let mut stage_ms: Vec<Vec<f64>> = vec![Vec::new(); stages.len()];
    let mut rss_after_warmup = None;
    let mut cpu_at_warmup = None;
    let mut overlapped_frames = 0;
    let total = schedule.warmup + schedule.measured;
    let clock = Instant::now();
    // When frame `i` is offered.
    let offered = |i: usize| match schedule.period {
        Some(period) => clock + period * i as u32,
        None => clock,
    };
    let wait_for = |i: usize| {
        let (now, at) = (Instant::now(), offered(i));
        if at > now {
            std::thread::sleep(at - now);
        }
    };
    let frame = |i: usize| &frames[i % frames.len()];
    // The next frame, already prepared beside this one's refinement, and when that began.
    let mut pending = None;
    for i in 0..total {
        if i == schedule.warmup {
            rss_after_warmup = resident_mib();
            cpu_at_warmup = process_cpu_s();
        }
        // This frame: prepared (`None` when processed whole), when its first half started, and
        // the processor's time on it so far.
        let (prepared, started, spent) = match pending.take() {
            Some((p, started)) => (Some(p), started, std::time::Duration::ZERO),
            None => {
                wait_for(i);
                let start = Instant::now();
                let p = if schedule.sequential {
                    None
                } else {
                    Some(processor.prepare(frame(i)).map_err(|e| e.to_string())?)
                };
                (p, start, start.elapsed())
            }
        };
        // The next frame overlaps this one when it is already there, as in deard.
        let overlap = !schedule.sequential
            && processor.overlaps_frames()
            && i + 1 < total
            && Instant::now() >= offered(i + 1);
        let mut header = FrameHeader::new(frame(i).index, w as u32, h as u32);
        let out = FrameOutput {
            depth: depth.view_mut(),
            rgb: rgb.view_mut(),
            confidence: confidence.view_mut(),
        };
        let t = Instant::now();
        let finished = match prepared {
            None => processor
                .process_into(frame(i), &mut header, out)
                .map(|()| None),
            Some(prepared) => {
                let next = overlap.then(|| frame(i + 1));
                let finished = processor.finish_into(prepared, next, &mut header, out);
                finished.result.and_then(|()| finished.next.transpose())
            }
        }
        .map_err(|e| e.to_string())?;
        let ms = (spent + t.elapsed()).as_secs_f64() * 1e3;
        let frame_latency = started.elapsed().as_secs_f64() * 1e3;
        if let Some(next) = finished {
            if i + 1 >= schedule.warmup {
                overlapped_frames += 1;
            }
            pending = Some((next, t));
        }
        if i < schedule.warmup {
            continue;
        }
        latency.push(frame_latency);
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
        latency: Summary::of(&latency).expect("at least one measured frame"),
        overlapped_frames,
        without_network: Summary::of(&without),
        with_network: Summary::of(&with),
        stage_median_ms: stages
            .iter()
            .zip(&stage_ms)
            .filter_map(|(s, v)| Some((format!("{s:?}").to_lowercase(), Summary::of(v)?.median_ms)))
            .collect(),
        rss_after_warmup_mib: rss_after_warmup,
        rss_end_mib: resident_mib(),
        cpu_ms_per_frame: process_cpu_s()
            .zip(cpu_at_warmup)
            .map(|(end, start)| (end - start) * 1e3 / schedule.measured as f64),
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
    line("latency (first stage to out)", &Some(r.latency));
    println!("  overlapped frames: {}", r.overlapped_frames);
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
    if let Some(ms) = r.cpu_ms_per_frame {
        println!("  CPU time per frame (every thread): {ms:.1} ms");
    }
}

/// CPU time this process has used (user + system, every thread), seconds.
fn process_cpu_s() -> Option<f64> {
    // SAFETY: getrusage writes the zeroed struct it is given.
    let usage = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        (libc::getrusage(libc::RUSAGE_SELF, &mut usage) == 0).then_some(usage)
    }?;
    let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    Some(s(usage.ru_utime) + s(usage.ru_stime))
}

/// This process's resident set (VmRSS), MiB; `None` where `/proc` does not say.
fn resident_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}
