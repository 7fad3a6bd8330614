//! `deard` and client processes over real iceoryx2 shared memory.
//!
//! The frame service is overwrite-oldest by design (`dear_proto::service`: a subscriber's queue
//! holds two samples, then the oldest is overwritten), so a client is not promised every frame
//! and these tests do not demand it. They check what the protocol does promise, against what
//! the daemon says it published (its `source finished` and `stopped` log lines): within one
//! `run_id` the `sequence` strictly increases; received + lost (sequence gaps) = published; each
//! payload is the pipeline's output for its `frame_id`; the publisher sent every readable input
//! frame once, in order. Any loss is on the client side and bounded ([`assert_loss_bound`]).

use std::collections::BTreeMap;
use std::time::Duration;

use dear_e2e_tests::engines::Engine;
use dear_e2e_tests::expected_payload_hashes;
use dear_e2e_tests::processes::{deard, lost_by_sequence, split_runs, Probe, Seen};
use dear_proto::flags;
use dear_test_support::daemon::{Counts, Daemon};
use dear_test_support::process::unique_service;
use dear_test_support::scene;

const W: u32 = 160;
const H: u32 = 120;
const WAIT: Duration = Duration::from_secs(30);

/// Checks what one probe received from one publisher run (`frames`: one `run_id`) against the
/// protocol and against what the publisher says it did (`counts`, from its log), and returns
/// the number of samples the probe lost. `readable` lists the frame ids of the replayed range
/// that the daemon can read, in order; `expected` the payload hash of each.
///
/// Each check fails if the daemon reorders, duplicates, loses or corrupts frames:
/// - `sequence` strictly increases ([`lost_by_sequence`]): nothing reordered or repeated;
/// - received + lost = published: the newest sample is never overwritten, so the publisher's
///   last sample arrives and every number before it is either received or a counted gap;
/// - published + dropped = readable frames: each readable input frame was either published or
///   counted as dropped by the capture queue (which only `--pacing timestamps` does);
/// - a frame's position among the readable ones minus its sequence is the number of input
///   frames dropped before it: never negative, never decreasing, at most `counts.dropped`.
///   With nothing dropped (always so with `--pacing fast`, whose queue blocks) this is
///   `frame_id == readable[sequence]`: every readable frame published once, in order;
/// - each payload hashes to the in-process pipeline's output for its frame id.
fn check_run(
    who: &str,
    frames: &[Seen],
    counts: Counts,
    readable: &[u64],
    expected: &BTreeMap<u64, String>,
) -> u64 {
    let last = frames
        .last()
        .unwrap_or_else(|| panic!("{who}: received nothing of the run"));
    assert_ne!(last.run_id, 0, "{who}: deard always stamps a run id");
    let lost = lost_by_sequence(frames);
    assert_eq!(
        frames.len() as u64 + lost,
        counts.published,
        "{who}: received {} + lost {lost} (sequence gaps) must be the {} published; last \
         sequence received {}",
        frames.len(),
        counts.published,
        last.sequence
    );
    assert_eq!(
        counts.published + counts.dropped,
        readable.len() as u64,
        "{who}: every readable frame published or counted as dropped ({counts:?})"
    );
    let mut dropped_before = 0;
    for s in frames {
        let position = readable
            .iter()
            .position(|&id| id == s.frame_id)
            .unwrap_or_else(|| {
                panic!(
                    "{who}: frame id {} is not a readable frame of the replay {readable:?}",
                    s.frame_id
                )
            }) as u64;
        let behind = position.checked_sub(s.sequence).unwrap_or_else(|| {
            panic!(
                "{who}: frame {} sent as sample {}, more samples than frames before it",
                s.frame_id, s.sequence
            )
        });
        assert!(
            behind >= dropped_before && behind <= counts.dropped,
            "{who}: frame {} sent as sample {}: {behind} frames missing before it, after {} \
             before the previous, {} dropped in all",
            s.frame_id,
            s.sequence,
            dropped_before,
            counts.dropped
        );
        dropped_before = behind;
        assert_eq!(
            s.sha256, expected[&s.frame_id],
            "{who}: frame {} content differs from the pipeline's",
            s.frame_id
        );
    }
    lost
}

