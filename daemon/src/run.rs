//! The daemon's life: open the source and the service, run capture and processing on their own
//! threads joined by a bounded queue, publish, report, and shut down cleanly on SIGINT/SIGTERM.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use dear_capture::{Calibration, RgbdFrame};
use dear_proto::{FrameHeader, Stage};

use crate::calibration_state::CalibrationState;
use crate::capture::replay::{ReplayOpenError, ReplaySource};
use crate::capture::v4l::{V4lOpenError, V4lSource};
use crate::capture::{BeyondRange, FrameSource, SourceItem};
use crate::config::{check_calibration_fits, Config, ConfigError, Pacing};
use crate::processing::{EngineError, PreparedFrame, Processor};
use crate::publish::{FramePublisher, PublisherError};
use crate::queue::{FrameQueue, Overflow};
use crate::record::{RecordError, Recorder};
use crate::shared_memory::{self, SharedMemoryError};
use crate::stats::Stats;

/// How often ports of dead subscribers are reclaimed.
const DEAD_PEER_CLEANUP: Duration = Duration::from_secs(1);

/// Why the daemon could not start, or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The capture cannot be opened.
    #[error(transparent)]
    Source(#[from] ReplayOpenError),
    /// The live module cannot be opened (its calibration file, a node, a format).
    #[error(transparent)]
    Live(#[from] V4lOpenError),
    /// `--record`'s directory cannot be made (or has files in it).
    #[error(transparent)]
    Record(#[from] RecordError),
    /// The static calibration cannot align a stream of this size.
    #[error(transparent)]
    Calibration(ConfigError),
    /// The capture's own calibration cannot align its frames.
    #[error("{source} (set [pipeline] static_calibration to override it)")]
    CaptureCalibration {
        #[source]
        source: ConfigError,
    },
    /// The stream's shared memory cannot be had.
    #[error("cannot serve {service:?}: {source}")]
    SharedMemory {
        service: String,
        #[source]
        source: SharedMemoryError,
    },
    /// `DEAR_IOX2_ROOT` is not a usable root.
    #[error(transparent)]
    Root(#[from] dear_proto::transport::NodeConfigError),
    /// The root directory cannot be made or is not this user's.
    #[error(transparent)]
    RootDirectory(#[from] dear_proto::transport::RootError),
    /// The service cannot be opened or published on.
    #[error(transparent)]
    Publisher(#[from] PublisherError),
    /// The processing engine cannot be made.
    #[error(transparent)]
    Engine(#[from] EngineError),
    /// The source failed while running (e.g. a replay pass without one readable frame).
    #[error("{0}")]
    SourceFailed(String),
}

/// Runs the daemon until the source ends (with `exit_when_done`) or `shutdown` is raised.
/// Returns the final statistics, or an error if it cannot start or the source fails (e.g. no
/// frame of a replay can be read).
pub fn run(config: &Config, shutdown: Arc<AtomicBool>) -> Result<Stats, RunError> {
    let source: Box<dyn FrameSource> = match config.capture.live() {
        Some(v4l) => Box::new(V4lSource::open(v4l)?),
        None => Box::new(ReplaySource::open(&config.capture)?),
    };
    let (width, height) = source.size();
    let restored = match (
        &config.runtime.state_file,
        config.pipeline.static_calibration,
    ) {
        (Some(path), None) => restore_calibration(path, width, height),
        _ => None,
    };
    let calibration = match config.pipeline.static_calibration.or(restored) {
        Some(calibration) => {
            check_calibration_fits("[pipeline] static_calibration", &calibration, width, height)
                .map_err(RunError::Calibration)?;
            calibration
        }
        None => {
            let calibration = source.initial_calibration();
            check_calibration_fits(
                &match config.capture.live() {
                    Some(v4l) => format!("{}: initial calibration", v4l.calibration.display()),
                    None => format!(
                        "{}: initial_calibration",
                        config.capture.path.join("capture.json").display()
                    ),
                },
                &calibration,
                width,
                height,
            )
            .map_err(|source| RunError::CaptureCalibration { source })?;
            calibration
        }
    };
    let service = config.service.service_name();
    let source_description = source.describe();
    // The RGB camera's intrinsics, in every header (format 3); model 0 "unknown" without them.
    let rgb_intrinsics = source.rgb_intrinsics();
    match &rgb_intrinsics {
        Some(k) => tracing::info!(fx = k.fx, fy = k.fy, cx = k.cx, cy = k.cy, distortion = ?k.distortion, "frame headers carry the RGB intrinsics"),
        None => tracing::warn!("the source gives no RGB intrinsics: frame headers say \"unknown\" (rgb_camera_model 0) and clients cannot make point clouds"),
    }
    tracing::info!(source = %source_description, %service, width, height, ?calibration, bundle = ?config.pipeline.bundle, refine = ?config.pipeline.refine, "starting");

    // The transport's files (frames included) live in its root directory: made (or checked
    // to be this user's) before anything else, so the free-space check reads its file system.
    let transport = dear_proto::node_config()?;
    let root = dear_proto::transport::prepare_root(&transport)?;
    shared_memory::check_fits(width, height, config.service.max_shared_memory_mb, &root).map_err(
        |source| RunError::SharedMemory {
            service: service.clone(),
            source,
        },
    )?;
    let publisher = FramePublisher::new(&transport, &service, width, height)?;
    publisher.set_subscribers_per_user(config.service.max_subscribers_per_user);
    let mut processor = Processor::from_config(width, height, calibration, &config.pipeline)?;
    // Before the source starts: a paced replay's clock and a camera's frames start with it.
    match processor.warm_up() {
        Ok(took) => tracing::info!(ms = took.as_secs_f64() * 1e3, "frame path warmed up"),
        // The same failure would come with the first frame, which is skipped and counted then.
        Err(e) => tracing::warn!(error = %e, "the frame path failed on the warm-up frame"),
    }
    let overflow = match config.capture.pacing {
        Pacing::Timestamps => Overflow::DropOldest,
        Pacing::Fast => Overflow::Block,
    };
    let queue = Arc::new(FrameQueue::new(config.capture.queue_depth, overflow));
    let recorder = match &config.capture.record {
        Some(path) => Some(Recorder::start(path, source.recording_manifest())?),
        None => None,
    };
    let beyond_range = Arc::new(BeyondRange::default());
    match source.depth_limit() {
        Some(limit) => tracing::info!(max_m = limit.max_m, origin = %limit.origin, "depth beyond the module's range is marked invalid"),
        None => tracing::info!("no depth limit known (no max_range_m, no single modulation frequency): depth is not range-checked"),
    }
    let capture = spawn_capture(
        source,
        recorder,
        queue.clone(),
        shutdown.clone(),
        beyond_range.clone(),
    );

    let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
    let mut watchdog = Watchdog::from_env();
    tracing::info!(%service, watchdog_s = watchdog.as_ref().map(|w| w.interval.as_secs_f64() * 2.0), "serving");
    let mut stats = Stats::new(Duration::from_secs_f64(config.runtime.stats_interval_s));
    let mut last_cleanup = Instant::now();
    let mut source_ended = false;
    let mut failure = None;
    // The header of the latest frame whose calibration came from the online estimator, saved
    // to `[runtime] state_file` at every statistics line and at shutdown.
    let mut latest_estimate: Option<FrameHeader> = None;
    let description = source_description;
    // The frame whose first half is done (see `Processor::finish_into`): it is finished beside
    // the next frame's first half when that one is already queued, alone otherwise, so a frame
    // never waits for its successor.
    let mut waiting: Option<Waiting> = None;
    let mut path = FramePath {
        publisher: &publisher,
        processor: &mut processor,
        stats: &mut stats,
        latest_estimate: &mut latest_estimate,
    };
    while !shutdown.load(Ordering::Relaxed) {
        let timeout = if waiting.is_some() {
            Duration::ZERO
        } else {
            Duration::from_millis(100)
        };
        match queue.pop(timeout) {
            Some(SourceItem::Frame {
                frame,
                arrived,
                decode_us,
            }) => {
                let mut header = FrameHeader::new(frame.index, width, height);
                header.capture_timestamp_ns = frame.timestamp_ns;
                header.stage_latency_us[Stage::Capture as usize] = decode_us;
                header.frames_skipped = path.stats.skipped;
                header.frames_dropped = queue.dropped();
                header.set_intrinsics(rgb_intrinsics.as_ref());
                let next = Incoming {
                    frame,
                    header,
                    arrived,
                };
                waiting = match waiting.take() {
                    Some(w) => path.finish(w, Some(next)),
                    None => path.prepare(next),
                };
            }
            Some(SourceItem::Skipped { frame_id, reason }) => {
                path.stats.skipped += 1;
                tracing::warn!(frame = frame_id, %reason, skipped_total = path.stats.skipped, "frame skipped");
            }
            Some(SourceItem::Failed { reason }) => {
                if let Some(w) = waiting.take() {
                    path.finish(w, None);
                }
                failure = Some(reason);
                break;
            }
            Some(SourceItem::End) => {
                if let Some(w) = waiting.take() {
                    path.finish(w, None);
                }
                source_ended = true;
                tracing::info!(
                    published = path.stats.published,
                    skipped = path.stats.skipped,
                    dropped = queue.dropped(),
                    depth_beyond_range_frames = beyond_range.frames(),
                    depth_beyond_range_pixels = beyond_range.pixels(),
                    "source finished"
                );
                if config.runtime.exit_when_done {
                    break;
                }
                tracing::info!(
                    "keeping the service up until stopped (runtime.exit_when_done = false)"
                );
            }
            None => {
                if let Some(w) = waiting.take() {
                    waiting = path.finish(w, None);
                }
            }
        }
        // Pinged from the frame loop itself, so a loop stuck in a frame (or anywhere) stops the
        // pings and systemd restarts the service.
        if let Some(watchdog) = watchdog.as_mut() {
            watchdog.ping_if_due();
        }
        if last_cleanup.elapsed() >= DEAD_PEER_CLEANUP {
            publisher.cleanup_dead_peers();
            publisher.check_transport();
            last_cleanup = Instant::now();
        }
        if let Some(report) = path.stats.poll() {
            save_calibration(config, path.latest_estimate.take(), &description);
            if !(source_ended && report.fps == 0.0) {
                tracing::info!(
                    published = path.stats.published,
                    skipped = path.stats.skipped,
                    dropped = queue.dropped(),
                    network_rejected = path.processor.network_output_rejected(),
                    depth_beyond_range_frames = beyond_range.frames(),
                    depth_beyond_range_pixels = beyond_range.pixels(),
                    "{report}"
                );
            }
        }
    }
    // Stopped with a frame half done: it is finished and published.
    if let Some(w) = waiting.take() {
        path.finish(w, None);
    }
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    save_calibration(config, latest_estimate.take(), &description);
    queue.close();
    stats.dropped = queue.dropped();
    let recording = match capture.join() {
        Ok(recording) => recording,
        Err(_) => {
            tracing::error!("the capture thread panicked");
            None
        }
    };
    tracing::info!(
        published = stats.published,
        skipped = stats.skipped,
        dropped = stats.dropped,
        network_rejected = processor.network_output_rejected(),
        depth_beyond_range_frames = beyond_range.frames(),
        depth_beyond_range_pixels = beyond_range.pixels(),
        uptime_s = stats.uptime_s(),
        "stopped"
    );
    match (failure, recording) {
        (Some(reason), _) => Err(RunError::SourceFailed(reason)),
        // `--record` failed (a full disk): said at once in the log; the exit status says it too.
        (None, Some(e)) => Err(RunError::Record(e)),
        (None, None) => Ok(stats),
    }
}

/// A frame as it left the queue, with the header started for it.
struct Incoming {
    frame: Box<RgbdFrame>,
    header: FrameHeader,
    arrived: Instant,
}

/// A frame whose first half is done, waiting for its second.
struct Waiting {
    prepared: PreparedFrame<Box<RgbdFrame>>,
    header: FrameHeader,
    arrived: Instant,
}

/// What the frame loop hands frames through: processing, publishing and the counts.
struct FramePath<'a> {
    publisher: &'a FramePublisher,
    processor: &'a mut Processor,
    stats: &'a mut Stats,
    /// The header of the latest frame whose calibration came from the online estimator.
    latest_estimate: &'a mut Option<FrameHeader>,
}

impl FramePath<'_> {
    /// The first half of `frame`; a frame that cannot be processed is skipped and counted.
    fn prepare(&mut self, incoming: Incoming) -> Option<Waiting> {
        let index = incoming.frame.index;
        match self.processor.prepare(incoming.frame) {
            Ok(prepared) => Some(Waiting {
                prepared,
                header: incoming.header,
                arrived: incoming.arrived,
            }),
            Err(reason) => {
                self.skip(index, &reason);
                None
            }
        }
    }

    /// Counts a frame that cannot be processed or published, and says why.
    fn skip(&mut self, frame: u64, reason: &dyn std::fmt::Display) {
        self.stats.skipped += 1;
        tracing::warn!(frame, %reason, "frame skipped");
    }

    /// Finishes and publishes `waiting`, preparing `next` beside it; returns `next`, prepared.
    /// A frame that cannot be processed or published is skipped and counted.
    fn finish(&mut self, waiting: Waiting, next: Option<Incoming>) -> Option<Waiting> {
        let index = waiting.prepared.frame().index;
        let (mut next_frame, next_meta) = match next {
            Some(n) => (Some(n.frame), Some((n.header, n.arrived))),
            None => (None, None),
        };
        let mut next_prepared = None;
        let processor = &mut *self.processor;
        let published = self
            .publisher
            .publish(waiting.header, waiting.arrived, |h, out| {
                let finished = processor.finish_into(waiting.prepared, next_frame.take(), h, out);
                next_prepared = finished.next;
                finished.result
            });
        match published {
            Ok(sent) => {
                self.stats.record(&sent);
                if sent.flags & dear_proto::flags::CALIBRATION_ONLINE != 0 {
                    *self.latest_estimate = Some(sent);
                }
            }
            Err(reason) => self.skip(index, &reason),
        }
        let (header, arrived) = next_meta?;
        match (next_prepared, next_frame) {
            (Some(Ok(prepared)), _) => Some(Waiting {
                prepared,
                header,
                arrived,
            }),
            (Some(Err(reason)), _) => {
                self.skip(header.frame_id, &reason);
                None
            }
            // The sample was never filled (no loan): the next frame is prepared on its own.
            (None, Some(frame)) => self.prepare(Incoming {
                frame,
                header,
                arrived,
            }),
            (None, None) => None,
        }
    }
}

/// The calibration saved by an earlier run, when `[runtime] state_file` has one for a stream of
/// this size. A damaged or unreadable file is logged and left for the next save to replace:
/// the daemon starts with the source's calibration rather than not at all.
fn restore_calibration(path: &Path, width: u32, height: u32) -> Option<Calibration> {
    match CalibrationState::load(path) {
        Ok(Some(state))
            if (state.width, state.height) == (width, height)
                && check_calibration_fits("saved", &state.calibration, width, height).is_ok() =>
        {
            tracing::info!(path = %path.display(), calibration = ?state.calibration, quality = state.quality, age_s = state.age().as_secs(), saved_from = %state.source, "restored the online calibration estimate of an earlier run");
            Some(state.calibration)
        }
        Ok(Some(state)) => {
            tracing::warn!(path = %path.display(), saved = ?(state.width, state.height), stream = ?(width, height), calibration = ?state.calibration, "the saved calibration is for another frame size or does not fit it: not used");
            None
        }
        Ok(None) => None,
        Err(e) => {
            tracing::warn!(error = %e, "the saved calibration cannot be used; starting from the source's");
            None
        }
    }
}

/// Saves the estimate `header` carries to `[runtime] state_file` (when set); a failure is
/// logged, not fatal.
fn save_calibration(config: &Config, header: Option<FrameHeader>, source: &str) {
    let (Some(path), Some(header)) = (&config.runtime.state_file, header) else {
        return;
    };
    if let Some(state) = CalibrationState::from_header(&header, source) {
        if let Err(e) = state.save(path) {
            tracing::warn!(error = %e, "cannot save the calibration estimate");
        }
    }
}

/// systemd's watchdog (`WatchdogSec=` in the unit): when enabled, `WATCHDOG=1` is sent at half
/// the period systemd expects it.
struct Watchdog {
    interval: Duration,
    last: Instant,
}

impl Watchdog {
    /// `Some` when the service manager asked for pings (`WATCHDOG_USEC`, for this process).
    fn from_env() -> Option<Self> {
        let period = sd_notify::watchdog_enabled()?;
        let watchdog = Watchdog {
            interval: period / 2,
            last: Instant::now(),
        };
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
        Some(watchdog)
    }

    fn ping_if_due(&mut self) {
        if self.last.elapsed() >= self.interval {
            if let Err(e) = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]) {
                tracing::warn!(error = %e, "cannot ping the systemd watchdog");
            }
            self.last = Instant::now();
        }
    }
}

/// The capture thread: pulls items from the source into the queue until the source ends or
/// fails, the queue closes or shutdown is requested. The source's waits give way to `shutdown`
/// and the queue's to [`FrameQueue::close`], so the thread can always be joined promptly.
/// Depth beyond the source's [`DepthLimit`](crate::capture::DepthLimit) is marked invalid
/// (and counted in `beyond_range`) first, so the recorder records what is processed. Returns
/// why the recording failed, if it did.
fn spawn_capture(
    mut source: Box<dyn FrameSource>,
    mut recorder: Option<Recorder>,
    queue: Arc<FrameQueue<SourceItem>>,
    shutdown: Arc<AtomicBool>,
    beyond_range: Arc<BeyondRange>,
) -> thread::JoinHandle<Option<RecordError>> {
    let limit = source.depth_limit();
    thread::Builder::new()
        .name("capture".into())
        .spawn(move || {
            while !shutdown.load(Ordering::Relaxed) {
                let mut item = source.next_item(&shutdown);
                if shutdown.load(Ordering::Relaxed) {
                    break;
                }
                if let (Some(limit), SourceItem::Frame { frame, .. }) = (&limit, &mut item) {
                    beyond_range.apply(limit, frame);
                }
                if let (Some(rec), SourceItem::Frame { frame, .. }) = (&mut recorder, &item) {
                    rec.offer(frame);
                }
                let end = matches!(item, SourceItem::End | SourceItem::Failed { .. });
                // Only good frames may be dropped; skip reports, failures and the end marker
                // always arrive.
                if !queue.push(item, |i| matches!(i, SourceItem::Frame { .. })) || end {
                    break;
                }
            }
            let rec = recorder?;
            let e = rec.finish().err()?;
            tracing::error!(error = %e, "the recording could not be finished");
            Some(e)
        })
        .expect("spawn capture thread")
}
