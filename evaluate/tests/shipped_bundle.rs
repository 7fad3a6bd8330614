//! The bundle the daemon runs by default (`models/edge`): it verifies, it was trained (its
//! manifest records the recipe and validation metrics), and through tract it makes the
//! bundled sample's depth better than the ToF input, measured against the sample's ground
//! truth with the same evaluation code as `dear eval`; on frames rendered aligned, the chain
//! finds (almost) no misalignment.

use std::path::{Path, PathBuf};

use dear_capture::CaptureDir;
use dear_eval::{
    ground_truth_flow, ground_truth_mask, BundleMethod, Evaluation, Method, MethodRunner,
    OnlineBundleMethod,
};
use dear_pipeline::engine::{typical_delay_frames, MeasurementSchedule};
use dear_pipeline::model::{ClassicalEstimate, ModelBundle};
use dear_pipeline::recalibration::OnlineConfig;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn the_shipped_edge_bundle_is_trained_and_improves_the_sample() {
    let dir = root().join("models/edge");
    let bundle = ModelBundle::load(&dir).expect("models/edge verifies");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("model.json")).unwrap()).unwrap();
    assert_eq!(manifest["tier"], "edge");
    let validation = &manifest["validation"];
    assert!(
        validation["aepe_rough"].as_f64().is_some(),
        "model.json records validation metrics: {validation}"
    );

    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let (w, h) = capture.size();
    let (w, h) = (w as usize, h as usize);
    let mut chain = BundleMethod::new(&bundle, "edge", h, w).unwrap();
    let mut classical = MethodRunner::new(h, w, capture.manifest().initial_calibration);
    let mut eval = Evaluation::new();
    for position in [0, capture.len() / 2, capture.len() - 1] {
        let sample = capture.read_sample(position).unwrap();
        let frame = &sample.frame;
        let valid = ground_truth_mask(&sample).unwrap();
        let truth = ground_truth_flow(&sample);
        let raw = classical.run(Method::RawTof, &sample).unwrap();
        eval.add("input", &sample, &raw, valid.view(), truth.as_ref());
        let out = chain.run(frame).unwrap();
        eval.add("edge", &sample, &out.refined, valid.view(), truth.as_ref());
    }
    let reports = eval.reports();
    let (input, edge) = (&reports[0], &reports[1]);
    let (mae_in, mae_out) = (input.mae_all_cm.unwrap(), edge.mae_all_cm.unwrap());
    assert!(
        mae_out < 0.9 * mae_in,
        "the shipped bundle should cut the sample's depth error by more than 10 %: \
         {mae_in:.2} cm in, {mae_out:.2} cm out"
    );
    assert!(edge.coverage > 0.95, "coverage {}", edge.coverage);
}

