//! `/status.json`: the stream's state, the newest frame's header and calibration, and the
//! history the page plots. Field meanings follow the frame header (docs/protocol.md).

use std::time::Instant;

use dear_proto::{flags, FrameHeader, Stage};
use serde::Serialize;

use crate::intake::Shared;

/// The whole document.
#[derive(Debug, Serialize)]
pub struct Status {
    pub service: String,
    /// Pictures per second the page should ask for.
    pub max_fps: f64,
    /// Seconds since the viewer started; the history's `t_s` counts on the same clock.
    pub uptime_s: f64,
    pub frames_received: u64,
    pub rejected: u64,
    /// Frames the viewer missed (gaps in `sequence`): it read too slowly.
    pub lost: u64,
    pub publisher_restarts: u64,
    /// Over the last two seconds; 0 when frames stopped.
    pub fps: f64,
    /// Seconds since the newest frame arrived; `None` before the first.
    pub last_frame_age_s: Option<f64>,
    /// The last receive error, if the newest attempt failed.
    pub error: Option<String>,
    /// Id of the newest snapshot the pictures are drawn from (0: none yet).
    pub snapshot: u64,
    pub frame: Option<FrameStatus>,
    pub calibration: Option<CalibrationStatus>,
    /// One point a second, oldest first.
    pub history: Vec<HistoryPoint>,
}

/// The newest frame's header, as a person reads it.
#[derive(Debug, Serialize)]
pub struct FrameStatus {
    pub frame_id: u64,
    pub sequence: u64,
    /// Hex; `None` when the publisher gave none.
    pub run_id: Option<String>,
    pub width: u32,
    pub height: u32,
    /// Receive time − publish time (both `CLOCK_MONOTONIC`), ms.
    pub transport_latency_ms: f64,
    /// The daemon's arrival-to-publish time (stage `total`), ms; `None` when not reported.
    pub daemon_latency_ms: Option<f64>,
    /// `"network"`, `"classical"` or `"none"`.
    pub refinement: &'static str,
    pub bundle: Option<String>,
    /// The network's output was implausible on this frame and the classical filter's was
    /// published instead.
    pub network_output_rejected: bool,
    /// Depth was warped onto the RGB grid.
    pub aligned: bool,
    /// `"expected error"` (codes: `1 mm · 2^((255 − v)/16)`) or `"support × agreement"`.
    pub confidence: &'static str,
    pub frames_skipped: u64,
    pub frames_dropped: u64,
}

/// The calibration the newest frame was aligned with (flow model `W = t/z + c`).
#[derive(Debug, Serialize)]
pub struct CalibrationStatus {
    /// px·m.
    pub tx: f32,
    pub ty: f32,
    /// px.
    pub cx: f32,
    pub cy: f32,
    /// `"online"` (the estimator's) or `"static"`.
    pub source: &'static str,
    /// RMS residual of the last fit, px; `None` when not estimated or fitted to edges.
    pub residual_px: Option<f32>,
    /// [0, 1]; 0 = static / unknown.
    pub quality: f32,
    /// Frames since the calibration was last estimated.
    pub age_frames: u32,
    /// A new measurement entered the estimate on this frame.
    pub estimated_this_frame: bool,
    /// `"unknown"`, `"good"`, `"can improve"` or `"needs recalibration"`
    /// (docs/calibration-health.md).
    pub health: &'static str,
    /// Directions of `(t_x, t_y, c_x, c_y)` the last measurement's frame constrained, 0–4.
    pub constrained: u8,
}

/// One second of the history.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HistoryPoint {
    /// End of the second, seconds since the viewer started.
    pub t_s: f64,
    /// Frames received in the second.
    pub fps: f64,
    /// The calibration of the second's newest frame; `None` when no frame came.
    pub tx: Option<f32>,
    pub ty: Option<f32>,
    pub cx: Option<f32>,
    pub cy: Option<f32>,
    pub residual_px: Option<f32>,
    pub quality: Option<f32>,
    /// The calibration health of the second's newest frame.
    pub health: Option<&'static str>,
}

impl HistoryPoint {
    pub fn new(t_s: f64, fps: f64, header: Option<&FrameHeader>) -> HistoryPoint {
        HistoryPoint {
            t_s,
            fps,
            tx: header.map(|h| h.calib_tx),
            ty: header.map(|h| h.calib_ty),
            cx: header.map(|h| h.calib_cx),
            cy: header.map(|h| h.calib_cy),
            residual_px: header.and_then(|h| finite(h.calib_residual_px)),
            quality: header.map(|h| h.calib_quality),
            health: header.map(|h| h.calibration_health().name()),
        }
    }
}

