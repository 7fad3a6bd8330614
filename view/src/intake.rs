//! The intake: reads every frame of the service on one thread, keeps the statistics, a
//! once-a-second history and a copy of the newest frame (a [`Snapshot`]) at most `max_fps`
//! times a second. Nothing here waits on a viewer: the HTTP workers only lock [`State`] for the
//! time it takes to clone an `Arc` or a few numbers.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use dear_client::{Client, Frame, ReceiveError, SequenceStep, SequenceTracker};
use dear_proto::FrameHeader;
use ndarray::{ArrayView2, ArrayView3};

use crate::http::Viewers;
use crate::render::Cache;
use crate::status::HistoryPoint;
use crate::{ViewConfig, POLL};

/// Seconds of history kept (one point a second).
pub const HISTORY_SECONDS: usize = 300;
/// The window the frame rate is measured over.
const FPS_WINDOW: Duration = Duration::from_secs(2);

/// A copy of one frame's header and planes, owned (the shared-memory sample is released as
/// soon as it is taken).
#[derive(Debug)]
pub struct Snapshot {
    /// Counts snapshots from 1 in this viewer; names the pictures rendered from it (a frame's
    /// own `sequence` restarts with the daemon).
    pub id: u64,
    pub header: FrameHeader,
    pub width: usize,
    pub height: usize,
    /// Metres, row-major, 0 = invalid.
    pub depth: Vec<f32>,
    /// `(H, W, 3)` row-major.
    pub rgb: Vec<u8>,
    pub confidence: Vec<u8>,
}

impl Snapshot {
    /// Copies `frame`'s header and planes.
    pub fn copy(frame: &Frame, id: u64) -> Snapshot {
        let (width, height) = frame.size();
        Snapshot {
            id,
            header: *frame.header(),
            width,
            height,
            depth: frame.depth().to_vec(),
            rgb: frame.rgb().to_vec(),
            confidence: frame.confidence().to_vec(),
        }
    }

    pub fn depth_view(&self) -> ArrayView2<'_, f32> {
        ArrayView2::from_shape((self.height, self.width), &self.depth)
            .expect("a snapshot's depth is height × width")
    }

    pub fn rgb_view(&self) -> ArrayView3<'_, u8> {
        ArrayView3::from_shape((self.height, self.width, 3), &self.rgb)
            .expect("a snapshot's RGB is height × width × 3")
    }
}

/// The newest header and when it arrived.
#[derive(Debug, Clone, Copy)]
pub struct Latest {
    pub header: FrameHeader,
    pub received: Instant,
    /// `CLOCK_MONOTONIC` at receipt, comparable with the header's publish time.
    pub received_ns: u64,
}

/// What the intake knows; read by the status and picture handlers.
#[derive(Debug)]
pub struct State {
    pub latest: Option<Latest>,
    pub snapshot: Option<Arc<Snapshot>>,
    /// Frames received (good ones).
    pub received: u64,
    /// Frames received but malformed.
    pub rejected: u64,
    /// Frames the intake missed: gaps in `sequence` within one run.
    pub lost: u64,
    /// Times the publisher's run id changed (daemon restarts).
    pub publisher_restarts: u64,
    /// The last receive error, cleared by the next good frame.
    pub error: Option<String>,
    /// One point a second, oldest first, at most [`HISTORY_SECONDS`].
    pub history: VecDeque<HistoryPoint>,
    arrivals: VecDeque<Instant>,
    sequence: SequenceTracker,
    second_start: Instant,
    second_frames: u32,
    /// The newest header of the running second.
    second_last: Option<FrameHeader>,
}

/// Everything the threads share.
pub struct Shared {
    pub service: String,
    pub max_fps: f64,
    pub depth_range: Option<(f32, f32)>,
    pub started: Instant,
    state: Mutex<State>,
    pub cache: Cache,
    pub viewers: Mutex<Viewers>,
}

impl Shared {
    pub fn new(config: &ViewConfig) -> Shared {
        let now = Instant::now();
        Shared {
            service: config.service.clone(),
            max_fps: config.max_fps,
            depth_range: config.depth_range,
            started: now,
            state: Mutex::new(State {
                latest: None,
                snapshot: None,
                received: 0,
                rejected: 0,
                lost: 0,
                publisher_restarts: 0,
                error: None,
                history: VecDeque::with_capacity(HISTORY_SECONDS),
                arrivals: VecDeque::new(),
                sequence: SequenceTracker::default(),
                second_start: now,
                second_frames: 0,
                second_last: None,
            }),
            cache: Cache::default(),
            viewers: Mutex::new(Viewers::new(config.max_viewers)),
        }
    }

    /// The state, also after a panic elsewhere (its numbers stay usable).
    pub fn state(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The newest snapshot, if any frame was copied yet.
    pub fn snapshot(&self) -> Option<Arc<Snapshot>> {
        self.state().snapshot.clone()
    }
}

impl State {
    /// Counts one good frame.
    pub fn record(&mut self, header: &FrameHeader, now: Instant, now_ns: u64) {
        self.received += 1;
        self.error = None;
        self.arrivals.push_back(now);
        self.trim_arrivals(now);
        match self.sequence.see(header) {
            SequenceStep::Next { lost } => self.lost += lost,
            SequenceStep::Restart => self.publisher_restarts += 1,
            SequenceStep::First | SequenceStep::Unnumbered => {}
        }
        self.latest = Some(Latest {
            header: *header,
            received: now,
            received_ns: now_ns,
        });
        self.second_frames += 1;
        self.second_last = Some(*header);
    }

    fn trim_arrivals(&mut self, now: Instant) {
        while self
            .arrivals
            .front()
            .is_some_and(|&t| now.duration_since(t) > FPS_WINDOW)
        {
            self.arrivals.pop_front();
        }
    }

