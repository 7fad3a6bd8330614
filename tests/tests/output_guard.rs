//! The output guard with real graphs through tract on the sample capture: refine graphs with
//! absurd outputs (`fixtures/bundles/broken-refine`: depth ×1000, NaN, −depth) put into a copy
//! of the smoke bundle are rejected on every frame and the frame gets the classical filter's
//! depth and confidence; the shipped bundle's output passes the guard on every frame of the
//! sample. On every published frame confidence is 0 exactly where depth is 0.
use std::path::{Path, PathBuf};

use dear_capture::{CaptureDir, RgbdFrame};
use dear_e2e_tests::bundles::{broken_refine_graph, smoke_bundle_with_refine};
use dear_pipeline::chain::{ChainInput, ChainMode, ChainOutput, ChainReport, DearChain};
use dear_pipeline::filter::ClassicalRefiner;
use dear_pipeline::model::ModelBundle;
use ndarray::Array2;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The smoke bundle with `fixtures/bundles/broken-refine/<name>.onnx` as its refine graph.
fn broken_bundle(name: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    smoke_bundle_with_refine(dir.path(), &broken_refine_graph(name));
    dir
}

struct Published {
    report: ChainReport,
    depth: Array2<f32>,
    confidence: Array2<u8>,
}

fn run(chain: &mut DearChain, frame: &RgbdFrame, mode: ChainMode) -> Published {
    let (h, w) = frame.dim();
    let mut depth = Array2::from_elem((h, w), -1.0f32);
    let mut confidence = Array2::from_elem((h, w), 77u8);
    let report = chain
        .process(
            ChainInput::from(frame),
            mode,
            ChainOutput {
                depth: depth.view_mut(),
                confidence: confidence.view_mut(),
            },
        )
        .unwrap();
    Published {
        report,
        depth,
        confidence,
    }
}

fn assert_confidence_zero_exactly_without_depth(p: &Published, what: &str) {
    for ((y, x), &z) in p.depth.indexed_iter() {
        assert!(
            z == 0.0 || (z > 0.0 && z.is_finite()),
            "{what}: depth {z} at ({y}, {x})"
        );
        assert_eq!(
            p.confidence[[y, x]] == 0,
            z == 0.0,
            "{what}: depth {z} with confidence {} at ({y}, {x})",
            p.confidence[[y, x]]
        );
    }
}

#[test]
fn absurd_refine_outputs_fall_back_to_the_classical_filter() {
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let frame = capture.read_frame(0).unwrap();
    let (h, w) = frame.dim();
    let calibration = capture.manifest().initial_calibration;
    for (name, field) in [
        ("scaled", "moved beyond the bound"),
        ("nan", "non-finite"),
        ("negative", "at or below zero"),
    ] {
        let dir = broken_bundle(name);
        let bundle = ModelBundle::load(dir.path()).expect("the broken bundle verifies");
        let mut chain = DearChain::new(&bundle, w, h).unwrap();
        for mode in [ChainMode::Full, ChainMode::Cached(calibration)] {
            let what = format!("{name} {mode:?}");
            let p = run(&mut chain, &frame, mode);
            let check = p
                .report
                .rejected_refinement
                .unwrap_or_else(|| panic!("{what}: the guard let the output through"));
            assert!(check.measured > h * w / 2, "{what}: {check}");
            assert_eq!(check.implausible(), check.measured, "{what}: {check}");
            assert!(check.to_string().contains(field), "{what}: {check}");
            // What was published is the classical filter of the chain's own refinement input.
            let mut want_depth = Array2::zeros((h, w));
            let mut want_confidence = Array2::zeros((h, w));
            ClassicalRefiner::default().refine_into(
                chain.depth_warped().view(),
                frame.rgb.view(),
                want_depth.view_mut(),
                want_confidence.view_mut(),
            );
            assert_eq!(p.depth, want_depth, "{what}");
            assert_eq!(p.confidence, want_confidence, "{what}");
            assert_confidence_zero_exactly_without_depth(&p, &what);
        }
    }
}

