//! `dear-ipc-bench`: publish→receive latency of full RGB-D frames through the real `deard`
//! publisher and the real client SDK, with N subscriber processes woken by events.
//!
//! ```sh
//! cargo run --release -p dear-tools --bin dear-ipc-bench -- --subscribers 1
//! cargo run --release -p dear-tools --bin dear-ipc-bench -- --subscribers 4
//! ```
//!
//! Latency = the subscriber's `CLOCK_MONOTONIC` on return from `Client::wait` minus the
//! header's `publish_timestamp_ns` (stamped just before `send`). With zero copies it should not
//! grow with the number of subscribers or with the frame size.

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use clap::Parser;
use dear_client::Client;
use dear_proto::FrameHeader;
use deard::publish::FramePublisher;

#[derive(Parser)]
struct Args {
    /// Subscriber processes.
    #[arg(long, default_value_t = 1)]
    subscribers: usize,
    /// Frames to publish.
    #[arg(long, default_value_t = 500)]
    frames: usize,
    /// Milliseconds between frames.
    #[arg(long, default_value_t = 10)]
    interval_ms: u64,
    #[arg(long, default_value_t = 640)]
    width: u32,
    #[arg(long, default_value_t = 480)]
    height: u32,
    /// Internal: run as a subscriber of this service.
    #[arg(long, hide = true)]
    child: Option<String>,
}

fn main() {
    let args = Args::parse();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    match &args.child {
        Some(service) => subscriber(service, args.frames),
        None => publisher(&args),
    }
}

fn subscriber(service: &str, frames: usize) {
    let client = Client::connect(service).expect("connect");
    let mut out = std::io::stdout().lock();
    writeln!(out, "ready").unwrap();
    out.flush().unwrap();
    let mut latencies = Vec::with_capacity(frames);
    while latencies.len() < frames {
        match client.wait(Duration::from_secs(5)).expect("wait") {
            Some(frame) => {
                let now = dear_proto::time::monotonic_ns();
                latencies.push(now.saturating_sub(frame.header().publish_timestamp_ns));
            }
            None => break,
        }
    }
    let text: Vec<String> = latencies.iter().map(u64::to_string).collect();
    writeln!(out, "{}", text.join(" ")).unwrap();
}

fn publisher(args: &Args) {
    let service = format!("dear-bench/{}/frames", std::process::id());
    let exe = std::env::current_exe().expect("own path");
    let mut children: Vec<_> = (0..args.subscribers)
        .map(|_| {
            Command::new(&exe)
                .args(["--child", &service, "--frames", &args.frames.to_string()])
                .stdout(Stdio::piped())
                .spawn()
                .expect("spawn subscriber")
        })
        .collect();
    let mut readers: Vec<_> = children
        .iter_mut()
        .map(|c| BufReader::new(c.stdout.take().expect("stdout")))
        .collect();
    for r in &mut readers {
        let mut line = String::new();
        r.read_line(&mut line).expect("subscriber ready");
        assert_eq!(line.trim(), "ready");
    }
    let transport = dear_proto::node_config().expect("DEAR_IOX2_ROOT");
    dear_proto::transport::prepare_root(&transport).expect("the transport's root directory");
    let publisher =
        FramePublisher::new(&transport, &service, args.width, args.height).expect("publisher");
    // Let the subscribers' connections settle before timing.
    std::thread::sleep(Duration::from_millis(200));
    let start = Instant::now();
    for i in 0..args.frames {
        let header = FrameHeader::new(i as u64, args.width, args.height);
        publisher
            .publish(header, Instant::now(), |_, mut out| {
                out.depth.fill(i as f32);
                Ok::<_, std::convert::Infallible>(())
            })
            .expect("publish");
        let due = start + Duration::from_millis(args.interval_ms * (i as u64 + 1));
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
    }
    let mut all = Vec::new();
    for (i, r) in readers.iter_mut().enumerate() {
        let mut line = String::new();
        r.read_line(&mut line).expect("latencies");
        let lat: Vec<u64> = line
            .split_whitespace()
            .map(|v| v.parse().expect("number"))
            .collect();
        let (median, p99) = percentiles(&lat);
        println!(
            "subscriber {i}: {} of {} frames, median {:.1} µs, p99 {:.1} µs",
            lat.len(),
            args.frames,
            median,
            p99
        );
        all.extend(lat);
    }
    for c in &mut children {
        let _ = c.wait();
    }
    let (median, p99) = percentiles(&all);
    let layout = dear_proto::PayloadLayout::new(args.width, args.height)
        .expect("FramePublisher::new accepted this size");
    let mib = layout.size as f64 / (1 << 20) as f64;
    println!(
        "{} subscriber(s), {}x{} frame ({mib:.2} MiB payload), event-driven: median {median:.1} µs, p99 {p99:.1} µs over {} receptions",
        args.subscribers,
        args.width,
        args.height,
        all.len()
    );
}

/// Nearest-rank median and p99 ([`dear_stats::Summary`]) in µs; NaN for no values.
fn percentiles(values: &[u64]) -> (f64, f64) {
    match dear_stats::Summary::of(&mut values.to_vec()) {
        Some(s) => (s.p50 as f64 / 1e3, s.p99 as f64 / 1e3),
        None => (f64::NAN, f64::NAN),
    }
}
