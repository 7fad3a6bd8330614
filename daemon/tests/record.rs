//! `deard --record DIR`: a real daemon replaying `samples/demo` writes what it read as a capture
//! directory, and that recording holds the same sensor frames, bit for bit, with the source's
//! intrinsics and calibration. (A live module's recording is checked in the V4L2 VM test,
//! `scripts/test-v4l2-vm.sh --deard`: replaying it gives exactly the depth that was fed.)

use std::process::Command;

use dear_capture::CaptureDir;
use dear_test_support::process::unique_service;

#[test]
fn a_recording_of_a_replay_holds_the_same_sensor_frames() {
    let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo");
    let tmp = tempfile::tempdir().unwrap();
    let rec = tmp.path().join("recording");
    let out = Command::new(env!("CARGO_BIN_EXE_deard"))
        .args([
            "--replay",
            demo,
            "--refine",
            "none",
            "--pacing",
            "fast",
            "--exit-when-done",
        ])
        .args(["--end", "6", "--record", rec.to_str().unwrap()])
        .args(["--service", &unique_service("record")])
        .output()
        .expect("run deard");
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("recording finished"), "{log}");

    let original = CaptureDir::open(demo).unwrap();
    let recorded = CaptureDir::open(&rec).unwrap();
    assert_eq!(recorded.len(), 6);
    let (o, r) = (original.manifest(), recorded.manifest());
    assert_eq!((r.width, r.height), (o.width, o.height));
    assert_eq!(r.intrinsics, o.intrinsics);
    assert_eq!(r.initial_calibration, o.initial_calibration);
    assert_eq!(r.depth_scale, o.depth_scale);
    for k in 0..6 {
        let (a, b) = (
            original.read_frame(k).unwrap(),
            recorded.read_frame(k).unwrap(),
        );
        assert_eq!(a.rgb, b.rgb, "frame {k} rgb");
        assert_eq!(a.depth, b.depth, "frame {k} depth");
        assert_eq!(a.amplitude, b.amplitude, "frame {k} amplitude");
        assert_eq!(a.timestamp_ns, b.timestamp_ns, "frame {k} timestamp");
    }
}

#[test]
fn a_record_directory_with_files_in_it_stops_the_daemon_naming_it() {
    let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo");
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("precious.txt"), "keep").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_deard"))
        .args(["--replay", demo, "--refine", "none", "--exit-when-done"])
        .args(["--record", tmp.path().to_str().unwrap()])
        .args(["--service", &unique_service("record-busy")])
        .output()
        .expect("run deard");
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{log}");
    assert!(
        log.contains("--record") && log.contains("files in it"),
        "{log}"
    );
    assert_eq!(
        std::fs::read_to_string(tmp.path().join("precious.txt")).unwrap(),
        "keep"
    );
}

/// Depth beyond a capture's unambiguous range (one modulation frequency: `c / 2f`) is no
/// measurement: the daemon marks it invalid as the frame arrives — the recording, which holds
/// what is processed, has exactly those pixels invalid and every other one as it was — and
/// counts it in its log.
#[test]
fn depth_beyond_the_unambiguous_range_is_marked_invalid_and_counted() {
    use dear_capture::FramePaths;

    const FRAMES: usize = 3;
    // 50 MHz: 2.998 m, through the middle of the demo scene's depths (0.02 .. 7.4 m).
    const MODULATION_HZ: f64 = 50e6;
    let range_m = (299_792_458.0 / (2.0 * MODULATION_HZ)) as f32;
    let demo = CaptureDir::open(concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo")).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let capture = tmp.path().join("capture");
    std::fs::create_dir_all(capture.join("frames")).unwrap();
    let mut manifest = demo.manifest().clone();
    manifest.frames.truncate(FRAMES);
    manifest.modulation_frequencies_hz = vec![MODULATION_HZ];
    for k in 0..FRAMES {
        let (from, to) = (
            demo.frame_paths(k),
            FramePaths::new(&capture, manifest.frames[k].id),
        );
        for (a, b) in [
            (&from.rgb, &to.rgb),
            (&from.amplitude, &to.amplitude),
            (&from.depth, &to.depth),
        ] {
            std::fs::copy(a, b).unwrap();
        }
    }
    std::fs::write(
        capture.join("capture.json"),
        serde_json::to_string_pretty(&manifest).unwrap(),
    )
    .unwrap();

    let rec = tmp.path().join("recording");
    let out = Command::new(env!("CARGO_BIN_EXE_deard"))
        .arg("--replay")
        .arg(&capture)
        .args(["--refine", "none", "--pacing", "fast", "--exit-when-done"])
        .args(["--record", rec.to_str().unwrap()])
        .args(["--service", &unique_service("beyond-range")])
        .output()
        .expect("run deard");
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    assert!(
        log.contains("depth beyond the module's range is marked invalid") && log.contains("50 MHz"),
        "the limit and where it comes from are logged: {log}"
    );

    let original = CaptureDir::open(&capture).unwrap();
    let recorded = CaptureDir::open(&rec).unwrap();
    assert_eq!(recorded.len(), FRAMES);
    let mut beyond = 0;
    for k in 0..FRAMES {
        let (a, b) = (
            original.read_frame(k).unwrap(),
            recorded.read_frame(k).unwrap(),
        );
        for ((&da, &db), (&aa, &ab)) in a
            .depth
            .iter()
            .zip(&b.depth)
            .zip(a.amplitude.iter().zip(&b.amplitude))
        {
            if da > range_m {
                beyond += 1;
                assert_eq!(
                    (db, ab),
                    (0.0, 0.0),
                    "frame {k}: {da} m is beyond {range_m} m"
                );
            } else {
                assert_eq!(
                    (db, ab),
                    (da, aa),
                    "frame {k}: {da} m is within {range_m} m"
                );
            }
        }
    }
    assert!(
        beyond > 10_000,
        "the test scene reaches beyond the range: {beyond} pixels"
    );
    let stopped = log
        .lines()
        .find(|l| l.contains("stopped"))
        .unwrap_or_else(|| panic!("no 'stopped' line: {log}"));
    assert!(
        stopped.contains(&format!("depth_beyond_range_pixels={beyond}"))
            && stopped.contains(&format!("depth_beyond_range_frames={FRAMES}")),
        "{stopped}"
    );
}