/// The daemon's online mode on the drifting sample (its engine, the measurements delivered as
/// late as deard's background worker typically delivers them at the sample's 15 fps):
/// following the principal point with the edge check between network runs must align better
/// than holding the last network estimate, and both better than the factory calibration
/// (`dear eval --online` measures the same on the 300-frame sequence of `scripts/results.sh`).
#[test]
fn online_tracking_follows_the_drifting_sample() {
    let bundle = ModelBundle::load(root().join("models/edge")).unwrap();
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let (w, h) = capture.size();
    let (w, h) = (w as usize, h as usize);
    let initial = capture.manifest().initial_calibration;
    let mut classical = MethodRunner::new(h, w, initial);
    let mut eval = Evaluation::new();
    let frames = &capture.manifest().frames;
    let fps = (frames.len() - 1) as f64
        / ((frames[frames.len() - 1].timestamp_ns - frames[0].timestamp_ns) as f64 * 1e-9);
    let schedule = MeasurementSchedule::Delayed(typical_delay_frames(w, h, fps));
    let mut runs: Vec<OnlineBundleMethod> = [("tracking", 0.7), ("held", 0.0)]
        .into_iter()
        .map(|(name, gain)| {
            let config = OnlineConfig {
                track_gain: gain,
                ..OnlineConfig::default()
            };
            OnlineBundleMethod::new(&bundle, name, (h, w), initial, config, schedule).unwrap()
        })
        .collect();
    for position in 0..capture.len() {
        let sample = capture.read_sample(position).unwrap();
        let frame = &sample.frame;
        let valid = ground_truth_mask(&sample).unwrap();
        let truth = ground_truth_flow(&sample);
        let fixed = classical.run(Method::StaticCalibration, &sample).unwrap();
        eval.add("static", &sample, &fixed, valid.view(), truth.as_ref());
        for method in &mut runs {
            let (out, _) = method.run(frame).unwrap();
            eval.add(method.name(), &sample, &out, valid.view(), truth.as_ref());
        }
    }
    let aepe = |name: &str| {
        let reports = eval.reports();
        let r = reports.iter().find(|r| r.method == name).unwrap();
        r.aepe_px.unwrap()
    };
    let (fixed, tracking, held) = (aepe("static"), aepe("tracking"), aepe("held"));
    println!("AEPE over the sample: static {fixed:.2} px, held {held:.2}, tracking {tracking:.2}");
    assert!(
        tracking < 0.8 * held && tracking < 0.8 * fixed,
        "static {fixed:.2} px, held estimate {held:.2} px, tracking {tracking:.2} px"
    );
}

/// The safety property of the shipped refiner, measured: depth the sensor got right should come
/// out nearly unchanged. The ground-truth depth of three sample frames (clean: no noise, no
/// multi-path error) goes through `refine.onnx` and its tail with the frame's amplitude and RGB
/// and, for a hybrid refiner, the classical filter's output on it, as the chain runs it.
/// Measured on 2026-11-25: the shipped hybrid refiner (10 epochs) moves it by 4.79 cm on
/// average within 4 m (90th percentile 11.08 cm); the same refiner after 3 epochs moved it by
/// 3.57 cm (p90 6.58 cm), the gated refiner (`models/edge-gated`) by 4.1 cm (p90 7.1 cm) and the
/// ToF-KPN (`models/edge-kpn`) by 16.8 cm (p90 32.2 cm). The bounds below fail the ToF-KPN by
/// a factor of three. They are far from "unchanged": the refiner subtracts part of the
/// multi-path error its training scenes had from depth that has none — here the amplitude and
/// RGB still show the real frame's multi-path corners while the depth is clean. The longer
/// training traded some of this for accuracy on real (noisy) input: at the true calibration
/// 8.34 vs 9.35 cm on the fixed-seed aligned set and 5.91 vs 6.01 cm on the held-out family,
/// the low-error quarter within +0.28 / +0.39 cm of the input (models/edge/README.md).
#[test]
fn the_shipped_refiner_bounds_its_change_to_clean_depth() {
    use dear_pipeline::chain::preprocess::{normalize_amplitude_into, rgb_planes_into};
    use dear_pipeline::model::BundleRunner;
    use ndarray::Array2;

    let bundle = ModelBundle::load(root().join("models/edge")).expect("models/edge verifies");
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let (w, h) = capture.size();
    let (w, h) = (w as usize, h as usize);
    let mut runner = BundleRunner::new(&bundle, w, h).unwrap();
    let mut classical = runner
        .refine_uses_classical()
        .then(dear_pipeline::filter::ClassicalRefiner::default);
    let (mut classical_depth, mut classical_confidence) =
        (Array2::zeros((h, w)), Array2::zeros((h, w)));
    let percentile = bundle.normalisation().amplitude_percentile;
    let (mut amp, mut out) = (Array2::zeros((h, w)), Array2::zeros((h, w)));
    let mut planes = [(); 3].map(|_| Array2::zeros((h, w)));
    let mut scratch = Vec::new();
    let mut changes = Vec::new();
    for position in [0, capture.len() / 2, capture.len() - 1] {
        let sample = capture.read_sample(position).unwrap();
        let frame = &sample.frame;
        let clean = sample
            .truth
            .depth
            .clone()
            .expect("the sample has ground truth");
        normalize_amplitude_into(
            frame.amplitude.view(),
            clean.view(),
            percentile,
            &mut scratch,
            amp.view_mut(),
        );
        rgb_planes_into(frame.rgb.view(), &mut planes);
        if let Some(refiner) = &mut classical {
            refiner.refine_into(
                clean.view(),
                frame.rgb.view(),
                classical_depth.view_mut(),
                classical_confidence.view_mut(),
            );
        }
        runner
            .refine(
                amp.view(),
                clean.view(),
                Some([planes[0].view(), planes[1].view(), planes[2].view()]),
                classical.is_some().then(|| ClassicalEstimate {
                    depth: classical_depth.view(),
                    confidence: classical_confidence.view(),
                }),
                out.view_mut(),
            )
            .unwrap();
        for (o, d) in out.iter().zip(clean.iter()) {
            if *d > 0.0 && *d <= 4.0 {
                changes.push((o - d).abs());
            }
        }
    }
    assert!(changes.len() > 10_000, "{} pixels", changes.len());
    let mean = changes.iter().sum::<f32>() / changes.len() as f32;
    changes.sort_by(f32::total_cmp);
    let p90 = changes[changes.len() * 9 / 10];
    println!(
        "clean depth through the shipped refiner: mean |change| {:.2} cm, p90 {:.2} cm",
        100.0 * mean,
        100.0 * p90
    );
    assert!(mean < 0.055, "mean change {:.2} cm", 100.0 * mean);
    assert!(p90 < 0.12, "p90 change {:.2} cm", 100.0 * p90);
}

