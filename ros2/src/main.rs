//! `dear-ros2`: publishes a deard frame service as ROS 2 topics (docs/ros2.md).

use std::net::IpAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use dear_capture::Intrinsics;
use dear_client::Client;
use dear_ros2::bridge::{Bridge, Options};
use dear_ros2::convert::{namespace_for_service, DepthEncoding, Planes};

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Publishes a deard frame service as ROS 2 topics over DDS: depth, colour and confidence
/// images, and CameraInfo and an organised PointCloud2 from the intrinsics each frame header
/// carries (or --intrinsics) (sensor-data QoS, stamps = the frames' capture times). No ROS
/// install needed; docs/ros2.md.
#[derive(Debug, Parser)]
#[command(name = "dear-ros2", version)]
struct Args {
    /// Frame service to read.
    #[arg(long, default_value_t = dear_proto::default_service_name(dear_proto::DEFAULT_CAMERA))]
    service: String,
    /// ROS 2 namespace of the topics (default: from the service, `dear/cam0/frames` →
    /// `/dear/cam0`).
    #[arg(long, value_name = "NS")]
    namespace: Option<String>,
    /// `frame_id` of every message (default: `<camera>_optical_frame`, the camera being the
    /// service's last part before `/frames`).
    #[arg(long)]
    frame_id: Option<String>,
    /// DDS domain (default: $ROS_DOMAIN_ID, else 0).
    #[arg(long, value_name = "ID")]
    domain_id: Option<u16>,
    /// Depth image encoding: 16UC1 (mm, 0 = invalid) or 32FC1 (m, NaN = invalid).
    #[arg(long, value_enum, default_value_t = DepthEncoding::Mm16)]
    depth_encoding: DepthEncoding,
    /// RGB intrinsics `FX,FY,CX,CY` in px (a pinhole), instead of the ones each frame header
    /// carries (format 3). A frame with neither gets no CameraInfo and no PointCloud2.
    #[arg(long, value_name = "FX,FY,CX,CY", value_parser = dear_capture::parse_intrinsics)]
    intrinsics: Option<Intrinsics>,
    /// Do not publish the point cloud.
    #[arg(long)]
    no_cloud: bool,
    /// Give the point cloud an `rgb` field (16 bytes a point instead of 12).
    #[arg(long)]
    cloud_rgb: bool,
    /// Use only this local address for DDS (repeatable; e.g. 127.0.0.1 to stay on this host).
    #[arg(long, value_name = "ADDR")]
    interface: Vec<IpAddr>,
    /// Exit after publishing this many frames.
    #[arg(long, value_name = "N")]
    count: Option<u64>,
    /// Give up when the service cannot be joined, or no frame arrives, for this many seconds
    /// (0: never; a deard restart within it is followed).
    #[arg(long, value_name = "S", default_value_t = 30.0)]
    timeout_s: f64,
    /// Message stamps: `capture` is the header's capture time as it is (a live V4L2 camera's
    /// CLOCK_MONOTONIC, a replay's recorded time); `wall` maps a CLOCK_MONOTONIC capture time
    /// to the system clock (ROS time), for nodes that compare stamps with `now()` or TF.
    #[arg(long, value_enum, default_value_t = Stamp::Capture)]
    stamp: Stamp,
    /// Print the bridge's figures (added latency, CPU per frame) as one JSON line on exit.
    #[arg(long)]
    stats: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Stamp {
    Capture,
    Wall,
}

/// CPU time (user + system) of this process, all threads, in seconds.
fn cpu_seconds() -> f64 {
    // SAFETY: rusage is plain integers, for which all zero bytes are a valid value.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage writes the struct it is given.
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) };
    let t = |tv: libc::timeval| tv.tv_sec as f64 + tv.tv_usec as f64 * 1e-6;
    t(usage.ru_utime) + t(usage.ru_stime)
}

