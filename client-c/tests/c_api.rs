//! The C API from C: `examples/receive.c` and `tests/c_api.c` are compiled with the system `cc`
//! against this crate's `libdear_client.a` and run against a real `deard`, each test with its
//! own service under one private iceoryx2 root (`DEAR_IOX2_ROOT` in a temporary directory).
//!
//! The tests build the static library themselves (`cargo build -p dear-client-c` with the cargo
//! that runs them: a no-op when it is fresh), since cargo builds a library without an rlib
//! for no integration test. `deard` is another package's binary: the tests use
//! target/<profile>/deard when it is there (`cargo test --workspace` builds it) and otherwise
//! build it with `cargo build -p deard` first.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use dear_test_support::daemon::Daemon;
use dear_test_support::paths::{bin_dir, demo_capture};
use dear_test_support::process::{unique_service, wait_exit};

/// What the static library needs from the system (`cargo rustc -p dear-client-c --release --
/// --print native-static-libs`; the same list is in the README and the header).
const NATIVE_LIBS: &[&str] = &[
    "-lgcc_s",
    "-lutil",
    "-lrt",
    "-lpthread",
    "-lm",
    "-ldl",
    "-lc",
];

fn crate_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Builds a package with the cargo that runs these tests, in this test's profile.
fn cargo_build(package: &str) {
    let mut command = Command::new(env!("CARGO"));
    command.args(["build", "--quiet", "-p", package]);
    if bin_dir().file_name().is_some_and(|n| n == "release") {
        command.arg("--release");
    }
    let status = command
        .current_dir(crate_dir())
        .status()
        .expect("run cargo build");
    assert!(status.success(), "cargo build -p {package} failed");
}

/// The workspace's `deard`, built first when missing.
fn deard() -> &'static Path {
    static DEARD: OnceLock<PathBuf> = OnceLock::new();
    DEARD.get_or_init(|| {
        let path = bin_dir().join("deard");
        if !path.is_file() {
            eprintln!("{} missing: cargo build -p deard", path.display());
            cargo_build("deard");
        }
        assert!(path.is_file(), "{} not built", path.display());
        path
    })
}

/// The iceoryx2 root of every process of these tests, daemons and C programs alike: a
/// temporary directory (removed when the test process exits normally), set once as this
/// process's `DEAR_IOX2_ROOT` too, for the Rust SDK's client.
fn iox2_root() -> &'static Path {
    static ROOT: OnceLock<tempfile::TempDir> = OnceLock::new();
    ROOT.get_or_init(|| {
        let dir = tempfile::tempdir().expect("temporary directory");
        // Set before any client of this process exists: every test calls this first, and
        // the others wait here until it is done.
        std::env::set_var(dear_proto::IOX2_ROOT_ENV, dir.path().join("iceoryx2"));
        dir
    })
    .path()
}

/// This crate's static library, built now: `cargo test` builds a library without an rlib
/// for no test (the integration tests cannot link it), so it would be missing or stale.
fn static_library() -> &'static Path {
    static LIBRARY: OnceLock<PathBuf> = OnceLock::new();
    LIBRARY.get_or_init(|| {
        cargo_build("dear-client-c");
        let path = bin_dir().join("libdear_client.a");
        assert!(path.is_file(), "{} not built", path.display());
        path
    })
}

