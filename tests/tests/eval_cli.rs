//! `dear eval` as a user runs it: the real binary on a capture directory on disk, with the
//! fixture bundle through tract, writing JSON, Markdown and figures.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use dear_capture::Calibration;
use dear_test_support::paths::binary;
use dear_test_support::scene;

const W: u32 = 64;
const H: u32 = 48;

fn fixture_bundle() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/bundles/smoke-edge")
}

fn dear_eval(args: &[&str]) -> Output {
    Command::new(binary("dear"))
        .arg("eval")
        .args(args)
        .output()
        .expect("run dear eval")
}

#[test]
fn eval_measures_baselines_and_a_bundle_and_writes_json_markdown_and_figures() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = tmp.path().join("capture");
    let out = tmp.path().join("out");
    scene::write_capture_with_ground_truth(&capture, 4, W, H);
    let bundle = fixture_bundle();
    let result = dear_eval(&[
        "--capture",
        capture.to_str().unwrap(),
        "--baselines",
        "--bundle",
        bundle.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--frames",
        "3",
        "--figures",
        "1",
        "--online",
        "--online-interval",
        "2",
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(result.status.success(), "dear eval failed: {stderr}");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval.json")).unwrap()).unwrap();
    assert_eq!(json["frames_evaluated"], 3);
    let methods = json["methods"].as_array().unwrap();
    let names: Vec<&str> = methods
        .iter()
        .map(|m| m["method"].as_str().unwrap())
        .collect();
    for expected in [
        "raw-tof",
        "static-calibration",
        "static+classical-filter",
        "edge-matching",
        "oracle-calibration",
        "smoke-edge aligned",
        "smoke-edge",
        "smoke-edge refine @ true calibration",
        "smoke-edge online",
    ] {
        assert!(names.contains(&expected), "no row {expected} in {names:?}");
    }
    for m in methods {
        assert_eq!(m["frames"], 3, "{m}");
        let mae = m["mae_all_cm"].as_f64().unwrap();
        assert!(mae.is_finite() && mae >= 0.0, "{m}");
        assert!(m["median_seconds"].as_f64().unwrap() > 0.0, "{m}");
    }
    let row = |name: &str| methods.iter().find(|m| m["method"] == name).unwrap();
    // The input's error is the scene's noise: uniform over 13 levels of ±12 mm, mean 6.5 mm
    // (plus millimetre quantisation); a wrong pixel pairing or unit would be far off.
    let raw = row("raw-tof")["mae_all_cm"].as_f64().unwrap();
    assert!((0.55..0.75).contains(&raw), "raw ToF MAE {raw} cm");
    // The bundle's chain produced flows, scored against the zero ground-truth flow: an AEPE is
    // a mean of end-point distances (finite, not negative), and the row's value is the mean of
    // the per-frame values `--online` writes to tracking.csv (4 decimals) for the same flows.
    let tracking = std::fs::read_to_string(out.join("tracking.csv")).unwrap();
    let per_frame: Vec<f64> = tracking
        .lines()
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|cells| cells[1] == "smoke-edge") // frame,method,aepe_px,flow_network,…
        .map(|cells| cells[2].parse().unwrap())
        .collect();
    assert_eq!(per_frame.len(), 3, "{tracking}");
    let mean = per_frame.iter().sum::<f64>() / 3.0;
    let aepe = row("smoke-edge")["aepe_px"].as_f64().unwrap();
    assert!(aepe.is_finite() && aepe >= 0.0, "AEPE {aepe}");
    assert!(
        (aepe - mean).abs() <= 5e-5 + 1e-9,
        "AEPE {aepe}, per-frame mean {mean}"
    );
    let rough = row("smoke-edge")["aepe_rough_px"].as_f64().unwrap();
    assert!(rough.is_finite() && rough >= 0.0, "rough AEPE {rough}");
    // The true calibration of an aligned capture is the identity: no flow error.
    let oracle = row("oracle-calibration")["aepe_px"].as_f64().unwrap();
    assert!(oracle < 1e-3, "oracle AEPE {oracle}");

    // Online mode: the warm-up runs the network on every frame until three measurements are
    // accepted, so on three frames it ran 1–3 times; tracking.csv has one line per frame and
    // method with a flow.
    let network_runs = json["online_network_frames"][0][1].as_u64().unwrap();
    assert!((1..=3).contains(&network_runs), "{network_runs}");
    assert!(tracking.starts_with(
        "frame,method,aepe_px,flow_network,health,constrained,correction_px,uncertainty_px,\
         held_back,disagreement,shift_px,shift_ncc,shift_at_limit\n"
    ));
    assert_eq!(
        tracking.matches(",smoke-edge online,").count(),
        3,
        "{tracking}"
    );
    // The online rows say the calibration's health (issue 32): the estimator starts from the
    // capture's static calibration, so it is assessed from the first frame.
    let states = ["good", "can improve", "needs recalibration"];
    for line in tracking
        .lines()
        .filter(|l| l.contains(",smoke-edge online,"))
    {
        let health = line.split(',').nth(4).unwrap();
        assert!(states.contains(&health), "{line}");
    }
    assert_eq!(
        tracking.matches(",static-calibration,").count(),
        3,
        "{tracking}"
    );

    let markdown = std::fs::read_to_string(out.join("eval.md")).unwrap();
    assert!(markdown.contains("| raw-tof |"), "{markdown}");
    let figures = json["figures"].as_array().unwrap();
    assert_eq!(figures.len(), 3, "panel, blend and scan line of one frame");
    for f in figures {
        let path = out.join(f.as_str().unwrap());
        let img = image::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(img.width() >= W && img.height() >= H);
        assert!(markdown.contains(f.as_str().unwrap()));
    }
}

#[test]
fn eval_rejects_a_capture_without_ground_truth_naming_the_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = tmp.path().join("capture");
    scene::write_capture(&capture, 2, W, H, Calibration::default());
    let result = dear_eval(&[
        "--capture",
        capture.to_str().unwrap(),
        "--out",
        tmp.path().join("out").to_str().unwrap(),
    ]);
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        stderr.contains("frame 0 has no ground truth") && stderr.contains("000000.gt.png"),
        "{stderr}"
    );
    assert!(!tmp.path().join("out/eval.json").exists());
}
