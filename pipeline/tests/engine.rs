//! The per-frame engine (`dear_pipeline::engine`) with the shipped bundle through tract, on the
//! bundled drifting sample: with the deterministic schedule a measurement asked for on frame k
//! reaches the estimator on frame k + N, it is the measurement of frame k, and two runs give
//! the same calibrations and the same depth, bit for bit.
#![cfg(feature = "inference")]

use std::num::NonZeroU32;
use std::path::{Path, PathBuf};

use dear_capture::CaptureDir;
use dear_capture::{Calibration, RgbdFrame};
use dear_pipeline::chain::{ChainInput, ChainOutput, DearChain};
use dear_pipeline::engine::{
    CalibrationPolicy, EngineConfig, FrameEngine, FrameReport, MeasurementSchedule,
};
use dear_pipeline::model::ModelBundle;
use dear_pipeline::recalibration::observability::Information;
use dear_pipeline::recalibration::OnlineConfig;
use ndarray::Array2;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The sample's first `count` frames.
fn frames(count: usize) -> Vec<RgbdFrame> {
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    (0..count)
        .map(|i| capture.read_sample(i).unwrap().frame)
        .collect()
}

/// The sample's true calibration at its first frame, its principal point moved by 3 px: the
/// static calibration the engine starts from, so that a measurement visibly moves it.
fn misaligned_start() -> Calibration {
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let truth = capture.manifest().initial_calibration;
    Calibration {
        cx: truth.cx + 3.0,
        ..truth
    }
}

/// What one frame gave: the engine's report, the calibration that aligned it, the depth.
struct Step {
    report: FrameReport,
    aligned_with: Option<Calibration>,
    depth: Array2<f32>,
}

/// Runs the engine over `frames` as `dear eval --online` does (each frame prepared, then
/// finished alone), tracking off so that the estimate moves only when a measurement arrives.
fn run(bundle: &ModelBundle, frames: &[RgbdFrame], delay: u32) -> Vec<Step> {
    run_after(bundle, frames, delay, false)
}

/// [`run`], with the engine warmed up first when `warm_up`.
fn run_after(bundle: &ModelBundle, frames: &[RgbdFrame], delay: u32, warm_up: bool) -> Vec<Step> {
    let (h, w) = frames[0].dim();
    let config = EngineConfig {
        calibration: CalibrationPolicy::Online {
            config: OnlineConfig {
                track_gain: 0.0,
                ..OnlineConfig::default()
            },
            schedule: MeasurementSchedule::Delayed(NonZeroU32::new(delay).unwrap()),
        },
        label: "edge".into(),
    };
    let mut engine = FrameEngine::new(bundle, w, h, misaligned_start(), config).unwrap();
    assert!(engine.overlaps_frames());
    if warm_up {
        engine.warm_up().unwrap();
    }
    let mut depth = Array2::zeros((h, w));
    let mut confidence = Array2::zeros((h, w));
    frames
        .iter()
        .map(|frame| {
            let prepared = engine
                .prepare(ChainInput::from(frame))
                .unwrap()
                .expect("overlapped");
            let aligned_with = prepared.calibration();
            let output = ChainOutput {
                depth: depth.view_mut(),
                confidence: confidence.view_mut(),
            };
            let (report, next) =
                engine.finish(frame.index, prepared, ChainInput::from(frame), output, None);
            assert!(next.is_none());
            Step {
                report: report.unwrap(),
                aligned_with,
                depth: depth.clone(),
            }
        })
        .collect()
}