/// The client-side loss a test accepts. The transport allows any loss, but `dear-probe` only
/// copies each payload before returning the sample, so it loses frames only when its receiving
/// thread is not scheduled for two publish intervals: rare, even on a loaded machine. Losing
/// more than half the frames means the stream is not being delivered (e.g. only the latest
/// sample reaching a subscriber), which these tests exist to catch. (Seen: no loss with a busy
/// loop on the second core; at most 4 of 8 with three busy loops on the 2-core test machine.)
fn assert_loss_bound(who: &str, lost: u64, published: u64) {
    // Shown with --nocapture: how close the runs come to the bound.
    eprintln!("{who}: lost {lost} of {published} frames");
    assert!(
        lost * 2 <= published,
        "{who}: lost {lost} of {published} frames; the probe keeps up unless starved"
    );
}

/// The untrained bundle of the same architecture as `models/edge` (fixtures/README.md).
fn fixture_bundle() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/bundles/smoke-edge")
}

/// Every received payload equals the in-process DEAR chain's, with the flags of a
/// network-refined, online-calibrated frame; the first frame (which must arrive: with the
/// network inline the daemon spends two network runs before it could be overwritten) ran the
/// rough-flow network.
#[test]
fn with_a_bundle_the_daemon_publishes_the_dear_chain_output_with_online_calibration() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(
        &tmp.path().join("cap"),
        8,
        W,
        H,
        scene::factory_calibration(),
    );
    let bundle = fixture_bundle();
    // The network inline on the frames that ask for it: deterministic, so every payload can
    // be compared with the in-process chain (background delivery depends on timing; the next
    // test covers it).
    let engine = Engine::dear_inline(&bundle);
    let expected = expected_payload_hashes(&capture, &engine.pipeline);
    assert_eq!(expected.len(), 8);
    let readable: Vec<u64> = expected.keys().copied().collect();
    let service = unique_service("dear-bundle");
    let probe = Probe::start(&service, 1000);
    let mut daemon = Daemon::spawn(
        deard(&service, &engine.replay_fast(capture.root())),
        &tmp.path().join("deard.log"),
    );
    let finished = daemon.wait_source_finished(WAIT);
    let seen = probe.collect_until(
        |seen| seen.last().unwrap().sequence + 1 >= finished.published,
        WAIT,
    );
    assert!(daemon.terminate(WAIT).expect("stops").success());
    let counts = daemon.final_counts();
    assert_eq!(counts, finished, "nothing published after the replay");
    assert_eq!(counts.dropped, 0, "--pacing fast never drops");
    let log = daemon.log_text();
    let lost = check_run("probe", &seen, counts, &readable, &expected);
    assert_loss_bound("probe", lost, counts.published);
    for s in &seen {
        let want = flags::ALIGNED | flags::REFINED_NETWORK | flags::CALIBRATION_ONLINE;
        assert_eq!(
            s.flags & want,
            want,
            "frame {} flags {:x}\n{log}",
            s.frame_id,
            s.flags
        );
        assert_eq!(s.flags & flags::REFINED_CLASSICAL, 0);
        assert!(s.bundle.starts_with("edge/"), "bundle name {:?}", s.bundle);
    }
    // The first frame has no estimate yet, so the rough-flow network runs on it. (How often it
    // runs after that depends on whether the untrained fixture's measurements pass the gate.)
    assert_eq!(
        seen[0].sequence, 0,
        "the first frame was overwritten before the probe read it"
    );
    assert_ne!(seen[0].flags & flags::CALIBRATION_ESTIMATED, 0);
}

