//! `soak_client`: a subscriber for `scripts/soak.sh` that counts what it receives, what it lost
//! and how late frames arrived, and writes that as JSON when it stops.
//!
//! ```text
//! cargo run --release -p dear-tools --bin soak_client -- \
//!     --service dear/cam0/frames [--hold-ms 200] [--loop-frames 42] [--frames N] \
//!     [--report report.json]
//! ```
//!
//! One line per second goes to stdout (`elapsed_s,received,lost,out_of_order,rejected,
//! last_frame_id`), so a script can watch progress; the report is written on SIGINT/SIGTERM or
//! after `--frames` frames.
//!
//! `--hold-ms` makes a deliberately slow client: it keeps each sample borrowed (the shared
//! memory stays referenced) for that long before taking the next one. The service overwrites
//! the oldest queued frame for a subscriber that falls behind, so such a client must lose
//! frames but never stall the daemon or the other subscribers: that is what the soak checks.
//!
//! Losses are counted from gaps in the header's frame numbering. A publisher that stamps
//! `run_id` (non-zero) numbers its samples with `sequence`, gap-free on its side, so every gap
//! is a loss and a new `run_id` a daemon restart. A publisher that does not (`run_id` 0, e.g.
//! a daemon older than format version 2) leaves only `frame_id`, the capture's own id, which
//! restarts at 0 on every pass of a looping replay: `--loop-frames` (the capture's frame count)
//! lets a restart be read as a wrap rather than as a reordering, and a gap longer than a whole
//! pass cannot be seen, so the script also compares the total with the daemon's published count.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use dear_client::{Client, FrameHeader, ReceiveError, Stage};
use serde::Serialize;

/// How long one wait may block: bounds the reaction time to a signal and the lateness of the
/// progress line.
const POLL: Duration = Duration::from_millis(100);
/// Sleep granularity while holding a frame, so a long `--hold-ms` still stops promptly.
const HOLD_STEP: Duration = Duration::from_millis(20);

#[derive(Debug, Parser)]
#[command(about = "Soak-test subscriber: counts received and lost frames and latencies")]
struct Args {
    /// Frame service to subscribe to.
    #[arg(long, default_value_t = dear_client::default_service_name("cam0"))]
    service: String,
    /// Keep each received frame borrowed for this long before taking the next (a slow client).
    #[arg(long, default_value_t = 0)]
    hold_ms: u64,
    /// Frames per pass of a looping replay: frame ids wrap from loop_frames − 1 to 0. Without
    /// it a decreasing id counts as out of order.
    #[arg(long)]
    loop_frames: Option<u64>,
    /// Stop after receiving this many frames (default: until SIGINT/SIGTERM).
    #[arg(long)]
    frames: Option<u64>,
    /// Write the final report (JSON) here as well as to stdout's last line.
    #[arg(long)]
    report: Option<PathBuf>,
    /// A label for the report (e.g. "fast" or "slow").
    #[arg(long, default_value = "client")]
    name: String,
}

/// How a frame is numbered: which counter its loss is read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Numbering {
    /// `sequence` of publisher instance `run_id`: gap-free on the publisher's side.
    Sequence { run_id: u64, sequence: u64 },
    /// `frame_id` only (the publisher stamped no `run_id`): restarts on every replay pass.
    FrameId(u64),
}

impl Numbering {
    fn of(h: &FrameHeader) -> Self {
        if h.run_id != 0 {
            Numbering::Sequence {
                run_id: h.run_id,
                sequence: h.sequence,
            }
        } else {
            Numbering::FrameId(h.frame_id)
        }
    }
}