/// Alignment on aligned input: on frames rendered with RGB and ToF on the same pixel grid (the
/// simulator's scenes, seeds no test set uses), the chain as the daemon runs it per frame
/// (`Full` mode: the rough-flow network, its least-squares calibration refined by the direct
/// fit to the frame's edges) must find almost no flow. The paper's chain alone (the network
/// and fusion, `direct_fit: None`) invented 0.9 px on RESULTS.md's aligned set.
#[test]
fn the_shipped_chain_finds_no_misalignment_in_aligned_frames() {
    use dear_synth::scene::{Camera, Scene, SceneConfig};
    use dear_synth::simulate::{simulate, SimConfig};

    let bundle = ModelBundle::load(root().join("models/edge")).unwrap();
    let (w, h) = (320, 240);
    let camera = Camera::from_hfov(w, h, 70.0);
    let mut chain = BundleMethod::new(&bundle, "edge", h, w).unwrap();
    let mut eval = Evaluation::new();
    for i in 0..4 {
        let scene = Scene::random(camera, &SceneConfig::default(), 4242, i);
        let sample = simulate(&scene, &SimConfig::default(), 4242, i).into_capture_sample(i, 0);
        let frame = &sample.frame;
        let valid = ground_truth_mask(&sample).unwrap();
        let truth = ground_truth_flow(&sample);
        let out = chain.run(frame).unwrap();
        eval.add("edge", &sample, &out.aligned, valid.view(), truth.as_ref());
    }
    let aepe = eval.reports()[0].aepe_px.unwrap();
    println!("AEPE of the shipped chain on 4 aligned frames: {aepe:.3} px");
    assert!(aepe <= 0.3, "AEPE {aepe:.3} px on aligned frames");
}