/// The daemon's default: the network frames run on the background worker. No frame waits for
/// it — the first frame is published without a network measurement, aligned by the factory
/// calibration — and the worker's measurements reach later frames (the replay loops at the
/// capture's 30 fps until one does; an unoptimised test build measures slowly).
#[test]
fn with_the_network_in_the_background_no_frame_waits_and_measurements_arrive() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(
        &tmp.path().join("cap"),
        30,
        W,
        H,
        scene::factory_calibration(),
    );
    let bundle = fixture_bundle();
    let service = unique_service("dear-background");
    let limit = 900;
    let probe = Probe::start(&service, limit);
    let mut daemon = Daemon::spawn(
        deard(
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
        ),
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

/// Two clients get the same stream: the pipeline's output for each frame, in publish order,
/// the same frame and payload for each sequence number both received. Not "every frame": the
/// service may overwrite a slow client's oldest samples, and a client process can be starved
/// on a loaded machine. The probe keeps up (it copies, then hashes on another thread), so the
/// test asserts the loss bound ([`assert_loss_bound`]) and that received + lost = published.
#[test]
fn two_clients_receive_the_frames_in_order_with_the_pipeline_output() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(
        &tmp.path().join("cap"),
        12,
        W,
        H,
        scene::factory_calibration(),
    );
    let expected = expected_payload_hashes(&capture, &Engine::classical().pipeline);
    assert_eq!(expected.len(), 12);
    let readable: Vec<u64> = expected.keys().copied().collect();
    let service = unique_service("two-clients");
    let a = Probe::start(&service, 1000);
    let b = Probe::start(&service, 1000);
    // Fast pacing: the capture queue blocks, so the publisher must send all 12 frames.
    let mut daemon = Daemon::spawn(
        deard(&service, &Engine::classical().replay_fast(capture.root())),
        &tmp.path().join("deard.log"),
    );
    let finished = daemon.wait_source_finished(WAIT);
    let end = |seen: &[Seen]| seen.last().unwrap().sequence + 1 >= finished.published;
    let seen_a = a.collect_until(end, WAIT);
    let seen_b = b.collect_until(end, WAIT);
    let status = daemon.terminate(WAIT).expect("deard stops on SIGTERM");
    assert!(
        status.success(),
        "clean exit on SIGTERM: {status:?}\n{}",
        daemon.log_text()
    );
    let counts = daemon.final_counts();
    assert_eq!(counts, finished, "nothing published after the replay");
    assert_eq!(counts.dropped, 0, "--pacing fast never drops");
    for (who, seen) in [("client a", &seen_a), ("client b", &seen_b)] {
        let lost = check_run(who, seen, counts, &readable, &expected);
        assert_loss_bound(who, lost, counts.published);
        for s in seen.iter() {
            assert_eq!(
                (s.skipped, s.dropped),
                (0, 0),
                "{who}: frame {}",
                s.frame_id
            );
        }
    }
    assert_eq!(seen_a[0].run_id, seen_b[0].run_id, "one publisher");
    let by_sequence: BTreeMap<u64, &Seen> = seen_a.iter().map(|s| (s.sequence, s)).collect();
    for s in &seen_b {
        if let Some(other) = by_sequence.get(&s.sequence) {
            assert_eq!(*other, s, "both clients got sample {}", s.sequence);
        }
    }
}

/// The overflow policy the other tests account for, shown on purpose: a client that reads
/// slower than the daemon publishes loses its own oldest frames, counted exactly by the
/// sequence gaps, and still gets the newest one; the daemon does not wait for it, and a client
/// beside it that keeps up is not disturbed.
#[test]
fn a_slow_client_loses_only_its_own_oldest_frames_and_counts_them() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(
        &tmp.path().join("cap"),
        20,
        W,
        H,
        scene::factory_calibration(),
    );
    let expected = expected_payload_hashes(&capture, &Engine::classical().pipeline);
    assert_eq!(expected.len(), 20);
    let readable: Vec<u64> = expected.keys().copied().collect();
    let service = unique_service("slow-client");
    let fast = Probe::start(&service, 1000);
    // 300 ms a frame: the daemon publishes the 20 frames (a few ms each) long before the slow
    // client could read them, so it must lose some; were the daemon to block for it instead,
    // the replay would take 6 s and nothing would be lost.
    let slow = Probe::start_with_delay(&service, 1000, Duration::from_millis(300));
    let mut daemon = Daemon::spawn(
        deard(&service, &Engine::classical().replay_fast(capture.root())),
        &tmp.path().join("deard.log"),
    );
    let finished = daemon.wait_source_finished(WAIT);
    let end = |seen: &[Seen]| seen.last().unwrap().sequence + 1 >= finished.published;
    let seen_fast = fast.collect_until(end, WAIT);
    let seen_slow = slow.collect_until(end, WAIT);
    assert!(daemon.terminate(WAIT).expect("stops").success());
    let counts = daemon.final_counts();
    assert_eq!(counts, finished, "nothing published after the replay");
    assert_eq!(counts.dropped, 0, "--pacing fast never drops");
    let lost_fast = check_run("fast client", &seen_fast, counts, &readable, &expected);
    assert_loss_bound("fast client", lost_fast, counts.published);
    let lost_slow = check_run("slow client", &seen_slow, counts, &readable, &expected);
    eprintln!("slow client: lost {lost_slow} of {}", counts.published);
    assert!(
        lost_slow > 0,
        "the slow client read all {} frames: the daemon waited for it",
        counts.published
    );
}