/// Counts frames and losses from the numbers of the frames a subscriber sees.
///
/// A frame is new when its publish time is later than the last one's: the publish timestamp
/// orders frames even when ids wrap, so a frame seen twice (or an older one) is never taken for
/// a wrap.
#[derive(Debug, Default, Clone, PartialEq)]
struct LossCounter {
    /// Frames per replay pass, for [`Numbering::FrameId`].
    loop_frames: Option<u64>,
    received: u64,
    /// Frames missing between received ones by `sequence` (all lost by this client).
    sequence_gaps: u64,
    /// Frames missing between received ones by `frame_id`: lost by this client, or input the
    /// daemon dropped or skipped (never published).
    frame_id_gaps: u64,
    /// For `frame_id`: the daemon's drops and skips inside the gaps. Always 0 with `sequence`,
    /// which numbers published samples only.
    daemon_missed: u64,
    /// The daemon's `frames_dropped + frames_skipped` as of the last frame.
    last_daemon_missed: u64,
    wraps: u64,
    out_of_order: u64,
    /// New `run_id`s after the first: daemon restarts (no loss is counted across one).
    restarts: u64,
    /// Frames counted by `sequence` and by `frame_id`.
    by_sequence: u64,
    by_frame_id: u64,
    run_id: Option<u64>,
    first_id: Option<u64>,
    last_id: Option<u64>,
    last_publish_ns: u64,
}

impl LossCounter {
    fn new(loop_frames: Option<u64>) -> Self {
        LossCounter {
            loop_frames,
            ..Default::default()
        }
    }

    /// Records one frame, with the daemon's running count of input frames it dropped or
    /// skipped (`frames_dropped + frames_skipped`); returns false when the frame was not newer
    /// than the last one (not counted).
    fn push(&mut self, numbering: Numbering, daemon_missed: u64, publish_ns: u64) -> bool {
        let (id, wrap) = match numbering {
            Numbering::Sequence { run_id, sequence } => {
                if self.run_id.is_some_and(|r| r != run_id) {
                    // A new publisher instance numbers from 0 again: start over, losing
                    // nothing we could count.
                    self.restarts += 1;
                    self.last_id = None;
                }
                self.run_id = Some(run_id);
                (sequence, None)
            }
            Numbering::FrameId(id) => (id, self.loop_frames),
        };
        if let Some(last) = self.last_id {
            if publish_ns <= self.last_publish_ns {
                self.out_of_order += 1;
                return false;
            }
            let gap = if id > last {
                id - last - 1
            } else {
                match wrap {
                    // Ids restart each pass: the rest of the last pass, then the start of this
                    // one.
                    Some(n) if last < n && id < n => {
                        self.wraps += 1;
                        (n - 1 - last) + id
                    }
                    // A decrease that is no wrap cannot be interpreted; it is counted, and the
                    // numbering goes on from this frame.
                    _ => {
                        self.out_of_order += 1;
                        0
                    }
                }
            };
            match numbering {
                Numbering::Sequence { .. } => self.sequence_gaps += gap,
                Numbering::FrameId(_) => {
                    self.frame_id_gaps += gap;
                    self.daemon_missed += daemon_missed.saturating_sub(self.last_daemon_missed);
                }
            }
        }
        self.last_daemon_missed = daemon_missed;
        match numbering {
            Numbering::Sequence { .. } => self.by_sequence += 1,
            Numbering::FrameId(_) => self.by_frame_id += 1,
        }
        self.first_id.get_or_insert(id);
        self.received += 1;
        self.last_id = Some(id);
        self.last_publish_ns = publish_ns;
        true
    }

    /// Frames this client lost: gaps in `sequence`, and gaps in `frame_id` less the input the
    /// daemon dropped (fell behind) or skipped (bad), which shows as a gap in `frame_id` too
    /// but was never published. The daemon stamps a drop on the next frame it publishes, which
    /// may be one gap late, so that split is exact in total, not per gap.
    fn lost(&self) -> u64 {
        self.sequence_gaps + self.frame_id_gaps.saturating_sub(self.daemon_missed)
    }

