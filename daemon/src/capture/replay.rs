//! Replaying a capture directory (docs/capture-format.md): paced by the recorded timestamps or as
//! fast as possible, optionally looping, between a start and an end position.

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use dear_capture::{Calibration, CaptureDir, CaptureError, CaptureManifest};

use super::{sleep_unless, DepthLimit, FrameSource, SourceItem};
use crate::config::{CaptureConfig, Pacing};

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
}

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
    /// Frames read successfully in this pass: a pass without one is a failure, not a loop.
    good_in_pass: usize,
    /// Why the last unreadable frame could not be read.
    last_error: Option<String>,
}

impl ReplaySource {
    /// Opens and validates the capture directory named by the config.
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
        Ok(ReplaySource {
            dir,
            pacing: config.pacing,
            loop_: config.loop_,
            start: config.start,
            end,
            position: config.start,
            pass_origin: None,
            good_in_pass: 0,
            last_error: None,
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
        sleep_unless(shutdown, due.saturating_duration_since(Instant::now()))
    }

    /// The error for a pass over `start..end` that read no frame.
    fn nothing_readable(&self) -> SourceItem {
        SourceItem::Failed {
            reason: format!(
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
            ),
        }
    }
}

impl FrameSource for ReplaySource {
    fn next_item(&mut self, shutdown: &AtomicBool) -> SourceItem {
        if self.position >= self.end {
            // A pass in which every frame was skipped would repeat forever (looping) or leave a
            // service with nothing to serve (not looping).
            if self.good_in_pass == 0 {
                return self.nothing_readable();
            }
            if !self.loop_ {
                return SourceItem::End;
            }
            self.position = self.start;
            self.pass_origin = None;
            self.good_in_pass = 0;
        }
        let position = self.position;
        if !self.pace(position, shutdown) {
            return SourceItem::End;
        }
        self.position += 1;
        let arrived = std::time::Instant::now();
        // Sensor planes only: the replay is a camera, its ground truth is not published.
        match self.dir.read_frame(position) {
            Ok(frame) => {
                self.good_in_pass += 1;
                SourceItem::Frame {
                    frame: Box::new(frame),
                    arrived,
                    decode_us: arrived.elapsed().as_micros().min(u32::MAX as u128) as u32,
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::{Path, PathBuf};
    use std::sync::atomic::Ordering;
    use std::sync::Arc;

    use dear_capture::FramePaths;

    /// A capture at `root` with one frame per `(timestamp_ns, readable)`, copied from
    /// `samples/demo`'s first frame; unreadable frames have a truncated depth PNG.
    fn write_capture(root: &Path, frames: &[(u64, bool)]) -> PathBuf {
        let demo = CaptureDir::open(concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo"))
            .expect("samples/demo opens");
        let source = demo.frame_paths(0);
        let mut manifest = demo.manifest().clone();
        let template = manifest.frames[0].clone();
        manifest.frames.clear();
        std::fs::create_dir_all(root.join("frames")).unwrap();
        for (id, &(timestamp_ns, readable)) in frames.iter().enumerate() {
            let paths = FramePaths::new(root, id as u64);
            std::fs::copy(&source.rgb, &paths.rgb).unwrap();
            std::fs::copy(&source.amplitude, &paths.amplitude).unwrap();
            std::fs::copy(&source.depth, &paths.depth).unwrap();
            if !readable {
                std::fs::write(&paths.depth, b"\x89PNG truncated").unwrap();
            }
            let mut entry = template.clone();
            entry.id = id as u64;
            entry.timestamp_ns = timestamp_ns;
            manifest.frames.push(entry);
        }
        std::fs::write(
            root.join("capture.json"),
            serde_json::to_string(&manifest).unwrap(),
        )
        .unwrap();
        root.to_path_buf()
    }

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