#[test]
fn a_delayed_measurement_of_frame_k_is_applied_at_frame_k_plus_n() {
    const DELAY: u32 = 3;
    let bundle = ModelBundle::load(root().join("models/edge")).unwrap();
    let frames = frames(2 * DELAY as usize + 2);
    let steps = run(&bundle, &frames, DELAY);
    let n = DELAY as usize;
    let start = misaligned_start();

    // The estimator asks for the network from the first frame on (warm-up); the measurement
    // is busy until it is delivered, so frames 0, N, 2N are measured and N, 2N receive.
    let measured: Vec<usize> = (0..steps.len())
        .filter(|&i| steps[i].report.measured)
        .collect();
    let delivered: Vec<usize> = (0..steps.len())
        .filter(|&i| steps[i].report.delivered.is_some())
        .collect();
    assert_eq!(measured, vec![0, n, 2 * n]);
    assert_eq!(delivered, vec![n, 2 * n]);
    // No frame on the frame path runs the network.
    assert!(steps.iter().all(|s| !s.report.chain.ran_flow_network));

    // What arrives at frame N is the measurement of frame 0's planes, judged against the
    // calibration in use then (the static one: no estimate yet).
    let (h, w) = frames[0].dim();
    let mut chain = DearChain::new(&bundle, w, h).unwrap();
    chain.set_reference(Some(start));
    let of_frame_0 = chain
        .measure(ChainInput::from(&frames[0]))
        .unwrap()
        .measurement;
    assert_eq!(steps[n].report.delivered.as_ref(), Some(&of_frame_0));
    assert!(of_frame_0.is_ok(), "the sample's first frame is measurable");

    // Until frame N the static calibration aligns and is published; the delivery at frame N
    // moves the estimate (by most of the 3 px error), and frame N + 1 is aligned with it.
    for step in &steps[..n] {
        assert_eq!(step.aligned_with, Some(start));
        assert_eq!(step.report.calibration, start);
    }
    assert_eq!(steps[n].aligned_with, Some(start));
    let updated = steps[n].report.calibration;
    assert!(
        (updated.cx - start.cx).abs() > 1.0,
        "the measurement delivered at frame N moves c_x: {start:?} -> {updated:?}"
    );
    assert_eq!(steps[n + 1].aligned_with, Some(updated));
}

/// Two runs give the same calibrations and depth bit for bit, also when one engine was warmed
/// up first (deard warms its engine before the first frame): the warm-up leaves no trace.
#[test]
fn the_delayed_schedule_is_reproducible_and_a_warm_up_leaves_no_trace() {
    let bundle = ModelBundle::load(root().join("models/edge")).unwrap();
    let frames = frames(14);
    let (first, second) = (
        run(&bundle, &frames, 2),
        run_after(&bundle, &frames, 2, true),
    );
    for (i, (a, b)) in first.iter().zip(&second).enumerate() {
        assert_eq!(a.report.calibration, b.report.calibration, "frame {i}");
        assert_eq!(a.report.delivered, b.report.delivered, "frame {i}");
        assert_eq!(a.aligned_with, b.aligned_with, "frame {i}");
        let bits = |d: &Array2<f32>| d.iter().map(|z| z.to_bits()).collect::<Vec<_>>();
        assert_eq!(
            bits(&a.depth),
            bits(&b.depth),
            "frame {i}: the depth, bit for bit"
        );
    }
    assert!(
        first
            .iter()
            .filter(|s| s.report.delivered.is_some())
            .count()
            >= 3,
        "the runs compared deliver measurements"
    );
}

/// The chain's measurement judged against the calibration in use
/// (`DearChain::set_reference`), on the sample's first frame: its true calibration is kept
/// bit for bit, with zero information (the estimator leaves its estimate); a calibration 3 px
/// off is replaced by one closer to the truth.
#[test]
fn the_chain_keeps_a_correct_calibration_in_use_and_replaces_a_wrong_one() {
    let bundle = ModelBundle::load(root().join("models/edge")).unwrap();
    let frame = &frames(1)[0];
    let (h, w) = frame.dim();
    let truth = CaptureDir::open(root().join("samples/demo"))
        .unwrap()
        .manifest()
        .initial_calibration;
    let mut chain = DearChain::new(&bundle, w, h).unwrap();

    chain.set_reference(Some(truth));
    let kept = chain
        .measure(ChainInput::from(frame))
        .unwrap()
        .measurement
        .unwrap();
    assert_eq!(kept.calibration, truth);
    assert_eq!(kept.information, Some(Information::ZERO));

    let wrong = misaligned_start();
    chain.set_reference(Some(wrong));
    let moved = chain
        .measure(ChainInput::from(frame))
        .unwrap()
        .measurement
        .unwrap();
    // The principal point decides the flow at every depth here: 3 px off before.
    assert!(
        (moved.calibration.cx - truth.cx).abs() < 1.0,
        "{moved:?} vs truth {truth:?}"
    );
}