/// Overlapping frames (`finish_and_prepare`: a frame's refinement beside the next frame's
/// alignment, warps and classical stage) publishes exactly what processing them one by one
/// does: the halves write separate buffers. Run with the shipped (`hybrid`) bundle, whose
/// classical stage is part of the first half.
#[test]
fn overlapped_frames_publish_the_same_bits_as_one_by_one() {
    use dear_pipeline::chain::{ChainInput, ChainMode, ChainOutput, ChainReport, DearChain};
    use ndarray::Array2;

    let bundle = ModelBundle::load(root().join("models/edge")).unwrap();
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let (w, h) = capture.size();
    let (w, h) = (w as usize, h as usize);
    let calibration = capture.manifest().initial_calibration;
    // Each frame aligned with a slightly different calibration, as the online estimator's
    // would be: a frame must be aligned with its own.
    let mode = |k: usize| {
        let mut c = calibration;
        c.cx += 0.25 * k as f32;
        ChainMode::Cached(c)
    };
    let frames: Vec<_> = (0..4).map(|p| capture.read_frame(p).unwrap()).collect();
    let input = |k: usize| ChainInput::from(&frames[k]);
    let planes = || (Array2::<f32>::zeros((h, w)), Array2::<u8>::zeros((h, w)));
    let strip = |r: ChainReport| ChainReport {
        timings: Default::default(),
        ..r
    };

    let mut one_by_one = DearChain::new(&bundle, w, h).unwrap();
    let mut expected = Vec::new();
    for k in 0..frames.len() {
        let (mut depth, mut confidence) = planes();
        let output = ChainOutput {
            depth: depth.view_mut(),
            confidence: confidence.view_mut(),
        };
        let report = one_by_one.process(input(k), mode(k), output).unwrap();
        expected.push((strip(report), depth, confidence));
    }

    let mut overlapped = DearChain::new(&bundle, w, h).unwrap();
    let mut pending = Some(overlapped.prepare(input(0), mode(0)).unwrap());
    for (k, (report, depth, confidence)) in expected.into_iter().enumerate() {
        let (mut got_depth, mut got_confidence) = planes();
        let output = ChainOutput {
            depth: got_depth.view_mut(),
            confidence: got_confidence.view_mut(),
        };
        let prepared = pending.take().unwrap();
        let got = if k + 1 < frames.len() {
            let (finished, next) = overlapped.finish_and_prepare(
                prepared,
                frames[k].rgb.view(),
                output,
                input(k + 1),
                mode(k + 1),
            );
            pending = Some(next.unwrap());
            finished.unwrap()
        } else {
            overlapped
                .finish(prepared, frames[k].rgb.view(), output)
                .unwrap()
        };
        assert_eq!(strip(got), report, "frame {k}: report");
        assert!(
            got_depth
                .iter()
                .zip(&depth)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "frame {k}: depth differs"
        );
        assert_eq!(got_confidence, confidence, "frame {k}: confidence");
        assert!(depth.iter().any(|&z| z > 0.0), "frame {k} has depth");
    }
}

/// A frame can only be finished while it is the latest one prepared: finishing an older one
/// would publish another frame's buffers.
#[test]
#[should_panic(expected = "only the latest prepared frame can be finished")]
fn finishing_a_superseded_frame_is_refused() {
    use dear_pipeline::chain::{ChainInput, ChainMode, ChainOutput, DearChain};
    use ndarray::Array2;

    let bundle = ModelBundle::load(root().join("models/edge")).unwrap();
    let capture = CaptureDir::open(root().join("samples/demo")).unwrap();
    let (w, h) = capture.size();
    let (w, h) = (w as usize, h as usize);
    let frame = capture.read_frame(0).unwrap();
    let input = ChainInput::from(&frame);
    let mode = ChainMode::Cached(capture.manifest().initial_calibration);
    let mut chain = DearChain::new(&bundle, w, h).unwrap();
    let first = chain.prepare(input, mode).unwrap();
    let _second = chain.prepare(input, mode).unwrap();
    let (mut depth, mut confidence) = (Array2::zeros((h, w)), Array2::zeros((h, w)));
    let output = ChainOutput {
        depth: depth.view_mut(),
        confidence: confidence.view_mut(),
    };
    let _ = chain.finish(first, frame.rgb.view(), output);
}
