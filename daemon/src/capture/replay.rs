//! Replaying a capture directory (DESIGN.md format): paced by the recorded timestamps or as
//! fast as possible, optionally looping, between a start and an end position.

use std::thread;
use std::time::{Duration, Instant};

use dear_pipeline::capture::CaptureDir;
use dear_pipeline::Calibration;

use super::{FrameSource, SourceItem};
use crate::config::{CaptureConfig, Pacing};

/// A [`FrameSource`] over a capture directory.
pub struct ReplaySource {
    dir: CaptureDir,
    pacing: Pacing,
    loop_: bool,
    start: usize,
    end: usize,
    position: usize,
    /// Wall-clock instant that corresponds to the timestamp of the first frame of this pass.
    pass_origin: Option<(Instant, u64)>,
}

impl ReplaySource {
    /// Opens and validates the capture directory named by the config.
    pub fn open(config: &CaptureConfig) -> Result<Self, String> {
        let dir = CaptureDir::open(&config.path).map_err(|e| format!("cannot replay: {e}"))?;
        if dir.is_empty() {
            return Err(format!(
                "cannot replay {}: the capture has no frames",
                config.path.display()
            ));
        }
        let end = config.end.unwrap_or(dir.len()).min(dir.len());
        if config.start >= end {
            return Err(format!(
                "cannot replay {}: start = {} is not before the end ({end} frames)",
                config.path.display(),
                config.start
            ));
        }
        Ok(ReplaySource {
            dir,
            pacing: config.pacing,
            loop_: config.loop_,
            start: config.start,
            end,
            position: config.start,
            pass_origin: None,
        })
    }

    /// Sleeps until the frame at `position` is due.
    fn pace(&mut self, position: usize) {
        if self.pacing != Pacing::Timestamps {
            return;
        }
        let stamp = self.dir.manifest().frames[position].timestamp_ns;
        let (origin, origin_stamp) = *self.pass_origin.get_or_insert((Instant::now(), stamp));
        let due = origin + Duration::from_nanos(stamp.saturating_sub(origin_stamp));
        let now = Instant::now();
        if due > now {
            thread::sleep(due - now);
        }
    }
}

impl FrameSource for ReplaySource {
    fn next_item(&mut self) -> SourceItem {
        if self.position >= self.end {
            if !self.loop_ {
                return SourceItem::End;
            }
            self.position = self.start;
            self.pass_origin = None;
        }
        let position = self.position;
        self.position += 1;
        self.pace(position);
        let arrived = std::time::Instant::now();
        match self.dir.read_frame(position) {
            Ok(frame) => SourceItem::Frame {
                frame: Box::new(frame),
                arrived,
                decode_us: arrived.elapsed().as_micros().min(u32::MAX as u128) as u32,
            },
            Err(e) => SourceItem::Skipped {
                frame_id: self.dir.manifest().frames[position].id,
                reason: e.to_string(),
            },
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
            "replay of {} (frames {}..{} of {}, {:?} pacing{})",
            self.dir.root().display(),
            self.start,
            self.end,
            self.dir.len(),
            self.pacing,
            if self.loop_ { ", looping" } else { "" }
        )
    }
}
