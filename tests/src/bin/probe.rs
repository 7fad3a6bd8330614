//! `dear-probe`: a minimal client process for the end-to-end tests. Subscribes, prints `ready`,
//! then one line per received frame:
//! `frame <id> <skipped> <dropped> <sha256 of the payload> <flags, hex> <bundle name or ->`.
//! Exits 0 after `--count` frames, 3 if `--timeout-s` passes first.

use std::io::Write;
use std::time::{Duration, Instant};

use clap::Parser;
use dear_client::Client;

#[derive(Parser)]
struct Args {
    #[arg(long)]
    service: String,
    #[arg(long)]
    count: usize,
    #[arg(long, default_value_t = 60.0)]
    timeout_s: f64,
}

fn main() {
    let args = Args::parse();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let client = Client::connect(&args.service).unwrap_or_else(|e| {
        eprintln!("dear-probe: {e}");
        std::process::exit(2)
    });
    let mut out = std::io::stdout().lock();
    writeln!(out, "ready").unwrap();
    out.flush().unwrap();
    let deadline = Instant::now() + Duration::from_secs_f64(args.timeout_s);
    let mut received = 0;
    while received < args.count {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            eprintln!(
                "dear-probe: timed out after {received} of {} frames",
                args.count
            );
            std::process::exit(3);
        }
        match client.wait(left) {
            Ok(Some(frame)) => {
                let h = frame.header();
                let hash = dear_e2e_tests::sha256_hex(frame.payload());
                writeln!(
                    out,
                    "frame {} {} {} {hash} {:x} {}",
                    h.frame_id,
                    h.frames_skipped,
                    h.frames_dropped,
                    h.flags,
                    if h.bundle_name().is_empty() {
                        "-"
                    } else {
                        h.bundle_name()
                    }
                )
                .unwrap();
                out.flush().unwrap();
                received += 1;
            }
            Ok(None) => {}
            Err(e) => {
                eprintln!("dear-probe: {e}");
                std::process::exit(2);
            }
        }
    }
}
