//! Issue 33: the shipped refiner leaves clean depth alone and still corrects multi-path.
//!
//! `models/edge`'s refine graph carries the multi-path gate
//! (`train/dear_train/models/multipath_gate.py`): a frame-level probability that the frame has
//! multi-path scales the refiner's bias, smoothing and pull towards the classical estimate.
//! Frames rendered here, at the true calibration, through tract and the daemon's tail, with
//! seeds no test set uses: bright single-bounce frames of the `clean` family must come out no
//! worse than the measurement (the refiner before the gate tripled their error), and frames of
//! a module with multi-path (`wide`, 3 bounces) must still come out far better than it.

use std::path::PathBuf;

use dear_eval::{ground_truth_mask, BundleMethod, Evaluation, MethodOutput};
use dear_pipeline::model::ModelBundle;
use dear_synth::family::Family;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// MAE within 4 m over all pixels and over the input's low-error quarter, in cm, of the input
/// and of the shipped refiner on `frames` frames of `family` at `w`×`h`.
fn input_and_refined(
    family: Family,
    seed: u64,
    frames: usize,
    (w, h): (usize, usize),
) -> [(f64, f64); 2] {
    let params = family.draw(seed, 0, frames, w, h);
    let bundle = ModelBundle::load(root().join("models/edge")).unwrap();
    let mut refiner = BundleMethod::new(&bundle, "edge", h, w).unwrap();
    let mut eval = Evaluation::new();
    for i in 0..frames as u64 {
        let sample = params.sample(i);
        let valid = ground_truth_mask(&sample).unwrap();
        let input = MethodOutput::measurement(&sample.frame);
        eval.add("input", &sample, &input, valid.view(), None);
        let out = refiner.run_refine_only(&sample).unwrap().unwrap();
        eval.add("edge", &sample, &out, valid.view(), None);
    }
    let reports = eval.reports();
    let mae = |name: &str| {
        let r = reports.iter().find(|r| r.method == name).unwrap();
        (r.mae_all_cm.unwrap(), r.mae_cm[0].unwrap())
    };
    [mae("input"), mae("edge")]
}

#[test]
fn clean_single_bounce_depth_comes_out_no_worse_than_it_went_in() {
    // 320×240 and a smaller module's 240×180 (the gate sees every stream on the same grid),
    // each with the low-error quarter's allowance over the input's (cm): issue 33's clean-family
    // bound at the size the families are rendered at (+0.05 measured; +0.12 with the jump term
    // on every pixel), its every-family bound at 240×180 (+0.12 measured; +0.16).
    for (size, allowance) in [((320, 240), 0.1), ((240, 180), 0.3)] {
        let [input, refined] = input_and_refined(Family::Clean, 4343, 3, size);
        println!(
            "clean frames at {size:?}, MAE all (low quarter) cm: input {:.2} ({:.2}), edge {:.2} ({:.2})",
            input.0, input.1, refined.0, refined.1
        );
        assert!(
            refined.0 <= input.0,
            "{size:?}: MAE {refined:?} vs input {input:?}"
        );
        // Where the classical filter replaced a pixel its estimate still wins, which costs a
        // little; before the gate these frames lost 2.66 cm (320×240).
        assert!(
            refined.1 <= input.1 + allowance,
            "{size:?}: low-error quarter {refined:?} vs input {input:?}"
        );
    }
}

#[test]
fn multi_path_is_still_corrected() {
    let [input, refined] = input_and_refined(Family::Wide, 4344, 3, (320, 240));
    println!(
        "wide module, multi-path, MAE all (low quarter) cm: input {:.2} ({:.2}), edge {:.2} ({:.2})",
        input.0, input.1, refined.0, refined.1
    );
    assert!(
        refined.0 < 0.85 * input.0,
        "MAE {refined:?} vs input {input:?}: the multi-path correction is off"
    );
}
