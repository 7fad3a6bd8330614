//! Per-second statistics of a frame stream, as `dear watch` prints them.
//!
//! Pure: it sees headers and receive times, never a clock or a socket, so the numbers are
//! testable by hand. [`Window::push`] each received frame, [`Window::report`] once a second.
//!
//! "Median" is `dear_stats`'s nearest-rank 0.5-percentile (the lower middle value for an even
//! count), the same definition as the daemon's log and the soak client.

use std::fmt;
use std::time::Duration;

use dear_client::{SequenceStep, SequenceTracker};
use dear_proto::{flags, FrameHeader, Stage};
use serde::Serialize;

/// Frames received since the last report, plus what must carry over between reports.
#[derive(Debug, Default)]
pub struct Window {
    /// Client receive time − publish time, ns, per frame.
    end_to_end_ns: Vec<u64>,
    /// The daemon's per-stage latencies in µs, per stage, only from frames that ran it.
    stages: [Vec<u32>; Stage::ALL.len()],
    rejected: u64,
    last: Option<FrameHeader>,
    /// `(run_id, skipped, dropped)` of the last frame of the previous report, for the
    /// per-second delta.
    previous_counters: Option<(u64, u64, u64)>,
    /// The newest numbered frame received, across reports: the next frame's sequence gap is
    /// what this client lost.
    sequence: SequenceTracker,
    /// Frames lost in the window (gaps in `sequence`).
    lost: u64,
    /// New run ids seen in the window: publisher restarts.
    restarts: u64,
}

/// A latency distribution over one second, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Latency {
    pub median_ms: f64,
    pub max_ms: f64,
}

/// The median latency of one daemon stage over one second.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageLatency {
    pub stage: &'static str,
    /// `None` when no frame of the second ran the stage.
    pub median_ms: Option<f64>,
}

/// The calibration estimate carried by the newest frame of the second.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationReport {
    pub tx: f32,
    pub ty: f32,
    pub cx: f32,
    pub cy: f32,
    /// RMS residual of the fit in px; `None` for a static calibration (header NaN).
    pub residual_px: Option<f32>,
    pub quality: f32,
    pub age_frames: u32,
    /// Calibration health (docs/calibration-health.md): `"unknown"`, `"good"`, `"can improve"`
    /// or `"needs recalibration"`.
    pub health: &'static str,
    /// Directions of `(t, c)` the last measurement's frame constrained, 0–4.
    pub constrained: u8,
}

/// One line of `dear watch`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Frames received in the window.
    pub frames: usize,
    /// `frames / window length`.
    pub fps: f64,
    /// Newest frame id, if any frame arrived.
    pub frame_id: Option<u64>,
    /// Client receive time − publish timestamp (both `CLOCK_MONOTONIC`): what the shared-memory
    /// hop and the client's wake-up add to the daemon's own latency.
    pub end_to_end: Option<Latency>,
    /// The daemon's `Total` stage: its arrival-to-publish time.
    pub daemon_total: Option<Latency>,
    /// Median of every other stage.
    pub stages: Vec<StageLatency>,
    pub calibration: Option<CalibrationReport>,
    /// Decoded [`flags`] of the newest frame.
    pub flags: Vec<&'static str>,
    pub bundle: Option<String>,
    /// The daemon's running totals as of the newest frame.
    pub frames_skipped: Option<u64>,
    pub frames_dropped: Option<u64>,
    /// Increase of those totals since the previous report (0 for the first one).
    pub skipped_in_window: u64,
    pub dropped_in_window: u64,
    /// Frames the client received but rejected as malformed.
    pub rejected: u64,
    /// `run_id` of the newest frame, hex; `None` when no frame came or its publisher gave
    /// none (0).
    pub run_id: Option<String>,
    /// Frames this client lost in the window: gaps in `sequence` (its queue overwrote them
    /// because it read too slowly). 0 when the publisher stamps no run id.
    pub lost: u64,
    /// Times the run id changed in the window: the publisher restarted (its `frame_id`,
    /// `sequence` and counters started again).
    pub publisher_restarts: u64,
}

