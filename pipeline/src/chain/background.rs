//! Network frames off the frame path: the calibration measurement of a `Full` frame (rough
//! flow, least squares, direct fit — [`DearChain::measure`]) on a worker thread of its own.
//!
//! At 640×480 that measurement takes 0.5–0.9 s on one core of the development machine, twenty
//! frames of a 30 fps camera. Run inline, every network frame stalls the stream and the queue
//! drops what arrives meanwhile. With this worker the frame path never waits: the frame that
//! asked for the network is copied (three planes, about 3.4 MB at VGA, into buffers reused
//! frame after frame) and processed like any other with the current estimate; the measurement
//! is delivered to the online estimator on the first frame after it is ready, and the frames
//! after that use the updated estimate.
//!
//! The worker runs at the lowest scheduling priority, so that on a two-core board it takes what
//! the frame path leaves instead of competing with it: Linux's `SCHED_IDLE` policy, and nice +19
//! above the thread that calls it (capped at 19), which is what remains where the policy cannot
//! be set. The measurement's parallel loops (the direct fit's candidate search and residuals,
//! the splat) run on a rayon pool of the worker's own, as many threads as the caller's pool and
//! each at the worker's priority: on the global pool they would run on the frame path's threads
//! at its priority, and a frame's stages would wait behind them. With frames overlapping, the
//! frame path keeps both cores busy when it falls behind, and at nice +10 the worker's 0.3 s
//! measurement every 30 frames still slowed the frames around it: `deard-bench` at 640×480,
//! 200 frames back to back, p95 82.5 / 78.6 ms and median 43.8 / 44.7 at +10 against 56.8 /
//! 53.2 and 41.2 / 39.0 at +19 (alternating runs, 2026-11-26). At nice +19 a frame thread
//! that woke on the worker's core could still wait behind it (under the kernel's EEVDF
//! scheduler a waking thread need not preempt a running one before the latter's slice is
//! used, whatever their weights); the kernel preempts a `SCHED_IDLE` thread for any waking
//! thread of the normal policy. With frames back to back on two cores the p95 went from
//! 28.6 / 29.4 / 29.9 ms to 19.5 / 17.6 / 17.9 (medians 15.5 / 15.3 / 15.9 → 14.2 / 14.3 /
//! 14.5; alternating runs, 2026-11-29, docs/performance.md). The price is paid only under
//! overload, where the worker gets less: in 300 frames back to back on two cores it started 2
//! measurements instead of 6; at 30 fps it started as many as at nice +19, and a daemon that
//! keeps up leaves idle time the worker runs in whatever its priority.
//!
//! One measurement is in flight at a time: while the worker is busy a new request is answered
//! [`Submit::Busy`] and the caller simply asks again on a later frame.
//!
//! When the worker's result arrives depends on the machine and its load, so a run over a
//! recorded sequence would differ from run to run. [`DelayedCalibrator`] is its deterministic
//! stand-in for evaluation (`dear eval --online`, through [`crate::engine`]): the same
//! measurement of the same frame, made at once on the caller's thread, handed out exactly `n`
//! frames after the frame that asked for it.

use std::num::NonZeroU32;
use std::sync::mpsc::{self, Receiver, SyncSender, TryRecvError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use ndarray::{Array2, Array3};

use crate::chain::dear_chain::{ChainError, ChainInput, DearChain, MeasureReport};
use dear_capture::calibration::Calibration;

/// The worker's nice value relative to the caller (Linux: nice is per thread), where
/// `SCHED_IDLE` cannot be set; see the module documentation for why the lowest.
const WORKER_NICE: i32 = 19;

/// Owned copies of one frame's sensor planes, reused between jobs.
#[derive(Debug)]
struct Planes {
    rgb: Array3<u8>,
    amplitude: Array2<f32>,
    depth: Array2<f32>,
}

struct Job<T> {
    ticket: T,
    planes: Planes,
    /// The calibration in use when the frame was submitted ([`DearChain::set_reference`]).
    reference: Option<Calibration>,
}

struct Done<T> {
    ticket: T,
    report: Result<MeasureReport, ChainError>,
    elapsed: Duration,
    planes: Planes,
}

/// A finished measurement.
#[derive(Debug)]
pub struct Delivered<T> {
    /// What the caller attached to the frame when it submitted it.
    pub ticket: T,
    /// The measurement, or why the chain could not run on that frame.
    pub report: Result<MeasureReport, ChainError>,
    /// Wall time the worker spent on it.
    pub elapsed: Duration,
}

/// What became of a submission.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Submit {
    /// The frame was copied and the worker started on it.
    Started,
    /// A measurement is still running; ask again on a later frame.
    Busy,
    /// The worker thread is gone (it panicked); no measurement will come.
    Stopped,
}

