//! What the daemon's integration tests share (each test file includes it with `mod support;`).

use std::process::Command;

/// Runs `deard` with `toml` as its configuration file and `args` after it, on a service of its
/// own (`dear-test/<pid>/<tag>/frames`), requires that it fails to start, and returns its
/// standard error (what the error message tests read).
pub fn start_failure(toml: &str, args: &[&str], tag: &str) -> String {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("deard.toml");
    std::fs::write(&file, toml).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_deard"))
        .args(["--config", file.to_str().unwrap()])
        .args(args)
        .args([
            "--service",
            &format!("dear-test/{}/{tag}/frames", std::process::id()),
        ])
        .output()
        .expect("run deard");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "deard started with {toml:?}: {err}");
    err
}
