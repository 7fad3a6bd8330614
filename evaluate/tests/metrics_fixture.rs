//! `metrics::{DepthErrorSplit, aepe, Reliability, TemporalChange}` against the hand-computed
//! cases in `fixtures/metrics/` (made by `make_metrics.py` beside them;
//! `train/tests/test_metrics_fixture.py` checks the Python mirror in
//! `train/dear_train/metrics.py` against the same files, so both languages compute one
//! definition).
//!
//! The depth case tells the definitions apart: ranking pooled over the set (checked below by
//! stacking the frames into one), other quarter boundaries, other tie-breaking or counting an
//! invalid output all give different figures.

#[path = "../../pipeline/tests/common/mod.rs"]
mod common;

use dear_capture::Flow;
use dear_eval::metrics::{
    aepe, DepthErrorSplit, Reliability, TemporalChange, CLASSES, MAX_EVAL_DEPTH_M,
    RELIABILITY_EDGES_CM, STATIC_TOLERANCE_M,
};
use ndarray::{concatenate, Array2, Axis, Zip};
use serde_json::Value;

/// Every depth is a multiple of 1/64 m, so the f32 arithmetic is exact; this only absorbs the
/// order of the f64 sums.
const TOL: f64 = 1e-9;

fn load(name: &str) -> Value {
    common::load_fixture(&format!("metrics/{name}.json"))
}

fn plane<T>((shape, data): (Vec<usize>, Vec<T>)) -> Array2<T> {
    assert_eq!(shape.len(), 2, "a plane has two dimensions: {shape:?}");
    Array2::from_shape_vec((shape[0], shape[1]), data).unwrap()
}

fn f32s(v: &Value) -> Array2<f32> {
    assert_eq!(v["dtype"], "f32");
    plane(common::f32_array(v))
}

fn bools(v: &Value) -> Array2<bool> {
    assert_eq!(v["dtype"], "bool");
    plane(common::bool_array(v))
}

fn u64s(v: &Value) -> Vec<u64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap())
        .collect()
}

fn close(got: f64, want: f64, what: &str) {
    assert!((got - want).abs() <= TOL, "{what}: got {got}, want {want}");
}

/// `(input, output, gt)` of each frame, the ground truth zeroed outside `valid` as
/// `dear_eval::report` does.
fn depth_frames(doc: &Value) -> Vec<(Array2<f32>, Array2<f32>, Array2<f32>)> {
    doc["inputs"]["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let valid = bools(&f["valid"]);
            let gt = Zip::from(&f32s(&f["gt"]))
                .and(&valid)
                .map_collect(|&g, &v| if v { g } else { 0.0 });
            (f32s(&f["input"]), f32s(&f["output"]), gt)
        })
        .collect()
}

fn check_split(split: &DepthErrorSplit, want: &Value, what: &str) {
    assert_eq!(
        split.counts.to_vec(),
        u64s(&want["counts"]),
        "{what}: counts"
    );
    assert_eq!(
        split.missing,
        want["missing"].as_u64().unwrap(),
        "{what}: missing"
    );
    for (k, s) in want["sums_m"].as_array().unwrap().iter().enumerate() {
        close(
            split.sums[k],
            s.as_f64().unwrap(),
            &format!("{what}: sum {k}"),
        );
    }
}

#[test]
fn depth_split_matches_the_fixture() {
    let doc = load("depth_error_split");
    let max_depth = doc["inputs"]["max_depth_m"].as_f64().unwrap() as f32;
    assert_eq!(max_depth, MAX_EVAL_DEPTH_M);
    let out = &doc["outputs"];
    let mut total = DepthErrorSplit::default();
    for (i, ((input, output, gt), want)) in depth_frames(&doc)
        .iter()
        .zip(out["per_frame"].as_array().unwrap())
        .enumerate()
    {
        let mut one = DepthErrorSplit::default();
        one.add_frame(input.view(), output.view(), gt.view(), max_depth);
        check_split(&one, want, &format!("frame {i}"));
        total.merge(&one);
    }
    check_split(&total, out, "total");
    for (k, c) in CLASSES.iter().enumerate() {
        close(
            total.mae_cm(k).unwrap(),
            out["mae_cm"][c].as_f64().unwrap(),
            &format!("mae_cm {c}"),
        );
    }
    close(
        total.mae_all_cm().unwrap(),
        out["mae_all_cm"].as_f64().unwrap(),
        "mae_all_cm",
    );
    close(
        total.coverage(),
        out["coverage"].as_f64().unwrap(),
        "coverage",
    );
}

