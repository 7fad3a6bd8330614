//! Reading a capture's frames ahead, on a thread of their own ([`FramePrefetch`]).
//!
//! A replay that decodes each frame when it is due puts the decoding (three PNGs, several ms at
//! 640×480) on the path of every frame, at the moment the frame is wanted. The prefetcher's
//! thread decodes the frames in order into a bounded channel, `ahead` frames ahead of the
//! reader: the reader takes a decoded frame when it is due, and the decoding happens in the
//! time before, at a lower scheduling priority when asked ([`PrefetchOptions::nice`]) so that
//! it fills the gaps the frame path leaves instead of competing with it. Memory: `ahead + 2`
//! decoded frames at most (the channel, the one being decoded, the one the reader holds).
//!
//! The order is the capture's: positions `range.start..range.end`, then, when looping, again
//! from `range.start`, with a [`Prefetched::EndOfPass`] after each pass. A frame that cannot
//! be read arrives in its place as its error (naming the file), and the next frames follow.
//! Dropping the prefetcher stops its thread (after the frame it is decoding) and joins it.

use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::error::CaptureError;
use crate::frame::RgbdFrame;
use crate::reader::CaptureDir;

/// Most frames decoded ahead: more only holds memory (3.3 MB a 640×480 frame).
pub const MAX_AHEAD: usize = 64;

/// What the prefetcher reads and how.
#[derive(Debug, Clone)]
pub struct PrefetchOptions {
    /// Positions in the capture's frame list, read in order.
    pub range: Range<usize>,
    /// After the last position, start again at the first.
    pub looping: bool,
    /// Decoded frames held ready (1..=[`MAX_AHEAD`]).
    pub ahead: usize,
    /// Niceness added to the decoding thread's (Linux: per thread; 0 keeps the caller's, 19
    /// is the lowest priority). A raised nice value cannot be lowered again without privilege,
    /// so it is applied to the prefetcher's own thread only.
    pub nice: i32,
}

/// One item from the prefetcher, in capture order.
#[derive(Debug)]
pub enum Prefetched {
    /// The frame at `position`, or why it cannot be read (the error names the file), and how
    /// long reading it took.
    Frame {
        position: usize,
        frame: Result<Box<RgbdFrame>, CaptureError>,
        decode: Duration,
    },
    /// Every position of the range has been sent once more.
    EndOfPass,
}

/// Why a prefetcher could not start.
#[derive(Debug, thiserror::Error)]
pub enum PrefetchError {
    /// The range is empty or beyond the capture's frames.
    #[error("cannot prefetch frames {}..{} of {} ({} frames)", range.start, range.end, root.display(), frames)]
    Range {
        root: std::path::PathBuf,
        range: Range<usize>,
        frames: usize,
    },
    /// `ahead` is 0 or more than [`MAX_AHEAD`].
    #[error("cannot prefetch {0} frames ahead: it must be within 1..={MAX_AHEAD}")]
    Ahead(usize),
    /// The thread could not be made.
    #[error("cannot start the frame prefetch thread: {0}")]
    Thread(#[from] std::io::Error),
}

/// A thread reading a capture's frames ahead into a bounded channel (module docs).
#[derive(Debug)]
pub struct FramePrefetch {
    receiver: Option<Receiver<Prefetched>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl FramePrefetch {
    /// Starts the thread; it begins decoding at once.
    pub fn start(dir: CaptureDir, options: PrefetchOptions) -> Result<Self, PrefetchError> {
        let PrefetchOptions {
            range,
            looping,
            ahead,
            nice,
        } = options;
        if range.is_empty() || range.end > dir.len() {
            return Err(PrefetchError::Range {
                root: dir.root().to_owned(),
                range,
                frames: dir.len(),
            });
        }
        if !(1..=MAX_AHEAD).contains(&ahead) {
            return Err(PrefetchError::Ahead(ahead));
        }
        let (sender, receiver) = sync_channel(ahead);
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let stop = stop.clone();
            std::thread::Builder::new()
                .name("frame-prefetch".into())
                .spawn(move || {
                    lower_priority(nice);
                    loop {
                        for position in range.clone() {
                            if stop.load(Ordering::Relaxed) {
                                return;
                            }
                            let started = Instant::now();
                            let frame = dir.read_frame(position).map(Box::new);
                            let decode = started.elapsed();
                            let item = Prefetched::Frame {
                                position,
                                frame,
                                decode,
                            };
                            // An error: the reader is gone.
                            if sender.send(item).is_err() {
                                return;
                            }
                        }
                        if sender.send(Prefetched::EndOfPass).is_err() || !looping {
                            return;
                        }
                    }
                })?
        };
        Ok(FramePrefetch {
            receiver: Some(receiver),
            stop,
            thread: Some(thread),
        })
    }

