//! `models/edge-guarded` (issue 33): a guarded refiner publishes expected-error codes, and on
//! clean input — bright, single-bounce scenes, the measurement already right — it does less
//! harm than the shipped hybrid refiner, which "corrects" multi-path that is not there.

use std::path::PathBuf;

use dear_eval::{ground_truth_mask, BundleMethod, Evaluation};
use dear_pipeline::model::ModelBundle;
use dear_synth::family::Family;
use dear_synth::scene::Scene;
use dear_synth::simulate::simulate;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn the_guarded_refiner_does_less_harm_to_clean_depth_and_says_how_wrong_it_expects_to_be() {
    let (w, h) = (160, 120);
    // Seeds no test set uses; three frames of one clean module.
    let params = Family::Clean.draw(4343, 0, 3, w, h);
    let camera = params.camera();
    let guarded = ModelBundle::load(root().join("models/edge-guarded")).unwrap();
    let hybrid = ModelBundle::load(root().join("models/edge")).unwrap();
    let mut methods = [
        BundleMethod::new(&guarded, "guarded", h, w).unwrap(),
        BundleMethod::new(&hybrid, "hybrid", h, w).unwrap(),
    ];
    let mut eval = Evaluation::new();
    for i in 0..3 {
        let scene = Scene::random(camera, &params.scene, params.seed, i);
        let sample = simulate(&scene, &params.sim, params.seed, i).into_capture_sample(i, 0);
        let valid = ground_truth_mask(&sample).unwrap();
        eval.add("input", &sample, &raw(&sample), valid.view(), None);
        for m in &mut methods {
            let out = m.run_refine_only(&sample).unwrap().unwrap();
            if m.name() == "guarded" {
                let codes = out
                    .expected_error_code
                    .as_ref()
                    .expect("a guarded refiner's codes");
                for (z, c) in out.depth.iter().zip(codes) {
                    assert_eq!(*z > 0.0, *c > 0, "code 0 exactly where there is no depth");
                }
            } else {
                assert!(
                    out.expected_error_code.is_none(),
                    "the hybrid has no error maps"
                );
            }
            eval.add(m.name(), &sample, &out, valid.view(), None);
        }
    }
    let reports = eval.reports();
    let mae = |name: &str| {
        let r = reports.iter().find(|r| r.method == name).unwrap();
        (r.mae_all_cm.unwrap(), r.mae_cm[0].unwrap())
    };
    let (input, guarded, hybrid) = (mae("input"), mae("guarded"), mae("hybrid"));
    println!(
        "clean frames, MAE all (low quarter) cm: input {:.2} ({:.2}), guarded {:.2} ({:.2}), \
         hybrid {:.2} ({:.2})",
        input.0, input.1, guarded.0, guarded.1, hybrid.0, hybrid.1
    );
    assert!(
        guarded.0 < hybrid.0 && guarded.1 < hybrid.1,
        "{guarded:?} vs {hybrid:?}"
    );
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

/// The measurement as a method's output (the "ToF input" row).
fn raw(sample: &dear_capture::Sample) -> dear_eval::MethodOutput {
    dear_eval::MethodOutput {
        depth: sample.frame.depth.clone(),
        flow: None,
        flow_rough: None,
        calibration: None,
        seconds: 0.0,
        expected_error_code: None,
    }
}
