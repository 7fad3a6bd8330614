//! `deard --record DIR`: the frames the source produced, written as a capture directory while
//! the daemon serves — sensor planes (RGB, depth, amplitude), the source's calibration and
//! timestamps — so that `deard --replay DIR` processes the same frames again, bit for bit (a
//! live source rounds its planes to what the format stores before processing them).
//!
//! Writing three PNGs per frame must not slow the capture: frames go to a writer thread through
//! a short queue, and when the disk falls behind a frame is left out of the recording (counted,
//! logged) rather than delaying the stream. The manifest is rewritten every
//! `MANIFEST_EVERY` frames, so a recording cut short by a crash replays up to that point.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::thread::{self, JoinHandle};

use dear_capture::{CaptureError, CaptureManifest, CaptureWriter, RgbdFrame};

/// Frames waiting for the writer.
const QUEUE: usize = 8;
/// Frames between manifest rewrites.
const MANIFEST_EVERY: usize = 30;

/// Why a recording cannot start.
#[derive(Debug, thiserror::Error)]
#[error("--record {}: {source}", path.display())]
pub struct RecordError {
    path: PathBuf,
    #[source]
    source: CaptureError,
}

/// What a finished recording holds.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RecordSummary {
    pub written: usize,
    /// Frames left out because the writer was behind.
    pub left_out: u64,
    /// Frames left out because they came before the last one written (a looping replay
    /// starting over): a capture's timestamps only go forward.
    pub out_of_order: u64,
}

/// A frame could not be written (a full disk: ENOSPC): says so at once, naming the file,
/// removes what was written of the frame `partial` (on a full disk that also frees room) and
/// writes the manifest of the frames before it, so the recording replays up to there. The
/// recording stops; the daemon serves on and exits non-zero when stopped.
fn stop_on_error(
    writer: &CaptureWriter,
    dir: &Path,
    partial: Option<u64>,
    written: usize,
    error: CaptureError,
) -> CaptureError {
    tracing::error!(path = %dir.display(), %error, frames_kept = written, "the recording stopped: a frame could not be written (the stream goes on; deard will exit with an error)");
    let partial = partial.map(|index| dear_capture::FramePaths::new(dir, index));
    let tmp = dir.join(format!("{}.tmp", dear_capture::layout::MANIFEST_FILE));
    let files = partial
        .iter()
        .flat_map(|p| [&p.rgb, &p.amplitude, &p.depth]);
    for file in files.chain([&tmp]) {
        match std::fs::remove_file(file) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                tracing::warn!(file = %file.display(), error = %e, "cannot remove a partly written frame file")
            }
        }
    }
    match writer.write_manifest() {
        Ok(()) => {
            tracing::info!(path = %dir.display(), frames = written, "wrote the manifest of the frames recorded before the error: the directory replays up to there")
        }
        Err(e) => {
            tracing::error!(error = %e, "the manifest cannot be written either: the recording does not replay")
        }
    }
    error
}

/// The writer thread and the queue to it.
pub struct Recorder {
    tx: Option<SyncSender<Box<RgbdFrame>>>,
    thread: Option<JoinHandle<Result<RecordSummary, CaptureError>>>,
    left_out: u64,
    path: PathBuf,
}

impl Recorder {
    /// Creates the directory (new or empty) and starts the writer.
    pub fn start(path: &Path, manifest: CaptureManifest) -> Result<Self, RecordError> {
        let mut writer = CaptureWriter::create(path, manifest).map_err(|source| RecordError {
            path: path.to_path_buf(),
            source,
        })?;
        let (tx, rx) = mpsc::sync_channel::<Box<RgbdFrame>>(QUEUE);
        let dir = path.to_path_buf();
        let thread = thread::Builder::new()
            .name("record".into())
            .spawn(move || {
                let mut summary = RecordSummary::default();
                let mut last_ts = None;
                for mut frame in rx {
                    if last_ts.is_some_and(|t| frame.timestamp_ns < t) {
                        summary.out_of_order += 1;
                        continue;
                    }
                    last_ts = Some(frame.timestamp_ns);
                    // Sequential ids: a looping replay repeats its own.
                    frame.index = summary.written as u64;
                    if let Err(e) = writer.write_frame(&frame) {
                        let partial = Some(frame.index);
                        return Err(stop_on_error(&writer, &dir, partial, summary.written, e));
                    }
                    summary.written += 1;
                    if summary.written % MANIFEST_EVERY == 0 {
                        if let Err(e) = writer.write_manifest() {
                            return Err(stop_on_error(&writer, &dir, None, summary.written, e));
                        }
                    }
                }
                writer.finish()?;
                Ok(summary)
            })
            .expect("spawn the recording thread");
        tracing::info!(path = %path.display(), "recording the source's frames");
        Ok(Recorder {
            tx: Some(tx),
            thread: Some(thread),
            left_out: 0,
            path: path.to_path_buf(),
        })
    }