/// The fixture tells per-frame ranking from ranking pooled over the set: the frames stacked
/// into one (row-major, so in the order a pooled implementation would concatenate them) give
/// another `low` class.
#[test]
fn pooled_ranking_would_fail_the_fixture() {
    let doc = load("depth_error_split");
    let frames = depth_frames(&doc);
    // 0: input, 1: output, 2: ground truth.
    let stack = |plane: usize| {
        let views: Vec<_> = frames
            .iter()
            .map(|f| [&f.0, &f.1, &f.2][plane].view())
            .collect();
        concatenate(Axis(0), &views).unwrap()
    };
    let (input, output, gt) = (stack(0), stack(1), stack(2));
    let mut pooled = DepthErrorSplit::default();
    pooled.add_frame(input.view(), output.view(), gt.view(), MAX_EVAL_DEPTH_M);
    let out = &doc["outputs"];
    close(
        pooled.mae_cm(0).unwrap(),
        out["pooled_ranking_low_mae_cm"].as_f64().unwrap(),
        "pooled low",
    );
    assert!((pooled.mae_cm(0).unwrap() - out["mae_cm"]["low"].as_f64().unwrap()).abs() > 0.1);
    assert_ne!(pooled.counts.to_vec(), u64s(&out["counts"]));
}

#[test]
fn aepe_matches_the_fixture() {
    let doc = load("aepe");
    let want = &doc["outputs"];
    let mut per_frame = Vec::new();
    for (i, (f, w)) in doc["inputs"]["frames"]
        .as_array()
        .unwrap()
        .iter()
        .zip(want["per_frame"].as_array().unwrap())
        .enumerate()
    {
        let estimate = Flow {
            u: f32s(&f["estimate_u"]),
            v: f32s(&f["estimate_v"]),
        };
        let truth = Flow {
            u: f32s(&f["truth_u"]),
            v: f32s(&f["truth_v"]),
        };
        let got = aepe(&estimate, &truth, bools(&f["valid"]).view());
        match (got, w.as_f64()) {
            (Some(g), Some(w)) => close(g, w, &format!("frame {i}")),
            (None, None) => {}
            (g, w) => panic!("frame {i}: got {g:?}, want {w:?}"),
        }
        per_frame.extend(got);
    }
    // A set's AEPE, as `dear_eval::report` accumulates it: the mean over frames that have one.
    let mean = per_frame.iter().sum::<f64>() / per_frame.len() as f64;
    close(
        mean,
        want["mean_over_frames"].as_f64().unwrap(),
        "mean over frames",
    );
}

/// A float32 plane that may hold the non-finite strings `"NaN"`, `"inf"`, `"-inf"` (JSON has no
/// such numbers; `reliability.json` and `temporal_change.json` write them so).
fn f32s_nonfinite(v: &Value) -> Array2<f32> {
    assert_eq!(v["dtype"], "f32");
    let shape: Vec<usize> = u64s(&v["shape"]).iter().map(|&d| d as usize).collect();
    let data = v["data"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| match x {
            Value::String(s) => match s.as_str() {
                "NaN" => f32::NAN,
                "inf" => f32::INFINITY,
                "-inf" => f32::NEG_INFINITY,
                other => panic!("unexpected element {other:?}"),
            },
            _ => x
                .as_f64()
                .unwrap_or_else(|| panic!("unexpected element {x}")) as f32,
        })
        .collect();
    plane((shape, data))
}

/// `plane` with the ground truth zeroed outside `valid`, as `dear_eval::report` passes it.
fn masked(gt: &Array2<f32>, valid: &Array2<bool>) -> Array2<f32> {
    Zip::from(gt)
        .and(valid)
        .map_collect(|&g, &v| if v { g } else { 0.0 })
}

