//! The real `deard` binary under hostile input: it stops promptly on SIGTERM whatever it is
//! waiting for, and a replay with nothing readable in it is an error, not a spin or a silent
//! success.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use dear_capture::{CaptureDir, FramePaths};
use dear_test_support::capture::write_demo_copies;
use dear_test_support::daemon::Daemon;
use dear_test_support::paths::demo_capture;
use dear_test_support::process::unique_service;

/// Generous bound for a liveness check (the daemon polls its shutdown flag every 100 ms).
const STOP_WITHIN: Duration = Duration::from_secs(5);

/// `deard --service <service> --refine none --replay <capture> <args…>`, its log in `log`.
fn start(service: &str, capture: &Path, args: &[&str], log: &Path) -> Daemon {
    start_with_env(service, capture, args, log, &[])
}

/// [`start`] with extra environment variables.
fn start_with_env(
    service: &str,
    capture: &Path,
    args: &[&str],
    log: &Path,
    env: &[(&str, &Path)],
) -> Daemon {
    let mut command = Command::new(env!("CARGO_BIN_EXE_deard"));
    command
        .args(["--service", service, "--refine", "none", "--replay"])
        .arg(capture)
        .args(args)
        .envs(env.iter().copied());
    Daemon::spawn(command, log)
}

#[test]
fn sigterm_stops_a_replay_waiting_for_a_distant_timestamp() {
    let tmp = tempfile::tempdir().unwrap();
    // The second frame is due an hour after the first: the capture thread waits for it.
    let capture = write_demo_copies(
        &tmp.path().join("cap"),
        &[(0, true), (3_600_000_000_000, true)],
    );
    let mut daemon = start(
        &unique_service("sigterm-pacing"),
        &capture,
        &["--pacing", "timestamps", "--stats-interval", "0.05"],
        &tmp.path().join("deard.log"),
    );
    daemon.wait_for_log("serving", Duration::from_secs(60));
    // The first frame published: the capture thread has handed it over and waits for the
    // second.
    daemon.wait_for_counts("the first frame published", Duration::from_secs(60), |c| {
        c.published >= 1
    });
    let sent = Instant::now();
    daemon.signal(libc::SIGTERM);
    let status = daemon.wait(STOP_WITHIN).unwrap_or_else(|| {
        panic!(
            "deard still running {STOP_WITHIN:?} after SIGTERM:\n{}",
            daemon.log_text()
        )
    });
    assert!(
        status.success(),
        "clean exit on SIGTERM: {status}\n{}",
        daemon.log_text()
    );
    assert!(
        daemon.log_text().contains("stopped"),
        "{}",
        daemon.log_text()
    );
    assert!(sent.elapsed() < STOP_WITHIN);
}

#[test]
fn a_looping_replay_with_no_readable_frame_stops_with_an_error_instead_of_spinning() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = write_demo_copies(&tmp.path().join("cap"), &[(0, false), (33_000_000, false)]);
    let mut daemon = start(
        &unique_service("loop-all-bad"),
        &capture,
        &["--loop", "--pacing", "fast"],
        &tmp.path().join("deard.log"),
    );
    let status = daemon.wait(Duration::from_secs(30)).unwrap_or_else(|| {
        let log = daemon.log_text();
        panic!(
            "deard kept looping over unreadable frames ({} log lines):\n{}",
            log.lines().count(),
            log.lines().take(20).collect::<Vec<_>>().join("\n")
        )
    });
    let log = daemon.log_text();
    assert!(!status.success(), "an error exit: {status}\n{log}");
    assert!(log.contains("no readable frame"), "{log}");
    assert!(
        log.lines().count() < 50,
        "a few lines, not a flood: {} lines",
        log.lines().count()
    );
}

