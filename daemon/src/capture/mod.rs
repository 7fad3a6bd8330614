//! Frame sources. A [`FrameSource`] yields frames one by one; a bad frame is reported as
//! [`SourceItem::Skipped`] (with the error naming the file) and the stream goes on, unless
//! nothing at all can be read ([`SourceItem::Failed`]). Every wait of a source gives way to the
//! shutdown flag ([`sleep_unless`]).
//!
//! Back ends: [`replay`] (a capture directory) and [`v4l`] (a live module's V4L2 nodes, with
//! its calibration file read by [`module`]).

pub mod module;
pub mod replay;
pub mod v4l;

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use dear_capture::{Calibration, CaptureManifest, RgbdFrame};

/// What a source produced next.
#[derive(Debug)]
pub enum SourceItem {
    /// A good frame, and when it became available (for latency accounting).
    Frame {
        frame: Box<RgbdFrame>,
        arrived: Instant,
        decode_us: u32,
    },
    /// A frame that could not be read; `reason` names the file and the problem.
    Skipped { frame_id: u64, reason: String },
    /// The source has no more frames (or its wait was cut short by the shutdown flag).
    End,
    /// The source cannot produce any frame (e.g. a whole replay pass without one readable
    /// frame); the daemon stops with this error.
    Failed { reason: String },
}

/// A stream of RGB-D frames.
pub trait FrameSource: Send {
    /// The next item. Blocks for pacing when the source is paced, but returns promptly (with
    /// any item; the caller checks the flag) once `shutdown` is raised.
    fn next_item(&mut self, shutdown: &AtomicBool) -> SourceItem;
    /// `(width, height)` of every frame.
    fn size(&self) -> (u32, u32);
    /// The factory calibration that came with the stream.
    fn initial_calibration(&self) -> Calibration;
    /// Human-readable description for logs.
    fn describe(&self) -> String;
    /// The manifest of a recording of this stream (`deard --record`), without frames: size,
    /// intrinsics of the output grid, initial calibration, depth scale and where it came from.
    fn recording_manifest(&self) -> CaptureManifest;
}

/// Longest uninterrupted sleep of [`sleep_unless`]: how late a shutdown may be noticed.
const SLEEP_SLICE: Duration = Duration::from_millis(20);

/// Sleeps for `duration` in short slices, returning early once `shutdown` is raised (a signal
/// handler only sets the flag, so a plain long sleep would outlive SIGTERM). Returns whether the
/// whole duration was slept.
pub fn sleep_unless(shutdown: &AtomicBool, duration: Duration) -> bool {
    let deadline = Instant::now() + duration;
    loop {
        if shutdown.load(Ordering::Relaxed) {
            return false;
        }
        let now = Instant::now();
        if now >= deadline {
            return true;
        }
        std::thread::sleep((deadline - now).min(SLEEP_SLICE));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn sleep_unless_sleeps_the_whole_duration_without_shutdown() {
        let start = Instant::now();
        assert!(sleep_unless(
            &AtomicBool::new(false),
            Duration::from_millis(50)
        ));
        assert!(start.elapsed() >= Duration::from_millis(50));
    }

    #[test]
    fn sleep_unless_wakes_soon_after_shutdown() {
        let shutdown = Arc::new(AtomicBool::new(false));
        let raiser = {
            let shutdown = shutdown.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(50));
                shutdown.store(true, Ordering::Relaxed);
            })
        };
        let start = Instant::now();
        assert!(!sleep_unless(&shutdown, Duration::from_secs(3600)));
        assert!(start.elapsed() < Duration::from_secs(5));
        raiser.join().unwrap();
        assert!(
            !sleep_unless(&shutdown, Duration::from_secs(3600)),
            "raised: no sleep"
        );
    }
}