/// A C source of this crate compiled against the static library, once per test process.
fn c_program(source: &'static str) -> PathBuf {
    static BUILT: OnceLock<std::sync::Mutex<BTreeMap<&'static str, PathBuf>>> = OnceLock::new();
    let built = BUILT.get_or_init(Default::default);
    let mut built = built.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(path) = built.get(source) {
        return path.clone();
    }
    let library = static_library();
    let out_dir = bin_dir().join("dear-client-c-tests");
    std::fs::create_dir_all(&out_dir).unwrap();
    let source_path = crate_dir().join(source);
    let name = source_path.file_stem().unwrap().to_owned();
    let binary = out_dir.join(name);
    let output = Command::new("cc")
        .args(["-std=c11", "-Wall", "-Wextra", "-Werror", "-O1", "-g"])
        .arg("-I")
        .arg(crate_dir().join("include"))
        .arg(&source_path)
        .arg(library)
        .args(NATIVE_LIBS)
        .arg("-o")
        .arg(&binary)
        .output()
        .expect("run cc (a C compiler is needed to link Rust anyway)");
    assert!(
        output.status.success(),
        "cc {source} failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    built.insert(source, binary.clone());
    binary
}

/// A running `deard` replaying `samples/demo` in a loop at its recorded pace, alignment only,
/// in the tests' root, once it serves.
fn start_daemon(service: &str) -> Daemon {
    start_daemon_on(service, &demo_capture())
}

/// [`start_daemon`] replaying another capture.
fn start_daemon_on(service: &str, capture: &Path) -> Daemon {
    let mut command = Command::new(deard());
    command
        .args(["--service", service, "--refine", "none", "--loop"])
        .args([
            "--pacing",
            "timestamps",
            "--stats-interval",
            "1",
            "--replay",
        ])
        .arg(capture)
        .env(dear_proto::IOX2_ROOT_ENV, iox2_root().join("iceoryx2"));
    let mut daemon = Daemon::spawn_logging_to_temp(command);
    daemon.wait_for_log("serving", Duration::from_secs(60));
    daemon
}

/// Runs a compiled C program with the tests' root and returns its output (killed after 120 s).
fn run(binary: &Path, args: &[&str]) -> Output {
    let mut child = Command::new(binary)
        .args(args)
        .env(dear_proto::IOX2_ROOT_ENV, iox2_root().join("iceoryx2"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run the C program");
    if wait_exit(&mut child, Duration::from_secs(120)).is_none() {
        let _ = child.kill();
    }
    child.wait_with_output().unwrap()
}

/// [`run`] against a running daemon: the program must succeed (else its output and the
/// daemon's log are shown); returns its stdout.
fn run_against(daemon: &Daemon, binary: &Path, args: &[&str]) -> String {
    let output = run(binary, args);
    assert!(
        output.status.success(),
        "{}\ndeard log:\n{}",
        describe(&output),
        daemon.log_text()
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn describe(output: &Output) -> String {
    format!(
        "{}\nstdout:\n{}\nstderr:\n{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// One line of `receive`: `frame <id> <w>x<h> valid=<n> run=<hex> seq=<n>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Line {
    frame_id: u64,
    width: u32,
    height: u32,
    valid: usize,
    run_id: u64,
    sequence: u64,
}

fn parse_line(line: &str) -> Line {
    fn parse(line: &str) -> Option<Line> {
        let parts: Vec<&str> = line.split(' ').collect();
        if parts.len() != 6 || parts[0] != "frame" {
            return None;
        }
        let (width, height) = parts[2].split_once('x')?;
        Some(Line {
            frame_id: parts[1].parse().ok()?,
            width: width.parse().ok()?,
            height: height.parse().ok()?,
            valid: parts[3].strip_prefix("valid=")?.parse().ok()?,
            run_id: u64::from_str_radix(parts[4].strip_prefix("run=")?, 16).ok()?,
            sequence: parts[5].strip_prefix("seq=")?.parse().ok()?,
        })
    }
    parse(line).unwrap_or_else(|| panic!("not a frame line of receive: {line:?}"))
}

/// What the Rust SDK receives on `service` until stopped: `(run_id, sequence)` → the frame as
/// `receive` would print it. Returns once the client is subscribed and has seen a frame.
struct RustClient {
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<BTreeMap<(u64, u64), Line>>,
}

impl RustClient {
    fn start(service: &str) -> RustClient {
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let service = service.to_string();
        let thread = {
            let stop = stop.clone();
            std::thread::spawn(move || {
                let client = sdk::Client::connect(&service).expect("the Rust SDK connects");
                let mut seen = BTreeMap::new();
                while !stop.load(Ordering::Relaxed) {
                    let Some(frame) = client.wait(Duration::from_millis(100)).expect("receive")
                    else {
                        continue;
                    };
                    let h = frame.header();
                    let line = Line {
                        frame_id: h.frame_id,
                        width: h.width,
                        height: h.height,
                        valid: frame.depth().iter().filter(|&&z| z > 0.0).count(),
                        run_id: h.run_id,
                        sequence: h.sequence,
                    };
                    seen.insert((line.run_id, line.sequence), line);
                    let _ = ready_tx.send(());
                }
                seen
            })
        };
        ready_rx
            .recv_timeout(Duration::from_secs(60))
            .expect("the Rust SDK received no frame in 60 s");
        RustClient { stop, thread }
    }

    fn finish(self) -> BTreeMap<(u64, u64), Line> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.join().expect("the Rust client thread")
    }
}

#[test]
fn the_example_receives_frames_and_agrees_with_the_rust_sdk() {
    iox2_root();
    let receive = c_program("examples/receive.c");
    let service = unique_service("example");
    let _daemon = start_daemon(&service);
    let rust = RustClient::start(&service);

    let output = run(&receive, &[&service, "5", "20000"]);
    let by_rust = rust.finish();
    assert!(
        output.status.success(),
        "receive failed: {}",
        describe(&output)
    );
    let stdout = String::from_utf8(output.stdout.clone()).unwrap();
    let lines: Vec<Line> = stdout.lines().map(parse_line).collect();
    assert_eq!(lines.len(), 5, "{}", describe(&output));

    for line in &lines {
        assert_eq!(
            (line.width, line.height),
            (320, 240),
            "samples/demo's size: {line:?}"
        );
        assert!(line.valid > 0, "no valid depth: {line:?}");
        assert!(line.valid <= 320 * 240);
        assert_ne!(line.run_id, 0, "deard draws a run id");
        assert_eq!(line.run_id, lines[0].run_id, "one daemon, one run");
    }
    for pair in lines.windows(2) {
        assert!(
            pair[1].sequence > pair[0].sequence,
            "sequence must increase: {pair:?}"
        );
    }
    // frame_id increases too, but for the replay's loop (42 frames): it restarts at most
    // once in 5 consecutive frames.
    let restarts = lines
        .windows(2)
        .filter(|p| p[1].frame_id <= p[0].frame_id)
        .count();
    assert!(restarts <= 1, "frame ids go back more than once: {lines:?}");

    // The same samples as the Rust SDK saw them: same frame, same valid depth.
    let matched: Vec<_> = lines
        .iter()
        .filter_map(|line| {
            by_rust
                .get(&(line.run_id, line.sequence))
                .map(|r| (line, r))
        })
        .collect();
    for (c, rust) in &matched {
        assert_eq!(
            c, rust,
            "the C example and the Rust SDK disagree on a sample"
        );
    }
    assert!(
        matched.len() >= 3,
        "the Rust SDK saw only {} of the example's 5 samples: {lines:?} vs {:?}",
        matched.len(),
        by_rust.keys().collect::<Vec<_>>()
    );
}

#[test]
fn null_arguments_and_a_bad_service_name_are_reported() {
    iox2_root();
    let c_api = c_program("tests/c_api.c");
    let bad = "no spaces/in service names";
    let output = run(&c_api, &["arguments", bad]);
    assert!(output.status.success(), "{}", describe(&output));
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("checks passed"), "{}", describe(&output));
    // The whole error chain: what failed, for which service, and why.
    let message = stdout
        .lines()
        .find_map(|l| l.strip_prefix("bad service: "))
        .expect("the message printed");
    assert!(
        message.contains(&format!("cannot connect to {bad:?}")),
        "{message}"
    );
    assert!(message.contains("contains ' '"), "{message}");

    // The example exits non-zero and prints the message.
    let receive = c_program("examples/receive.c");
    let output = run(&receive, &[bad, "1", "100"]);
    assert_eq!(output.status.code(), Some(1), "{}", describe(&output));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("DEAR_CONNECT_FAILED") && stderr.contains(bad),
        "{}",
        describe(&output)
    );
}

#[test]
fn without_a_daemon_waiting_times_out() {
    iox2_root();
    let c_api = c_program("tests/c_api.c");
    let service = unique_service("timeout");
    let output = run(&c_api, &["timeout", &service]);
    assert!(output.status.success(), "{}", describe(&output));

    let receive = c_program("examples/receive.c");
    let output = run(&receive, &[&service, "1", "300"]);
    assert_eq!(output.status.code(), Some(3), "{}", describe(&output));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("DEAR_TIMEOUT")
            && stderr.contains(&format!("no frame from {service:?} within 300 ms")),
        "{}",
        describe(&output)
    );
    assert!(output.stdout.is_empty(), "{}", describe(&output));
}

/// Format 3: a real deard frame's point cloud from C, through the Rust SDK's math: each point
/// checked in C against the header's intrinsics, which must be the replayed capture's.
#[test]
fn a_point_cloud_from_c_uses_the_captures_intrinsics() {
    iox2_root();
    let c_api = c_program("tests/c_api.c");
    let service = unique_service("points");
    let daemon = start_daemon(&service);
    let stdout = run_against(&daemon, &c_api, &["points", &service]);
    assert!(stdout.contains("ok point cloud"), "{stdout}");
    let manifest = std::fs::read_to_string(demo_capture().join("capture.json")).unwrap();
    let k = dear_capture::CaptureManifest::from_json(&manifest)
        .unwrap()
        .intrinsics;
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix("intrinsics "))
        .expect("the intrinsics line");
    let values: Vec<f64> = line.split(' ').map(|v| v.parse().unwrap()).collect();
    assert_eq!(values[0], 1.0, "pinhole");
    let want = [("fx", k.fx), ("fy", k.fy), ("cx", k.cx), ("cy", k.cy)];
    for (got, (name, want)) in values[1..].iter().zip(want) {
        assert!(
            (got - f64::from(want)).abs() < 1e-4,
            "header {name} {got}, capture.json {want}"
        );
    }
}

/// A capture whose `capture.json` has a Brown–Conrady `distortion`: deard publishes it in the
/// header (model 2, the coefficients), and the point cloud C gets undoes it: every valid
/// point, projected back through the lens model in C, lands on its own pixel.
#[test]
fn a_distorted_cameras_point_cloud_reprojects_onto_its_pixels() {
    iox2_root();
    let c_api = c_program("tests/c_api.c");
    let tmp = tempfile::tempdir().unwrap();
    let capture = dear_test_support::capture::write_demo_copies(
        &tmp.path().join("distorted"),
        &[(0, true), (33_000_000, true), (66_000_000, true)],
    );
    let path = capture.join("capture.json");
    let mut manifest =
        dear_capture::CaptureManifest::from_json(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let coefficients = ["-0.2", "0.05", "0.001", "-0.0005", "0.01"];
    manifest.distortion = Some(coefficients.map(|c| c.parse().unwrap()));
    std::fs::write(&path, serde_json::to_string_pretty(&manifest).unwrap()).unwrap();

    let service = unique_service("distorted");
    let daemon = start_daemon_on(&service, &capture);
    let mut args = vec!["distorted", service.as_str()];
    args.extend(coefficients);
    let stdout = run_against(&daemon, &c_api, &args);
    assert!(stdout.contains("ok distorted point cloud"), "{stdout}");
    if let Some(figures) = stdout.lines().find(|l| l.starts_with("distorted: ")) {
        println!("{figures}");
    }
}

#[test]
fn frames_are_zero_copy_and_at_most_two_are_held() {
    iox2_root();
    let c_api = c_program("tests/c_api.c");
    let service = unique_service("frames");
    let daemon = start_daemon(&service);
    let stdout = run_against(&daemon, &c_api, &["frames", &service]);
    for check in [
        "ok frames: header and planes",
        "ok a third held frame: DEAR_TOO_MANY_FRAMES_HELD",
        "ok after a release the next frame comes",
        "ok frames released after their client",
    ] {
        assert!(stdout.contains(check), "{check:?} missing:\n{stdout}");
    }
    let held = BufReader::new(stdout.as_bytes())
        .lines()
        .map_while(Result::ok)
        .find(|l| l.starts_with("held: "))
        .expect("the held-frames message");
    assert!(held.contains(&format!("{service:?}")), "{held}");
}

/// `dear_client_connect_reconnecting`: the daemon is killed and another started on the service
/// while the C client waits; its channel stalls, is connected again, and the new daemon's
/// frames arrive.
#[test]
fn a_reconnecting_client_outlives_its_daemon() {
    iox2_root();
    let c_api = c_program("tests/c_api.c");
    let service = unique_service("reconnect");
    let mut daemon = start_daemon(&service);
    let mut child = Command::new(&c_api)
        .args(["reconnecting", &service])
        .env(dear_proto::IOX2_ROOT_ENV, iox2_root().join("iceoryx2"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run the C program");
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    stdout.read_line(&mut line).unwrap();
    assert_eq!(line.trim(), "ready", "deard log:\n{}", daemon.log_text());
    daemon.crash();
    // Longer than the client's stall time (500 ms): its channel is given up meanwhile.
    std::thread::sleep(Duration::from_millis(1500));
    let second = start_daemon(&service);
    if wait_exit(&mut child, Duration::from_secs(90)).is_none() {
        let _ = child.kill();
    }
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut stdout, &mut rest).unwrap();
    let output = child.wait_with_output().unwrap();
    assert!(
        output.status.success() && rest.contains("ok reconnecting: the stream outlives its daemon"),
        "{}\nstdout:\n{rest}\nstderr:\n{}\ndeard log:\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr),
        second.log_text()
    );
}
