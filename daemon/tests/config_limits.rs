//! Configuration values that parse but cannot work are rejected at start-up, by key, with the
//! allowed range: not accepted and left to panic, spin or publish garbage later.

use std::process::Command;

use dear_test_support::process::unique_service;
use deard::config::Config;

mod support;

/// The validation error for `toml`, panicking if it is accepted.
fn rejected(toml: &str) -> String {
    match Config::from_toml(toml) {
        Ok(config) => panic!("accepted {toml:?} as {config:?}"),
        Err(e) => e.to_string(),
    }
}

fn accepted(toml: &str) -> Config {
    Config::from_toml(toml).unwrap_or_else(|e| panic!("rejected {toml:?}: {e}"))
}

/// Each of `values` for `key` in `[section]` is refused, the error naming `key = value` and the
/// allowed `range`.
fn refused_outside(section: &str, key: &str, values: &[&str], range: &str) {
    for value in values {
        let err = rejected(&format!("[{section}]\n{key} = {value}\n"));
        assert!(
            err.contains(&format!("{key} = {value}")) && err.contains(range),
            "{err}"
        );
    }
}

/// Each of `values` for `key` in `[section]` is accepted and read back as given by `read`.
fn accepted_as_given(section: &str, key: &str, values: &[usize], read: impl Fn(&Config) -> usize) {
    for &value in values {
        let config = accepted(&format!("[{section}]\n{key} = {value}\n"));
        assert_eq!(read(&config), value, "{key} = {value}");
    }
}

/// Runs `deard` on `samples/demo` with the configuration `toml` on a service of its own
/// (`test` names it), expecting it to fail at start-up; returns its stderr.
fn start_failure(toml: &str, test: &str) -> String {
    let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo");
    support::start_failure(toml, &["--replay", demo, "--exit-when-done"], test)
}

#[test]
fn max_subscribers_per_user_is_bounded_by_the_services_slots() {
    let key = "max_subscribers_per_user";
    refused_outside("service", key, &["0", "9", "100000"], "1..=8");
    accepted_as_given("service", key, &[1, 6, 8], |c| {
        c.service.max_subscribers_per_user
    });
    assert_eq!(accepted("").service.max_subscribers_per_user, 6);
}

#[test]
fn queue_depth_is_bounded() {
    let too_deep = ["0", "65", "100000", "9223372036854775807"];
    refused_outside("capture", "queue_depth", &too_deep, "1..=64");
    accepted_as_given("capture", "queue_depth", &[1, 2, 64], |c| {
        c.capture.queue_depth
    });
}

#[test]
fn stats_interval_must_be_finite_positive_and_at_most_a_day() {
    for s in [
        "1e20", "86401.0", "inf", "nan", "0.0", "-1.0", "5e-324", "0.0009",
    ] {
        let err = rejected(&format!("[runtime]\nstats_interval_s = {s}\n"));
        assert!(
            err.contains("stats_interval_s") && err.contains("86400"),
            "{s}: {err}"
        );
    }
    for s in [0.001, 5.0, 86400.0] {
        let config = accepted(&format!("[runtime]\nstats_interval_s = {s:?}\n"));
        assert_eq!(config.runtime.stats_interval_s, s);
    }
}

#[test]
fn static_calibration_must_be_finite_and_physical() {
    for (field, value) in [
        ("tx", "nan"),
        ("ty", "inf"),
        ("cx", "-inf"),
        ("tx", "1e30"),
        ("ty", "-5000.0"),
        ("cx", "1e30"),
        ("cy", "9000.0"),
    ] {
        let mut values = [("tx", "1.0"), ("ty", "0.5"), ("cx", "2.0"), ("cy", "-1.0")];
        for v in values.iter_mut() {
            if v.0 == field {
                v.1 = value;
            }
        }
        let table: Vec<String> = values.iter().map(|(k, v)| format!("{k} = {v}")).collect();
        let toml = format!(
            "[pipeline]\nstatic_calibration = {{ {} }}\n",
            table.join(", ")
        );
        let err = rejected(&toml);
        assert!(
            err.contains(&format!("static_calibration.{field}")),
            "{toml}: {err}"
        );
    }
    let config =
        accepted("[pipeline]\nstatic_calibration = { tx = -1.2, ty = 1.4, cx = 1.1, cy = 0.7 }\n");
    assert_eq!(config.pipeline.static_calibration.unwrap().tx, -1.2);
}

#[test]
fn camera_must_be_one_service_name_segment() {
    for camera in [
        "",
        "a/b",
        "/",
        "left cam",
        "tab\tcam",
        "bell\u{7}",
        "caméra",
    ] {
        let toml = format!("[service]\ncamera = {camera:?}\n");
        let err = rejected(&toml);
        assert!(err.contains("camera"), "{toml}: {err}");
    }
    for camera in ["cam0", "left-1", "ir_2.a"] {
        let config = accepted(&format!("[service]\ncamera = {camera:?}\n"));
        assert_eq!(
            config.service.service_name(),
            format!("dear/{camera}/frames")
        );
    }
}

