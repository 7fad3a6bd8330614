//! Replaying a capture directory (docs/capture-format.md): paced by the recorded timestamps or as
//! fast as possible, optionally looping, between a start and an end position.
//!
//! The frames are decoded ahead by a [`FramePrefetch`] thread ([`PREFETCH_AHEAD`] frames ahead,
//! at nice +[`PREFETCH_NICE`]), not when they are due: the PNG decoding (about 5–8 ms a
//! 640×480 frame) fills the time the frame path leaves free instead of delaying each frame or
//! competing with the frame path when it is busy. The pacing is unchanged: a frame is handed
//! on when its timestamp is due (or at once, as fast pacing), and a frame whose decoding is
//! late is handed on when it is ready.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use dear_capture::prefetch::{Finished, PrefetchError};
use dear_capture::{
    Calibration, CaptureDir, CaptureError, CaptureManifest, FramePrefetch, PrefetchOptions,
    Prefetched,
};

use dear_proto::CameraIntrinsics;

use super::{sleep_unless, DepthLimit, FrameSource, SourceItem};
use crate::config::{CaptureConfig, Pacing};

/// Decoded frames held ready: at 30 fps, 133 ms of decoding slack, 13 MB at 640×480.
pub const PREFETCH_AHEAD: usize = 4;

/// The decoding thread's nice value above the daemon's: it yields to the frame path, and runs
/// before the background calibration worker (nice +19).
pub const PREFETCH_NICE: i32 = 10;

/// A paced frame handed on later than this after its due time is counted late.
const LATE: Duration = Duration::from_millis(10);

/// How long a wait for the decoder lasts before the shutdown flag is looked at again.
const WAIT_SLICE: Duration = Duration::from_millis(20);

/// Why a capture directory cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayOpenError {
    /// The directory or its `capture.json` cannot be read or is invalid.
    #[error("cannot replay: {0}")]
    Capture(#[from] CaptureError),
    /// The capture lists no frame.
    #[error("cannot replay {}: the capture has no frames", path.display())]
    Empty { path: std::path::PathBuf },
    /// `[capture] start` is at or after the end.
    #[error("cannot replay {}: start = {start} is not before the end ({end} frames)", path.display())]
    EmptyRange {
        path: std::path::PathBuf,
        start: usize,
        end: usize,
    },
    /// The decoding thread cannot be started.
    #[error("cannot replay {}: {source}", path.display())]
    Prefetch {
        path: std::path::PathBuf,
        #[source]
        source: PrefetchError,
    },
}

/// A [`FrameSource`] over a capture directory.
pub struct ReplaySource {
    dir: CaptureDir,
    /// The frames of `start..end`, decoded ahead, in order (looping when `loop_`).
    prefetch: FramePrefetch,
    pacing: Pacing,
    loop_: bool,
    start: usize,
    end: usize,
    /// Wall-clock instant that corresponds to the timestamp of the first frame of this pass.
    pass_origin: Option<(Instant, u64)>,
    /// Frames read successfully in this pass: a pass without one is a failure, not a loop.
    good_in_pass: usize,
    /// Why the last unreadable frame could not be read.
    last_error: Option<String>,
    /// Frames of this pass handed on more than [`LATE`] after they were due.
    late_in_pass: usize,
    /// Once the replay is over: `None` for its end, `Some(reason)` for a failure; every later
    /// call returns the same.
    over: Option<Option<String>>,
}

impl ReplaySource {
    /// Opens and validates the capture directory named by the config, and starts decoding its
    /// first frames.
    pub fn open(config: &CaptureConfig) -> Result<Self, ReplayOpenError> {
        let dir = CaptureDir::open(&config.path)?;
        if dir.is_empty() {
            return Err(ReplayOpenError::Empty {
                path: config.path.clone(),
            });
        }
        let end = config.end.unwrap_or(dir.len()).min(dir.len());
        if let Some(asked) = config.end.filter(|&e| e > dir.len()) {
            tracing::warn!(path = %config.path.display(), end = asked, frames = dir.len(), "[capture] end is beyond the capture's frames: replaying to its last frame");
        }
        if config.start >= end {
            return Err(ReplayOpenError::EmptyRange {
                path: config.path.clone(),
                start: config.start,
                end,
            });
        }
        let prefetch = FramePrefetch::start(
            dir.clone(),
            PrefetchOptions {
                range: config.start..end,
                looping: config.loop_,
                ahead: PREFETCH_AHEAD,
                nice: PREFETCH_NICE,
            },
        )
        .map_err(|source| ReplayOpenError::Prefetch {
            path: config.path.clone(),
            source,
        })?;
        Ok(ReplaySource {
            dir,
            prefetch,
            pacing: config.pacing,
            loop_: config.loop_,
            start: config.start,
            end,
            pass_origin: None,
            good_in_pass: 0,
            last_error: None,
            late_in_pass: 0,
            over: None,
        })
    }