/// A client killed mid-stream (SIGKILL: its port and queue are left behind until the daemon's
/// dead-peer cleanup) neither stops the daemon nor the other client's stream: the survivor
/// receives the replay to its last frame, consistent with what the daemon published, within
/// the loss bound. Paced at the capture's 30 fps so the victim dies while frames still come.
#[test]
fn killing_a_client_disturbs_neither_the_daemon_nor_the_other_client() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(
        &tmp.path().join("cap"),
        30,
        W,
        H,
        scene::factory_calibration(),
    );
    let expected = expected_payload_hashes(&capture, &Engine::classical().pipeline);
    assert_eq!(expected.len(), 30);
    let readable: Vec<u64> = expected.keys().copied().collect();
    let service = unique_service("kill-client");
    let survivor = Probe::start(&service, 1000);
    let mut victim = Probe::start(&service, 1000);
    let mut daemon = Daemon::spawn(
        deard(
            &service,
            &[
                "--refine",
                "classical",
                "--pacing",
                "timestamps",
                "--replay",
                capture.root().to_str().unwrap(),
            ],
        ),
        &tmp.path().join("deard.log"),
    );
    let before = victim.collect_until(|seen| seen.len() >= 5, WAIT);
    assert_eq!(before.len(), 5, "the victim receives frames before it dies");
    victim.crash();
    let finished = daemon.wait_source_finished(WAIT);
    let seen = survivor.collect_until(
        |seen| seen.last().unwrap().sequence + 1 >= finished.published,
        WAIT,
    );
    assert!(
        daemon.is_running(),
        "daemon survives a client crash:\n{}",
        daemon.log_text()
    );
    assert!(daemon.terminate(WAIT).expect("stops").success());
    let counts = daemon.final_counts();
    assert_eq!(counts, finished, "nothing published after the replay");
    // Timestamp pacing may drop input frames if the daemon is starved; `check_run` holds
    // them to the daemon's dropped count.
    let lost = check_run("survivor", &seen, counts, &readable, &expected);
    assert_loss_bound("survivor", lost, counts.published);
    // What the victim got before it died was the same stream.
    lost_by_sequence(&before);
    for s in &before {
        assert_eq!(s.run_id, seen[0].run_id, "victim: one publisher");
        assert_eq!(
            s.sha256, expected[&s.frame_id],
            "victim: frame {} content differs from the pipeline's",
            s.frame_id
        );
    }
}