#[test]
fn a_replay_with_no_readable_frame_exits_non_zero() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = write_demo_copies(&tmp.path().join("cap"), &[(0, false), (33_000_000, false)]);
    // With and without exit_when_done: a service with nothing to serve is a failure either way.
    for (name, args) in [
        (
            "all-bad-exit",
            &["--pacing", "fast", "--exit-when-done"][..],
        ),
        ("all-bad-stay", &["--pacing", "fast"][..]),
    ] {
        let log = tmp.path().join(format!("{name}.log"));
        let mut daemon = start(&unique_service(name), &capture, args, &log);
        let status = daemon.wait(Duration::from_secs(30)).unwrap_or_else(|| {
            panic!(
                "{name}: deard kept running with nothing to serve:\n{}",
                daemon.log_text()
            )
        });
        let log = daemon.log_text();
        assert!(!status.success(), "{name}: an error exit: {status}\n{log}");
        assert!(log.contains("no readable frame"), "{name}: {log}");
        assert!(
            log.contains("000000.depth.png"),
            "{name}: names the file: {log}"
        );
    }
}

#[test]
fn a_looping_replay_with_some_readable_frames_keeps_serving() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = write_demo_copies(
        &tmp.path().join("cap"),
        &[(0, false), (33_000_000, true), (66_000_000, false)],
    );
    let mut daemon = start(
        &unique_service("loop-some-bad"),
        &capture,
        &[
            "--loop",
            "--pacing",
            "timestamps",
            "--stats-interval",
            "0.05",
        ],
        &tmp.path().join("deard.log"),
    );
    daemon.wait_for_log("serving", Duration::from_secs(60));
    // Its one readable frame published three times: the replay went past the capture's end
    // (where one with no readable frame stops) twice.
    daemon.wait_for_counts(
        "three passes over the capture (published=3)",
        Duration::from_secs(60),
        |c| c.published >= 3,
    );
    assert!(
        daemon.wait(Duration::ZERO).is_none(),
        "still serving:\n{}",
        daemon.log_text()
    );
    daemon.signal(libc::SIGTERM);
    let status = daemon.wait(STOP_WITHIN).expect("stops on SIGTERM");
    assert!(status.success(), "{status}\n{}", daemon.log_text());
}

/// One daemon per service: a second one refuses to start, naming the first one's process, and
/// the first keeps serving; once the first is killed (its publisher left behind in shared
/// memory), a new one cleans up after it and serves.
#[test]
fn a_second_daemon_on_the_same_service_refuses_to_start() {
    let tmp = tempfile::tempdir().unwrap();
    let service = unique_service("single-instance");
    let mut first = start(
        &service,
        &demo_capture(),
        &["--loop"],
        &tmp.path().join("first.log"),
    );
    first.wait_for_log("serving", Duration::from_secs(60));
    let mut second = start(
        &service,
        &demo_capture(),
        &["--loop"],
        &tmp.path().join("second.log"),
    );
    let status = second
        .wait(Duration::from_secs(60))
        .unwrap_or_else(|| panic!("the second deard kept running:\n{}", second.log_text()));
    assert!(!status.success(), "{status}\n{}", second.log_text());
    let log = second.log_text();
    assert!(
        log.contains("another process already publishes")
            && log.contains(&format!("pid {}", first.child.id())),
        "{log}"
    );
    assert!(
        matches!(first.child.try_wait(), Ok(None)),
        "the first deard keeps serving:\n{}",
        first.log_text()
    );

    first.signal(libc::SIGKILL);
    first.wait(STOP_WITHIN).expect("killed");
    let mut third = start(
        &service,
        &demo_capture(),
        &["--loop"],
        &tmp.path().join("third.log"),
    );
    // Serving proves the killed daemon's publisher no longer counts. (Who removed it is not
    // asserted: any iceoryx2 node created meanwhile — a client, another test's daemon — cleans
    // up dead nodes too.)
    third.wait_for_log("serving", Duration::from_secs(60));
    third.signal(libc::SIGTERM);
    assert!(third.wait(STOP_WITHIN).expect("stops").success());
}