impl Window {
    /// Adds one received frame; `receive_ns` is the client's `CLOCK_MONOTONIC` at receipt.
    pub fn push(&mut self, header: &FrameHeader, receive_ns: u64) {
        // A publish time after the receive time cannot happen on one clock; count it as 0
        // rather than wrapping.
        self.end_to_end_ns
            .push(receive_ns.saturating_sub(header.publish_timestamp_ns));
        for stage in Stage::ALL {
            let us = header.latency_us(stage);
            if us > 0 {
                self.stages[stage as usize].push(us);
            }
        }
        match self.sequence.see(header) {
            SequenceStep::Next { lost } => self.lost += lost,
            SequenceStep::Restart => self.restarts += 1,
            SequenceStep::First | SequenceStep::Unnumbered => {}
        }
        self.last = Some(*header);
    }

    /// Counts a frame that arrived but failed validation.
    pub fn reject(&mut self) {
        self.rejected += 1;
    }

    /// Summarises the window (which lasted `elapsed`) and starts a new one.
    pub fn report(&mut self, elapsed: Duration) -> Report {
        let frames = self.end_to_end_ns.len();
        let secs = elapsed.as_secs_f64();
        let fps = if secs > 0.0 {
            frames as f64 / secs
        } else {
            0.0
        };
        let end_to_end = latency(self.end_to_end_ns.iter().map(|&ns| ns as f64 * 1e-6));
        let daemon_total = latency(
            self.stages[Stage::Total as usize]
                .iter()
                .map(|&us| f64::from(us) * 1e-3),
        );
        let stages = Stage::ALL
            .iter()
            .filter(|&&s| s != Stage::Total)
            .map(|&s| StageLatency {
                stage: s.name(),
                median_ms: median(
                    self.stages[s as usize]
                        .iter()
                        .map(|&us| f64::from(us) * 1e-3)
                        .collect(),
                ),
            })
            .collect();
        let last = self.last.take();
        let counters = last.map(|h| (h.run_id, h.frames_skipped, h.frames_dropped));
        let (skipped_in_window, dropped_in_window) = match (self.previous_counters, counters) {
            // A restarted publisher (new run id) counts from 0 again: all of its totals are new.
            (Some((r0, _, _)), Some((r1, s1, d1))) if r0 != r1 => (s1, d1),
            // Saturating: a publisher without run ids may restart unseen.
            (Some((_, s0, d0)), Some((_, s1, d1))) => {
                (s1.saturating_sub(s0), d1.saturating_sub(d0))
            }
            _ => (0, 0),
        };
        if counters.is_some() {
            self.previous_counters = counters;
        }
        let report = Report {
            frames,
            fps,
            frame_id: last.map(|h| h.frame_id),
            end_to_end,
            daemon_total,
            stages,
            calibration: last.map(|h| CalibrationReport {
                tx: h.calib_tx,
                ty: h.calib_ty,
                cx: h.calib_cx,
                cy: h.calib_cy,
                residual_px: Some(h.calib_residual_px).filter(|r| r.is_finite()),
                quality: h.calib_quality,
                age_frames: h.calib_age_frames,
                health: h.calibration_health().name(),
                constrained: h.calib_constrained,
            }),
            flags: last.map(|h| flag_names(h.flags)).unwrap_or_default(),
            bundle: last
                .map(|h| h.bundle_name().to_string())
                .filter(|b| !b.is_empty()),
            frames_skipped: counters.map(|c| c.1),
            frames_dropped: counters.map(|c| c.2),
            skipped_in_window,
            dropped_in_window,
            rejected: self.rejected,
            run_id: last
                .filter(|h| h.run_id != 0)
                .map(|h| format!("{:016x}", h.run_id)),
            lost: self.lost,
            publisher_restarts: self.restarts,
        };
        self.end_to_end_ns.clear();
        self.stages.iter_mut().for_each(Vec::clear);
        self.rejected = 0;
        self.lost = 0;
        self.restarts = 0;
        report
    }
}