    /// How the losses were counted, for the report.
    fn method(&self) -> String {
        let frame_id = match self.loop_frames {
            Some(n) => format!("gaps in frame_id, wrapping every {n} frames"),
            None => "gaps in frame_id".to_string(),
        };
        match (self.by_sequence, self.by_frame_id) {
            (0, 0) => "none (no frames)".to_string(),
            (_, 0) => "gaps in sequence".to_string(),
            (0, _) => frame_id,
            (s, f) => format!("gaps in sequence ({s} frames) and {frame_id} ({f} frames)"),
        }
    }
}

/// Nearest-rank percentiles of a latency sample ([`dear_stats::Summary`]), milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
struct Percentiles {
    n: usize,
    p50_ms: f64,
    p95_ms: f64,
    p99_ms: f64,
    max_ms: f64,
}

/// Nearest-rank percentiles of `values_ns` (sorted in place); `None` when empty.
fn percentiles(values_ns: &mut [u64]) -> Option<Percentiles> {
    let s = dear_stats::Summary::of(values_ns)?;
    let ms = |ns: u64| ns as f64 / 1e6;
    Some(Percentiles {
        n: s.count,
        p50_ms: ms(s.p50),
        p95_ms: ms(s.p95),
        p99_ms: ms(s.p99),
        max_ms: ms(s.max),
    })
}

