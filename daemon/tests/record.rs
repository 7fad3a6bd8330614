//! `deard --record DIR`: a real daemon replaying `samples/demo` writes what it read as a capture
//! directory, and that recording holds the same sensor frames, bit for bit, with the source's
//! intrinsics and calibration. (A live module's recording is checked in the V4L2 VM test,
//! `scripts/test-v4l2-vm.sh --deard`: replaying it gives exactly the depth that was fed.)

use std::process::Command;

use dear_pipeline::capture::CaptureDir;

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
        .args([
            "--service",
            &format!("dear-test/{}/record/frames", std::process::id()),
        ])
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
        .args([
            "--service",
            &format!("dear-test/{}/record-busy/frames", std::process::id()),
        ])
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