    /// The next item, waiting up to `timeout` for it: `Ok(None)` when none came in time,
    /// `Err(Finished)` once a non-looping prefetcher has sent everything.
    pub fn next(&self, timeout: Duration) -> Result<Option<Prefetched>, Finished> {
        let receiver = self.receiver.as_ref().expect("receiver until dropped");
        match receiver.recv_timeout(timeout) {
            Ok(item) => Ok(Some(item)),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => Err(Finished),
        }
    }
}

/// A non-looping prefetcher has sent its last item (and its thread has ended).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Finished;

impl Drop for FramePrefetch {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Dropping the receiver fails the thread's pending or next send, so it returns.
        drop(self.receiver.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// Adds `nice` to the calling thread's nice value (Linux: the nice value is per thread, and
/// `setpriority(PRIO_PROCESS, 0, …)` names the calling thread). Best effort: a failure leaves
/// the priority as it was.
fn lower_priority(nice: i32) {
    if nice <= 0 {
        return;
    }
    #[cfg(target_os = "linux")]
    // SAFETY: getpriority/setpriority take plain integers; `who = 0` names the calling thread.
    unsafe {
        *libc::__errno_location() = 0;
        let current = libc::getpriority(libc::PRIO_PROCESS, 0);
        if current == -1 && *libc::__errno_location() != 0 {
            return;
        }
        let _ = libc::setpriority(libc::PRIO_PROCESS, 0, (current + nice).min(19));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::{Path, PathBuf};

    use crate::layout::FramePaths;

    /// A capture at `root` of `frames` copies of `samples/demo`'s first frame (ids 0..), each
    /// with its own timestamp; the frames in `bad` have a truncated depth PNG.
    fn write_capture(root: &Path, frames: usize, bad: &[usize]) -> PathBuf {
        let demo = CaptureDir::open(concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo"))
            .expect("samples/demo opens");
        let source = demo.frame_paths(0);
        let mut manifest = demo.manifest().clone();
        let template = manifest.frames[0].clone();
        manifest.frames.clear();
        std::fs::create_dir_all(root.join("frames")).unwrap();
        for id in 0..frames {
            let paths = FramePaths::new(root, id as u64);
            std::fs::copy(&source.rgb, &paths.rgb).unwrap();
            std::fs::copy(&source.amplitude, &paths.amplitude).unwrap();
            std::fs::copy(&source.depth, &paths.depth).unwrap();
            if bad.contains(&id) {
                std::fs::write(&paths.depth, b"\x89PNG truncated").unwrap();
            }
            let mut entry = template.clone();
            entry.id = id as u64;
            entry.timestamp_ns = 1_000 * id as u64;
            manifest.frames.push(entry);
        }
        std::fs::write(
            root.join("capture.json"),
            serde_json::to_string(&manifest).unwrap(),
        )
        .unwrap();
        root.to_path_buf()
    }

    /// What the prefetcher sends, as `(position, frame id or error)`, `None` for the end of a
    /// pass; stops after `count` items or when the prefetcher finishes.
    fn drain(prefetch: &FramePrefetch, count: usize) -> Vec<Option<(usize, Result<u64, String>)>> {
        let mut items = Vec::new();
        while items.len() < count {
            match prefetch.next(Duration::from_secs(30)) {
                Ok(Some(Prefetched::Frame {
                    position, frame, ..
                })) => items.push(Some((
                    position,
                    frame.map(|f| f.index).map_err(|e| e.to_string()),
                ))),
                Ok(Some(Prefetched::EndOfPass)) => items.push(None),
                Ok(None) => panic!("no item in 30 s after {items:?}"),
                Err(Finished) => break,
            }
        }
        items
    }

    fn options(range: Range<usize>, looping: bool, ahead: usize) -> PrefetchOptions {
        PrefetchOptions {
            range,
            looping,
            ahead,
            nice: 0,
        }
    }

    #[test]
    fn frames_arrive_in_order_with_a_bad_one_in_its_place_then_the_end() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = CaptureDir::open(write_capture(&tmp.path().join("cap"), 6, &[3])).unwrap();
        let prefetch = FramePrefetch::start(dir, options(1..6, false, 2)).unwrap();
        let items = drain(&prefetch, 100);
        assert_eq!(items.len(), 6, "{items:?}");
        for (k, position) in (1..6).enumerate() {
            let (got, frame) = items[k].clone().expect("a frame");
            assert_eq!(got, position);
            match frame {
                Ok(id) => assert!(position != 3 && id == position as u64),
                Err(e) => assert!(
                    position == 3 && e.contains("000003.depth.png"),
                    "{position}: {e}"
                ),
            }
        }
        assert_eq!(items[5], None, "the end of the pass");
        // Finished for good: asked again, it says so again.
        assert_eq!(prefetch.next(Duration::from_secs(5)).err(), Some(Finished));
    }

    #[test]
    fn a_loop_starts_again_at_the_range_start_after_each_pass() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = CaptureDir::open(write_capture(&tmp.path().join("cap"), 4, &[])).unwrap();
        let prefetch = FramePrefetch::start(dir, options(1..3, true, 1)).unwrap();
        let positions: Vec<Option<usize>> = drain(&prefetch, 9)
            .into_iter()
            .map(|item| {
                item.map(|(position, frame)| {
                    assert_eq!(frame, Ok(position as u64));
                    position
                })
            })
            .collect();
        assert_eq!(
            positions,
            [
                Some(1),
                Some(2),
                None,
                Some(1),
                Some(2),
                None,
                Some(1),
                Some(2),
                None
            ]
        );
    }

    #[test]
    fn a_looping_prefetcher_stops_when_dropped() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = CaptureDir::open(write_capture(&tmp.path().join("cap"), 3, &[])).unwrap();
        let prefetch = FramePrefetch::start(dir, options(0..3, true, 2)).unwrap();
        assert_eq!(drain(&prefetch, 1), [Some((0, Ok(0)))]);
        // The thread loops for ever, blocked on the full channel or decoding: dropping the
        // prefetcher ends and joins it (the test hangs in `drop` otherwise).
        drop(prefetch);
    }

    #[test]
    fn an_empty_range_or_no_lookahead_is_refused_with_what_is_wrong() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = CaptureDir::open(write_capture(&tmp.path().join("cap"), 2, &[])).unwrap();
        let e = FramePrefetch::start(dir.clone(), options(1..4, false, 2)).unwrap_err();
        assert!(
            e.to_string().contains("frames 1..4") && e.to_string().contains("(2 frames)"),
            "{e}"
        );
        let e = FramePrefetch::start(dir.clone(), options(1..1, false, 2)).unwrap_err();
        assert!(matches!(e, PrefetchError::Range { .. }), "{e}");
        let e = FramePrefetch::start(dir, options(0..2, false, 0)).unwrap_err();
        assert!(e.to_string().contains("0 frames ahead"), "{e}");
    }
}
