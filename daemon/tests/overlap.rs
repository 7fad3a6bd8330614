//! The processor's overlapped path (`Processor::prepare` / `finish_into`) with a real bundle and
//! real frames: frames come out in order with the DEAR flags, and a bad frame offered as the
//! next one is refused with an error naming it while the held frame is still published.

use std::path::PathBuf;

use dear_capture::{CaptureDir, RgbdFrame};
use dear_proto::{flags, FrameHeader};
use deard::config::{PipelineConfig, RefineMode};
use deard::processing::{FrameOutput, ProcessError, Processor};
use ndarray::{s, Array2, Array3};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

struct Planes {
    depth: Array2<f32>,
    rgb: Array3<u8>,
    confidence: Array2<u8>,
}

impl Planes {
    fn new(h: usize, w: usize) -> Self {
        Planes {
            depth: Array2::from_elem((h, w), f32::NAN),
            rgb: Array3::zeros((h, w, 3)),
            confidence: Array2::zeros((h, w)),
        }
    }

    fn output(&mut self) -> FrameOutput<'_> {
        FrameOutput {
            depth: self.depth.view_mut(),
            rgb: self.rgb.view_mut(),
            confidence: self.confidence.view_mut(),
        }
    }
}

#[test]
fn overlapped_frames_are_published_and_a_bad_next_frame_is_refused_by_name() {
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let (w, h) = capture.size();
    let config = PipelineConfig {
        refine: RefineMode::Dear,
        bundle: root().join("fixtures/bundles/smoke-edge"),
        ..PipelineConfig::default()
    };
    let mut processor =
        Processor::from_config(w, h, capture.manifest().initial_calibration, &config).unwrap();
    // The daemon's default: online calibration with the network in the background.
    assert!(processor.overlaps_frames());
    let frames: Vec<RgbdFrame> = (0..3).map(|p| capture.read_frame(p).unwrap()).collect();
    let (h, w) = (h as usize, w as usize);
    // A frame of the wrong size (a row short), as a broken source could deliver.
    let mut bad = frames[1].clone();
    bad.index = 99;
    bad.depth = bad.depth.slice(s![..h - 1, ..]).to_owned();
    let want = flags::ALIGNED | flags::REFINED_NETWORK | flags::CALIBRATION_ONLINE;

    let mut pending = processor.prepare(&frames[0]).unwrap();
    for (k, next) in [&frames[1], &bad, &frames[2]].into_iter().enumerate() {
        let mut planes = Planes::new(h, w);
        let mut header = FrameHeader::new(pending.frame().index, w as u32, h as u32);
        let finished = processor.finish_into(pending, Some(next), &mut header, planes.output());
        finished.result.unwrap_or_else(|e| panic!("step {k}: {e}"));
        assert_eq!(
            header.flags & want,
            want,
            "step {k}: flags {:x}",
            header.flags
        );
        assert!(
            planes.depth.iter().all(|z| z.is_finite()),
            "step {k}: depth written"
        );
        assert!(
            planes.depth.iter().any(|&z| z > 0.0),
            "step {k}: depth published"
        );
        assert_eq!(
            planes.rgb, frames[header.frame_id as usize].rgb,
            "step {k}: RGB"
        );
        pending = match finished.next.expect("a next frame was given") {
            Ok(p) => p,
            Err(ProcessError::Size { frame, .. }) => {
                assert_eq!(frame, 99, "the error names the bad frame");
                // Skipped: the stream goes on with the next good frame.
                processor.prepare(&frames[2]).unwrap()
            }
            Err(e) => panic!("step {k}: unexpected {e}"),
        };
        assert_ne!(pending.frame().index, 99, "the bad frame is never held");
    }
    // The last held frame is finished on its own.
    let mut planes = Planes::new(h, w);
    let mut header = FrameHeader::new(pending.frame().index, w as u32, h as u32);
    let finished = processor.finish_into(pending, None, &mut header, planes.output());
    finished.result.unwrap();
    assert!(finished.next.is_none());
    assert_eq!(header.frame_id, 2);
}

