//! The simulator's outputs through the capture format: generate → read back → perturb →
//! sequence, checking contents, not only that files appear.

use std::path::Path;

use dear_capture::Calibration;
use dear_capture::CaptureDir;
use dear_synth::dataset::{generate, GenerateParams};
use dear_synth::perturb::{perturb_dir, PerturbMode, ViewSource, RENDERED_VIEW};
use dear_synth::scene::SceneConfig;
use dear_synth::sequence::{generate_sequence, DriftParams, SequenceParams};
use dear_synth::simulate::SimConfig;

/// Fast settings; direct light only, so ToF and ground truth must agree up to noise and flying
/// pixels (MPI is tested in `physics.rs`).
fn small_sim() -> SimConfig {
    let mut sim = SimConfig::default();
    sim.render.spp = 2;
    sim.render.max_bounces = 1;
    sim
}

/// `count` random scenes of `width`×`height` at 70° with [`small_sim`].
fn small_params(width: usize, height: usize, count: usize) -> GenerateParams {
    GenerateParams {
        width,
        height,
        hfov_deg: 70.0,
        count,
        seed: 5,
        sim: small_sim(),
        scene: SceneConfig::default(),
    }
}

#[test]
fn generate_then_perturb_round_trips_with_exact_flow() {
    let tmp = tempfile::tempdir().unwrap();
    let aligned = tmp.path().join("aligned");
    let params = small_params(64, 48, 3);
    let mut calls = 0;
    generate(&aligned, &params, |_| calls += 1).unwrap();
    assert_eq!(calls, 3);
    let dir = CaptureDir::open(&aligned).unwrap();
    assert_eq!(dir.len(), 3);
    assert_eq!(dir.manifest().modulation_frequencies_hz, vec![20e6]);
    assert!(dir.manifest().source["amplitude_gain_e_per_dn"].as_f64() == Some(4.0));
    for i in 0..3 {
        let dear_capture::Sample { frame: f, truth } = dir.read_sample(i).unwrap();
        let gt = truth.depth.as_ref().unwrap();
        let mask = truth.mask.as_ref().unwrap();
        // Aligned: the ToF depth agrees with the ground truth on most valid pixels (noise
        // and flying pixels aside), and the amplitude uses the 16-bit range.
        let mut errs: Vec<f32> = gt
            .indexed_iter()
            .filter(|(p, _)| mask[*p])
            .map(|(p, &z)| (f.depth[p] - z).abs())
            .collect();
        let within = errs.iter().filter(|&&e| e < 0.05).count() as f64 / errs.len() as f64;
        errs.sort_by(f32::total_cmp);
        let median = errs[errs.len() / 2];
        assert!(
            within > 0.6 && median < 0.04,
            "frame {i}: {within} within 5 cm, median {median}"
        );
        assert!(mask.iter().filter(|&&m| m).count() > 64 * 48 * 9 / 10);
        let amax = f.amplitude.iter().cloned().fold(0.0, f32::max);
        assert!(
            amax > 500.0,
            "amplitude barely uses the 16-bit range: {amax}"
        );
        assert!(truth.perturbation == Some(Calibration::default()) && truth.flow.is_none());
    }

    for view in [ViewSource::Render, ViewSource::Splat] {
        check_misaligned(&dir, &aligned, &tmp.path().join(format!("{view:?}")), view);
    }
}