fn finite(v: f32) -> Option<f32> {
    Some(v).filter(|v| v.is_finite())
}

impl FrameStatus {
    fn new(h: &FrameHeader, received_ns: u64) -> FrameStatus {
        let total = h.latency_us(Stage::Total);
        FrameStatus {
            frame_id: h.frame_id,
            sequence: h.sequence,
            run_id: (h.run_id != 0).then(|| format!("{:016x}", h.run_id)),
            width: h.width,
            height: h.height,
            transport_latency_ms: received_ns.saturating_sub(h.publish_timestamp_ns) as f64 * 1e-6,
            daemon_latency_ms: (total > 0).then(|| f64::from(total) * 1e-3),
            refinement: if h.flags & flags::REFINED_NETWORK != 0 {
                "network"
            } else if h.flags & flags::REFINED_CLASSICAL != 0 {
                "classical"
            } else {
                "none"
            },
            bundle: Some(h.bundle_name().to_string()).filter(|b| !b.is_empty()),
            network_output_rejected: h.flags & flags::NETWORK_OUTPUT_REJECTED != 0,
            aligned: h.flags & flags::ALIGNED != 0,
            confidence: if h.flags & flags::CONFIDENCE_EXPECTED_ERROR != 0 {
                "expected error"
            } else {
                "support × agreement"
            },
            frames_skipped: h.frames_skipped,
            frames_dropped: h.frames_dropped,
        }
    }
}

impl CalibrationStatus {
    fn new(h: &FrameHeader) -> CalibrationStatus {
        CalibrationStatus {
            tx: h.calib_tx,
            ty: h.calib_ty,
            cx: h.calib_cx,
            cy: h.calib_cy,
            source: if h.flags & flags::CALIBRATION_ONLINE != 0 {
                "online"
            } else {
                "static"
            },
            residual_px: finite(h.calib_residual_px),
            quality: h.calib_quality,
            age_frames: h.calib_age_frames,
            estimated_this_frame: h.flags & flags::CALIBRATION_ESTIMATED != 0,
            health: h.calibration_health().name(),
            constrained: h.calib_constrained,
        }
    }
}

/// The status now.
pub fn status(shared: &Shared) -> Status {
    let now = Instant::now();
    let mut state = shared.state();
    let fps = state.fps(now);
    let latest = state.latest;
    Status {
        service: shared.service.clone(),
        max_fps: shared.max_fps,
        uptime_s: now.duration_since(shared.started).as_secs_f64(),
        frames_received: state.received,
        rejected: state.rejected,
        lost: state.lost,
        publisher_restarts: state.publisher_restarts,
        fps,
        last_frame_age_s: latest.map(|l| now.duration_since(l.received).as_secs_f64()),
        error: state.error.clone(),
        snapshot: state.snapshot.as_ref().map_or(0, |s| s.id),
        frame: latest.map(|l| FrameStatus::new(&l.header, l.received_ns)),
        calibration: latest.map(|l| CalibrationStatus::new(&l.header)),
        history: state.history.iter().cloned().collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_fields_read_as_a_person_would() {
        let mut h = FrameHeader::new(5, 4, 3);
        h.flags = flags::ALIGNED
            | flags::REFINED_CLASSICAL
            | flags::NETWORK_OUTPUT_REJECTED
            | flags::CALIBRATION_ONLINE;
        h.stage_latency_us[Stage::Total as usize] = 12_500;
        h.publish_timestamp_ns = 1_000_000;
        h.set_bundle_name("edge");
        h.calib_health = 3;
        h.calib_constrained = 2;
        let f = FrameStatus::new(&h, 3_000_000);
        assert_eq!(f.refinement, "classical");
        assert!(f.network_output_rejected && f.aligned);
        assert_eq!(f.bundle.as_deref(), Some("edge"));
        assert_eq!(f.run_id, None);
        assert_eq!(f.daemon_latency_ms, Some(12.5));
        assert!((f.transport_latency_ms - 2.0).abs() < 1e-9);
        assert_eq!(f.confidence, "support × agreement");
        let c = CalibrationStatus::new(&h);
        assert_eq!((c.source, c.residual_px), ("online", None));
        assert_eq!((c.health, c.constrained), ("needs recalibration", 2));
        // NaN never reaches the JSON (it has no NaN).
        let p = HistoryPoint::new(1.0, 2.0, Some(&h));
        let json = serde_json::to_value(&p).unwrap();
        assert!(json["residual_px"].is_null());
        assert_eq!(json["health"], "needs recalibration");
    }
}
