//! Online recalibration (beyond the paper): on a device the weak calibration drifts slowly
//! compared with the frame rate, so the rough-flow network need not run on every frame.
//!
//! - [`measurement`]: one `(t, c)` fit of a frame — a robust fit of a network flow with its
//!   inlier statistics, or the direct fit to the frame's edges with its edge correlation;
//! - [`estimator`]: [`OnlineCalibrator`], when to run the network and the robust filter over
//!   time (admission, innovation gate with jump confirmation, running median), with a quality
//!   figure;
//! - [`observability`]: how well a frame constrains each direction of `(t, c)` (the fit's
//!   information matrix and its eigen-decomposition), which the estimator projects each
//!   measurement's step onto (issue 32; docs/calibration-health.md);
//! - [`residual`]: a cheap per-frame alignment check (RGB vs warped-amplitude edges) that
//!   triggers the network early when the alignment degrades, and measures the principal-point
//!   correction the estimator tracks between network frames.
//!
//! Independent of tract: it works on flows and depths, whoever computed them.

pub mod estimator;
pub mod measurement;
pub mod observability;
pub mod residual;

pub use estimator::{
    FrameDecision, HealthReport, NetworkTicket, OnlineCalibrator, OnlineConfig, Outcome, Rejection,
    Trigger,
};
pub use measurement::{Evidence, Measurement};
pub use observability::{Eigen, Information, Observability};
pub use residual::{EdgeAlignment, EdgeCheck, EdgeShift};
