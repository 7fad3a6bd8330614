//! The `deard` binary's configuration handling: defaults, file + flag precedence, and clear
//! errors for bad keys and bad capture directories.

use std::process::Command;

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
        config.capture.queue_depth, 2,
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
