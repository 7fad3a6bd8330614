//! `dear-probe`: a minimal client process for the end-to-end tests. Subscribes, prints `ready`,
//! then one line per received frame:
//!
//! `frame <frame_id> <run_id, 16 hex digits> <sequence> <skipped> <dropped> <sha256 of the
//! payload> <flags, hex> <bundle name or ->`
//!
//! (`run_id` and `sequence` as the header carries them: a new `run_id` is a new publisher
//! instance, a gap in `sequence` within one run is the number of samples this probe lost.)
//! Exits 0 after `--count` frames, 3 if `--timeout-s` passes first. `--delay-ms` makes it a
//! slow client: it sleeps that long after each frame before it reads the next.
//!
//! The probe keeps up with the daemon as well as a client can: the frame service overwrites
//! the oldest sample of a subscriber that falls two samples behind
//! (`dear_proto::service::QOS_SUBSCRIBER_BUFFER`), so one thread only copies each payload out
//! of shared memory and returns the sample, and another hashes and prints. A loss can then only
//! come from the receiving thread not being scheduled for two publish intervals.

use std::io::Write;
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use clap::Parser;
use dear_client::Client;
use dear_proto::FrameHeader;

#[derive(Parser)]
struct Args {
    #[arg(long)]
    service: String,
    #[arg(long)]
    count: usize,
    #[arg(long, default_value_t = 60.0)]
    timeout_s: f64,
    #[arg(long, default_value_t = 0)]
    delay_ms: u64,
}

fn main() {
    let args = Args::parse();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let client = Client::connect(&args.service).unwrap_or_else(|e| {
        // The whole chain: the reason is in the sources.
        let mut text = e.to_string();
        let mut source = std::error::Error::source(&e);
        while let Some(s) = source {
            text.push_str(&format!(": {s}"));
            source = s.source();
        }
        eprintln!("dear-probe: {text}");
        std::process::exit(2)
    });
    // Before the printing thread starts: it holds the stdout lock for its whole life.
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "ready").unwrap();
        out.flush().unwrap();
    }
    // Received frames, copied out of shared memory, to the hashing and printing thread.
    let (tx, rx) = mpsc::channel::<(FrameHeader, Vec<u8>)>();
    let printer = thread::spawn(move || {
        let mut out = std::io::stdout().lock();
        for (h, payload) in rx {
            let hash = dear_pipeline::model::hex_sha256(&payload);
            writeln!(
                out,
                "frame {} {:016x} {} {} {} {hash} {:x} {}",
                h.frame_id,
                h.run_id,
                h.sequence,
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
        }
    });
    let deadline = Instant::now() + Duration::from_secs_f64(args.timeout_s);
    let mut received = 0;
    let mut refused = false;
    let status = loop {
        if received >= args.count {
            break 0;
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            eprintln!(
                "dear-probe: timed out after {received} of {} frames",
                args.count
            );
            break 3;
        }
        match client.wait(left) {
            Ok(Some(frame)) => {
                // The copy releases the sample at once (the frame is dropped here).
                tx.send((*frame.header(), frame.payload().to_vec()))
                    .expect("the printing thread runs until the channel closes");
                received += 1;
                // A slow client: the service keeps queueing (and overwriting) meanwhile.
                thread::sleep(Duration::from_millis(args.delay_ms));
            }
            Ok(None) => {}
            // Another user's publisher (issue 34): refused, said once, and the probe goes on.
            Err(e @ dear_client::ReceiveError::UntrustedPublisher { .. }) => {
                if !refused {
                    eprintln!("dear-probe: {e}");
                    refused = true;
                }
            }
            Err(e) => {
                eprintln!("dear-probe: {e}");
                break 2;
            }
        }
    };
    // Every received frame is printed before the probe exits, whatever the status.
    drop(tx);
    printer.join().expect("the printing thread");
    // Leaves the service (its subscriber and node slots are free at once, not after the
    // daemon's next cleanup of dead nodes), even after an error.
    drop(client);
    std::process::exit(status);
}
