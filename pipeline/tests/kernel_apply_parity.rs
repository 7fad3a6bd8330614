//! The gated, hybrid and guarded refiners' tails in Rust (`model::kernel_apply`) against
//! PyTorch (`fixtures/kernel_apply/{gated,hybrid,guarded}.json`, made by `make_gated.py`).

#![cfg(feature = "inference")]

mod common;

use dear_pipeline::model::kernel_apply::{
    apply_gated, blend_classical, select_guarded, ClassicalEstimate, ErrorMaps, GatedKernel,
    GATED_CHANNELS, GUARDED_CHANNELS, HYBRID_CHANNELS,
};
use dear_pipeline::model::manifest::JumpOn;
use ndarray::{Array2, Array3};

#[test]
fn gated_tail_matches_pytorch() {
    let doc = fixture("gated.json");
    let depth = plane(&doc["depth"]);
    let maps = maps(&doc, GATED_CHANNELS);
    let (_, want) = common::f32_array(&doc["out"]);
    let kernel = kernel(&doc, None, None);
    let mut out = Array2::zeros(depth.dim());
    apply_gated(&maps, depth.view(), out.view_mut(), &kernel);
    let mut worst = 0.0f32;
    for ((got, want), d) in out.iter().zip(&want).zip(depth.iter()) {
        if *d == 0.0 {
            assert_eq!(*got, 0.0, "a hole must stay a hole");
        }
        worst = worst.max((got - want).abs());
    }
    println!("gated tail vs PyTorch: max |Δ| = {worst:.2e} m");
    assert!(worst < 1e-5, "max |Rust − PyTorch| = {worst} m");
    // The case exercises what it claims: the output differs from the input.
    let moved = out
        .iter()
        .zip(depth.iter())
        .filter(|(o, d)| (*o - *d).abs() > 1e-3)
        .count();
    assert!(moved > out.len() / 4, "only {moved} pixels changed");
}

/// The hybrid refinement of `depth`: the per-pixel blend with the classical estimate (its
/// confidence: measured everywhere unless given), then the gated kernel (what the guarded tail
/// selects its `refined` candidate from).
fn hybrid_tail(
    maps: &[Array2<f32>],
    depth: &Array2<f32>,
    classical: &Array2<f32>,
    confidence: Option<&Array2<u8>>,
    kernel: &GatedKernel,
) -> Array2<f32> {
    let mut base = Array2::zeros(depth.dim());
    let mut out = Array2::zeros(depth.dim());
    let measured = Array2::from_elem(depth.dim(), 255u8);
    let estimate = ClassicalEstimate {
        depth: classical.view(),
        confidence: confidence.unwrap_or(&measured).view(),
    };
    blend_classical(maps, depth.view(), estimate, base.view_mut(), kernel);
    apply_gated(maps, base.view(), out.view_mut(), kernel);
    out
}

/// The largest |a − b| over two planes of one shape.
fn max_abs_diff(a: &Array2<f32>, b: &Array2<f32>) -> f32 {
    assert_eq!(a.dim(), b.dim());
    a.iter()
        .zip(b.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max)
}

fn fixture(name: &str) -> serde_json::Value {
    common::load_fixture(&format!("kernel_apply/{name}"))
}

fn plane(v: &serde_json::Value) -> Array2<f32> {
    let (s, d) = common::f32_array(v);
    Array2::from_shape_vec((s[0], s[1]), d).unwrap()
}

/// The fixture's `channels` maps, one plane each.
fn maps(doc: &serde_json::Value, channels: usize) -> Vec<Array2<f32>> {
    let (ms, md) = common::f32_array(&doc["maps"]);
    assert_eq!(ms[0], channels);
    let maps3 = Array3::from_shape_vec((ms[0], ms[1], ms[2]), md).unwrap();
    maps3.outer_iter().map(|m| m.to_owned()).collect()
}

/// The kernel of a fixture: its stride and depth scale, the exporter's constants (checked
/// against the Python side by `train/tests/test_kernel_apply_fixture.py`).
fn kernel(
    doc: &serde_json::Value,
    jump_scale: Option<f32>,
    errors: Option<ErrorMaps>,
) -> GatedKernel {
    GatedKernel {
        stride: doc["stride"].as_u64().unwrap() as usize,
        max_bias: 0.05,
        range_scale: 100.0,
        max_depth_m: doc["max_depth_m"].as_f64().unwrap() as f32,
        jump_scale,
        jump_on: JumpOn::EveryPixel,
        errors,
    }
}