/// Under systemd (`Type=notify`, `WatchdogSec=`) the daemon says when it is ready and pings the
/// watchdog from its frame loop at half the period systemd gives it; stopping, it says so.
/// systemd is played by a datagram socket in `NOTIFY_SOCKET`, as the protocol defines it.
#[test]
fn the_daemon_notifies_systemd_and_pings_its_watchdog() {
    use std::os::unix::net::UnixDatagram;
    let tmp = tempfile::tempdir().unwrap();
    let socket_path = tmp.path().join("notify.sock");
    let socket = UnixDatagram::bind(&socket_path).unwrap();
    socket
        .set_read_timeout(Some(Duration::from_secs(60)))
        .unwrap();
    let log = tmp.path().join("deard.log");
    let mut command = Command::new(env!("CARGO_BIN_EXE_deard"));
    command
        .args(["--service", &unique_service("watchdog"), "--refine", "none"])
        .arg("--replay")
        .arg(demo_capture())
        .arg("--loop")
        .env("NOTIFY_SOCKET", &socket_path)
        // A 0.4 s watchdog: pings every 0.2 s.
        .env("WATCHDOG_USEC", "400000");
    let mut daemon = Daemon::spawn(command, &log);
    let mut buf = [0u8; 4096];
    let mut receive = || {
        let n = socket.recv(&mut buf).expect("a notification");
        String::from_utf8_lossy(&buf[..n]).into_owned()
    };
    let first = receive();
    assert!(first.contains("READY=1"), "{first:?}");
    let start = Instant::now();
    let mut pings = 0;
    while pings < 10 {
        let message = receive();
        assert!(message.contains("WATCHDOG=1"), "{message:?}");
        pings += 1;
    }
    // Ten pings at 0.2 s take about 2 s; far fewer than 20 s, or the pings are not periodic.
    let elapsed = start.elapsed();
    assert!(elapsed < Duration::from_secs(20), "{elapsed:?}");
    daemon.signal(libc::SIGTERM);
    loop {
        let message = receive();
        if message.contains("STOPPING=1") {
            break;
        }
        assert!(message.contains("WATCHDOG=1"), "{message:?}");
    }
    assert!(daemon.child.wait().unwrap().success());
}

/// What a crashed daemon left in shared memory is removed when the next one starts, and the
/// log says so (it said `cleanups: 0`: iceoryx2's own cleanup inside node creation had already
/// removed everything and reported nothing). The daemons use an iceoryx2 root of their own
/// (`DEAR_IOX2_ROOT`), so no other process on the machine cleans up first.
#[test]
fn the_cleanup_after_a_crashed_daemon_is_reported() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("iceoryx2");
    let env = [("DEAR_IOX2_ROOT", root.as_path())];
    let service = unique_service("cleanup-report");
    let mut crashed = start_with_env(
        &service,
        &demo_capture(),
        &["--loop"],
        &tmp.path().join("crashed.log"),
        &env,
    );
    crashed.wait_for_log("serving", Duration::from_secs(60));
    assert!(
        !crashed
            .log_text()
            .contains("removed the shared-memory resources"),
        "nothing to remove in a fresh root:\n{}",
        crashed.log_text()
    );
    crashed.signal(libc::SIGKILL);
    crashed.wait(STOP_WITHIN).expect("killed");
    let mut next = start_with_env(
        &service,
        &demo_capture(),
        &["--loop"],
        &tmp.path().join("next.log"),
        &env,
    );
    next.wait_for_log("serving", Duration::from_secs(60));
    let log = next.log_text();
    assert!(
        log.lines().any(|l| {
            l.contains("removed the shared-memory resources of dead processes (at start)")
                && l.contains("processes=1")
        }),
        "{log}"
    );
    next.signal(libc::SIGTERM);
    assert!(next.wait(STOP_WITHIN).expect("stops").success());
}