#[test]
fn the_shipped_bundle_passes_the_guard_on_every_sample_frame() {
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let (w, h) = capture.size();
    let bundle = ModelBundle::load(root().join("models/edge")).unwrap();
    let mut chain = DearChain::new(&bundle, w as usize, h as usize).unwrap();
    let calibration = capture.manifest().initial_calibration;
    let guard = chain
        .options()
        .output_guard
        .expect("the guard is on by default");
    for position in 0..capture.len() {
        let frame = capture.read_frame(position).unwrap();
        let mode = if position % 10 == 0 {
            ChainMode::Full
        } else {
            ChainMode::Cached(calibration)
        };
        let p = run(&mut chain, &frame, mode);
        let what = format!("frame {position}");
        assert_eq!(p.report.rejected_refinement, None, "{what}");
        // Not near the threshold either: the shipped refiner moves 1.0–2.0 % of the measured
        // pixels beyond the bound (flying pixels at depth edges snapped across the gap).
        let check = guard.check(chain.depth_warped().view(), chain.refined_raw().view());
        assert!(
            check.implausible_fraction() < 0.5 * guard.max_implausible_fraction,
            "{what}: {check} (threshold {})",
            guard.max_implausible_fraction
        );
        assert_confidence_zero_exactly_without_depth(&p, &what);
    }
}

/// The daemon with a broken refine graph keeps serving: every frame is published refined by
/// the classical filter and flagged, never as network-refined; the log says the network looks
/// broken once the rejections run on, and counts them.
#[test]
fn the_daemon_publishes_classically_refined_frames_when_the_network_is_broken() {
    use dear_e2e_tests::engines::Engine;
    use dear_e2e_tests::expected_payload_hashes;
    use dear_e2e_tests::processes::{deard, Probe};
    use dear_proto::flags;
    use dear_test_support::daemon::Daemon;
    use dear_test_support::process::unique_service;
    use dear_test_support::scene;
    use std::time::Duration;

    const FRAMES: usize = 12;
    let wait = Duration::from_secs(30);
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(
        &tmp.path().join("cap"),
        FRAMES as u64,
        160,
        120,
        scene::factory_calibration(),
    );
    let bundle = smoke_bundle_with_refine(&tmp.path().join("bundle"), &broken_refine_graph("nan"));
    // Inline network frames: deterministic, so every payload can be compared with the
    // in-process processing (which the test above ties to the classical filter).
    let engine = Engine::dear_inline(&bundle);
    let expected = expected_payload_hashes(&capture, &engine.pipeline);
    let service = unique_service("broken-network");
    let probe = Probe::start(&service, 1000);
    let mut daemon = Daemon::spawn(
        deard(&service, &engine.replay_fast(capture.root())),
        &tmp.path().join("deard.log"),
    );
    // Every frame is published (fast pacing); the probe checks the ones it receives (the
    // transport may overwrite some in its queue under load, by design) and must get the last.
    let finished = daemon.wait_source_finished(wait);
    assert_eq!(finished.published, FRAMES as u64, "{}", daemon.log_text());
    let seen = probe.collect_until(
        |seen| seen.last().unwrap().sequence + 1 >= finished.published,
        wait,
    );
    assert_eq!(
        seen.last().map(|s| s.sequence + 1),
        Some(finished.published)
    );
    for s in &seen {
        let want = flags::ALIGNED | flags::REFINED_CLASSICAL | flags::NETWORK_OUTPUT_REJECTED;
        assert_eq!(
            s.flags & want,
            want,
            "frame {} flags {:x}",
            s.frame_id,
            s.flags
        );
        assert_eq!(s.flags & flags::REFINED_NETWORK, 0, "frame {}", s.frame_id);
        assert_eq!(s.sha256, expected[&s.frame_id], "frame {}", s.frame_id);
    }
    assert!(
        daemon.is_running(),
        "deard keeps serving\n{}",
        daemon.log_text()
    );
    assert!(daemon.terminate(wait).expect("stops").success());
    let log = daemon.log_text();
    assert_eq!(
        log.matches("refinement network output rejected").count(),
        1,
        "{log}"
    );
    assert_eq!(log.matches("the bundle looks broken").count(), 1, "{log}");
    assert!(log.contains(&format!("network_rejected={FRAMES}")), "{log}");
}