#[test]
fn hybrid_tail_matches_pytorch() {
    let doc = fixture("hybrid.json");
    let depth = plane(&doc["depth"]);
    let classical = plane(&doc["classical"]);
    let maps = maps(&doc, HYBRID_CHANNELS);
    let want = plane(&doc["out"]);
    let kernel = kernel(&doc, Some(300.0), None);
    let out = hybrid_tail(&maps, &depth, &classical, None, &kernel);
    let worst = max_abs_diff(&out, &want);
    println!("hybrid tail vs PyTorch: max |Δ| = {worst:.2e} m");
    assert!(worst < 1e-5, "max |Rust − PyTorch| = {worst} m");
    // The case exercises both sources: some outputs follow the classical estimate far from
    // the measurement, and holes in the measurement are filled.
    let followed_jumps = out
        .iter()
        .zip(depth.iter())
        .filter(|(o, d)| **d > 0.0 && (*o - *d).abs() > 0.2)
        .count();
    let filled = out
        .iter()
        .zip(depth.iter())
        .filter(|(o, d)| **d == 0.0 && **o > 0.0)
        .count();
    assert!(
        followed_jumps > 5 && filled > 5,
        "{followed_jumps} jumps, {filled} fills"
    );
}

#[test]
fn hybrid_tail_with_the_jump_on_replaced_pixels_matches_pytorch() {
    let doc = fixture("hybrid_replaced.json");
    let depth = plane(&doc["depth"]);
    let classical = plane(&doc["classical"]);
    let confidence = plane(&doc["classical_confidence"]).mapv(|c| c as u8);
    let maps = maps(&doc, HYBRID_CHANNELS);
    let want = plane(&doc["out"]);
    let kernel = GatedKernel {
        jump_on: JumpOn::Replaced,
        ..kernel(&doc, Some(300.0), None)
    };
    let out = hybrid_tail(&maps, &depth, &classical, Some(&confidence), &kernel);
    let worst = max_abs_diff(&out, &want);
    println!("hybrid tail, jump on replaced pixels, vs PyTorch: max |Δ| = {worst:.2e} m");
    assert!(worst < 1e-5, "max |Rust − PyTorch| = {worst} m");
    // The case exercises the restriction: with the jump everywhere, some far moves the filter
    // measured (smoothed) are followed that are not followed here.
    let every = hybrid_tail(
        &maps,
        &depth,
        &classical,
        Some(&confidence),
        &GatedKernel {
            jump_on: JumpOn::EveryPixel,
            ..kernel
        },
    );
    let differ = out
        .iter()
        .zip(every.iter())
        .filter(|(a, b)| (*a - *b).abs() > 0.1)
        .count();
    assert!(differ > 5, "only {differ} pixels depend on the restriction");
}

#[test]
fn guarded_tail_matches_pytorch() {
    let doc = fixture("guarded.json");
    let depth = plane(&doc["depth"]);
    let classical = plane(&doc["classical"]);
    let maps = maps(&doc, GUARDED_CHANNELS);
    let want = plane(&doc["out"]);
    let want_log_error = plane(&doc["log_error"]);
    let errors = ErrorMaps {
        unit: common::f32_array(&doc["error_unit"]).1[0],
        log_bound: 6.0,
        floor: None,
    };
    let kernel = kernel(&doc, Some(300.0), Some(errors));
    let refined = hybrid_tail(&maps, &depth, &classical, None, &kernel);
    // select_guarded takes the refined candidate in the plane it publishes into.
    let mut out = refined.clone();
    let mut log_error = Array2::zeros(depth.dim());
    select_guarded(
        &maps,
        depth.view(),
        classical.view(),
        out.view_mut(),
        log_error.view_mut(),
        &kernel,
    );
    let mut worst = (0.0f32, 0.0f32);
    for (((got, want), got_e), want_e) in out.iter().zip(&want).zip(&log_error).zip(&want_log_error)
    {
        worst.0 = worst.0.max((got - want).abs());
        if *want_e >= 1e29 {
            assert!(got_e.is_infinite() && *got == 0.0, "nothing to publish");
        } else {
            worst.1 = worst.1.max((got_e - want_e).abs());
        }
    }
    println!(
        "guarded tail vs PyTorch: max |Δ depth| = {:.2e} m, max |Δ ln error| = {:.2e}",
        worst.0, worst.1
    );
    assert!(worst.0 < 1e-5 && worst.1 < 1e-5, "{worst:?}");
    // Every candidate is published somewhere, and nothing where no candidate is valid.
    let count = |f: &dyn Fn(usize) -> bool| (0..out.len()).filter(|&i| f(i)).count();
    let (o, r, d, c) = (
        out.as_slice().unwrap(),
        refined.as_slice().unwrap(),
        depth.as_slice().unwrap(),
        classical.as_slice().unwrap(),
    );
    let took_refined = count(&|i| o[i] == r[i] && r[i] != d[i] && r[i] != c[i]);
    let took_measured = count(&|i| o[i] == d[i] && d[i] > 0.0 && r[i] != d[i]);
    let took_classical = count(&|i| o[i] == c[i] && c[i] > 0.0 && r[i] != c[i] && d[i] != c[i]);
    assert!(
        took_refined > 20 && took_measured > 20 && took_classical > 20,
        "refined {took_refined}, measured {took_measured}, classical {took_classical}"
    );
    assert!(
        count(&|i| d[i] == 0.0 && c[i] == 0.0) > 0,
        "the case has empty pixels"
    );
}
