//! What the daemon's integration tests share (each test file includes it with `mod support;`).

use std::path::Path;
use std::process::{Command, Output};

use dear_test_support::process::unique_service;

/// Runs `deard --config CONFIG ARGS…` to its end on a service of its own
/// (`dear-test/<pid>/<tag>/frames`).
pub fn run_deard(config: &Path, args: &[&str], tag: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_deard"))
        .args(["--config", config.to_str().unwrap()])
        .args(args)
        .args(["--service", &unique_service(tag)])
        .output()
        .expect("run deard")
}

/// Runs `deard` with `toml` as its configuration file and `args` after it ([`run_deard`]),
/// requires that it fails to start, and returns its standard error (what the error message
/// tests read).
// Not every test file that includes this module calls it.
#[allow(dead_code)]
pub fn start_failure(toml: &str, args: &[&str], tag: &str) -> String {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("deard.toml");
    std::fs::write(&file, toml).unwrap();
    let out = run_deard(&file, args, tag);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "deard started with {toml:?}: {err}");
    err
}