    /// Sleeps until the frame at `position` is due, or until `shutdown` is raised (then returns
    /// `false`).
    fn pace(&mut self, position: usize, shutdown: &AtomicBool) -> bool {
        if self.pacing != Pacing::Timestamps {
            return true;
        }
        let stamp = self.dir.manifest().frames[position].timestamp_ns;
        let (origin, origin_stamp) = *self.pass_origin.get_or_insert((Instant::now(), stamp));
        let due = origin + Duration::from_nanos(stamp.saturating_sub(origin_stamp));
        let now = Instant::now();
        if now > due + LATE {
            self.late_in_pass += 1;
        }
        sleep_unless(shutdown, due.saturating_duration_since(now))
    }

    /// Logs the pass that just ended, when frames of it were handed on late (their decoding, or
    /// the capture thread, was behind when they were due: a machine too busy for them), and
    /// starts the next pass's count.
    fn end_pass(&mut self) {
        if self.late_in_pass > 0 {
            tracing::info!(
                late_frames = self.late_in_pass,
                late_by_more_than_ms = LATE.as_millis() as u64,
                "replay pass ended with frames handed on late: the decoder or the capture thread was behind when they were due"
            );
        }
        self.late_in_pass = 0;
    }

    /// The reason for a pass over `start..end` that read no frame.
    fn nothing_readable(&self) -> String {
        format!(
            "no readable frame in {} (frames {}..{}, every one skipped{}); last error: {}",
            self.dir.root().display(),
            self.start,
            self.end,
            if self.loop_ {
                "; not looping over them again"
            } else {
                ""
            },
            self.last_error.as_deref().unwrap_or("none")
        )
    }

    /// Ends the replay: this item now and at every later call.
    fn finish(&mut self, failure: Option<String>) -> SourceItem {
        self.over = Some(failure);
        self.over_item()
    }

    fn over_item(&self) -> SourceItem {
        match &self.over {
            Some(Some(reason)) => SourceItem::Failed {
                reason: reason.clone(),
            },
            _ => SourceItem::End,
        }
    }
}

impl FrameSource for ReplaySource {
    fn next_item(&mut self, shutdown: &AtomicBool) -> SourceItem {
        loop {
            if self.over.is_some() {
                return self.over_item();
            }
            let item = match self.prefetch.next(WAIT_SLICE) {
                Ok(Some(item)) => item,
                Ok(None) if shutdown.load(Ordering::Relaxed) => return SourceItem::End,
                Ok(None) => continue,
                // The prefetcher ends a pass with `EndOfPass`, and stops only after the last
                // one of a replay that does not loop: the replay is over either way.
                Err(Finished) => return self.finish(None),
            };
            let (position, frame, decode) = match item {
                Prefetched::EndOfPass => {
                    self.end_pass();
                    // A pass in which every frame was skipped would repeat forever (looping)
                    // or leave a service with nothing to serve (not looping).
                    if self.good_in_pass == 0 {
                        let reason = self.nothing_readable();
                        return self.finish(Some(reason));
                    }
                    if !self.loop_ {
                        return self.finish(None);
                    }
                    self.pass_origin = None;
                    self.good_in_pass = 0;
                    continue;
                }
                Prefetched::Frame {
                    position,
                    frame,
                    decode,
                } => (position, frame, decode),
            };
            if !self.pace(position, shutdown) {
                return SourceItem::End;
            }
            return match frame {
                Ok(frame) => {
                    self.good_in_pass += 1;
                    SourceItem::Frame {
                        frame,
                        // Due now; its decoding was done ahead, and is reported as the capture
                        // stage.
                        arrived: Instant::now(),
                        decode_us: decode.as_micros().min(u32::MAX as u128) as u32,
                    }
                }
                Err(e) => {
                    let reason = e.to_string();
                    self.last_error = Some(reason.clone());
                    SourceItem::Skipped {
                        frame_id: self.dir.manifest().frames[position].id,
                        reason,
                    }
                }
            };
        }
    }

    fn size(&self) -> (u32, u32) {
        self.dir.size()
    }

    fn initial_calibration(&self) -> Calibration {
        self.dir.manifest().initial_calibration
    }

    fn describe(&self) -> String {
        format!(
            "replay of {} (frames {}..{} of {}, {:?} pacing{}, decoded {} frames ahead)",
            self.dir.root().display(),
            self.start,
            self.end,
            self.dir.len(),
            self.pacing,
            if self.loop_ { ", looping" } else { "" },
            PREFETCH_AHEAD
        )
    }
    fn recording_manifest(&self) -> CaptureManifest {
        let mut manifest = self.dir.manifest().clone();
        manifest.frames.clear();
        manifest.source = serde_json::json!({
            "kind": "deard --record of a replay",
            "replayed": self.dir.root().display().to_string(),
            "original_source": self.dir.manifest().source,
        });
        manifest
    }

    fn depth_limit(&self) -> Option<DepthLimit> {
        DepthLimit::of_manifest(self.dir.manifest())
    }

