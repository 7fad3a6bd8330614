//! Estimating the weak calibration `(t, c)` from the frames themselves (the model `W = t / z + c`
//! is [`dear_capture::Calibration`]; [`align`](crate::align) applies a known one): the fits of
//! one frame and, beyond the paper, their tracking over time. On a device the weak calibration
//! drifts slowly compared with the frame rate, so the rough-flow network need not run on every
//! frame.
//!
//! Fits of one frame:
//! - [`lsq`]: the paper's per-axis least squares of a flow against inverse depth, plain and
//!   robust (IRLS/Huber);
//! - [`edges`]: RGB and amplitude edge maps on one scale (what the direct fit compares);
//! - [`direct`]: the direct fit of the calibration to all edge pixels at once (edge
//!   correlation), kept at a reference calibration unless the frame clearly shows it wrong;
//! - [`measurement`]: one `(t, c)` fit of a frame — a robust fit of a network flow with its
//!   inlier statistics, or the direct fit to the frame's edges with its edge correlation.
//!
//! Over time:
//! - [`estimator`]: [`OnlineCalibrator`], when to run the network and the robust filter over
//!   time (admission, innovation gate with jump confirmation, running median), with a quality
//!   figure and the health report;
//! - [`observability`]: how well a frame constrains each direction of `(t, c)` (the fit's
//!   information matrix and its eigen-decomposition), which the estimator projects each
//!   measurement's step onto (issue 32; docs/calibration-health.md);
//! - [`residual`]: a cheap per-frame alignment check (RGB vs warped-amplitude edges) that
//!   triggers the network early when the alignment degrades, and measures the principal-point
//!   correction the estimator tracks between network frames.
//!
//! Independent of tract: it works on flows, depths and images, whoever computed them. The
//! chain (`chain`, feature `inference`) runs the networks whose flow these fits take.

pub mod direct;
pub mod edges;
pub mod estimator;
pub mod lsq;
pub mod measurement;
pub mod observability;
pub mod residual;

pub use estimator::{
    FrameDecision, HealthReport, NetworkTicket, OnlineCalibrator, OnlineConfig, Outcome, Rejection,
    Trigger,
};
pub use lsq::{
    solve_calibration, solve_calibration_robust, CalibrationFit, LsqError, RobustOptions,
};
pub use measurement::{Evidence, Measurement};
pub use observability::{Eigen, Information, Observability};
pub use residual::{EdgeAlignment, EdgeCheck, EdgeShift};
