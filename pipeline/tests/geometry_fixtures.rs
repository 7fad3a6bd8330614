//! The geometry test vectors in `fixtures/geometry/` are what the code computes (the Python
//! port is checked against the same files), and they exercise the interesting paths.

#[allow(dead_code)] // `write_all` is the example's
#[path = "support/geometry_cases.rs"]
mod geometry_cases;

use geometry_cases::*;
use serde_json::Value;

/// Structural comparison; numbers within 1e-6 relative to max(1, |x|).
fn assert_json_close(got: &Value, want: &Value, path: &str) {
    match (got, want) {
        (Value::Number(a), Value::Number(b)) => {
            let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
            assert!(
                (a - b).abs() <= 1e-6 * b.abs().max(1.0),
                "{path}: {a} vs committed {b}"
            );
        }
        (Value::Array(a), Value::Array(b)) => {
            assert_eq!(a.len(), b.len(), "{path}: length differs");
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                assert_json_close(x, y, &format!("{path}[{i}]"));
            }
        }
        (Value::Object(a), Value::Object(b)) => {
            let mut ka: Vec<_> = a.keys().collect();
            let mut kb: Vec<_> = b.keys().collect();
            ka.sort();
            kb.sort();
            assert_eq!(ka, kb, "{path}: keys differ");
            for k in ka {
                assert_json_close(&a[k], &b[k], &format!("{path}.{k}"));
            }
        }
        _ => assert_eq!(got, want, "{path}"),
    }
}

#[test]
fn committed_fixtures_match_the_code() {
    let dir = fixtures_dir();
    for case in all_cases() {
        let path = dir.join(case.file_name);
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
            panic!(
                "{}: {e}; regenerate with `cargo run -p dear-pipeline --example write_geometry_fixtures`",
                path.display()
            )
        });
        let committed: Value =
            serde_json::from_str(&text).expect("committed fixture is valid JSON");
        assert_json_close(&case.json, &committed, case.file_name);
    }
}

#[test]
fn fixtures_exercise_the_interesting_paths() {
    let cases = all_cases();
    let get = |name: &str| {
        cases
            .iter()
            .find(|c| c.file_name == name)
            .unwrap()
            .json
            .clone()
    };
    let count = |v: &Value, pred: &dyn Fn(&Value) -> bool| {
        v["data"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|x| pred(x))
            .count()
    };
    let wd = get("warp_depth.json");
    // Some samples fall outside the image, most do not.
    let zeros = count(&wd["outputs"]["out"], &|x| x.as_f64() == Some(0.0));
    assert!(
        zeros > 10 && zeros < H * W / 2,
        "{zeros} invalid warp_depth outputs"
    );
    let wb = get("warp_bilinear.json");
    assert!(count(&wb["outputs"]["valid"], &|x| x == &Value::Bool(false)) > 10);
    let sv = get("synthesize_view.json");
    let invalid = count(&sv["outputs"]["valid"], &|x| x == &Value::Bool(false));
    assert!(
        invalid > 5 && invalid < H * W / 3,
        "{invalid} invalid synthesised pixels"
    );
    // The robust fit is closer to the truth than a plain fit of the same data would be.
    let rc = &get("lsq_robust.json")["outputs"]["calibration"];
    assert!((rc["cx"].as_f64().unwrap() - f64::from(LSQ_TRUE.cx)).abs() < 0.5);
}
