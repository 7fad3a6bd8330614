//! The `deard` binary's configuration handling: defaults, file + flag precedence, and clear
//! errors for bad keys and bad capture directories.

use std::process::Command;

use dear_test_support::process::{output_within, unique_service};

fn deard(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_deard"))
        .args(args)
        .output()
        .expect("run deard")
}

#[test]
fn print_config_shows_defaults_and_flag_overrides() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("deard.toml");
    std::fs::write(
        &file,
        "[capture]\npath = \"/data/cap\"\npacing = \"fast\"\n[service]\ncamera = \"left\"\n",
    )
    .unwrap();
    let out = deard(&[
        "--config",
        file.to_str().unwrap(),
        "--camera",
        "right",
        "--print-config",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let config = deard::config::Config::from_toml(&text).expect("printed config parses back");
    assert_eq!(config.capture.path, std::path::PathBuf::from("/data/cap"));
    assert_eq!(config.capture.pacing, deard::config::Pacing::Fast);
    assert_eq!(
        config.service.service_name(),
        "dear/right/frames",
        "flag overrides file"
    );
    assert_eq!(
        config.capture.queue_depth, 4,
        "unset keys keep their defaults"
    );
}

#[test]
fn unknown_keys_are_rejected_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("deard.toml");
    std::fs::write(&file, "[capture]\npaht = \"x\"\n").unwrap();
    let out = deard(&["--config", file.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("paht") && err.contains("deard.toml"), "{err}");
}

#[test]
fn an_out_of_range_tracking_gain_is_rejected_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("deard.toml");
    std::fs::write(&file, "[pipeline]\nonline_track_gain = 1.5\n").unwrap();
    let out = deard(&["--config", file.to_str().unwrap(), "--print-config"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("online_track_gain = 1.5") && err.contains("0..=1"),
        "{err}"
    );
}

#[test]
fn the_example_config_is_the_default_config() {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/deard.example.toml"))
        .unwrap();
    let example = deard::config::Config::from_toml(&text).expect("example parses");
    assert_eq!(
        example,
        deard::config::Config::default(),
        "the example documents the defaults"
    );
}

/// A missing capture is named, and the error is printed once (it used to go to stderr both
/// through the log and by `main`).
#[test]
fn a_missing_capture_is_a_clear_startup_error_printed_once() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nope");
    let out = deard(&[
        "--replay",
        missing.to_str().unwrap(),
        "--service",
        "dear-test/cli/missing",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("nope/capture.json") && err.contains("missing"),
        "{err}"
    );
    assert_eq!(err.matches("nope/capture.json").count(), 1, "{err}");
}

/// Issue 34: a write error on stdout is an error naming it, not a panic (exit 101).
#[test]
fn print_config_to_a_full_device_fails_cleanly() {
    let out = Command::new(env!("CARGO_BIN_EXE_deard"))
        .arg("--print-config")
        .stdout(
            std::fs::OpenOptions::new()
                .write(true)
                .open("/dev/full")
                .unwrap(),
        )
        .output()
        .expect("run deard");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("cannot write the configuration to stdout"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

/// Runs `deard ARGS` and requires it to end by itself within 30 s (a daemon blocked on a FIFO
/// would not: it is killed and the test fails).
fn deard_within(args: &[&str]) -> std::process::Output {
    let child = Command::new(env!("CARGO_BIN_EXE_deard"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run deard");
    output_within(
        child,
        &format!("deard {args:?}"),
        std::time::Duration::from_secs(30),
        || {},
    )
}

fn mkfifo(path: &std::path::Path) {
    let status = Command::new("mkfifo").arg(path).status().unwrap();
    assert!(status.success());
}

/// Issue 34: a FIFO or a device as the configuration file is refused by its type, naming it:
/// a FIFO blocked the daemon (SIGTERM ignored) and `/dev/zero` grew to gigabytes.
#[test]
fn a_fifo_or_device_as_the_configuration_is_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let fifo = tmp.path().join("deard.toml");
    mkfifo(&fifo);
    for (path, kind) in [
        (fifo.to_str().unwrap(), "a FIFO"),
        ("/dev/zero", "a character device"),
    ] {
        let out = deard_within(&["--config", path, "--print-config"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains(path) && err.contains(kind), "{err}");
    }
    // A regular file over the 1 MiB a configuration may hold is refused before it is read.
    let big = tmp.path().join("big.toml");
    std::fs::write(&big, vec![b'#'; 2 << 20]).unwrap();
    let out = deard_within(&["--config", big.to_str().unwrap(), "--print-config"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("big.toml") && err.contains("more than the 1.0 MiB"),
        "{err}"
    );
}

/// Issue 34: a FIFO as a bundle's `model.json` is refused, and a bundle path that is a file
/// is reported as "not a directory" (it was "missing").
#[test]
fn a_bundle_that_is_a_file_or_holds_a_fifo_is_refused_by_name() {
    let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo");
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("bundle-file");
    std::fs::write(&file, "x").unwrap();
    let service = unique_service("bundle-kind");
    let run = |bundle: &std::path::Path| {
        let bundle = bundle.to_str().unwrap();
        deard_within(&[
            "--replay",
            demo,
            "--exit-when-done",
            "--service",
            &service,
            "--bundle",
            bundle,
        ])
    };
    let out = run(&file);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("bundle-file: not a directory"), "{err}");

    let dir = tmp.path().join("bundle-fifo");
    std::fs::create_dir(&dir).unwrap();
    mkfifo(&dir.join("model.json"));
    let out = run(&dir);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("model.json") && err.contains("a FIFO"),
        "{err}"
    );
}

/// Issue 34 (notes): `[capture] end` beyond the capture's frames is said, not clamped silently.
#[test]
fn an_end_beyond_the_capture_is_logged() {
    let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo");
    let service = unique_service("end-beyond");
    let out = Command::new(env!("CARGO_BIN_EXE_deard"))
        .args(["--replay", demo, "--refine", "none", "--pacing", "fast"])
        .args(["--exit-when-done", "--end", "1000", "--service", &service])
        .env("RUST_LOG", "warn")
        .output()
        .expect("run deard");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("[capture] end is beyond the capture's frames") && err.contains("end=1000"),
        "{err}"
    );
}

/// Issue 37: `--pin-threads` pins the frame path's threads one per CPU the daemon may run on
/// (checked inside the daemon, which refuses to start when a pin did not take) and says which;
/// asking for more threads than CPUs is a start-up error naming both.
#[test]
fn pinned_threads_serve_and_too_many_are_refused_by_name() {
    let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo");
    let allowed = dear_pipeline::threads::allowed_cpus().unwrap();
    let service = unique_service("pin-threads");
    let run = |threads: Option<usize>| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_deard"));
        command
            .args(["--replay", demo, "--pin-threads"])
            .args(["--refine", "classical", "--pacing", "fast"])
            .args(["--exit-when-done", "--end", "5"])
            .args(["--service", &service])
            .env("RUST_LOG", "info")
            .env_remove("RAYON_NUM_THREADS");
        if let Some(n) = threads {
            command.env("RAYON_NUM_THREADS", n.to_string());
        }
        command.output().expect("run deard")
    };
    let out = run(None);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("frame path's threads pinned") && err.contains(&format!("cpus={allowed:?}")),
        "{err}"
    );

    let out = run(Some(allowed.len() + 1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("pin_threads")
            && err.contains("RAYON_NUM_THREADS")
            && err.contains(&format!("{} frame-path threads", allowed.len() + 1)),
        "{err}"
    );
}
