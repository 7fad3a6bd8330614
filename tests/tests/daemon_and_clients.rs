//! `deard` and client processes over real iceoryx2 shared memory.

use std::time::Duration;

use dear_e2e_tests::processes::{unique_service, Daemon, Probe};
use dear_e2e_tests::{expected_payload_hashes, scene};
use dear_pipeline::Calibration;
use dear_proto::flags;
use deard::config::{NetworkPlacement, PipelineConfig, RefineMode};

const W: u32 = 160;
const H: u32 = 120;
const WAIT: Duration = Duration::from_secs(30);

fn calibration() -> Calibration {
    Calibration {
        tx: 4.0,
        ty: 0.5,
        cx: 1.5,
        cy: -1.0,
    }
}

fn classical() -> PipelineConfig {
    PipelineConfig {
        refine: RefineMode::Classical,
        ..PipelineConfig::default()
    }
}

/// The untrained bundle of the same architecture as `models/edge` (fixtures/README.md).
fn fixture_bundle() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/bundles/smoke-edge")
}

#[test]
fn with_a_bundle_the_daemon_publishes_the_dear_chain_output_with_online_calibration() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(&tmp.path().join("cap"), 8, W, H, calibration());
    let bundle = fixture_bundle();
    // The network inline on the frames that ask for it: deterministic, so every payload can
    // be compared with the in-process chain (background delivery depends on timing; the next
    // test covers it).
    let pipeline = PipelineConfig {
        refine: RefineMode::Dear,
        bundle: bundle.clone(),
        online_interval_frames: 3,
        online_network: NetworkPlacement::Inline,
        ..PipelineConfig::default()
    };
    let expected = expected_payload_hashes(&capture, &pipeline);
    assert_eq!(expected.len(), 8);
    let service = unique_service("dear-bundle");
    let probe = Probe::start(&service, 8);
    let mut daemon = Daemon::start(
        &service,
        &[
            "--refine",
            "dear",
            "--bundle",
            bundle.to_str().unwrap(),
            "--online-interval",
            "3",
            "--online-network",
            "inline",
            "--pacing",
            "fast",
            "--replay",
            capture.root().to_str().unwrap(),
        ],
        &tmp.path().join("deard.log"),
    );
    let seen = probe.take(8, WAIT);
    for s in &seen {
        assert_eq!(
            s.sha256,
            expected[&s.frame_id],
            "frame {} differs from the in-process DEAR chain\n{}",
            s.frame_id,
            daemon.log_text()
        );
        let want = flags::ALIGNED | flags::REFINED_NETWORK | flags::CALIBRATION_ONLINE;
        assert_eq!(
            s.flags & want,
            want,
            "frame {} flags {:x}",
            s.frame_id,
            s.flags
        );
        assert_eq!(s.flags & flags::REFINED_CLASSICAL, 0);
        assert!(s.bundle.starts_with("edge/"), "bundle name {:?}", s.bundle);
    }
    // The first frame has no estimate yet, so the rough-flow network runs on it. (How often it
    // runs after that depends on whether the untrained fixture's measurements pass the gate.)
    assert_ne!(seen[0].flags & flags::CALIBRATION_ESTIMATED, 0);
    assert!(daemon.terminate(WAIT).expect("stops").success());
}

/// The daemon's default: the network frames run on the background worker. No frame waits for
/// it — the first frame is published without a network measurement, aligned by the factory
/// calibration — and the worker's measurements reach later frames (the replay loops at the
/// capture's 30 fps until one does; an unoptimised test build measures slowly).
#[test]
fn with_the_network_in_the_background_no_frame_waits_and_measurements_arrive() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(&tmp.path().join("cap"), 30, W, H, calibration());
    let bundle = fixture_bundle();
    let service = unique_service("dear-background");
    let limit = 900;
    let probe = Probe::start(&service, limit);
    let mut daemon = Daemon::start(
        &service,
        &[
            "--refine",
            "dear",
            "--bundle",
            bundle.to_str().unwrap(),
            "--online-interval",
            "3",
            "--pacing",
            "timestamps",
            "--loop",
            "--replay",
            capture.root().to_str().unwrap(),
        ],
        &tmp.path().join("deard.log"),
    );
    let want = flags::ALIGNED | flags::REFINED_NETWORK | flags::CALIBRATION_ONLINE;
    let mut seen = Vec::new();
    while seen.len() < limit {
        let s = probe.next(WAIT).expect("the daemon keeps publishing");
        assert_eq!(
            s.flags & want,
            want,
            "frame {} flags {:x}",
            s.frame_id,
            s.flags
        );
        let delivered = s.flags & flags::CALIBRATION_ESTIMATED != 0;
        seen.push(s);
        if delivered {
            break;
        }
    }
    assert_eq!(
        seen[0].flags & flags::CALIBRATION_ESTIMATED,
        0,
        "the first frame must not wait for the network"
    );
    assert!(
        seen.len() < limit,
        "no background measurement reached any of {limit} frames\n{}",
        daemon.log_text()
    );
    assert!(daemon.terminate(WAIT).expect("stops").success());
}