/// A log that cannot be written (stderr on a full disk: `/dev/full` fails every write with
/// ENOSPC) does not stop the daemon: it serves the whole replay and exits cleanly. (Before,
/// tracing reported the failed write with `eprintln!`, which panicked: exit status 101.)
#[test]
fn a_full_disk_under_the_log_does_not_stop_the_daemon() {
    let status = Command::new(env!("CARGO_BIN_EXE_deard"))
        .args([
            "--service",
            &unique_service("full-disk"),
            "--refine",
            "none",
        ])
        .arg("--replay")
        .arg(demo_capture())
        .args([
            "--pacing",
            "fast",
            "--exit-when-done",
            "--stats-interval",
            "0.01",
        ])
        .env("RUST_LOG", "debug")
        .stdout(Stdio::null())
        .stderr(File::create("/dev/full").expect("/dev/full"))
        .status()
        .expect("run deard");
    assert!(status.success(), "{status}");
}

/// Issue 34: a FIFO in place of a frame's PNG is a skipped frame naming the file, not a daemon
/// blocked in `open` (SIGTERM was ignored; only SIGKILL ended it); the other frames are served.
#[test]
fn a_fifo_as_a_frame_file_is_skipped_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = write_demo_copies(&tmp.path().join("cap"), &[(0, true), (1, true), (2, true)]);
    let rgb = FramePaths::new(&capture, 1).rgb;
    std::fs::remove_file(&rgb).unwrap();
    let status = Command::new("mkfifo").arg(&rgb).status().unwrap();
    assert!(status.success());
    let log = tmp.path().join("deard.log");
    let mut daemon = start(
        &unique_service("fifo-frame"),
        &capture,
        &["--pacing", "fast", "--exit-when-done"],
        &log,
    );
    let status = daemon.wait(Duration::from_secs(30));
    let text = daemon.log_text();
    assert!(status.is_some_and(|s| s.success()), "{status:?}: {text}");
    assert!(
        text.contains("frame skipped")
            && text.contains("000001.rgb.png")
            && text.contains("a FIFO"),
        "{text}"
    );
    assert!(text.contains("published=2"), "{text}");
}

/// Issue 34: `--record` onto a disk that fills up says so at once, naming the file, leaves a
/// recording that replays up to the last whole frame (its capture.json written), serves on,
/// and exits non-zero. Needs root to mount a 3 MB tmpfs; CI runs as root.
#[test]
fn a_recording_that_fills_its_disk_fails_loudly_and_replays() {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("not root: cannot mount a small tmpfs; not checked");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let mnt = tmp.path().join("small");
    std::fs::create_dir(&mnt).unwrap();
    let mounted = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=3m", "tmpfs"])
        .arg(&mnt)
        .status()
        .unwrap();
    assert!(mounted.success(), "mount a tmpfs");
    struct Unmount(PathBuf);
    impl Drop for Unmount {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(&self.0).status();
        }
    }
    let _unmount = Unmount(mnt.clone());
    let rec = mnt.join("rec");
    let log = tmp.path().join("deard.log");
    let mut daemon = start(
        &unique_service("record-enospc"),
        &demo_capture(),
        &["--loop", "--record", rec.to_str().unwrap()],
        &log,
    );
    // Said while the daemon still serves, not at shutdown.
    daemon.wait_for_log("the recording stopped", Duration::from_secs(120));
    daemon.wait_for_log(
        "wrote the manifest of the frames recorded before the error",
        STOP_WITHIN,
    );
    let text = daemon.log_text();
    assert!(
        text.contains("No space left on device") && text.contains(rec.to_str().unwrap()),
        "{text}"
    );
    assert!(
        daemon.child.try_wait().unwrap().is_none(),
        "still serving: {text}"
    );
    let recorded = CaptureDir::open(&rec).expect("the partial recording opens");
    assert!(!recorded.is_empty());
    for k in 0..recorded.len() {
        recorded.read_frame(k).expect("every listed frame is whole");
    }
    daemon.signal(libc::SIGTERM);
    let status = daemon.wait(STOP_WITHIN).expect("deard stops on SIGTERM");
    let text = daemon.log_text();
    assert!(
        !status.success(),
        "a failed recording is a failed run: {text}"
    );
    assert!(text.contains("--record"), "{text}");
}
