//! `fixtures/stats/percentiles.json`: the hand-worked cases that `train/tests/test_stats_fixture.py`
//! checks the Python definition against, so both languages report the same percentiles.

use dear_stats::{median, percentile_nearest_rank, sort, upper_median, Summary};
use serde_json::Value;

fn fixture() -> Value {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../fixtures/stats/percentiles.json"
    );
    serde_json::from_str(&std::fs::read_to_string(path).expect("fixture")).expect("JSON")
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

#[test]
fn every_case_agrees() {
    let fixture = fixture();
    let cases = fixture["cases"].as_array().expect("cases");
    assert!(cases.len() >= 6);
    for case in cases {
        let name = case["name"].as_str().unwrap();
        let values = floats(&case["values"]);
        let mut sorted = values.clone();
        sort(&mut sorted);
        for (q, want) in floats(&case["q"])
            .into_iter()
            .zip(floats(&case["percentiles"]))
        {
            assert_eq!(
                percentile_nearest_rank(&sorted, q),
                Some(want),
                "{name}: q = {q}"
            );
        }
        assert_eq!(median(&sorted), case["median"].as_f64(), "{name}: median");
        assert_eq!(
            upper_median(&mut values.clone()),
            case["upper_median"].as_f64(),
            "{name}: upper median"
        );
        let s = Summary::of(&mut values.clone()).unwrap();
        let want = &case["summary"];
        assert_eq!(s.count as u64, want["count"].as_u64().unwrap(), "{name}");
        for (got, key) in [
            (s.p50, "p50"),
            (s.p95, "p95"),
            (s.p99, "p99"),
            (s.max, "max"),
        ] {
            assert_eq!(Some(got), want[key].as_f64(), "{name}: {key}");
        }
        assert!(
            (s.mean - want["mean"].as_f64().unwrap()).abs() < 1e-12,
            "{name}: mean"
        );
        // Integer samples rank the same way.
        if values.iter().all(|v| v.fract() == 0.0 && *v >= 0.0) {
            let mut ints: Vec<u64> = values.iter().map(|&v| v as u64).collect();
            let s = Summary::of(&mut ints).unwrap();
            assert_eq!(
                Some(s.p50 as f64),
                want["p50"].as_f64(),
                "{name}: integer p50"
            );
            assert_eq!(
                Some(s.p99 as f64),
                want["p99"].as_f64(),
                "{name}: integer p99"
            );
        }
    }
}

#[test]
fn no_values_give_nothing() {
    assert_eq!(percentile_nearest_rank::<f64>(&[], 0.5), None);
    assert_eq!(median::<f64>(&[]), None);
    assert_eq!(upper_median::<f64>(&mut []), None);
    assert_eq!(Summary::<f64>::of(&mut []), None);
}