/// `perturb_dir`'s output of an aligned 64×48 capture: ToF images kept, RGB moved, the flow
/// that of the recorded perturbation at the ground-truth depth on every valid pixel.
fn check_misaligned(dir: &CaptureDir, aligned: &Path, misaligned: &Path, view: ViewSource) {
    perturb_dir(
        aligned,
        misaligned,
        &PerturbMode::Gaussian { sigma_px: 2.0 },
        9,
        view,
        |_, _| {},
    )
    .unwrap();
    let mdir = CaptureDir::open(misaligned).unwrap();
    let rendered = mdir.manifest().source["view"].as_str() == Some(RENDERED_VIEW);
    assert_eq!(rendered, view == ViewSource::Render);
    for i in 0..3 {
        let a = dir.read_frame(i).unwrap();
        let dear_capture::Sample { frame: m, truth } = mdir.read_sample(i).unwrap();
        let p = truth.perturbation.expect("perturbation recorded");
        assert_eq!(mdir.manifest().frames[i].perturbation, Some(p));
        // ToF images unchanged; RGB moved.
        assert_eq!(a.depth, m.depth);
        assert_eq!(a.amplitude, m.amplitude);
        assert_ne!(a.rgb, m.rgb);
        let flow = truth.flow.as_ref().unwrap();
        let gt = truth.depth.as_ref().unwrap();
        let mask = truth.mask.as_ref().unwrap();
        let mut n = 0;
        for (q, &valid) in mask.indexed_iter() {
            if valid {
                // The GT PNG stores millimetres: t/z is known to |t|·0.5 mm / z².
                let z = gt[q];
                let (u, v) = p.flow_at(z).unwrap();
                let tol = |t: f32| t.abs() * 5e-4 / (z * z) + 1e-3;
                assert!((flow.u[q] - u).abs() < tol(p.tx) && (flow.v[q] - v).abs() < tol(p.ty));
                n += 1;
            }
        }
        // σ in px is meant for full-size images: on 64×48 a near object moves far.
        assert!(
            n > 64 * 48 * 2 / 5,
            "{view:?} frame {i}: {n} valid pixels under {p:?}"
        );
        if view == ViewSource::Render {
            // A camera sees the room everywhere: ground truth at every pixel of the view.
            assert!(gt.iter().all(|&z| z > 0.0), "frame {i}: holes in the view");
        }
    }
}

/// A capture the simulator did not write (no scene parameters) cannot be rendered again: the
/// error names the capture and the way out.
#[test]
fn rendering_a_capture_without_scene_parameters_is_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let aligned = tmp.path().join("aligned");
    generate(&aligned, &small_params(32, 24, 1), |_| {}).unwrap();
    let manifest = aligned.join("capture.json");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&manifest).unwrap()).unwrap();
    json["source"] = serde_json::json!({ "generator": "a camera" });
    std::fs::write(&manifest, json.to_string()).unwrap();
    let mode = PerturbMode::Gaussian { sigma_px: 2.0 };
    let out = tmp.path().join("out");
    let err = perturb_dir(&aligned, &out, &mode, 1, ViewSource::Render, |_, _| {}).unwrap_err();
    let text = format!("{err:#}");
    assert!(
        text.contains(&aligned.display().to_string()) && text.contains("--view splat"),
        "{text}"
    );
    perturb_dir(&aligned, &out, &mode, 1, ViewSource::Splat, |_, _| {}).unwrap();
}

#[test]
fn sequence_records_a_smooth_drift() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("seq");
    let params = SequenceParams {
        width: 48,
        height: 32,
        hfov_deg: 70.0,
        frames: 4,
        fps: 30.0,
        seed: 2,
        sim: small_sim(),
        scene: SceneConfig::default(),
        drift: DriftParams::default(),
        write_flow: true,
    };
    generate_sequence(&out, &params, |_| {}).unwrap();
    let dir = CaptureDir::open(&out).unwrap();
    let m = dir.manifest();
    assert_eq!(m.frames.len(), 4);
    let ps: Vec<_> = m.frames.iter().map(|f| f.perturbation.unwrap()).collect();
    assert_eq!(m.initial_calibration, ps[0]);
    assert!(ps
        .windows(2)
        .all(|w| w[0] != w[1] && (w[0].cx - w[1].cx).abs() < 0.5));
    // Frames differ (motion) but are all valid captures with flow.
    let (a, b) = (dir.read_sample(0).unwrap(), dir.read_sample(3).unwrap());
    assert_ne!(a.frame.depth, b.frame.depth);
    assert!(b.truth.flow.is_some() && b.truth.depth.is_some());
    assert!(m.frames[3].timestamp_ns > m.frames[0].timestamp_ns);
}