    /// `capture.json`'s `intrinsics` and `distortion` (when it has one), at the manifest's size,
    /// which every frame has.
    fn rgb_intrinsics(&self) -> Option<CameraIntrinsics> {
        let m = self.dir.manifest();
        let k = m.intrinsics;
        Some(CameraIntrinsics {
            distortion: m.distortion,
            ..CameraIntrinsics::pinhole(k.fx, k.fy, k.cx, k.cy)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;
    use std::sync::atomic::Ordering;
    use std::sync::Arc;

    /// The shared writer: copies of `samples/demo`'s first frame, unreadable ones truncated.
    use dear_test_support::capture::write_demo_copies as write_capture;

    fn open(path: PathBuf, pacing: Pacing, loop_: bool) -> ReplaySource {
        ReplaySource::open(&CaptureConfig {
            path,
            pacing,
            loop_,
            ..CaptureConfig::default()
        })
        .unwrap()
    }

    fn kind(item: &SourceItem) -> &'static str {
        match item {
            SourceItem::Frame { .. } => "frame",
            SourceItem::Skipped { .. } => "skipped",
            SourceItem::End => "end",
            SourceItem::Failed { .. } => "failed",
        }
    }

    #[test]
    fn a_pass_without_a_readable_frame_fails_looping_or_not() {
        let tmp = tempfile::tempdir().unwrap();
        let path = write_capture(&tmp.path().join("cap"), &[(0, false), (1, false)]);
        let running = AtomicBool::new(false);
        for loop_ in [false, true] {
            let mut source = open(path.clone(), Pacing::Fast, loop_);
            let kinds: Vec<_> = (0..3).map(|_| kind(&source.next_item(&running))).collect();
            assert_eq!(kinds, ["skipped", "skipped", "failed"], "loop {loop_}");
            match source.next_item(&running) {
                SourceItem::Failed { reason } => assert!(
                    reason.contains("no readable frame") && reason.contains("000001.depth.png"),
                    "{reason}"
                ),
                other => panic!("{other:?}"),
            }
        }
    }

    #[test]
    fn a_loop_with_one_readable_frame_goes_on() {
        let tmp = tempfile::tempdir().unwrap();
        let path = write_capture(&tmp.path().join("cap"), &[(0, false), (1, true)]);
        let mut source = open(path, Pacing::Fast, true);
        let running = AtomicBool::new(false);
        let kinds: Vec<_> = (0..6).map(|_| kind(&source.next_item(&running))).collect();
        assert_eq!(
            kinds,
            ["skipped", "frame", "skipped", "frame", "skipped", "frame"]
        );
    }

    /// The frame id of each item, `Err(reason)` for a skipped frame, `"end"`/`"failed"`.
    fn ids(source: &mut ReplaySource, count: usize) -> Vec<Result<u64, String>> {
        let running = AtomicBool::new(false);
        (0..count)
            .map(|_| match source.next_item(&running) {
                SourceItem::Frame { frame, .. } => Ok(frame.index),
                SourceItem::Skipped { frame_id, reason } => {
                    assert!(
                        reason.contains(&format!("{frame_id:06}.depth.png")),
                        "{reason}"
                    );
                    Err(format!("skipped {frame_id}"))
                }
                other => Err(kind(&other).to_owned()),
            })
            .collect()
    }

    #[test]
    fn frames_come_in_order_a_bad_one_is_skipped_in_its_place_and_the_end_stays() {
        let tmp = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..5).map(|i| (i * 1_000, i != 2)).collect();
        let path = write_capture(&tmp.path().join("cap"), &frames);
        let mut source = open(path, Pacing::Timestamps, false);
        let end = || Err("end".to_owned());
        assert_eq!(
            ids(&mut source, 7),
            [
                Ok(0),
                Ok(1),
                Err("skipped 2".into()),
                Ok(3),
                Ok(4),
                end(),
                end()
            ]
        );
    }

    #[test]
    fn a_loop_over_start_to_end_replays_the_range_in_order() {
        let tmp = tempfile::tempdir().unwrap();
        let frames: Vec<_> = (0..6).map(|i| (i * 1_000, i != 2)).collect();
        let path = write_capture(&tmp.path().join("cap"), &frames);
        let mut source = ReplaySource::open(&CaptureConfig {
            path,
            pacing: Pacing::Fast,
            loop_: true,
            start: 1,
            end: Some(4),
            ..CaptureConfig::default()
        })
        .unwrap();
        let pass = [Ok(1), Err("skipped 2".to_owned()), Ok(3)];
        assert_eq!(
            ids(&mut source, 9),
            [pass.clone(), pass.clone(), pass].concat()
        );
    }

    #[test]
    fn pacing_gives_way_to_shutdown() {
        let tmp = tempfile::tempdir().unwrap();
        // The second frame is due an hour after the first.
        let path = write_capture(
            &tmp.path().join("cap"),
            &[(0, true), (3_600_000_000_000, true)],
        );
        let mut source = open(path, Pacing::Timestamps, false);
        let shutdown = Arc::new(AtomicBool::new(false));
        assert_eq!(kind(&source.next_item(&shutdown)), "frame");
        let raiser = {
            let shutdown = shutdown.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(100));
                shutdown.store(true, Ordering::Relaxed);
            })
        };
        let start = Instant::now();
        let item = source.next_item(&shutdown);
        assert!(start.elapsed() < Duration::from_secs(5), "{item:?}");
        assert_eq!(kind(&item), "end");
        raiser.join().unwrap();
    }
}