/// The reliability case: predictions either side of bin edges (scaling to cm in f32 would move
/// the ones below up a bin), a zero prediction (in), non-finite predictions, invalid outputs and
/// ground truth beyond range or outside the mask (out), two empty bins.
#[test]
fn reliability_matches_the_fixture() {
    let doc = load("reliability");
    let max_depth = doc["inputs"]["max_depth_m"].as_f64().unwrap() as f32;
    assert_eq!(max_depth, MAX_EVAL_DEPTH_M);
    let edges: Vec<f64> = doc["inputs"]["edges_cm"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_f64().unwrap())
        .collect();
    assert_eq!(edges, RELIABILITY_EDGES_CM.to_vec());
    let mut rel = Reliability::default();
    let mut non_finite = 0;
    for f in doc["inputs"]["frames"].as_array().unwrap() {
        let predicted = f32s_nonfinite(&f["predicted"]);
        non_finite += predicted.iter().filter(|p| !p.is_finite()).count();
        let gt = masked(&f32s_nonfinite(&f["gt"]), &bools(&f["valid"]));
        rel.add_frame(
            f32s_nonfinite(&f["output"]).view(),
            predicted.view(),
            gt.view(),
            max_depth,
        );
    }
    assert_eq!(non_finite, 3, "the NaN, inf and -inf predictions are read");
    let want = &doc["outputs"];
    assert_eq!(rel.counts.to_vec(), u64s(&want["counts"]), "counts");
    for (name, got) in [
        ("predicted_sums_m", &rel.predicted),
        ("measured_sums_m", &rel.measured),
    ] {
        for (b, w) in want[name].as_array().unwrap().iter().enumerate() {
            close(got[b], w.as_f64().unwrap(), &format!("{name}[{b}]"));
        }
    }
    let bins = rel.bins();
    let want_bins = want["bins"].as_array().unwrap();
    assert_eq!(bins.len(), want_bins.len(), "non-empty bins");
    for (got, w) in bins.iter().zip(want_bins) {
        let what = format!("bin from {} cm", got.predicted_lo_cm);
        assert_eq!(
            got.predicted_lo_cm,
            w["predicted_lo_cm"].as_f64().unwrap(),
            "{what}"
        );
        assert_eq!(got.predicted_hi_cm, w["predicted_hi_cm"].as_f64(), "{what}");
        assert_eq!(got.pixels, w["pixels"].as_u64().unwrap(), "{what}");
        close(
            got.mean_predicted_cm,
            w["mean_predicted_cm"].as_f64().unwrap(),
            &format!("{what}: mean predicted"),
        );
        close(
            got.mean_measured_cm,
            w["mean_measured_cm"].as_f64().unwrap(),
            &format!("{what}: mean measured"),
        );
        // `eval.json` writes the bins with serde: the fixture's field names.
        let json = serde_json::to_value(got).unwrap();
        let mut keys: Vec<_> = json.as_object().unwrap().keys().collect();
        let mut want_keys: Vec<_> = w.as_object().unwrap().keys().collect();
        keys.sort();
        want_keys.sort();
        assert_eq!(keys, want_keys, "{what}: fields");
    }
}

/// The temporal-change case: the static tolerance at exactly float32(1e-3) (in) and one float32
/// step beyond (out), invalid depths or ground truth in either frame, the range cut-off, and
/// two pairs of different sizes (the mean is pooled over pixels, not over pairs).
#[test]
fn temporal_change_matches_the_fixture() {
    let doc = load("temporal_change");
    let max_depth = doc["inputs"]["max_depth_m"].as_f64().unwrap() as f32;
    assert_eq!(max_depth, MAX_EVAL_DEPTH_M);
    assert_eq!(
        doc["inputs"]["static_tolerance_m"].as_f64().unwrap() as f32,
        STATIC_TOLERANCE_M
    );
    let frames: Vec<(Array2<f32>, Array2<f32>)> = doc["inputs"]["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let gt = masked(&f32s_nonfinite(&f["gt"]), &bools(&f["valid"]));
            (f32s_nonfinite(&f["depth"]), gt)
        })
        .collect();
    let want = &doc["outputs"];
    let mut total = TemporalChange::default();
    assert_eq!(total.mean_cm(), None);
    let mut pair_means = Vec::new();
    for (i, (pair, w)) in frames
        .windows(2)
        .zip(want["per_pair"].as_array().unwrap())
        .enumerate()
    {
        let (previous, current) = (&pair[0], &pair[1]);
        let mut one = TemporalChange::default();
        for t in [&mut one, &mut total] {
            t.add_pair(
                (previous.0.view(), previous.1.view()),
                (current.0.view(), current.1.view()),
                max_depth,
            );
        }
        assert_eq!(one.count, w["count"].as_u64().unwrap(), "pair {i}: count");
        close(
            one.sum,
            w["sum_m"].as_f64().unwrap(),
            &format!("pair {i}: sum"),
        );
        pair_means.push(one.mean_cm().unwrap());
    }
    assert_eq!(pair_means.len(), 2);
    assert_eq!(total.count, want["count"].as_u64().unwrap(), "count");
    close(total.sum, want["sum_m"].as_f64().unwrap(), "sum");
    close(
        total.mean_cm().unwrap(),
        want["mean_cm"].as_f64().unwrap(),
        "mean_cm",
    );
    let mean_of_means = pair_means.iter().sum::<f64>() / pair_means.len() as f64;
    close(
        mean_of_means,
        want["mean_of_pair_means_cm"].as_f64().unwrap(),
        "mean of the pairs' means",
    );
    assert!((mean_of_means - total.mean_cm().unwrap()).abs() > 0.1);
}