/// A worker thread that owns a [`DearChain`] and measures the calibration of the frames it is
/// given (see the module docs).
pub struct BackgroundCalibrator<T: Send + 'static> {
    jobs: Option<SyncSender<Job<T>>>,
    results: Receiver<Done<T>>,
    /// The frame buffers when no job holds them.
    spare: Option<Planes>,
    busy: bool,
    /// The calibration in use, sent with the next job.
    reference: Option<Calibration>,
    stopped: bool,
    thread: Option<JoinHandle<()>>,
}

impl<T: Send + 'static> std::fmt::Debug for BackgroundCalibrator<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BackgroundCalibrator")
            .field("busy", &self.busy)
            .field("stopped", &self.stopped)
            .finish_non_exhaustive()
    }
}

impl<T: Send + 'static> BackgroundCalibrator<T> {
    /// Starts the worker with `chain` (built by the caller, so a bundle problem is the
    /// caller's start-up error). `name` names the thread; its pool's threads are named
    /// `name` cut to 12 bytes, a dash and their index (Linux keeps 15 bytes of a name).
    ///
    /// # Errors
    /// When the thread or its pool's threads cannot be spawned.
    pub fn spawn(mut chain: DearChain, name: &str) -> std::io::Result<Self> {
        let (h, w) = chain.dim();
        let (job_tx, job_rx) = mpsc::sync_channel::<Job<T>>(1);
        let (done_tx, done_rx) = mpsc::sync_channel::<Done<T>>(1);
        let pool = worker_pool(name)?;
        let thread = std::thread::Builder::new()
            .name(name.to_owned())
            .spawn(move || {
                lower_priority();
                while let Ok(Job {
                    ticket,
                    planes,
                    reference,
                }) = job_rx.recv()
                {
                    let start = Instant::now();
                    chain.set_reference(reference);
                    let report = pool.install(|| {
                        chain.measure(ChainInput {
                            rgb: planes.rgb.view(),
                            amplitude: planes.amplitude.view(),
                            depth: planes.depth.view(),
                        })
                    });
                    let done = Done {
                        ticket,
                        report,
                        elapsed: start.elapsed(),
                        planes,
                    };
                    if done_tx.send(done).is_err() {
                        break;
                    }
                }
            })?;
        Ok(BackgroundCalibrator {
            jobs: Some(job_tx),
            results: done_rx,
            spare: Some(Planes {
                rgb: Array3::zeros((h, w, 3)),
                amplitude: Array2::zeros((h, w)),
                depth: Array2::zeros((h, w)),
            }),
            busy: false,
            reference: None,
            stopped: false,
            thread: Some(thread),
        })
    }

    /// The calibration in use that the next submitted frame's measurement must clearly beat
    /// ([`DearChain::set_reference`]).
    pub fn set_reference(&mut self, reference: Option<Calibration>) {
        self.reference = reference;
    }

    /// Copies the frame and starts measuring it, unless a measurement is still running.
    ///
    /// # Errors
    /// [`ChainError::Shape`] when a plane does not have the stream's shape (nothing started).
    pub fn try_submit(&mut self, input: ChainInput<'_>, ticket: T) -> Result<Submit, ChainError> {
        if self.stopped {
            return Ok(Submit::Stopped);
        }
        let Some(mut planes) = self.spare.take() else {
            return Ok(Submit::Busy);
        };
        if let Err(error) = input.check_shape(planes.depth.dim()) {
            self.spare = Some(planes);
            return Err(error);
        }
        planes.rgb.assign(&input.rgb);
        planes.amplitude.assign(&input.amplitude);
        planes.depth.assign(&input.depth);
        let sent = self.jobs.as_ref().is_some_and(|jobs| {
            jobs.send(Job {
                ticket,
                planes,
                reference: self.reference,
            })
            .is_ok()
        });
        if sent {
            self.busy = true;
            Ok(Submit::Started)
        } else {
            // The receiving end is gone: the worker panicked. The planes went with the job.
            self.stopped = true;
            Ok(Submit::Stopped)
        }
    }

    /// The finished measurement, if one is ready; never waits.
    pub fn poll(&mut self) -> Option<Delivered<T>> {
        match self.results.try_recv() {
            Ok(done) => Some(self.take(done)),
            Err(TryRecvError::Empty) => None,
            Err(TryRecvError::Disconnected) => {
                self.stopped = true;
                self.busy = false;
                None
            }
        }
    }

    /// Waits for the measurement in flight (tests and shutdown); `None` when none is running
    /// or the worker stopped.
    pub fn wait(&mut self) -> Option<Delivered<T>> {
        if !self.busy {
            return None;
        }
        match self.results.recv() {
            Ok(done) => Some(self.take(done)),
            Err(_) => {
                self.stopped = true;
                self.busy = false;
                None
            }
        }
    }

    fn take(&mut self, done: Done<T>) -> Delivered<T> {
        self.busy = false;
        self.spare = Some(done.planes);
        Delivered {
            ticket: done.ticket,
            report: done.report,
            elapsed: done.elapsed,
        }
    }

    /// Whether a measurement is running.
    pub fn is_busy(&self) -> bool {
        self.busy
    }

    /// Whether the worker thread is gone (it panicked): no further measurement will come.
    pub fn is_stopped(&self) -> bool {
        self.stopped
    }
}

