//! `[runtime] state_file`: a real daemon running the DEAR chain online saves its calibration
//! estimate, and the next start restores it (with its age in the log).

use deard::calibration_state::CalibrationState;

mod support;

fn run_deard(config: &std::path::Path, test: &str) -> String {
    let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo");
    let bundle = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/edge");
    let args = [
        "--replay",
        demo,
        "--bundle",
        bundle,
        "--pacing",
        "fast",
        "--end",
        "12",
        "--exit-when-done",
        "--online-network",
        "inline",
    ];
    let out = support::run_deard(config, &args, test);
    let log = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{log}");
    log
}

#[test]
fn the_online_estimate_is_saved_and_restored_at_the_next_start() {
    let tmp = tempfile::tempdir().unwrap();
    let state = tmp.path().join("calibration.json");
    let config = tmp.path().join("deard.toml");
    std::fs::write(
        &config,
        format!("[runtime]\nstate_file = {:?}\n", state.to_str().unwrap()),
    )
    .unwrap();

    let first = run_deard(&config, "state-1");
    assert!(
        !first.contains("restored"),
        "nothing to restore yet: {first}"
    );
    let saved = CalibrationState::load(&state)
        .unwrap()
        .expect("the online estimate was saved");
    assert_eq!((saved.width, saved.height), (320, 240));
    assert!(saved.source.contains("samples/demo"), "{}", saved.source);

    let second = run_deard(&config, "state-2");
    assert!(
        second.contains("restored the online calibration estimate of an earlier run"),
        "{second}"
    );
    let starting = second
        .lines()
        .find(|l| l.contains("starting"))
        .expect("a starting line");
    let c = saved.calibration;
    assert!(
        starting.contains(&format!("tx: {:?}", c.tx))
            && starting.contains(&format!("cx: {:?}", c.cx)),
        "the restored calibration is the one the chain starts from: {starting} vs {c:?}"
    );
}

#[test]
fn a_damaged_state_file_is_reported_and_the_daemon_still_serves() {
    let tmp = tempfile::tempdir().unwrap();
    let state = tmp.path().join("calibration.json");
    std::fs::write(&state, "not json").unwrap();
    let config = tmp.path().join("deard.toml");
    std::fs::write(
        &config,
        format!("[runtime]\nstate_file = {:?}\n", state.to_str().unwrap()),
    )
    .unwrap();
    let log = run_deard(&config, "state-bad");
    assert!(
        log.contains("the saved calibration cannot be used"),
        "{log}"
    );
    assert!(log.contains("calibration.json"), "{log}");
    // The bad file is replaced by this run's estimate.
    assert!(CalibrationState::load(&state).unwrap().is_some());
}
