//! `dear-v4l-check`: the client of the V4L2 end-to-end test (`scripts/test-v4l2-vm.sh`, guest
//! script `scripts/v4l2-vm/deard-live.sh`). The test feeds known depth frames (raw `Y16 `
//! millimetres, `--fed`) into vivid's video output, vivid loops them into its capture node,
//! and `deard` captures that node with `refine = "none"` and a zero calibration on an identity
//! registration — so each published depth must be one of the fed frames, to the millimetre,
//! valid exactly where the fed frame is non-zero and within the module's range
//! (`--max-range-m`: fed depth beyond it must be published invalid).
//!
//! Receives frames until `--count` of them were checked and prints one line per frame. Each
//! frame is one of:
//! - **fed k**: exactly fed frame k (counted);
//! - **blank**: no valid depth at all. vivid's own test pattern (what its capture node gives
//!   while no output buffer is looped in) lies wholly beyond the test module's range, so deard
//!   publishes it invalid; with `--allow-blank` such frames are accepted anywhere, printed and
//!   totalled, not counted (they say nothing about deard);
//! - **history**: published before this client connected — the service keeps its latest frame
//!   for late subscribers, and after a device loss that one predates the loss: printed, not
//!   counted;
//! - anything else — another size, a sample out of the publisher's order (its `sequence` must
//!   increase within one `run_id`), depth that is neither fed nor blank — is a failure (counted; the first differing pixel and
//!   the closest fed frame are printed).
//!
//! Exits 0 when `--count` fed frames arrived in order and nothing failed, 1 when a frame failed,
//! 2 on a usage or connection error, 3 when `--timeout-s` passed first. The last line sums up:
//! `dear-v4l-check: 4 fed frames in order, 0 failed, 0 blank (vivid's pattern), 1 from before
//! this client`.

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
    /// Frames to check: fed frames, plus failed ones.
    #[arg(long)]
    count: usize,
    #[arg(long, default_value_t = 60.0)]
    timeout_s: f64,
    /// The module's range (its calibration file's `max_range_m`): fed depth beyond it must be
    /// published invalid.
    #[arg(long)]
    max_range_m: Option<f64>,
    /// Accept frames without any valid depth (vivid's own pattern) anywhere.
    #[arg(long)]
    allow_blank: bool,
}

/// How many frames of each kind were seen.
#[derive(Default)]
struct Tally {
    fed: usize,
    failed: usize,
    blank: usize,
    history: usize,
}

impl Tally {
    fn summary(&self) -> String {
        format!(
            "{} fed frames in order, {} failed, {} blank (vivid's pattern), {} from before this client",
            self.fed, self.failed, self.blank, self.history
        )
    }
}

fn usage_error(message: String) -> ! {
    eprintln!("dear-v4l-check: {message}");
    std::process::exit(2)
}

fn main() {
    let args = Args::parse();
    if args.width == 0 || args.height == 0 || args.count == 0 {
        usage_error(format!(
            "--width {}, --height {} and --count {} must be positive",
            args.width, args.height, args.count
        ));
    }
    if let Some(r) = args.max_range_m {
        if !(r.is_finite() && r > 0.0) {
            usage_error(format!(
                "--max-range-m {r} must be a positive number of metres"
            ));
        }
    }
    let bytes = std::fs::read(&args.fed)
        .unwrap_or_else(|e| usage_error(format!("{}: {e}", args.fed.display())));
    let n = args.width * args.height;
    if bytes.is_empty() || bytes.len() % (n * 2) != 0 {
        usage_error(format!(
            "{}: {} bytes, not a whole number of {}x{} 16-bit frames",
            args.fed.display(),
            bytes.len(),
            args.width,
            args.height
        ));
    }
    // What each fed frame must be published as: fed millimetres, 0 (invalid) beyond the range.
    let max_mm = args.max_range_m.map(|r| r * 1000.0);
    let fed: Vec<Vec<u16>> = bytes
        .chunks_exact(n * 2)
        .map(|f| {
            f.chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .map(|mm| match max_mm {
                    Some(max) if f64::from(mm) > max => 0,
                    _ => mm,
                })
                .collect()
        })
        .collect();
    let client = Client::connect(&args.service).unwrap_or_else(|e| usage_error(e.to_string()));
    // Frames published before this instant were there before the client.
    let connected_ns = dear_proto::time::monotonic_ns();
    let deadline = Instant::now() + Duration::from_secs_f64(args.timeout_s);
    let mut tally = Tally::default();
    // (publisher run id, sample sequence) of the last frame checked: strictly increasing
    // within one publisher, unlike the frame id (which restarts when a replay loops).
    let mut last: Option<(u64, u64)> = None;
    while tally.fed + tally.failed < args.count {
        let Some(left) = deadline.checked_duration_since(Instant::now()) else {
            println!("dear-v4l-check: {}", tally.summary());
            eprintln!(
                "dear-v4l-check: {} of {} frames checked before the timeout ({} s){}",
                tally.fed + tally.failed,
                args.count,
                args.timeout_s,
                if tally.blank > 0 {
                    " — only vivid's own pattern came: is the feeder looping buffers in?"
                } else {
                    ""
                }
            );
            std::process::exit(3);
        };
        let frame = match client.wait(left) {
            Ok(Some(frame)) => frame,
            Ok(None) => continue,
            Err(e) => usage_error(e.to_string()),
        };
        let header = *frame.header();
        let id = header.frame_id;
        if header.publish_timestamp_ns < connected_ns {
            tally.history += 1;
            println!("frame {id}: published before this client connected (not counted)");
            continue;
        }
        if frame.size() != (args.width, args.height) {
            tally.failed += 1;
            println!(
                "frame {id}: size {:?}, fed {}x{}",
                frame.size(),
                args.width,
                args.height
            );
            continue;
        }
        let (run, sequence) = (header.run_id, header.sequence);
        if let Some((last_run, last_sequence)) = last {
            if run != last_run || sequence <= last_sequence {
                tally.failed += 1;
                println!(
                    "frame {id} (publisher {run:#x}, sample {sequence}) is out of order: it follows sample {last_sequence} of publisher {last_run:#x}"
                );
                continue;
            }
        }
        last = Some((run, sequence));
        let depth = frame.depth();
        if let Some(k) = fed
            .iter()
            .position(|f| first_difference(f, depth).is_none())
        {
            tally.fed += 1;
            println!("frame {id} matches fed {k}");
        } else if depth.iter().all(|&m| m == 0.0) {
            if args.allow_blank {
                tally.blank += 1;
                println!("frame {id}: no valid depth (vivid's own pattern, beyond the module's range; not counted)");
            } else {
                tally.failed += 1;
                println!("frame {id}: no valid depth (vivid's own pattern?) where a fed frame was expected");
            }
        } else {
            tally.failed += 1;
            // Report against the closest fed frame: the one with the fewest differences.
            let (k, d) = fed
                .iter()
                .enumerate()
                .map(|(k, f)| (k, differences(f, depth)))
                .min_by_key(|(_, d)| *d)
                .expect("fed is not empty");
            let (p, want, got) = first_difference(&fed[k], depth).expect("differs");
            println!(
                "frame {id} matches no fed frame: closest fed {k} differs at {d} pixels, first at x {} y {}: expected {want} mm (0 = invalid), published {got} m",
                p % args.width,
                p / args.width
            );
        }
    }
    println!("dear-v4l-check: {}", tally.summary());
    std::process::exit(i32::from(tally.failed > 0));
}

/// Published depth `m` (metres) agrees with the expected millimetres `mm` at a pixel: both
/// invalid, or the same millimetre.
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
