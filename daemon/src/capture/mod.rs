//! Frame sources. A [`FrameSource`] yields frames one by one; a bad frame is reported as
//! [`SourceItem::Skipped`] (with the error naming the file) and the stream goes on, unless
//! nothing at all can be read ([`SourceItem::Failed`]). Every wait of a source gives way to the
//! shutdown flag ([`sleep_unless`]).
//!
//! Back ends: [`replay`] (a capture directory) and [`v4l`] (a live module's V4L2 nodes, with
//! its calibration file read by [`module`]).
//!
//! Depth beyond what the module can measure ([`DepthLimit`]: its configured range, or its
//! modulation's unambiguous range) is marked invalid as each frame leaves its source, before
//! the recorder and the processing, by one definition for every back end.

pub mod module;
pub mod replay;
pub mod v4l;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use dear_capture::{Calibration, CaptureManifest, RgbdFrame};
use dear_proto::CameraIntrinsics;

/// Metres per second.
const SPEED_OF_LIGHT: f64 = 299_792_458.0;

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
    /// The farthest depth this stream's module measures, if known.
    fn depth_limit(&self) -> Option<DepthLimit>;
    /// The RGB camera's intrinsics at [`size`](Self::size) (the grid every published frame is
    /// on), for the frame header (format 3); `None` when the source knows none.
    fn rgb_intrinsics(&self) -> Option<CameraIntrinsics>;
}

/// The farthest z-depth a module measures. A single-frequency ToF module cannot tell a
/// distance `d` from `d + c/2f`, so a depth beyond its unambiguous range `c/2f` is no
/// measurement (the radial distance is at least the z-depth); a module's data sheet may give
/// a shorter range. Beyond the limit a pixel is marked invalid, as one the sensor did not
/// measure.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthLimit {
    /// Metres; a depth above it is invalid, at it valid.
    pub max_m: f32,
    /// Where the limit comes from, for the log.
    pub origin: String,
}

impl DepthLimit {
    /// The unambiguous range `c / (2 f)` of one modulation frequency; `None` for a frequency
    /// that is not positive and finite (the configuration and manifest checks refuse those).
    pub fn unambiguous(modulation_hz: f64) -> Option<Self> {
        (modulation_hz.is_finite() && modulation_hz > 0.0).then(|| DepthLimit {
            max_m: (SPEED_OF_LIGHT / (2.0 * modulation_hz)) as f32,
            origin: format!(
                "the unambiguous range c/(2f) of {} MHz modulation",
                modulation_hz / 1e6
            ),
        })
    }

    /// A capture's limit: the unambiguous range when its manifest lists exactly one modulation
    /// frequency. Several frequencies unwrap each other to a longer range the manifest does
    /// not state, so they give none.
    pub fn of_manifest(manifest: &CaptureManifest) -> Option<Self> {
        match manifest.modulation_frequencies_hz[..] {
            [f] => Self::unambiguous(f),
            _ => None,
        }
    }

    /// The nearer of two limits.
    pub fn nearer(a: Option<Self>, b: Option<Self>) -> Option<Self> {
        match (a, b) {
            (Some(a), Some(b)) => Some(if b.max_m < a.max_m { b } else { a }),
            (a, b) => a.or(b),
        }
    }

    /// Marks every depth beyond the limit invalid (depth and amplitude 0, as a pixel the
    /// sensor did not measure); returns how many pixels that was.
    pub fn apply(&self, frame: &mut RgbdFrame) -> usize {
        let mut beyond = 0;
        ndarray::Zip::from(&mut frame.depth)
            .and(&mut frame.amplitude)
            .for_each(|d, a| {
                if *d > self.max_m {
                    *d = 0.0;
                    *a = 0.0;
                    beyond += 1;
                }
            });
        beyond
    }
}

/// Frames and pixels whose depth was beyond the [`DepthLimit`] since start (shared by the
/// capture thread that applies it and the frame loop that reports it).
#[derive(Debug, Default)]
pub struct BeyondRange {
    frames: AtomicU64,
    pixels: AtomicU64,
}