/// A daemon crashed (SIGKILL, stale shared memory left) and started again is picked up by a
/// client that keeps running: the client sees the first run to its last frame, then a new
/// `run_id` whose sequence starts again, each run consistent with what its daemon published.
#[test]
fn a_restarted_daemon_is_picked_up_by_a_running_client() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(
        &tmp.path().join("cap"),
        16,
        W,
        H,
        scene::factory_calibration(),
    );
    let expected = expected_payload_hashes(&capture, &Engine::classical().pipeline);
    assert_eq!(expected.len(), 16);
    let readable: Vec<u64> = expected.keys().copied().collect();
    let service = unique_service("restart");
    let root = capture.root().to_str().unwrap();
    let probe = Probe::start(&service, 1000);
    let args = [
        "--refine",
        "classical",
        "--pacing",
        "fast",
        "--replay",
        root,
    ];
    let mut first = Daemon::spawn(
        deard(&service, &[&args[..], &["--end", "8"]].concat()),
        &tmp.path().join("deard1.log"),
    );
    let finished_first = first.wait_source_finished(WAIT);
    let seen_first = probe.collect_until(
        |seen| seen.last().unwrap().sequence + 1 >= finished_first.published,
        WAIT,
    );
    let first_run = seen_first
        .last()
        .expect("frames of the first daemon")
        .run_id;
    first.crash();
    let mut second = Daemon::spawn(
        deard(&service, &[&args[..], &["--start", "8"]].concat()),
        &tmp.path().join("deard2.log"),
    );
    let finished_second = second.wait_source_finished(WAIT);
    let seen_second = probe.collect_until(
        |seen| {
            let last = seen.last().unwrap();
            last.run_id != first_run && last.sequence + 1 >= finished_second.published
        },
        WAIT,
    );
    assert!(second.terminate(WAIT).expect("stops").success());
    let counts_second = second.final_counts();
    assert_eq!(counts_second, finished_second);

    let all: Vec<Seen> = seen_first.iter().chain(&seen_second).cloned().collect();
    let runs = split_runs(&all);
    assert_eq!(
        runs.len(),
        2,
        "the first daemon's frames, then the second's: {:?}",
        runs.iter()
            .map(|r| (r[0].run_id, r.len()))
            .collect::<Vec<_>>()
    );
    assert_ne!(runs[0][0].run_id, runs[1][0].run_id, "a new run id");
    for counts in [finished_first, counts_second] {
        assert_eq!(
            (counts.published, counts.dropped),
            (8, 0),
            "each daemon publishes its 8 frames (--pacing fast never drops)"
        );
    }
    let lost_first = check_run(
        "first run",
        runs[0],
        finished_first,
        &readable[..8],
        &expected,
    );
    let lost_second = check_run(
        "second run",
        runs[1],
        counts_second,
        &readable[8..],
        &expected,
    );
    assert_loss_bound("first run", lost_first, finished_first.published);
    assert_loss_bound("second run", lost_second, counts_second.published);
}

/// Unreadable input frames are skipped, counted in every later header and named in the log;
/// the daemon publishes every other frame, in order (fast pacing: nothing dropped).
#[test]
fn bad_frames_are_skipped_counted_and_named() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = scene::write_capture(
        &tmp.path().join("cap"),
        10,
        W,
        H,
        scene::factory_calibration(),
    );
    // A corrupt PNG, a missing file and a frame of the wrong resolution.
    let corrupt = capture.frame_paths(2).rgb;
    let bytes = std::fs::read(&corrupt).unwrap();
    std::fs::write(&corrupt, &bytes[..bytes.len() / 3]).unwrap();
    let missing = capture.frame_paths(5).amplitude;
    std::fs::remove_file(&missing).unwrap();
    let wrong_size = capture.frame_paths(7).depth;
    let small = ndarray::Array2::<f32>::from_elem((H as usize / 2, W as usize / 2), 1.0);
    dear_capture::png::write_depth(&wrong_size, small.view(), 0.001).unwrap();
    let expected = expected_payload_hashes(&capture, &Engine::classical().pipeline);
    let readable: Vec<u64> = expected.keys().copied().collect();
    assert_eq!(readable, vec![0, 1, 3, 4, 6, 8, 9]);
    let bad = [2u64, 5, 7];

    let service = unique_service("bad-frames");
    let probe = Probe::start(&service, 1000);
    let mut daemon = Daemon::spawn(
        deard(&service, &Engine::classical().replay_fast(capture.root())),
        &tmp.path().join("deard.log"),
    );
    let finished = daemon.wait_source_finished(WAIT);
    let seen = probe.collect_until(
        |seen| seen.last().unwrap().sequence + 1 >= finished.published,
        WAIT,
    );
    assert!(daemon.is_running(), "bad frames never stop the daemon");
    assert!(daemon.terminate(WAIT).expect("stops").success());
    let counts = daemon.final_counts();
    assert_eq!(counts, finished, "nothing published after the replay");
    assert_eq!(
        (counts.published, counts.skipped, counts.dropped),
        (7, 3, 0),
        "the good frames published, the bad ones skipped"
    );
    let lost = check_run("probe", &seen, counts, &readable, &expected);
    assert_loss_bound("probe", lost, counts.published);
    // Skip reports pass the (blocking) capture queue in order with the frames, so each header
    // counts exactly the bad frames before it; the last frame always arrives.
    for s in &seen {
        let before = bad.iter().filter(|&&b| b < s.frame_id).count() as u64;
        assert_eq!(
            s.skipped, before,
            "frame {}: skipped frames are counted in the header",
            s.frame_id
        );
    }
    assert_eq!(seen.last().unwrap().skipped, 3);
    let log = daemon.log_text();
    for path in [&corrupt, &missing, &wrong_size] {
        assert!(
            log.contains(&*path.to_string_lossy()),
            "log names {}:\n{log}",
            path.display()
        );
    }
}