#[derive(Debug, Serialize)]
struct Report {
    name: String,
    service: String,
    hold_ms: u64,
    /// How losses were counted.
    lost_method: String,
    received: u64,
    /// Frames missing between the first and the last received (gaps in the frame numbers).
    lost: u64,
    /// Input frames the daemon dropped or skipped between the received ones (never published;
    /// only counted when losses come from `frame_id`).
    daemon_missed_in_gaps: u64,
    wraps: u64,
    /// Daemon restarts seen (new `run_id`).
    restarts: u64,
    /// The last publisher instance seen, if it stamps one.
    run_id: Option<u64>,
    out_of_order: u64,
    /// Frames whose header or payload failed validation.
    rejected: u64,
    /// First and last frame number (`sequence`, or `frame_id` without it).
    first_frame_id: Option<u64>,
    last_frame_id: Option<u64>,
    /// Publish times (CLOCK_MONOTONIC ns) of the first and last received frame: the window in
    /// which the daemon's published count can be compared with `received + lost`.
    first_publish_ns: Option<u64>,
    last_publish_ns: Option<u64>,
    /// The daemon's running totals as of the last received frame.
    daemon_frames_skipped: Option<u64>,
    daemon_frames_dropped: Option<u64>,
    /// Receive time − publish time.
    publish_to_receive: Option<Percentiles>,
    /// The header's `Total` stage: the daemon's arrival-to-publish time.
    daemon_total: Option<Percentiles>,
    elapsed_s: f64,
    stopped_by: &'static str,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    dear_proto::validate_service_name(&args.service).map_err(anyhow::Error::msg)?;
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop))
            .with_context(|| format!("cannot install the handler of signal {signal}"))?;
    }
    let client = Client::connect(&args.service)?;
    let hold = Duration::from_millis(args.hold_ms);

    let mut counter = LossCounter::new(args.loop_frames);
    let mut rejected = 0u64;
    let mut first_publish_ns = None;
    let mut last_header: Option<FrameHeader> = None;
    // Every frame's latencies are kept (16 bytes per frame: 1.6 MB for 100,000 frames) so the
    // percentiles are exact rather than from a histogram.
    let mut publish_to_receive_ns = Vec::new();
    let mut daemon_total_ns = Vec::new();
    let mut checksum = 0u64;

    let started = Instant::now();
    let mut next_progress = started + Duration::from_secs(1);
    let mut stopped_by = "signal";
    println!("elapsed_s,received,lost,out_of_order,rejected,last_frame_id");
    while !stop.load(Ordering::Relaxed) {
        if args.frames.is_some_and(|n| counter.received >= n) {
            stopped_by = "frames";
            break;
        }
        match client.wait(POLL) {
            Ok(Some(frame)) => {
                let received_ns = dear_proto::time::monotonic_ns();
                let h = *frame.header();
                let missed = h.frames_dropped + h.frames_skipped;
                if counter.push(Numbering::of(&h), missed, h.publish_timestamp_ns) {
                    first_publish_ns.get_or_insert(h.publish_timestamp_ns);
                    publish_to_receive_ns.push(received_ns.saturating_sub(h.publish_timestamp_ns));
                    daemon_total_ns.push(u64::from(h.latency_us(Stage::Total)) * 1000);
                    last_header = Some(h);
                }
                // Read a plane so the client really touches the shared memory it was given.
                checksum = checksum.wrapping_add(
                    frame
                        .confidence()
                        .iter()
                        .step_by(97)
                        .map(|&c| u64::from(c))
                        .sum::<u64>(),
                );
                let held = Instant::now();
                while held.elapsed() < hold && !stop.load(Ordering::Relaxed) {
                    std::thread::sleep(HOLD_STEP.min(hold.saturating_sub(held.elapsed())));
                }
                drop(frame);
            }
            Ok(None) => {}
            Err(ReceiveError::BadFrame { source, .. }) => {
                rejected += 1;
                eprintln!("frame rejected: {source}");
            }
            // A signal interrupts the wait; that is a stop, not a failure.
            Err(_) if stop.load(Ordering::Relaxed) => break,
            Err(e) => return Err(e.into()),
        }
        let now = Instant::now();
        if now >= next_progress {
            println!(
                "{:.1},{},{},{},{},{}",
                (now - started).as_secs_f64(),
                counter.received,
                counter.lost(),
                counter.out_of_order,
                rejected,
                counter.last_id.map_or(String::new(), |id| id.to_string()),
            );
            next_progress = (next_progress + Duration::from_secs(1)).max(now);
        }
    }

    let report = Report {
        name: args.name.clone(),
        service: args.service.clone(),
        hold_ms: args.hold_ms,
        lost_method: counter.method(),
        received: counter.received,
        lost: counter.lost(),
        daemon_missed_in_gaps: counter.daemon_missed,
        wraps: counter.wraps,
        restarts: counter.restarts,
        run_id: counter.run_id,
        out_of_order: counter.out_of_order,
        rejected,
        first_frame_id: counter.first_id,
        last_frame_id: counter.last_id,
        first_publish_ns,
        last_publish_ns: last_header.map(|h| h.publish_timestamp_ns),
        daemon_frames_skipped: last_header.map(|h| h.frames_skipped),
        daemon_frames_dropped: last_header.map(|h| h.frames_dropped),
        publish_to_receive: percentiles(&mut publish_to_receive_ns),
        daemon_total: percentiles(&mut daemon_total_ns),
        elapsed_s: started.elapsed().as_secs_f64(),
        stopped_by,
    };
    let json = serde_json::to_string_pretty(&report)?;
    if let Some(path) = &args.report {
        std::fs::write(path, format!("{json}\n"))
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    // The checksum only keeps the read above from being optimised away.
    eprintln!(
        "{}: done ({} frames, checksum {checksum})",
        args.name, counter.received
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn push_ids(c: &mut LossCounter, frames: &[(u64, u64)]) -> Vec<bool> {
        frames
            .iter()
            .map(|&(id, t)| c.push(Numbering::FrameId(id), 0, t))
            .collect()
    }

    fn seq(run_id: u64, sequence: u64) -> Numbering {
        Numbering::Sequence { run_id, sequence }
    }

    #[test]
    fn gaps_count_as_lost() {
        let mut c = LossCounter::new(None);
        push_ids(&mut c, &[(5, 1), (6, 2), (9, 3), (10, 4)]);
        assert_eq!((c.received, c.lost(), c.out_of_order), (4, 2, 0));
        assert_eq!((c.first_id, c.last_id), (Some(5), Some(10)));
        assert_eq!(c.method(), "gaps in frame_id");
    }

    #[test]
    fn a_loop_wrap_counts_the_tail_and_head_of_the_passes() {
        // Ids 0..10 per pass. 8→1: 9 and 0 lost; 2→9: 3..=8 lost (6); 9→0: a clean wrap.
        let mut c = LossCounter::new(Some(10));
        push_ids(&mut c, &[(7, 1), (8, 2), (1, 3), (2, 4), (9, 5), (0, 6)]);
        assert_eq!(
            (c.received, c.lost(), c.wraps, c.out_of_order),
            (6, 8, 2, 0)
        );
    }

    #[test]
    fn a_repeated_or_older_frame_is_neither_received_nor_a_wrap() {
        let mut c = LossCounter::new(Some(10));
        let new = push_ids(&mut c, &[(3, 100), (3, 100), (2, 50), (4, 101)]);
        assert_eq!(new, [true, false, false, true]);
        assert_eq!(
            (c.received, c.lost(), c.wraps, c.out_of_order),
            (2, 0, 0, 2)
        );
    }

    #[test]
    fn a_decrease_without_a_loop_length_is_out_of_order() {
        let mut c = LossCounter::new(None);
        push_ids(&mut c, &[(3, 1), (1, 2), (2, 3)]);
        assert_eq!((c.received, c.lost(), c.out_of_order), (3, 0, 1));
    }

    #[test]
    fn frame_id_gaps_the_daemon_dropped_are_not_the_clients_losses() {
        // 1 → 5: three ids missing, two of them dropped by the daemon (its counter 4 → 6);
        // 5 → 6 → 9 (wrap at 10 not involved): 7 and 8 missing, one skipped (6 → 7).
        let mut c = LossCounter::new(Some(10));
        for (id, missed, t) in [(1, 4, 1), (5, 6, 2), (6, 6, 3), (9, 7, 4)] {
            assert!(c.push(Numbering::FrameId(id), missed, t));
        }
        assert_eq!((c.received, c.lost(), c.daemon_missed), (4, 2, 3));
    }

    #[test]
    fn sequence_gaps_are_losses_even_when_the_daemon_dropped_input() {
        // The sequence numbers published samples: a dropped input frame leaves no gap in it.
        let mut c = LossCounter::new(None);
        for (s, missed, t) in [(0, 0, 1), (1, 5, 2), (3, 9, 3)] {
            assert!(c.push(seq(7, s), missed, t));
        }
        assert_eq!((c.received, c.lost(), c.daemon_missed), (3, 1, 0));
    }

    #[test]
    fn sequence_gaps_are_losses_and_ignore_the_loop_length() {
        // With a sequence the loop length is irrelevant: 8 → 12 is 3 lost, not a wrap.
        let mut c = LossCounter::new(Some(10));
        for (s, t) in [(7, 1), (8, 2), (12, 3), (13, 4)] {
            assert!(c.push(seq(42, s), 0, t));
        }
        assert_eq!((c.received, c.lost(), c.wraps, c.restarts), (4, 3, 0, 0));
        assert_eq!(c.method(), "gaps in sequence");
    }

    #[test]
    fn a_new_run_id_is_a_restart_not_a_loss() {
        let mut c = LossCounter::new(None);
        for (n, t) in [
            (seq(1, 500), 1),
            (seq(1, 502), 2),
            (seq(2, 0), 3),
            (seq(2, 1), 4),
        ] {
            assert!(c.push(n, 0, t));
        }
        assert_eq!(
            (c.received, c.lost(), c.restarts, c.out_of_order),
            (4, 1, 1, 0)
        );
        assert_eq!(c.run_id, Some(2));
    }

    /// The definition's cases are `dear_stats`'s; this checks the unit (ns in, ms out).
    #[test]
    fn percentiles_are_in_milliseconds() {
        let mut v: Vec<u64> = (1..=100).rev().map(|ms| ms * 1_000_000).collect();
        let p = percentiles(&mut v).unwrap();
        assert_eq!(
            (p.n, p.p50_ms, p.p95_ms, p.p99_ms, p.max_ms),
            (100, 50.0, 95.0, 99.0, 100.0)
        );
        assert_eq!(percentiles(&mut []), None);
    }
}