/// Names of the set [`flags`] bits, in bit order.
pub fn flag_names(bits: u32) -> Vec<&'static str> {
    [
        (flags::ALIGNED, "aligned"),
        (flags::REFINED_NETWORK, "refined-network"),
        (flags::REFINED_CLASSICAL, "refined-classical"),
        (flags::CALIBRATION_ESTIMATED, "calib-estimated"),
        (flags::CALIBRATION_ONLINE, "online"),
    ]
    .into_iter()
    .filter(|(bit, _)| bits & bit != 0)
    .map(|(_, name)| name)
    .collect()
}

/// The median ([`dear_stats::median`]: nearest rank, the lower middle value for an even
/// count); `None` for no values.
pub fn median(mut values: Vec<f64>) -> Option<f64> {
    dear_stats::sort(&mut values);
    dear_stats::median(&values)
}

fn latency(values: impl Iterator<Item = f64>) -> Option<Latency> {
    let values: Vec<f64> = values.collect();
    let max_ms = values.iter().copied().reduce(f64::max)?;
    Some(Latency {
        median_ms: median(values)?,
        max_ms,
    })
}

fn opt_ms(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_string(), |ms| format!("{ms:.1}"))
}

impl fmt::Display for Report {
    /// One human-readable line, e.g.
    /// `#1234 30.0 fps | e2e 12.3/15.1 ms | daemon 10.2/13.0 ms | capture 1.2 … | calib …`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.frames == 0 {
            write!(f, "no frames")?;
            if self.rejected > 0 {
                write!(f, " | rejected {}", self.rejected)?;
            }
            return Ok(());
        }
        if self.publisher_restarts > 0 {
            // First on the line: the ids and totals after it started again.
            let run = self.run_id.as_deref().unwrap_or("?");
            write!(f, "publisher restarted (run {run}) | ")?;
        }
        if let Some(id) = self.frame_id {
            write!(f, "#{id} ")?;
        }
        write!(f, "{:.1} fps", self.fps)?;
        let lat = |l: Option<Latency>| {
            l.map_or_else(
                || "-".to_string(),
                |l| format!("{:.1}/{:.1} ms", l.median_ms, l.max_ms),
            )
        };
        write!(f, " | e2e med/max {}", lat(self.end_to_end))?;
        write!(f, " | daemon {}", lat(self.daemon_total))?;
        write!(f, " |")?;
        for s in &self.stages {
            write!(f, " {} {}", s.stage, opt_ms(s.median_ms))?;
        }
        if let Some(c) = &self.calibration {
            let residual = c
                .residual_px
                .map_or_else(|| "-".to_string(), |r| format!("{r:.2}"));
            write!(
                f,
                " | calib tx {:.2} ty {:.2} cx {:.2} cy {:.2} res {residual} q {:.2} age {} \
                 health {} ({}/4 seen)",
                c.tx, c.ty, c.cx, c.cy, c.quality, c.age_frames, c.health, c.constrained
            )?;
        }
        let flags = if self.flags.is_empty() {
            "raw".to_string()
        } else {
            self.flags.join("+")
        };
        write!(f, " | {flags}")?;
        if let Some(bundle) = &self.bundle {
            write!(f, " ({bundle})")?;
        }
        write!(
            f,
            " | skipped {} (+{}) dropped {} (+{})",
            self.frames_skipped.unwrap_or(0),
            self.skipped_in_window,
            self.frames_dropped.unwrap_or(0),
            self.dropped_in_window
        )?;
        if self.run_id.is_some() {
            write!(f, " | lost {}", self.lost)?;
        }
        if self.rejected > 0 {
            write!(f, " | rejected {}", self.rejected)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(id: u64, publish_ns: u64, total_us: u32, flow_us: u32) -> FrameHeader {
        let mut h = FrameHeader::new(id, 4, 3);
        h.publish_timestamp_ns = publish_ns;
        h.stage_latency_us[Stage::Total as usize] = total_us;
        h.stage_latency_us[Stage::Flow as usize] = flow_us;
        h.stage_latency_us[Stage::Capture as usize] = 100;
        h
    }

    #[test]
    fn one_second_of_frames() {
        let mut w = Window::default();
        // Medians are nearest rank: the lower middle value of an even count.
        // End-to-end: 2, 4, 9, 3 ms → sorted 2 3 4 9 → median 3, max 9.
        // Total: 10, 30, 20, 40 ms → median 20, max 40.
        // Flow: run on frames 0 and 2 only (5 ms, 8 ms) → median 5; fuse never → None.
        let frames = [
            (header(10, 1_000_000_000, 10_000, 5_000), 1_002_000_000),
            (header(11, 1_100_000_000, 30_000, 0), 1_104_000_000),
            (header(12, 1_200_000_000, 20_000, 8_000), 1_209_000_000),
            (header(13, 1_300_000_000, 40_000, 0), 1_303_000_000),
        ];
        for (h, rx) in &frames {
            w.push(h, *rx);
        }
        let r = w.report(Duration::from_millis(500));
        assert_eq!(r.frames, 4);
        assert!((r.fps - 8.0).abs() < 1e-9);
        assert_eq!(r.frame_id, Some(13));
        let e2e = r.end_to_end.unwrap();
        assert!((e2e.median_ms - 3.0).abs() < 1e-9, "{e2e:?}");
        assert!((e2e.max_ms - 9.0).abs() < 1e-9);
        let total = r.daemon_total.unwrap();
        assert!((total.median_ms - 20.0).abs() < 1e-9);
        assert!((total.max_ms - 40.0).abs() < 1e-9);
        let stage = |name: &str| r.stages.iter().find(|s| s.stage == name).unwrap().median_ms;
        assert_eq!(stage("flow"), Some(5.0));
        assert_eq!(stage("capture"), Some(0.1));
        assert_eq!(stage("fuse"), None);
        assert!(r.stages.iter().all(|s| s.stage != "total"));
        // The window is empty afterwards.
        let empty = w.report(Duration::from_secs(1));
        assert_eq!(empty.frames, 0);
        assert_eq!(empty.end_to_end, None);
        assert_eq!(empty.to_string(), "no frames");
    }

    #[test]
    fn publish_after_receive_counts_as_zero() {
        let mut w = Window::default();
        w.push(&header(1, 2_000, 0, 0), 1_000);
        let r = w.report(Duration::from_secs(1));
        assert_eq!(r.end_to_end.unwrap().max_ms, 0.0);
        assert_eq!(r.daemon_total, None, "total 0 means not measured");
    }

    #[test]
    fn calibration_flags_and_counters_come_from_the_newest_frame() {
        let mut w = Window::default();
        let mut a = header(1, 0, 1, 0);
        a.frames_skipped = 2;
        a.frames_dropped = 5;
        w.push(&a, 0);
        let first = w.report(Duration::from_secs(1));
        assert_eq!((first.skipped_in_window, first.dropped_in_window), (0, 0));
        assert_eq!(first.calibration.as_ref().unwrap().residual_px, None);
        assert_eq!(first.flags, Vec::<&str>::new());

        let mut b = header(2, 0, 1, 0);
        b.frames_skipped = 3;
        b.frames_dropped = 9;
        b.calib_tx = 12.5;
        b.calib_cy = -1.25;
        b.calib_residual_px = 0.4;
        b.calib_quality = 0.9;
        b.calib_age_frames = 7;
        b.calib_health = 2;
        b.calib_constrained = 3;
        b.flags = flags::ALIGNED | flags::REFINED_NETWORK | flags::CALIBRATION_ONLINE;
        b.set_bundle_name("edge");
        w.push(&b, 0);
        w.reject();
        let r = w.report(Duration::from_secs(1));
        assert_eq!((r.frames_skipped, r.frames_dropped), (Some(3), Some(9)));
        assert_eq!((r.skipped_in_window, r.dropped_in_window), (1, 4));
        assert_eq!(r.rejected, 1);
        let c = r.calibration.clone().unwrap();
        assert_eq!((c.tx, c.cy, c.residual_px), (12.5, -1.25, Some(0.4)));
        assert_eq!((c.quality, c.age_frames), (0.9, 7));
        assert_eq!((c.health, c.constrained), ("can improve", 3));
        assert_eq!(r.flags, ["aligned", "refined-network", "online"]);
        assert_eq!(r.bundle.as_deref(), Some("edge"));
        let line = r.to_string();
        for part in [
            "#2 ",
            "1.0 fps",
            "calib tx 12.50 ty 0.00 cx 0.00 cy -1.25 res 0.40 q 0.90 age 7",
            "health can improve (3/4 seen)",
            "aligned+refined-network+online (edge)",
            "skipped 3 (+1) dropped 9 (+4)",
            "rejected 1",
        ] {
            assert!(line.contains(part), "{part:?} not in {line:?}");
        }
        // A quiet second keeps the previous totals as the baseline.
        let _ = w.report(Duration::from_secs(1));
        let mut c2 = b;
        c2.frames_dropped = 10;
        w.push(&c2, 0);
        assert_eq!(w.report(Duration::from_secs(1)).dropped_in_window, 1);
    }

    fn numbered(run_id: u64, sequence: u64, dropped: u64) -> FrameHeader {
        let mut h = header(sequence, 0, 1, 0);
        h.run_id = run_id;
        h.sequence = sequence;
        h.frames_dropped = dropped;
        h
    }

    #[test]
    fn sequence_gaps_are_lost_frames_and_a_new_run_id_is_a_restart() {
        let mut w = Window::default();
        // Joining at sequence 10 loses nothing; 11 → 14 lost 12 and 13; 14 → 20 lost 5.
        for seq in [10, 11, 14, 20] {
            w.push(&numbered(0xabc, seq, 4), 0);
        }
        let r = w.report(Duration::from_secs(1));
        assert_eq!((r.lost, r.publisher_restarts), (7, 0));
        assert_eq!(r.run_id.as_deref(), Some("0000000000000abc"));
        assert!(r.to_string().ends_with("| lost 7"), "{r}");
        // Across a report: 20 → 21 is no loss. Then the publisher restarts (new run id,
        // sequence and counters from 0): no loss is counted across the restart, and its
        // dropped total is all new.
        w.push(&numbered(0xabc, 21, 6), 0);
        w.push(&numbered(0xdef, 0, 0), 0);
        w.push(&numbered(0xdef, 2, 1), 0);
        let r = w.report(Duration::from_secs(1));
        assert_eq!((r.lost, r.publisher_restarts), (1, 1));
        assert_eq!(r.dropped_in_window, 1, "the new run's own total");
        let line = r.to_string();
        assert!(
            line.starts_with("publisher restarted (run 0000000000000def) | #2 "),
            "{line}"
        );
        assert!(line.ends_with("| lost 1"), "{line}");
        // The next window, same run: no restart, the dropped delta is against the new run.
        w.push(&numbered(0xdef, 3, 3), 0);
        let r = w.report(Duration::from_secs(1));
        assert_eq!(
            (r.lost, r.publisher_restarts, r.dropped_in_window),
            (0, 0, 2)
        );
        assert!(!r.to_string().contains("restarted"));
    }

    #[test]
    fn without_a_run_id_nothing_is_counted_as_lost() {
        let mut w = Window::default();
        for id in [1, 5, 9] {
            w.push(&header(id, 0, 1, 0), 0);
        }
        let r = w.report(Duration::from_secs(1));
        assert_eq!(
            (r.lost, r.publisher_restarts, r.run_id.as_deref()),
            (0, 0, None)
        );
        assert!(!r.to_string().contains("lost"), "{r}");
    }

    #[test]
    fn json_line_has_named_fields_and_null_for_unknowns() {
        let mut w = Window::default();
        w.push(&header(5, 0, 2_000, 0), 1_000_000);
        let v = serde_json::to_value(w.report(Duration::from_secs(1))).unwrap();
        assert_eq!(v["frames"], 1);
        assert_eq!(v["end_to_end"]["median_ms"], 1.0);
        assert_eq!(v["daemon_total"]["max_ms"], 2.0);
        assert_eq!(v["calibration"]["residual_px"], serde_json::Value::Null);
        assert_eq!(v["stages"][2]["stage"], "flow");
        assert_eq!(v["stages"][2]["median_ms"], serde_json::Value::Null);
    }
}
