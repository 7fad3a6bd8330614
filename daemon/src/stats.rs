//! Live statistics of the daemon: frame rate, per-stage latency percentiles and the skipped /
//! dropped counters, logged every `stats_interval_s`. Median and p95 are `dear_stats`'s
//! nearest-rank percentiles, the definition `dear watch` and the soak client print too.

use std::time::{Duration, Instant};

use dear_proto::{FrameHeader, Stage};

/// Counters since start, plus the latencies of the current interval.
#[derive(Debug)]
pub struct Stats {
    started: Instant,
    interval_start: Instant,
    interval: Duration,
    interval_frames: u64,
    latencies: Vec<[u32; 8]>,
    pub published: u64,
    pub skipped: u64,
    pub dropped: u64,
}

/// One interval's summary.
#[derive(Debug, Clone, PartialEq)]
pub struct IntervalReport {
    pub fps: f64,
    /// `(stage, median µs, p95 µs)` for stages that ran.
    pub stages: Vec<(Stage, u32, u32)>,
}

impl Stats {
    pub fn new(interval: Duration) -> Self {
        let now = Instant::now();
        Stats {
            started: now,
            interval_start: now,
            interval,
            interval_frames: 0,
            latencies: Vec::new(),
            published: 0,
            skipped: 0,
            dropped: 0,
        }
    }

    /// Records a published frame.
    pub fn record(&mut self, header: &FrameHeader) {
        self.published += 1;
        self.interval_frames += 1;
        self.latencies.push(header.stage_latency_us);
    }

    /// The interval's report, if the interval is over (then a new one starts).
    pub fn poll(&mut self) -> Option<IntervalReport> {
        let elapsed = self.interval_start.elapsed();
        if elapsed < self.interval {
            return None;
        }
        let report = summarize(&self.latencies, self.interval_frames, elapsed);
        self.interval_start = Instant::now();
        self.interval_frames = 0;
        self.latencies.clear();
        Some(report)
    }

    /// Seconds since start.
    pub fn uptime_s(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }
}

/// Frame rate and per-stage median / p95 over one interval.
pub fn summarize(latencies: &[[u32; 8]], frames: u64, elapsed: Duration) -> IntervalReport {
    let fps = frames as f64 / elapsed.as_secs_f64().max(1e-9);
    let mut stages = Vec::new();
    for stage in Stage::ALL {
        let mut values: Vec<u32> = latencies
            .iter()
            .map(|l| l[stage as usize])
            .filter(|&v| v > 0)
            .collect();
        if values.is_empty() {
            continue;
        }
        dear_stats::sort(&mut values);
        let at = |q| dear_stats::percentile_nearest_rank(&values, q).expect("non-empty");
        stages.push((stage, at(0.5), at(0.95)));
    }
    IntervalReport { fps, stages }
}

impl std::fmt::Display for IntervalReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:.1} fps", self.fps)?;
        for (stage, median, p95) in &self.stages {
            write!(
                f,
                " | {} {:.1}/{:.1} ms",
                stage.name(),
                *median as f64 / 1e3,
                *p95 as f64 / 1e3
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_skips_stages_that_did_not_run() {
        let mut a = [0u32; 8];
        a[Stage::Warp as usize] = 100;
        a[Stage::Total as usize] = 400;
        let mut b = a;
        b[Stage::Warp as usize] = 300;
        let report = summarize(&[a, b], 2, Duration::from_secs(1));
        assert_eq!(report.fps, 2.0);
        assert_eq!(
            report.stages,
            vec![(Stage::Warp, 100, 300), (Stage::Total, 400, 400)]
        );
    }
}
