//! `metrics::{DepthErrorSplit, aepe}` against the hand-computed cases in `fixtures/metrics/`
//! (made by `make_metrics.py` beside them; `train/tests/test_metrics_fixture.py` checks the
//! Python mirror in `train/dear_train/evaluation.py` against the same files, so both languages
//! compute one definition).
//!
//! The depth case tells the definitions apart: ranking pooled over the set (checked below by
//! stacking the frames into one), other quarter boundaries, other tie-breaking or counting an
//! invalid output all give different figures.

mod common;

use dear_pipeline::metrics::{aepe, DepthErrorSplit, CLASSES, MAX_EVAL_DEPTH_M};
use dear_pipeline::Flow;
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
/// `evaluate::report` does.
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
    // A set's AEPE, as `evaluate::report` accumulates it: the mean over frames that have one.
    let mean = per_frame.iter().sum::<f64>() / per_frame.len() as f64;
    close(
        mean,
        want["mean_over_frames"].as_f64().unwrap(),
        "mean over frames",
    );
}
