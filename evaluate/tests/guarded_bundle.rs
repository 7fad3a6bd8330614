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