fn clock_ns(clock: libc::clockid_t) -> u64 {
    // SAFETY: timespec is plain integers, for which all zero bytes are a valid value.
    let mut ts: libc::timespec = unsafe { std::mem::zeroed() };
    // SAFETY: clock_gettime writes the struct it is given.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// `CLOCK_MONOTONIC` in ns, the clock of the header's `publish_timestamp_ns`.
fn monotonic_ns() -> u64 {
    clock_ns(libc::CLOCK_MONOTONIC)
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn connect(service: &str, timeout: Duration, stop: &AtomicBool) -> anyhow::Result<Client> {
    let start = Instant::now();
    loop {
        match Client::connect(service) {
            Ok(c) => return Ok(c),
            Err(e) if start.elapsed() >= timeout || stop.load(Ordering::Relaxed) => {
                return Err(e).with_context(|| format!("cannot join the frame service {service:?}"))
            }
            Err(_) => std::thread::sleep(Duration::from_millis(200)),
        }
    }
}

fn main() -> anyhow::Result<()> {
    // RustDDS warns of every datagram over 1,500 bytes (every fragment of an image): only its
    // errors are shown unless RUST_LOG asks for more.
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,rustdds=error".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let args = Args::parse();
    dear_proto::validate_service_name(&args.service)?;
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop))?;
    }
    let (namespace, camera) = namespace_for_service(&args.service);
    let domain_id = match args.domain_id {
        Some(d) => d,
        None => match std::env::var("ROS_DOMAIN_ID") {
            Ok(v) if !v.is_empty() => v
                .parse()
                .with_context(|| format!("ROS_DOMAIN_ID={v:?} is not a domain number"))?,
            _ => 0,
        },
    };
    let options = Options {
        domain_id,
        namespace: args.namespace.clone().unwrap_or(namespace),
        frame_id: args
            .frame_id
            .clone()
            .unwrap_or_else(|| format!("{camera}_optical_frame")),
        depth_encoding: args.depth_encoding,
        intrinsics: args.intrinsics,
        cloud: !args.no_cloud,
        cloud_rgb: args.cloud_rgb,
        interfaces: args.interface.clone(),
    };
    if !options.namespace.starts_with('/') {
        anyhow::bail!("--namespace {:?} must start with /", options.namespace);
    }
    let frame_id = options.frame_id.clone();
    let mut bridge = Bridge::new(options)?;
    if !(args.timeout_s >= 0.0 && args.timeout_s.is_finite()) {
        anyhow::bail!(
            "--timeout-s {} is not a number of seconds >= 0",
            args.timeout_s
        );
    }
    let timeout = if args.timeout_s == 0.0 {
        Duration::MAX
    } else {
        Duration::from_secs_f64(args.timeout_s)
    };
    let client = connect(&args.service, timeout, &stop)?;
    for (topic, kind) in bridge.topics() {
        tracing::info!("publishing {topic} ({kind})");
    }
    tracing::info!(
        "from {:?}, domain {domain_id}, frame_id {frame_id:?}",
        args.service
    );

    let mut frames = 0u64;
    let mut skipped = 0u64;
    let mut messages = 0u64;
    // Per frame published with at least one message: deard's publication → all written (ms),
    // and the conversion and writes alone (ms).
    let mut latency_ms = Vec::new();
    let mut work_ms = Vec::new();
    let mut cpu_start = None;
    let mut last_frame = Instant::now();
    let (mut no_intrinsics_said, mut bad_intrinsics_said) = (false, false);
    while !stop.load(Ordering::Relaxed) && args.count.is_none_or(|n| frames < n) {
        let Some(mut frame) = client.wait(Duration::from_millis(200))? else {
            if last_frame.elapsed() >= timeout {
                anyhow::bail!(
                    "no frame from {:?} for {} s (is deard running and publishing there? \
                     `dear list` shows the frame services)",
                    args.service,
                    args.timeout_s
                );
            }
            continue;
        };
        // Sensor data: the newest frame only, when the bridge fell behind.
        while let Some(newer) = client.try_receive()? {
            frame = newer;
            skipped += 1;
        }
        last_frame = Instant::now();
        let start_ns = monotonic_ns();
        let h = *frame.header();
        let (w, hgt) = frame.size();
        let planes = Planes {
            width: w as u32,
            height: hgt as u32,
            depth: frame.depth(),
            rgb: frame.rgb(),
            confidence: frame.confidence(),
            intrinsics: match h.intrinsics() {
                Ok(k) => k,
                Err(e) => {
                    // Published by no deard; said once, then the frame goes without them.
                    if !bad_intrinsics_said {
                        tracing::warn!(
                            frame = h.frame_id,
                            "{e}: no CameraInfo or PointCloud2 for such frames"
                        );
                        bad_intrinsics_said = true;
                    }
                    None
                }
            },
        };
        if planes.intrinsics.is_none() && args.intrinsics.is_none() && !no_intrinsics_said {
            tracing::warn!(
                "frame {} carries no intrinsics (rgb_camera_model 0) and no --intrinsics was \
                 given: images only, no CameraInfo or PointCloud2 for such frames",
                h.frame_id
            );
            no_intrinsics_said = true;
        }
        let stamp = match args.stamp {
            Stamp::Capture => h.capture_timestamp_ns,
            // The offset now, per frame: it follows the system clock's adjustments.
            Stamp::Wall => h.capture_timestamp_ns.wrapping_add(
                clock_ns(libc::CLOCK_REALTIME).wrapping_sub(clock_ns(libc::CLOCK_MONOTONIC)),
            ),
        };
        let n = bridge.publish(stamp, &planes)?;
        let end_ns = monotonic_ns();
        drop(frame);
        frames += 1;
        if n > 0 {
            messages += n as u64;
            // The first frame with readers starts the CPU clock (participant start-up and
            // discovery are not per-frame costs).
            if cpu_start.is_none() {
                cpu_start = Some((cpu_seconds(), frames));
            } else {
                latency_ms.push(end_ns.saturating_sub(h.publish_timestamp_ns) as f64 * 1e-6);
                work_ms.push((end_ns - start_ns) as f64 * 1e-6);
            }
        }
    }
    let cpu = cpu_start.map(|(c, f)| (cpu_seconds() - c, frames - f));
    tracing::info!("{frames} frames bridged ({skipped} older ones skipped), {messages} messages");
    if args.stats {
        latency_ms.sort_by(f64::total_cmp);
        work_ms.sort_by(f64::total_cmp);
        let mean = |v: &[f64]| {
            if v.is_empty() {
                f64::NAN
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        let cpu_ms_per_frame = match cpu {
            Some((s, n)) if n > 0 => s * 1e3 / n as f64,
            _ => f64::NAN,
        };
        let json = |v: f64| {
            if v.is_finite() {
                format!("{v:.3}")
            } else {
                "null".into()
            }
        };
        println!(
            "{{\"frames\": {frames}, \"skipped\": {skipped}, \"messages\": {messages}, \
             \"measured_frames\": {}, \"latency_ms\": {{\"mean\": {}, \"p50\": {}, \"p99\": {}}}, \
             \"work_ms\": {{\"mean\": {}, \"p50\": {}, \"p99\": {}}}, \"cpu_ms_per_frame\": {}}}",
            latency_ms.len(),
            json(mean(&latency_ms)),
            json(percentile(&latency_ms, 0.5)),
            json(percentile(&latency_ms, 0.99)),
            json(mean(&work_ms)),
            json(percentile(&work_ms, 0.5)),
            json(percentile(&work_ms, 0.99)),
            json(cpu_ms_per_frame),
        );
    }
    Ok(())
}