    /// Frames per second over the last `FPS_WINDOW`: intervals between the arrivals in it
    /// over their span; 0 when fewer than two frames came in it.
    pub fn fps(&mut self, now: Instant) -> f64 {
        self.trim_arrivals(now);
        match (self.arrivals.front(), self.arrivals.back()) {
            (Some(&first), Some(&last)) if self.arrivals.len() >= 2 && last > first => {
                (self.arrivals.len() - 1) as f64 / last.duration_since(first).as_secs_f64()
            }
            _ => 0.0,
        }
    }

    /// Closes the running second when it is over: one history point with its frame count and
    /// the calibration of its newest frame (none when no frame came).
    pub fn tick(&mut self, now: Instant, started: Instant) {
        let elapsed = now.duration_since(self.second_start);
        if elapsed < Duration::from_secs(1) {
            return;
        }
        let t_s = now.duration_since(started).as_secs_f64();
        let fps = f64::from(self.second_frames) / elapsed.as_secs_f64();
        if self.history.len() == HISTORY_SECONDS {
            self.history.pop_front();
        }
        self.history
            .push_back(HistoryPoint::new(t_s, fps, self.second_last.as_ref()));
        self.second_start = now;
        self.second_frames = 0;
        self.second_last = None;
    }
}

/// The intake loop: until `stop`, takes every frame as it comes; keeps a snapshot of the newest
/// at most `max_fps` times a second.
pub fn run(client: &Client, shared: &Shared, stop: &AtomicBool) {
    let snapshot_every = Duration::from_secs_f64(1.0 / shared.max_fps);
    let mut last_snapshot: Option<Instant> = None;
    let mut snapshots = 0u64;
    while !stop.load(Ordering::Relaxed) {
        let mut newest: Option<Frame> = None;
        let mut next = client.wait(POLL);
        // Drain the queue: every frame is counted, only the newest may be copied.
        loop {
            match next {
                Ok(Some(frame)) => {
                    let now = Instant::now();
                    shared
                        .state()
                        .record(frame.header(), now, dear_proto::time::monotonic_ns());
                    newest = Some(frame);
                }
                Ok(None) => break,
                Err(ReceiveError::BadFrame { source, .. }) => {
                    tracing::debug!(error = %source, "frame rejected");
                    let mut state = shared.state();
                    state.rejected += 1;
                    state.error = Some(format!("malformed frame: {source}"));
                }
                Err(e) => {
                    tracing::warn!(error = %e, "receiving failed");
                    shared.state().error = Some(e.to_string());
                    drop(newest.take());
                    std::thread::sleep(POLL);
                    break;
                }
            }
            next = client.try_receive();
        }
        let now = Instant::now();
        if let Some(frame) = newest {
            if last_snapshot.is_none_or(|t| now.duration_since(t) >= snapshot_every) {
                snapshots += 1;
                let snapshot = Arc::new(Snapshot::copy(&frame, snapshots));
                // The sample goes back to the daemon before anything else happens.
                drop(frame);
                shared.state().snapshot = Some(snapshot);
                last_snapshot = Some(now);
            }
        }
        shared.state().tick(now, shared.started);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state() -> (Shared, Instant) {
        let shared = Shared::new(&ViewConfig::new("127.0.0.1:0", "dear/test/frames"));
        let t0 = shared.state().second_start;
        (shared, t0)
    }

    fn header(run: u64, seq: u64) -> FrameHeader {
        let mut h = FrameHeader::new(seq, 4, 3);
        h.run_id = run;
        h.sequence = seq;
        h.calib_tx = 10.0 + seq as f32;
        h
    }

    #[test]
    fn fps_losses_and_restarts_are_counted() {
        let (shared, t0) = state();
        let mut s = shared.state();
        for i in 0..5u64 {
            // 20 fps, sequence 3 missing.
            let seq = if i >= 3 { i + 1 } else { i };
            s.record(&header(7, seq), t0 + Duration::from_millis(50 * i), 0);
        }
        assert!((s.fps(t0 + Duration::from_millis(200)) - 20.0).abs() < 1e-9);
        assert_eq!((s.received, s.lost, s.publisher_restarts), (5, 1, 0));
        s.record(&header(8, 0), t0 + Duration::from_millis(250), 0);
        assert_eq!((s.lost, s.publisher_restarts), (1, 1));
        // Nothing for longer than the window: 0 fps.
        assert_eq!(s.fps(t0 + Duration::from_secs(5)), 0.0);
    }

    #[test]
    fn history_gets_a_point_a_second_with_the_newest_calibration() {
        let (shared, t0) = state();
        let started = shared.started;
        let mut s = shared.state();
        s.tick(t0 + Duration::from_millis(500), started);
        assert!(s.history.is_empty());
        for i in 0..10 {
            s.record(&header(1, i), t0 + Duration::from_millis(100 * i), 0);
        }
        s.tick(t0 + Duration::from_secs(1), started);
        assert_eq!(s.history.len(), 1);
        let p = &s.history[0];
        assert!((p.fps - 10.0).abs() < 1e-9);
        assert_eq!(p.tx, Some(19.0));
        // A second without frames: a point without calibration.
        s.tick(t0 + Duration::from_secs(2), started);
        assert_eq!(s.history.len(), 2);
        assert_eq!((s.history[1].fps, s.history[1].tx), (0.0, None));
        for k in 0..(HISTORY_SECONDS as u64 + 10) {
            s.tick(t0 + Duration::from_secs(3 + k), started);
        }
        assert_eq!(s.history.len(), HISTORY_SECONDS);
    }
}