impl<T: Send + 'static> Drop for BackgroundCalibrator<T> {
    fn drop(&mut self) {
        // Closing the job channel ends the worker's loop after the job in flight.
        self.jobs = None;
        // Drain so a worker blocked on sending its result can finish.
        while self.results.recv().is_ok() {}
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The worker's deterministic stand-in (see the module docs): [`try_submit`](Self::try_submit)
/// measures the frame at once on the caller's thread, and the `delay_frames`-th
/// [`poll`](Self::poll) after it (one poll per frame, at the frame's start, as the engine polls
/// the worker) hands the result out — what the worker does on a stream where its measurement
/// takes `delay_frames` frame intervals. Busy until then, like the worker.
#[derive(Debug)]
pub struct DelayedCalibrator<T> {
    chain: DearChain,
    delay_frames: NonZeroU32,
    /// The measurement made and the polls still to pass before it is handed out.
    pending: Option<(u32, Delivered<T>)>,
}

impl<T> DelayedCalibrator<T> {
    /// Measures with `chain` (built by the caller, as for the worker), each result handed out
    /// by the `delay_frames`-th poll after its submission.
    pub fn new(chain: DearChain, delay_frames: NonZeroU32) -> Self {
        DelayedCalibrator {
            chain,
            delay_frames,
            pending: None,
        }
    }

    /// The calibration in use that the next measurements must clearly beat
    /// ([`DearChain::set_reference`]).
    pub fn set_reference(&mut self, reference: Option<Calibration>) {
        self.chain.set_reference(reference);
    }

    /// Measures the frame now, unless a measurement is still waiting to be handed out
    /// ([`Submit::Busy`]).
    ///
    /// # Errors
    /// [`ChainError::Shape`] when a plane does not have the chain's shape (nothing measured).
    pub fn try_submit(&mut self, input: ChainInput<'_>, ticket: T) -> Result<Submit, ChainError> {
        if self.pending.is_some() {
            return Ok(Submit::Busy);
        }
        input.check_shape(self.chain.dim())?;
        let start = Instant::now();
        let report = self.chain.measure(input);
        let delivered = Delivered {
            ticket,
            report,
            elapsed: start.elapsed(),
        };
        self.pending = Some((self.delay_frames.get(), delivered));
        Ok(Submit::Started)
    }

    /// A frame begins: the measurement, when this is the `delay_frames`-th poll since it was
    /// submitted.
    pub fn poll(&mut self) -> Option<Delivered<T>> {
        let (polls_left, _) = self.pending.as_mut()?;
        *polls_left -= 1;
        if *polls_left > 0 {
            return None;
        }
        self.pending.take().map(|(_, delivered)| delivered)
    }

    /// Whether a measurement is waiting to be handed out.
    pub fn is_busy(&self) -> bool {
        self.pending.is_some()
    }

    /// Frames from a submission to its delivery.
    pub fn delay_frames(&self) -> NonZeroU32 {
        self.delay_frames
    }
}

/// The worker's rayon pool: as many threads as the caller's pool (`RAYON_NUM_THREADS`, or one
/// per core, and the caller's CPU affinity, which threads inherit), each lowering its own
/// priority as it starts.
fn worker_pool(name: &str) -> std::io::Result<rayon::ThreadPool> {
    let base: String = name.chars().take(12).collect();
    rayon::ThreadPoolBuilder::new()
        .num_threads(rayon::current_num_threads())
        .thread_name(move |index| format!("{base}-{index}"))
        .start_handler(|_| lower_priority())
        .build()
        .map_err(std::io::Error::other)
}

/// Lowers the calling thread's scheduling priority to the lowest (Linux: nice value and
/// policy are per thread): nice +[`WORKER_NICE`], then the `SCHED_IDLE` policy. Best effort: a
/// failure leaves the worker at the priority it had (logged at debug level).
fn lower_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: getpriority/setpriority take plain integers, sched_setscheduler a pointer to a
    // live `sched_param`; `who = 0` / `pid = 0` name the calling thread.
    unsafe {
        // The nice value first: it is what stays where the policy cannot be set.
        *libc::__errno_location() = 0;
        let current = libc::getpriority(libc::PRIO_PROCESS, 0);
        if current != -1 || *libc::__errno_location() == 0 {
            let _ = libc::setpriority(libc::PRIO_PROCESS, 0, (current + WORKER_NICE).min(19));
        }
        let param = libc::sched_param { sched_priority: 0 };
        if libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) != 0 {
            tracing::debug!(
                error = %std::io::Error::last_os_error(),
                "the calibration worker keeps the normal policy: SCHED_IDLE refused"
            );
        }
    }
}
