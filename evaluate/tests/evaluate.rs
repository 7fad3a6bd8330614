//! The evaluation engine on a scene with known misalignment: the oracle calibration must beat
//! the static one, and the numbers must match what the geometry implies.

use dear_capture::{Calibration, RgbdFrame};
use dear_capture::{GroundTruth, Sample};
use dear_eval::{ground_truth_flow, ground_truth_mask, Evaluation, Method, MethodRunner};
use dear_pipeline::geometry::synthesize_view;
use ndarray::{Array2, Array3};

fn misaligned_frame(perturbation: Calibration) -> Sample {
    let (h, w) = (96, 128);
    let tof_depth = Array2::from_shape_fn((h, w), |(y, x)| {
        if (30..70).contains(&y) && (40..80).contains(&x) {
            1.0
        } else {
            2.0 + 0.005 * x as f32
        }
    });
    let rgb = Array3::from_shape_fn((h, w, 3), |(y, x, k)| {
        ((x * 3 + y * 5 + k * 40) % 256) as u8
    });
    let view = synthesize_view(rgb.view(), tof_depth.view(), &perturbation);
    let amplitude = tof_depth.mapv(|z| 1000.0 / (z * z));
    Sample {
        frame: RgbdFrame::new(0, 0, view.rgb, amplitude, tof_depth),
        truth: GroundTruth {
            depth: Some(view.depth),
            mask: Some(view.valid),
            flow: Some(view.flow),
            perturbation: Some(perturbation),
        },
    }
}

#[test]
fn oracle_beats_static_and_static_aepe_is_the_true_flow() {
    let p = Calibration {
        tx: 5.0,
        ty: 0.0,
        cx: 2.0,
        cy: -1.0,
    };
    let sample = misaligned_frame(p);
    let valid = ground_truth_mask(&sample).unwrap();
    let truth = ground_truth_flow(&sample);
    let mut runner = MethodRunner::new(96, 128, Calibration::IDENTITY);
    let mut eval = Evaluation::new();
    for method in [
        Method::RawTof,
        Method::StaticCalibration,
        Method::OracleCalibration,
    ] {
        let out = runner.run(method, &sample).unwrap();
        eval.add(method.name(), &sample, &out, valid.view(), truth.as_ref());
    }
    let reports = eval.reports();
    let by = |name: &str| reports.iter().find(|r| r.method == name).unwrap().clone();
    let (raw, fixed, oracle) = (
        by("raw-tof"),
        by("static-calibration"),
        by("oracle-calibration"),
    );

    // Identity calibration aligns nothing: same depth error as the raw input; its flow is zero,
    // so its AEPE is the mean true flow magnitude (|(t/z + c_x, c_y)|) over valid pixels.
    assert!((raw.mae_all_cm.unwrap() - fixed.mae_all_cm.unwrap()).abs() < 1e-6);
    let truth = sample.truth.flow.as_ref().unwrap();
    let (mut sum, mut n) = (0.0f64, 0usize);
    for ((u, v), ok) in truth.u.iter().zip(truth.v.iter()).zip(valid.iter()) {
        if *ok {
            sum += ((u * u + v * v) as f64).sqrt();
            n += 1;
        }
    }
    assert!((fixed.aepe_px.unwrap() - sum / n as f64).abs() < 1e-4);
    // The oracle aligns: errors collapse (edges keep a little).
    assert!(
        oracle.aepe_px.unwrap() < 0.2,
        "oracle AEPE {:?}",
        oracle.aepe_px
    );
    assert!(
        oracle.mae_all_cm.unwrap() < 0.2 * raw.mae_all_cm.unwrap(),
        "{oracle:?} vs {raw:?}"
    );
    assert!(eval.markdown().contains("| oracle-calibration |"));
}

#[test]
fn frames_without_ground_truth_are_rejected_by_name() {
    let mut sample = misaligned_frame(Calibration::IDENTITY);
    sample.frame.index = 42;
    sample.truth.depth = None;
    let err = ground_truth_mask(&sample).unwrap_err().to_string();
    assert!(err.contains("000042.gt.png"), "{err}");
}

#[test]
fn ground_truth_flow_comes_from_the_perturbation_when_no_flow_file_exists() {
    let p = Calibration {
        tx: 4.0,
        ty: -2.0,
        cx: 1.5,
        cy: 0.5,
    };
    let mut sample = misaligned_frame(p);
    sample.truth.flow = None;
    let flow = ground_truth_flow(&sample).unwrap();
    let gt = sample.truth.depth.as_ref().unwrap();
    for ((&z, &u), &v) in gt.iter().zip(flow.u.iter()).zip(flow.v.iter()) {
        if z > 0.0 {
            assert!((u - (4.0 / z + 1.5)).abs() < 1e-5 && (v - (-2.0 / z + 0.5)).abs() < 1e-5);
        } else {
            assert!(u.is_nan() && v.is_nan());
        }
    }
    sample.truth.perturbation = None;
    assert!(ground_truth_flow(&sample).is_none());
}
