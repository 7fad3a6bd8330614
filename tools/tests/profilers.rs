//! The profilers (`graph_profile`, `stage_profile`, `classical_profile`) explain their
//! arguments with `--help` and refuse bad input with an error that names it, instead of
//! panicking.

use std::process::{Command, Output};

const GRAPH_PROFILE: &str = env!("CARGO_BIN_EXE_graph_profile");
const STAGE_PROFILE: &str = env!("CARGO_BIN_EXE_stage_profile");
const CLASSICAL_PROFILE: &str = env!("CARGO_BIN_EXE_classical_profile");

/// `models/edge/refine.onnx`: four inputs (amplitude, depth, rgb, classical).
const REFINE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/edge/refine.onnx");

fn run(bin: &str, args: &[&str]) -> Output {
    Command::new(bin)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {bin}: {e}"))
}

fn text(out: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs `bin` with `args`, expects a failure (not a panic) and returns its stderr.
fn fails(bin: &str, args: &[&str]) -> String {
    let out = run(bin, args);
    let (stdout, stderr) = text(&out);
    assert!(
        !out.status.success(),
        "{bin} {args:?} succeeded:\n{stdout}{stderr}"
    );
    assert!(
        !stderr.contains("panicked"),
        "{bin} {args:?} panicked:\n{stderr}"
    );
    stderr
}

#[test]
fn help_names_every_positional_argument() {
    for (bin, positionals) in [
        (GRAPH_PROFILE, &["ONNX", "HEIGHT", "WIDTH", "CHANNELS"][..]),
        (STAGE_PROFILE, &["CAPTURE", "BUNDLE"][..]),
        (CLASSICAL_PROFILE, &["CAPTURE"][..]),
    ] {
        let out = run(bin, &["--help"]);
        let (stdout, stderr) = text(&out);
        assert!(out.status.success(), "{bin} --help:\n{stdout}{stderr}");
        for p in positionals {
            assert!(
                stdout.contains(p),
                "{bin} --help does not mention {p}:\n{stdout}"
            );
        }
    }
}

#[test]
fn no_arguments_is_a_usage_error() {
    for bin in [GRAPH_PROFILE, STAGE_PROFILE, CLASSICAL_PROFILE] {
        let stderr = fails(bin, &[]);
        assert!(stderr.contains("Usage"), "{bin}:\n{stderr}");
    }
}

#[test]
fn a_missing_capture_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("no-such-capture");
    let missing = missing.to_str().unwrap();
    for bin in [STAGE_PROFILE, CLASSICAL_PROFILE] {
        let stderr = fails(bin, &[missing]);
        assert!(stderr.contains(missing), "{bin}:\n{stderr}");
    }
    let stderr = fails(STAGE_PROFILE, &[missing, "models/edge", "--full"]);
    assert!(stderr.contains(missing), "{stderr}");
}

#[test]
fn a_missing_graph_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("no-such-graph.onnx");
    let missing = missing.to_str().unwrap();
    let stderr = fails(GRAPH_PROFILE, &[missing, "16", "16", "1,1,3,1"]);
    assert!(stderr.contains(missing), "{stderr}");
}

#[test]
fn a_channel_list_of_the_wrong_length_names_both_counts() {
    for (channels, entries) in [("1,1,3", "3"), ("1,1,3,1,1", "5")] {
        let stderr = fails(GRAPH_PROFILE, &[REFINE, "16", "16", channels]);
        assert!(
            stderr.contains(&format!("{entries} entries")) && stderr.contains("4 inputs"),
            "{channels}:\n{stderr}"
        );
    }
}

#[test]
fn a_channel_list_that_is_not_numbers_is_named() {
    let stderr = fails(GRAPH_PROFILE, &[REFINE, "16", "16", "1,x,3,1"]);
    assert!(
        stderr.contains("CHANNELS") && stderr.contains("`x`"),
        "{stderr}"
    );
}

/// `samples/demo`: a small capture in the repository (42 frames).
const DEMO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo");

#[test]
fn stage_profile_full_without_a_bundle_says_so() {
    let stderr = fails(STAGE_PROFILE, &[DEMO, "--full", "--iters", "1"]);
    assert!(stderr.contains("BUNDLE"), "{stderr}");
}

#[test]
fn classical_profile_refuses_more_frames_than_the_capture_has() {
    let stderr = fails(
        CLASSICAL_PROFILE,
        &[DEMO, "--frames", "1000", "--iters", "1"],
    );
    assert!(
        stderr.contains("--frames 1000") && stderr.contains(DEMO) && stderr.contains("42 frames"),
        "{stderr}"
    );
}