impl BeyondRange {
    /// Applies `limit` to `frame` and counts what it invalidated; the first frame with depth
    /// beyond the limit is logged, the totals are in the daemon's statistics lines.
    pub fn apply(&self, limit: &DepthLimit, frame: &mut RgbdFrame) -> usize {
        let beyond = limit.apply(frame);
        if beyond > 0 {
            let frames = self.frames.fetch_add(1, Ordering::Relaxed) + 1;
            let pixels = self.pixels.fetch_add(beyond as u64, Ordering::Relaxed) + beyond as u64;
            if frames == 1 {
                tracing::warn!(
                    frame = frame.index,
                    pixels = beyond,
                    max_m = limit.max_m,
                    origin = %limit.origin,
                    total_pixels = pixels,
                    "depth beyond the module's range marked invalid (counted as depth_beyond_range in the statistics)"
                );
            }
        }
        beyond
    }

    /// Frames with depth beyond the limit since start.
    pub fn frames(&self) -> u64 {
        self.frames.load(Ordering::Relaxed)
    }

    /// Pixels beyond the limit since start.
    pub fn pixels(&self) -> u64 {
        self.pixels.load(Ordering::Relaxed)
    }
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

    use ndarray::{Array2, Array3};

    fn frame(depth: &[f32]) -> RgbdFrame {
        let depth = Array2::from_shape_vec((1, depth.len()), depth.to_vec()).unwrap();
        let amplitude = Array2::from_elem(depth.dim(), 7.0);
        RgbdFrame::new(3, 0, Array3::zeros((1, depth.len(), 3)), amplitude, depth)
    }

    #[test]
    fn depth_beyond_the_limit_becomes_invalid_and_is_counted() {
        let limit = DepthLimit {
            max_m: 4.0,
            origin: "test".into(),
        };
        let mut f = frame(&[0.0, 1.5, 4.0, 4.001, 48.64]);
        let counts = BeyondRange::default();
        assert_eq!(counts.apply(&limit, &mut f), 2);
        assert_eq!(f.depth.as_slice().unwrap(), &[0.0, 1.5, 4.0, 0.0, 0.0]);
        assert_eq!(f.amplitude.as_slice().unwrap(), &[7.0, 7.0, 7.0, 0.0, 0.0]);
        // Applying it again finds nothing: what is invalid stays invalid.
        assert_eq!(counts.apply(&limit, &mut f), 0);
        assert_eq!((counts.frames(), counts.pixels()), (1, 2));
        let mut within = frame(&[1.0, 2.0]);
        assert_eq!(counts.apply(&limit, &mut within), 0);
        assert_eq!((counts.frames(), counts.pixels()), (1, 2));
    }

    #[test]
    fn a_single_modulation_frequency_bounds_the_depth_at_c_over_2f() {
        let l = DepthLimit::unambiguous(20e6).unwrap();
        assert!((l.max_m - 7.494_81).abs() < 1e-4, "{}", l.max_m);
        assert!(l.origin.contains("20 MHz"), "{}", l.origin);
        let l = DepthLimit::unambiguous(75e6).unwrap();
        assert!((l.max_m - 1.998_62).abs() < 1e-4, "{}", l.max_m);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert_eq!(DepthLimit::unambiguous(bad), None, "{bad}");
        }

        let intrinsics = dear_capture::Intrinsics {
            fx: 4.0,
            fy: 4.0,
            cx: 1.5,
            cy: 1.0,
        };
        let mut m = CaptureManifest::new(4, 3, intrinsics);
        assert_eq!(DepthLimit::of_manifest(&m), None, "no frequency: no limit");
        m.modulation_frequencies_hz = vec![75e6];
        assert_eq!(DepthLimit::of_manifest(&m), DepthLimit::unambiguous(75e6));
        m.modulation_frequencies_hz = vec![20e6, 16e6];
        assert_eq!(
            DepthLimit::of_manifest(&m),
            None,
            "two frequencies unwrap further"
        );
    }

    #[test]
    fn the_nearer_limit_wins() {
        let at = |m: f32| {
            Some(DepthLimit {
                max_m: m,
                origin: format!("{m}"),
            })
        };
        assert_eq!(DepthLimit::nearer(at(4.0), at(2.0)), at(2.0));
        assert_eq!(DepthLimit::nearer(at(2.0), at(4.0)), at(2.0));
        assert_eq!(DepthLimit::nearer(None, at(4.0)), at(4.0));
        assert_eq!(DepthLimit::nearer(at(4.0), None), at(4.0));
        assert_eq!(DepthLimit::nearer(None, None), None);
    }

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