/// `check_run` on made-up streams: it accepts client-side loss and counted capture drops, and
/// fails on each publisher-side fault the process tests exist to catch.
#[test]
fn the_stream_check_fails_on_publisher_faults_and_accepts_client_loss() {
    let readable: Vec<u64> = (0..6).collect();
    let expected: BTreeMap<u64, String> = readable.iter().map(|&i| (i, format!("h{i}"))).collect();
    let frame = |sequence: u64, frame_id: u64| Seen {
        frame_id,
        run_id: 0x5eed,
        sequence,
        skipped: 0,
        dropped: 0,
        sha256: format!("h{frame_id}"),
        flags: 0,
        bundle: "-".into(),
    };
    let counts = |published, dropped| Counts {
        published,
        skipped: 0,
        dropped,
    };
    let check = |frames: Vec<Seen>, counts: Counts| {
        std::panic::catch_unwind(|| check_run("made up", &frames, counts, &readable, &expected))
    };
    // Accepted: everything; client loss (first and middle samples); a dropped input frame
    // that the daemon counted.
    let all: Vec<Seen> = (0..6).map(|i| frame(i, i)).collect();
    assert_eq!(check(all.clone(), counts(6, 0)).ok(), Some(0));
    let gaps = vec![frame(1, 1), frame(4, 4), frame(5, 5)];
    assert_eq!(check(gaps, counts(6, 0)).ok(), Some(3));
    let counted_drop = vec![frame(0, 0), frame(1, 1), frame(2, 3), frame(4, 5)];
    assert_eq!(check(counted_drop, counts(5, 1)).ok(), Some(1));

    let mut wrong_payload = all.clone();
    wrong_payload[3].sha256 = "h4".into();
    let faults: Vec<(&str, Vec<Seen>, Counts)> = vec![
        ("wrong payload", wrong_payload, counts(6, 0)),
        (
            "samples reordered on the way",
            vec![frame(0, 0), frame(2, 2), frame(1, 1), frame(5, 5)],
            counts(6, 0),
        ),
        (
            "a sample delivered twice",
            vec![frame(0, 0), frame(1, 1), frame(1, 1), frame(5, 5)],
            counts(6, 0),
        ),
        (
            "frames published out of order",
            vec![frame(0, 1), frame(1, 0), frame(5, 5)],
            counts(6, 0),
        ),
        (
            "a frame published twice",
            vec![frame(0, 0), frame(1, 0), frame(6, 5)],
            counts(7, 0),
        ),
        (
            "a frame lost by the publisher, uncounted",
            vec![frame(0, 0), frame(1, 1), frame(2, 3), frame(4, 5)],
            counts(5, 0),
        ),
        (
            "more published than the client can account for",
            vec![frame(0, 0), frame(4, 4)],
            counts(6, 0),
        ),
        (
            "a frame id that is not in the replay",
            vec![frame(0, 0), frame(5, 9)],
            counts(6, 0),
        ),
    ];
    for (fault, frames, counts) in faults {
        assert!(check(frames, counts).is_err(), "not caught: {fault}");
    }
}
