//! `dear-v4l-check`: the client of the V4L2 end-to-end test (`scripts/test-v4l2-vm.sh`, guest
//! script `scripts/v4l2-vm/deard-live.sh`). The test feeds known depth frames (raw `Y16 `
//! millimetres, `--fed`) into vivid's video output, vivid loops them into its capture node,
//! and `deard` captures that node with `refine = "none"` and a zero calibration on an identity
//! registration — so each published depth must be one of the fed frames, to the millimetre,
//! valid exactly where the fed frame is non-zero.
//!
//! Receives `--count` frames and prints one line per frame (`frame <id> matches fed <k>` or
//! the first differing pixel); exits 0 when every frame matched a fed frame, 1 when one did
//! not, 3 when `--timeout-s` passed first. `--settle-frames N` tolerates up to N frames that
//! match nothing *before* the first that matches (they are printed, not counted): right after
//! vivid's nodes come back, its capture node delivers its own test pattern until the feeder's
//! first buffer reaches it.

use std::time::{Duration, Instant};

use clap::Parser;
use dear_client::Client;

#[derive(Parser)]
struct Args {
    #[arg(long)]
    service: String,
    /// Raw little-endian u16 millimetres, `--width` × `--height` per frame, frames back to back.
    #[arg(long)]
    fed: std::path::PathBuf,
    #[arg(long)]
    width: usize,
    #[arg(long)]
    height: usize,
    #[arg(long)]
    count: usize,
    #[arg(long, default_value_t = 60.0)]
    timeout_s: f64,
    /// Frames matching no fed frame tolerated before the first one that matches.
    #[arg(long, default_value_t = 0)]
    settle_frames: usize,
}

fn main() {
    let args = Args::parse();
    let bytes = std::fs::read(&args.fed).unwrap_or_else(|e| {
        eprintln!("dear-v4l-check: {}: {e}", args.fed.display());
        std::process::exit(2)
    });
    let n = args.width * args.height;
    let fed: Vec<Vec<u16>> = bytes
        .chunks_exact(n * 2)
        .map(|f| {
            f.chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect()
        })
        .collect();
    if fed.is_empty() {
        eprintln!("dear-v4l-check: {}: no whole frame", args.fed.display());
        std::process::exit(2);
    }
    let client = Client::connect(&args.service).unwrap_or_else(|e| {
        eprintln!("dear-v4l-check: {e}");
        std::process::exit(2)
    });
    let deadline = Instant::now() + Duration::from_secs_f64(args.timeout_s);
    let mut received = 0;
    let mut failed = false;
    // Unmatched frames still tolerated: only until the first match.
    let mut settling = args.settle_frames;
    while received < args.count {
        let Some(left) = deadline.checked_duration_since(Instant::now()) else {
            eprintln!(
                "dear-v4l-check: {received} of {} frames before the timeout",
                args.count
            );
            std::process::exit(3);
        };
        let frame = match client.wait(left) {
            Ok(Some(frame)) => frame,
            Ok(None) => continue,
            Err(e) => {
                eprintln!("dear-v4l-check: {e}");
                std::process::exit(2);
            }
        };
        let id = frame.header().frame_id;
        if frame.size() != (args.width, args.height) {
            received += 1;
            println!(
                "frame {id}: size {:?}, fed {}x{}",
                frame.size(),
                args.width,
                args.height
            );
            failed = true;
            continue;
        }
        let depth = frame.depth();
        match fed
            .iter()
            .position(|f| first_difference(f, depth).is_none())
        {
            Some(k) => {
                received += 1;
                settling = 0;
                println!("frame {id} matches fed {k}");
            }
            None if settling > 0 => {
                settling -= 1;
                println!("frame {id} matches no fed frame yet (settling, not counted)");
            }
            None => {
                received += 1;
                // Report against the closest fed frame: the one with the fewest differences.
                let (k, d) = fed
                    .iter()
                    .enumerate()
                    .map(|(k, f)| (k, differences(f, depth)))
                    .min_by_key(|(_, d)| *d)
                    .expect("fed is not empty");
                let (p, want, got) = first_difference(&fed[k], depth).expect("differs");
                println!(
                    "frame {id} matches no fed frame: closest fed {k} differs at {d} pixels, first at ({}, {}): fed {want} mm, published {got} m",
                    p / args.width,
                    p % args.width
                );
                failed = true;
            }
        }
    }
    std::process::exit(i32::from(failed));
}

/// Published depth `m` (metres) agrees with fed millimetres `mm` at a pixel: both invalid, or
/// the same millimetre.
fn agrees(mm: u16, m: f32) -> bool {
    if mm == 0 {
        m == 0.0
    } else {
        (m * 1000.0 - mm as f32).abs() < 0.5
    }
}

fn first_difference(fed: &[u16], depth: &[f32]) -> Option<(usize, u16, f32)> {
    fed.iter()
        .zip(depth)
        .position(|(&mm, &m)| !agrees(mm, m))
        .map(|p| (p, fed[p], depth[p]))
}

fn differences(fed: &[u16], depth: &[f32]) -> usize {
    fed.iter()
        .zip(depth)
        .filter(|(&mm, &m)| !agrees(mm, m))
        .count()
}
