//! `models/edge-guarded` (issue 33): a guarded refiner publishes an expected-error code exactly
//! where it publishes depth, and its rows carry a reliability table. (It was made to do less
//! harm to clean input than the hybrid refiner; the shipped hybrid now carries the multi-path
//! gate and leaves clean input alone, `multipath_gate.rs`, so that comparison is no longer the
//! guarded refiner's reason to exist: its expected errors are.)

use std::path::PathBuf;

use dear_eval::{ground_truth_mask, BundleMethod, Evaluation, MethodOutput};
use dear_pipeline::model::ModelBundle;
use dear_synth::family::Family;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn the_guarded_refiner_says_how_wrong_it_expects_to_be_wherever_it_publishes_depth() {
    let (w, h) = (160, 120);
    // Seeds no test set uses; three frames of one clean module.
    let params = Family::Clean.draw(4343, 0, 3, w, h);
    let guarded = ModelBundle::load(root().join("models/edge-guarded")).unwrap();
    let mut guarded = BundleMethod::new(&guarded, "guarded", h, w).unwrap();
    let mut eval = Evaluation::new();
    for i in 0..3 {
        let sample = params.sample(i);
        let valid = ground_truth_mask(&sample).unwrap();
        eval.add(
            "input",
            &sample,
            &MethodOutput::measurement(&sample.frame),
            valid.view(),
            None,
        );
        let out = guarded.run_refine_only(&sample).unwrap().unwrap();
        let codes = out
            .expected_error_code
            .as_ref()
            .expect("a guarded refiner's codes");
        for (z, c) in out.depth.iter().zip(codes) {
            assert_eq!(*z > 0.0, *c > 0, "code 0 exactly where there is no depth");
        }
        eval.add("guarded", &sample, &out, valid.view(), None);
    }
    let reports = eval.reports();
    let reliability = &reports
        .iter()
        .find(|r| r.method == "guarded")
        .unwrap()
        .reliability;
    assert!(
        !reliability.is_empty(),
        "the guarded rows carry a reliability table"
    );
}

/// The shipped bundle's expected-error floor (`apply.error_floor`, docs/models.md) on a frame of
/// the held-out family's noisier module: against the same bundle without the floor, the depth
/// is bit-identical, no pixel's expected error is lower, and some are higher (the head, trained
/// on less noise, predicts too little there).
#[test]
fn the_error_floor_only_raises_the_expected_error_and_leaves_the_depth_alone() {
    let (w, h) = (160, 120);
    let shipped = root().join("models/edge-guarded");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(shipped.join("model.json")).unwrap())
            .unwrap();
    assert!(
        manifest["graphs"]["refine"]["apply"]["error_floor"].is_object(),
        "the shipped guarded bundle has a floor"
    );
    // The same bundle without it: the graphs by symbolic link, the manifest edited.
    let without = tempfile::tempdir().unwrap();
    for file in ["flow.onnx", "fuse.onnx", "refine.onnx"] {
        std::os::unix::fs::symlink(shipped.join(file), without.path().join(file)).unwrap();
    }
    let mut edited = manifest.clone();
    edited["graphs"]["refine"]["apply"]
        .as_object_mut()
        .unwrap()
        .remove("error_floor");
    std::fs::write(
        without.path().join("model.json"),
        serde_json::to_string_pretty(&edited).unwrap(),
    )
    .unwrap();
    let floored = ModelBundle::load(&shipped).unwrap();
    let plain = ModelBundle::load(without.path()).unwrap();
    let mut floored = BundleMethod::new(&floored, "floored", h, w).unwrap();
    let mut plain = BundleMethod::new(&plain, "plain", h, w).unwrap();
    // A seed no test set uses.
    let sample = Family::Heldout.draw(4344, 0, 1, w, h).sample(0);
    let a = floored.run_refine_only(&sample).unwrap().unwrap();
    let b = plain.run_refine_only(&sample).unwrap().unwrap();
    assert_eq!(a.depth, b.depth, "the floor leaves the depth alone");
    let (ca, cb) = (
        a.expected_error_code.as_ref().unwrap(),
        b.expected_error_code.as_ref().unwrap(),
    );
    // A larger expected error is a smaller code.
    assert!(ca.iter().zip(cb).all(|(x, y)| x <= y));
    let raised = ca.iter().zip(cb).filter(|(x, y)| x < y).count();
    assert!(
        raised * 10 > ca.len(),
        "the floor raised {raised} of {} pixels' expected error",
        ca.len()
    );
}