#[test]
fn a_service_name_has_no_empty_segment() {
    for name in ["dear//frames", "/dear/cam0/frames", "dear/cam0/frames/"] {
        let err = rejected(&format!("[service]\nname = {name:?}\n"));
        assert!(err.contains("name") && err.contains(name), "{err}");
    }
    accepted("[service]\nname = \"dear/cam0/frames\"\n");
}

#[test]
fn the_binary_names_a_bad_key_once() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("deard.toml");
    std::fs::write(&file, "[service]\ncamera = \"\"\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_deard"))
        .args(["--config", file.to_str().unwrap(), "--print-config"])
        .output()
        .expect("run deard");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.matches("camera").count(), 1, "{err}");
}

#[test]
fn a_static_calibration_beyond_the_image_is_a_startup_error() {
    // samples/demo is 320x240: a principal-point offset of 300 px vertically leaves no overlap.
    let err = start_failure(
        "[pipeline]\nrefine = \"none\"\nstatic_calibration = { tx = 0.0, ty = 0.0, cx = 0.0, cy = 300.0 }\n",
        "calib-range",
    );
    assert!(
        err.contains("static_calibration.cy = 300") && err.contains("240"),
        "{err}"
    );
    assert_eq!(
        err.matches("static_calibration.cy").count(),
        1,
        "once: {err}"
    );
}

/// `online_network` is background by default, inline on request, and an unknown value in the
/// file or on the command line is refused by name (the file and the flags share one parser).
#[test]
fn online_network_placement_is_background_by_default_and_checked() {
    use deard::config::NetworkPlacement;
    assert_eq!(
        accepted("").pipeline.online_network,
        NetworkPlacement::Background
    );
    let config = accepted("[pipeline]\nonline_network = \"inline\"\n");
    assert_eq!(config.pipeline.online_network, NetworkPlacement::Inline);
    let err = rejected("[pipeline]\nonline_network = \"sometimes\"\n");
    assert!(
        err.contains("sometimes") || err.contains("online_network"),
        "{err}"
    );
    for p in [NetworkPlacement::Background, NetworkPlacement::Inline] {
        assert_eq!(p.name().parse::<NetworkPlacement>(), Ok(p));
    }
    let err = "sometimes".parse::<NetworkPlacement>().unwrap_err();
    assert!(
        err.contains("\"sometimes\"") && err.contains("inline"),
        "{err}"
    );
}

#[test]
fn max_shared_memory_is_bounded_and_enforced_at_start() {
    let values = ["0", "65537", "18446744073709551615"];
    refused_outside("service", "max_shared_memory_mb", &values, "1..=65536");
    assert_eq!(accepted("").service.max_shared_memory_mb, 1024);
    // samples/demo (320x240) needs 21.5 MB: a 10 MB limit refuses it before any is taken.
    let err = start_failure(
        "[pipeline]\nrefine = \"none\"\n[service]\nmax_shared_memory_mb = 10\n",
        "shm-limit",
    );
    assert!(
        err.contains("320x240 stream needs 21.5 MB of shared memory")
            && err.contains("max_shared_memory_mb = 10"),
        "{err}"
    );
}

/// Issue 34: a misspelt level (`inof`) or junk (`[[[`) in `[runtime] log` is refused by name;
/// tracing's parser took each as a target and turned every log line off, errors included.
#[test]
fn log_filter_is_checked_by_directive() {
    for bad in ["inof", "[[[", "info,deard=verbose", "=info", "warn,,inof"] {
        let err = rejected(&format!("[runtime]\nlog = {bad:?}\n"));
        assert!(
            err.contains("[runtime] log")
                && err.contains("directive")
                && err.contains("off, error, warn, info, debug, trace")
                || err.contains("no target"),
            "{bad}: {err}"
        );
    }
    for good in [
        "info",
        "WARN",
        "warn,deard=debug",
        "deard::run=trace",
        "off",
        "",
    ] {
        accepted(&format!("[runtime]\nlog = {good:?}\n"));
    }
    let err = start_failure("[runtime]\nlog = \"inof\"\n", "log-inof");
    assert!(err.contains("[runtime] log = \"inof\""), "{err}");
}

/// `RUST_LOG` (which overrides `[runtime] log`) is held to the same rules.
#[test]
fn a_bad_rust_log_is_refused_by_name() {
    let out = Command::new(env!("CARGO_BIN_EXE_deard"))
        .args(["--print-config"])
        .env("RUST_LOG", "inof")
        .output()
        .unwrap();
    // --print-config does not log: it is accepted there.
    assert!(out.status.success());
    let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo");
    let out = Command::new(env!("CARGO_BIN_EXE_deard"))
        .args(["--replay", demo, "--exit-when-done", "--refine", "none"])
        .args(["--service", &unique_service("rust-log")])
        .env("RUST_LOG", "inof")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("RUST_LOG = \"inof\""), "{err}");
}