#[test]
fn two_clients_receive_every_frame_in_order_with_the_pipeline_output() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(&tmp.path().join("cap"), 12, W, H, calibration());
    let expected = expected_payload_hashes(&capture, &classical());
    assert_eq!(expected.len(), 12);
    let service = unique_service("two-clients");
    let a = Probe::start(&service, 12);
    let b = Probe::start(&service, 12);
    let mut daemon = Daemon::start(
        &service,
        &[
            "--refine",
            "classical",
            "--replay",
            capture.root().to_str().unwrap(),
        ],
        &tmp.path().join("deard.log"),
    );
    for probe in [&a, &b] {
        let seen = probe.take(12, WAIT);
        let ids: Vec<u64> = seen.iter().map(|s| s.frame_id).collect();
        assert_eq!(ids, (0..12).collect::<Vec<_>>(), "every frame, in order");
        for s in &seen {
            assert_eq!(
                s.sha256, expected[&s.frame_id],
                "frame {} content differs from the pipeline's",
                s.frame_id
            );
            assert_eq!((s.skipped, s.dropped), (0, 0));
        }
    }
    let status = daemon.terminate(WAIT).expect("deard stops on SIGTERM");
    assert!(
        status.success(),
        "clean exit on SIGTERM: {status:?}\n{}",
        daemon.log_text()
    );
    assert!(
        daemon.log_text().contains("stopped"),
        "{}",
        daemon.log_text()
    );
}

#[test]
fn killing_a_client_disturbs_neither_the_daemon_nor_the_other_client() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(&tmp.path().join("cap"), 30, W, H, calibration());
    let service = unique_service("kill-client");
    let survivor = Probe::start(&service, 30);
    let mut victim = Probe::start(&service, 1000);
    let mut daemon = Daemon::start(
        &service,
        &[
            "--refine",
            "classical",
            "--replay",
            capture.root().to_str().unwrap(),
        ],
        &tmp.path().join("deard.log"),
    );
    let before = victim.take(5, WAIT);
    assert_eq!(before.last().unwrap().frame_id, 4);
    victim.crash();
    let seen = survivor.take(30, WAIT);
    let ids: Vec<u64> = seen.iter().map(|s| s.frame_id).collect();
    assert_eq!(
        ids,
        (0..30).collect::<Vec<_>>(),
        "the other client keeps getting every frame"
    );
    assert!(
        daemon.is_running(),
        "daemon survives a client crash:\n{}",
        daemon.log_text()
    );
    assert!(daemon.terminate(WAIT).expect("stops").success());
}

#[test]
fn a_restarted_daemon_is_picked_up_by_a_running_client() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(&tmp.path().join("cap"), 16, W, H, calibration());
    let expected = expected_payload_hashes(&capture, &classical());
    let service = unique_service("restart");
    let root = capture.root().to_str().unwrap();
    let probe = Probe::start(&service, 16);
    let mut first = Daemon::start(
        &service,
        &["--refine", "classical", "--replay", root, "--end", "8"],
        &tmp.path().join("deard1.log"),
    );
    let seen_first = probe.take(8, WAIT);
    first.crash();
    let mut second = Daemon::start(
        &service,
        &["--refine", "classical", "--replay", root, "--start", "8"],
        &tmp.path().join("deard2.log"),
    );
    let seen_second = probe.take(8, WAIT);
    let ids: Vec<u64> = seen_first
        .iter()
        .chain(&seen_second)
        .map(|s| s.frame_id)
        .collect();
    assert_eq!(ids, (0..16).collect::<Vec<_>>());
    for s in seen_first.iter().chain(&seen_second) {
        assert_eq!(s.sha256, expected[&s.frame_id]);
    }
    assert!(second.terminate(WAIT).expect("stops").success());
}

#[test]
fn bad_frames_are_skipped_counted_and_named() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(&tmp.path().join("cap"), 10, W, H, calibration());
    // A corrupt PNG, a missing file and a frame of the wrong resolution.
    let corrupt = capture.frame_paths(2).rgb;
    let bytes = std::fs::read(&corrupt).unwrap();
    std::fs::write(&corrupt, &bytes[..bytes.len() / 3]).unwrap();
    let missing = capture.frame_paths(5).amplitude;
    std::fs::remove_file(&missing).unwrap();
    let wrong_size = capture.frame_paths(7).depth;
    let small = ndarray::Array2::<f32>::from_elem((H as usize / 2, W as usize / 2), 1.0);
    dear_pipeline::capture::png::write_depth(&wrong_size, small.view(), 0.001).unwrap();
    let expected = expected_payload_hashes(&capture, &classical());

    let service = unique_service("bad-frames");
    let probe = Probe::start(&service, 7);
    let mut daemon = Daemon::start(
        &service,
        &[
            "--refine",
            "classical",
            "--replay",
            capture.root().to_str().unwrap(),
        ],
        &tmp.path().join("deard.log"),
    );
    let seen = probe.take(7, WAIT);
    let ids: Vec<u64> = seen.iter().map(|s| s.frame_id).collect();
    assert_eq!(ids, vec![0, 1, 3, 4, 6, 8, 9]);
    for s in &seen {
        assert_eq!(s.sha256, expected[&s.frame_id]);
    }
    assert_eq!(
        seen.last().unwrap().skipped,
        3,
        "skipped frames are counted in the header"
    );
    assert!(daemon.is_running(), "bad frames never stop the daemon");
    assert!(daemon.terminate(WAIT).expect("stops").success());
    let log = daemon.log_text();
    for path in [&corrupt, &missing, &wrong_size] {
        assert!(
            log.contains(&*path.to_string_lossy()),
            "log names {}:\n{log}",
            path.display()
        );
    }
}