    /// Queues a copy of `frame` (ground truth, which a source never has live, is not written);
    /// leaves it out when the writer is behind or has stopped on an error.
    pub fn offer(&mut self, frame: &RgbdFrame) {
        let Some(tx) = &self.tx else { return };
        let copy = Box::new(frame.clone());
        match tx.try_send(copy) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                self.left_out += 1;
                if self.left_out.is_power_of_two() {
                    tracing::warn!(left_out = self.left_out, path = %self.path.display(), "the recording falls behind the stream: frames left out of it");
                }
            }
            Err(TrySendError::Disconnected(_)) => {
                // The writer stopped on an error; `finish` reports it.
                self.tx = None;
            }
        }
    }

    /// Writes what is queued and the manifest; logs and returns what the recording holds.
    pub fn finish(mut self) -> Result<RecordSummary, RecordError> {
        self.tx = None;
        let result = self
            .thread
            .take()
            .expect("finish runs once")
            .join()
            .expect("the recording thread does not panic");
        let mut summary = result.map_err(|source| RecordError {
            path: self.path.clone(),
            source,
        })?;
        summary.left_out = self.left_out;
        tracing::info!(path = %self.path.display(), written = summary.written, left_out = summary.left_out, out_of_order = summary.out_of_order, "recording finished");
        Ok(summary)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dear_capture::{CaptureDir, Intrinsics};
    use ndarray::{Array2, Array3};

    fn frame(index: u64, timestamp_ns: u64) -> RgbdFrame {
        RgbdFrame::new(
            index,
            timestamp_ns,
            Array3::from_elem((4, 5, 3), index as u8),
            Array2::from_elem((4, 5), 100.0 + index as f32),
            Array2::from_elem((4, 5), 1.0 + 0.001 * index as f32),
        )
    }

    fn manifest() -> CaptureManifest {
        CaptureManifest::new(
            5,
            4,
            Intrinsics {
                fx: 5.0,
                fy: 5.0,
                cx: 2.0,
                cy: 1.5,
            },
        )
    }

    #[test]
    fn a_recording_replays_the_frames_it_was_offered() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rec");
        let mut rec = Recorder::start(&path, manifest()).unwrap();
        // A looping replay: ids repeat and time goes back after the third frame.
        for (i, ts) in [(7, 100), (8, 200), (9, 300), (7, 100)] {
            rec.offer(&frame(i, ts));
        }
        let summary = rec.finish().unwrap();
        assert_eq!(summary.written, 3);
        assert_eq!(summary.out_of_order, 1);
        let capture = CaptureDir::open(&path).unwrap();
        assert_eq!(capture.len(), 3);
        for k in 0..3 {
            let read = capture.read_frame(k).unwrap();
            let want = frame(7 + k as u64, 100 * (k as u64 + 1));
            assert_eq!(read.index, k as u64);
            assert_eq!(read.rgb, want.rgb);
            assert_eq!(read.depth, want.depth.mapv(|d| (d / 0.001).round() * 0.001));
            assert_eq!(read.amplitude, want.amplitude);
            let truth = capture.read_sample(k).unwrap().truth;
            assert!(
                truth.depth.is_none() && truth.perturbation.is_none(),
                "a recording holds no ground truth"
            );
        }
    }

    #[test]
    fn a_directory_with_files_is_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("keep.txt"), "x").unwrap();
        let err = Recorder::start(dir.path(), manifest()).err().unwrap();
        assert!(err.to_string().contains("--record"), "{err}");
        assert!(err.to_string().contains("files in it"), "{err}");
    }
}