/// Issue 32: every DEAR frame's header carries a calibration health state. With the static
/// calibration as the estimator's prior it is assessed from the first frame (never "unknown"),
/// a valid code, and the constrained-direction count is at most 4; the static engine says
/// "unknown".
#[test]
fn every_frame_carries_a_calibration_health_state() {
    use dear_proto::CalibrationHealth;
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let (w, h) = capture.size();
    let frames: Vec<RgbdFrame> = (0..4).map(|p| capture.read_frame(p).unwrap()).collect();
    let (hu, wu) = (h as usize, w as usize);
    for calibration in [
        deard::config::CalibrationMode::Online,
        deard::config::CalibrationMode::EveryFrame,
    ] {
        let config = PipelineConfig {
            refine: RefineMode::Dear,
            bundle: root().join("fixtures/bundles/smoke-edge"),
            calibration,
            ..PipelineConfig::default()
        };
        let mut processor =
            Processor::from_config(w, h, capture.manifest().initial_calibration, &config).unwrap();
        let mut seen = Vec::new();
        for frame in &frames {
            let mut planes = Planes::new(hu, wu);
            let mut header = FrameHeader::new(frame.index, w, h);
            processor
                .process_into(frame, &mut header, planes.output())
                .unwrap();
            assert!(header.calib_health <= 3, "{}", header.calib_health);
            assert!(header.calib_constrained <= 4);
            seen.push(header.calibration_health());
        }
        if calibration == deard::config::CalibrationMode::Online {
            assert!(
                seen.iter().all(|&s| s != CalibrationHealth::Unknown),
                "{calibration:?}: {seen:?}"
            );
        }
    }
    let config = PipelineConfig {
        refine: RefineMode::Classical,
        ..PipelineConfig::default()
    };
    let mut processor =
        Processor::from_config(w, h, capture.manifest().initial_calibration, &config).unwrap();
    let mut planes = Planes::new(hu, wu);
    let mut header = FrameHeader::new(0, w, h);
    header.calib_health = 9;
    processor
        .process_into(&frames[0], &mut header, planes.output())
        .unwrap();
    assert_eq!(header.calibration_health(), CalibrationHealth::Unknown);
    assert_eq!(header.calib_health, 0);
}

/// A guarded bundle's frames say their confidence is an expected-error code (flag bit 6), with
/// code 0 exactly where no depth is published; the shipped hybrid bundle's frames do not.
#[test]
fn a_guarded_bundle_publishes_expected_error_codes_and_says_so() {
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let (w, h) = capture.size();
    let frame = capture.read_frame(0).unwrap();
    for (bundle, guarded) in [("models/edge-guarded", true), ("models/edge", false)] {
        let config = PipelineConfig {
            refine: RefineMode::Dear,
            bundle: root().join(bundle),
            ..PipelineConfig::default()
        };
        let mut processor =
            Processor::from_config(w, h, capture.manifest().initial_calibration, &config).unwrap();
        let mut planes = Planes::new(h as usize, w as usize);
        let mut header = FrameHeader::new(frame.index, w, h);
        let pending = processor.prepare(&frame).unwrap();
        let finished = processor.finish_into(pending, None, &mut header, planes.output());
        finished.result.unwrap();
        assert_eq!(
            header.flags & flags::CONFIDENCE_EXPECTED_ERROR != 0,
            guarded,
            "{bundle}: flags {:x}",
            header.flags
        );
        assert!(header.flags & flags::REFINED_NETWORK != 0, "{bundle}");
        for (z, c) in planes.depth.iter().zip(&planes.confidence) {
            assert_eq!(
                *z > 0.0,
                *c > 0,
                "{bundle}: confidence 0 exactly where depth is 0"
            );
        }
        if guarded {
            // Codes spread over errors from millimetres to decimetres, not one value.
            let codes: std::collections::BTreeSet<u8> = planes
                .confidence
                .iter()
                .copied()
                .filter(|&c| c > 0)
                .collect();
            assert!(codes.len() > 20, "{} distinct codes", codes.len());
        }
    }
}
