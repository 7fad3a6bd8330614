//! `dear record --mcap` end to end: `deard` replays `samples/demo`, the real `dear` binary
//! records it, and the file is read back by a reader nobody here wrote — the `mcap` Python
//! package with `mcap-protobuf-support` (`tests/scripts/read_mcap.py`, in the project's
//! `.venv`, installed by `scripts/setup.sh` from `train/`'s dev extras). The calibration
//! channel must hold the capture's intrinsics, which deard puts in every frame header (format
//! 3), unless `--intrinsics` overrides them.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::Duration;

use dear_test_support::daemon::Daemon;
use dear_test_support::paths::{binary, demo_capture};
use dear_test_support::process::{unique_service, wait_until};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The venv's Python with the `mcap` packages; fails (never skips) when they are missing.
fn python() -> PathBuf {
    let python = root().join(".venv/bin/python");
    assert!(
        python.is_file(),
        "{} not found: run scripts/setup.sh (it creates .venv with the test dependencies, \
         among them the mcap reader this test needs)",
        python.display()
    );
    let check = Command::new(&python)
        .args(["-c", "import mcap.reader, mcap_protobuf.decoder, numpy"])
        .output()
        .expect("run the venv's python");
    assert!(
        check.status.success(),
        "the mcap reader is not installed in .venv: run scripts/setup.sh (train/ dev extras: \
         mcap, mcap-protobuf-support)\n{}",
        String::from_utf8_lossy(&check.stderr)
    );
    python
}

/// `deard` replaying `samples/demo` in a loop with the classical engine, on `service` under a
/// private iceoryx2 root. (Its frames have every pixel valid, with `--refine none` too, so the
/// valid-pixel comparison of read_mcap.py is a weak check on this capture.)
fn start_daemon(service: &str, iox_root: &Path, log: &Path) -> Daemon {
    let mut command = Command::new(binary("deard"));
    command
        .args([
            "--service",
            service,
            "--refine",
            "classical",
            "--loop",
            "--replay",
        ])
        .arg(demo_capture())
        .env("DEAR_IOX2_ROOT", iox_root);
    Daemon::spawn(command, log)
}

fn record_command(service: &str, iox_root: &Path, file: &Path, extra: &[&str]) -> Command {
    let mut cmd = Command::new(binary("dear"));
    cmd.args([
        "record",
        "--service",
        service,
        "--timeout-s",
        "60",
        "--mcap",
    ])
    .arg(file)
    .args(extra)
    .env("DEAR_IOX2_ROOT", iox_root);
    cmd
}

fn show(what: &str, out: &Output) -> String {
    format!(
        "{what}: {}\n--- stdout\n{}--- stderr\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Runs `tests/scripts/read_mcap.py` on `file`; panics with its output if a check fails.
fn read_back(python: &Path, file: &Path, service: &str, extra: &[&str]) {
    let prefix = format!("/{}", service.strip_suffix("/frames").unwrap());
    let out = Command::new(python)
        .arg(root().join("tests/scripts/read_mcap.py"))
        .arg(file)
        .args(["--prefix", &prefix, "--capture"])
        .arg(root().join("samples/demo/capture.json"))
        .args(extra)
        .output()
        .expect("run read_mcap.py");
    let text = show("read_mcap.py", &out);
    println!("{text}");
    assert!(out.status.success(), "{text}");
}

#[test]
fn ten_recorded_frames_read_back_with_the_mcap_package() {
    let python = python();
    let tmp = tempfile::tempdir().unwrap();
    let iox_root = tmp.path().join("iox2");
    let service = unique_service("record_mcap");
    let mut daemon = start_daemon(&service, &iox_root, &tmp.path().join("deard.log"));

    let file = tmp.path().join("x.mcap");
    let out = record_command(&service, &iox_root, &file, &["--count", "10"])
        .output()
        .expect("run dear record");
    let text = show("dear record --count 10", &out);
    println!("{text}");
    assert!(
        out.status.success(),
        "{text}\ndeard log:\n{}",
        daemon.log_text()
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("recorded 10 frames") && stdout.contains("lost "),
        "{text}"
    );
    read_back(&python, &file, &service, &["--frames", "10"]);

    // The metres encoding: the published f32 depth as it is.
    let file = tmp.path().join("metres.mcap");
    let out = record_command(
        &service,
        &iox_root,
        &file,
        &[
            "--count",
            "3",
            "--depth-encoding",
            "32FC1",
            "--intrinsics",
            "500,510,160,120",
        ],
    )
    .output()
    .expect("run dear record");
    let text = show("dear record --depth-encoding 32FC1", &out);
    assert!(out.status.success(), "{text}");
    read_back(
        &python,
        &file,
        &service,
        &[
            "--frames",
            "3",
            "--depth-encoding",
            "32FC1",
            // --intrinsics overrides the headers' (the capture's): read_mcap.py expects these.
            "--intrinsics",
            "500,510,160,120",
        ],
    );

    // The file exists now: a second recording must not overwrite it, and says so.
    let out = record_command(&service, &iox_root, &file, &["--count", "1"])
        .output()
        .expect("run dear record");
    let text = show("dear record onto an existing file", &out);
    assert!(!out.status.success(), "{text}");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains(&file.display().to_string()),
        "{text}"
    );

    assert!(daemon.is_running(), "deard died:\n{}", daemon.log_text());
    daemon.terminate(Duration::from_secs(10));
}

#[test]
fn sigterm_ends_an_open_recording_with_a_finished_file() {
    let python = python();
    let tmp = tempfile::tempdir().unwrap();
    let iox_root = tmp.path().join("iox2");
    let service = unique_service("record_mcap_sigterm");
    let mut daemon = start_daemon(&service, &iox_root, &tmp.path().join("deard.log"));

    let file = tmp.path().join("open.mcap");
    let child = record_command(&service, &iox_root, &file, &[])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn dear record");
    // Until a few frames are in: the file grows past its header once the first chunk is out.
    wait_until(
        "the recording to grow past 64 KiB",
        Duration::from_secs(60),
        || std::fs::metadata(&file).map(|m| m.len()).unwrap_or(0) >= 64 * 1024,
        || daemon.log_text(),
    );
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    let out = child.wait_with_output().expect("wait for dear record");
    let text = show("dear record stopped by SIGTERM", &out);
    println!("{text}");
    // Without --count or --seconds a signal is the normal end: exit 0.
    assert!(out.status.success(), "{text}");
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("recorded "),
        "{text}"
    );
    read_back(&python, &file, &service, &["--at-least", "1"]);
    daemon.terminate(Duration::from_secs(10));
}
