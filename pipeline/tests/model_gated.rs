//! Format-2 bundles: a `gated` refine graph (head maps at 1/4 resolution) run by tract, its
//! tail applied in Rust, equals PyTorch's whole refiner; malformed `apply` entries are refused.
//! The graph and the expected depth come from `fixtures/bundles/smoke-gated-refine/make.py`
//! (untrained weights), put into a copy of the smoke bundle.
#![cfg(feature = "inference")]

use std::path::{Path, PathBuf};

use dear_pipeline::model::{BundleRunner, ModelBundle};
use ndarray::Array2;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/bundles")
}

fn refine_doc() -> serde_json::Value {
    let path = fixtures().join("smoke-gated-refine/refine.json");
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The smoke bundle with the gated refiner in place of its own: a format-2 bundle.
fn gated_bundle(edit: impl FnOnce(&mut serde_json::Value)) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for f in ["model.json", "flow.onnx", "fuse.onnx"] {
        std::fs::copy(fixtures().join("smoke-edge").join(f), dir.path().join(f)).unwrap();
    }
    std::fs::copy(
        fixtures().join("smoke-gated-refine/refine.onnx"),
        dir.path().join("refine.onnx"),
    )
    .unwrap();
    let path = dir.path().join("model.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let doc = refine_doc();
    m["graphs"]["refine"] = doc["graph"].clone();
    m["variant"] = doc["variant"].clone();
    m["format_version"] = 2.into();
    edit(&mut m);
    std::fs::write(&path, serde_json::to_string_pretty(&m).unwrap()).unwrap();
    dir
}

fn plane(doc: &serde_json::Value, key: &str, h: usize, w: usize, k: usize) -> Array2<f32> {
    let data: Vec<f32> = doc[key].as_array().unwrap()[k * h * w..(k + 1) * h * w]
        .iter()
        .map(|v| v.as_f64().unwrap() as f32)
        .collect();
    Array2::from_shape_vec((h, w), data).unwrap()
}

#[test]
fn gated_refiner_through_tract_and_the_rust_tail_equals_pytorch() {
    let dir = gated_bundle(|_| {});
    let bundle = ModelBundle::load(dir.path()).unwrap();
    assert_eq!(bundle.manifest().format_version, 2);
    assert_eq!(bundle.refine_apply().unwrap().stride, 4);
    let doc = refine_doc();
    let case = &doc["case"];
    let (h, w) = (
        case["height"].as_u64().unwrap() as usize,
        case["width"].as_u64().unwrap() as usize,
    );
    let amp = plane(case, "amplitude", h, w, 0);
    let depth = plane(case, "depth", h, w, 0);
    let rgb = [0, 1, 2].map(|k| plane(case, "rgb", h, w, k));
    let want = plane(case, "out", h, w, 0);
    let mut runner = BundleRunner::new(&bundle, w, h).unwrap();
    let mut out = Array2::zeros((h, w));
    runner
        .refine(
            amp.view(),
            depth.view(),
            Some([rgb[0].view(), rgb[1].view(), rgb[2].view()]),
            None,
            out.view_mut(),
        )
        .unwrap();
    let worst = out
        .iter()
        .zip(want.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    println!("format-2 refiner, tract + Rust tail vs PyTorch: max |Δ| = {worst:.2e} m");
    assert!(worst < 1e-4, "max |Δ| = {worst} m");
    for (o, d) in out.iter().zip(depth.iter()) {
        if *d == 0.0 {
            assert_eq!(*o, 0.0, "holes stay holes");
        }
    }
}

/// An edit of a manifest.
type Edit = Box<dyn Fn(&mut serde_json::Value)>;

/// Makes the gated manifest's `apply` a well-formed guarded one (the graph is not run).
fn guarded(m: &mut serde_json::Value) {
    let a = &mut m["graphs"]["refine"]["apply"];
    a["kind"] = "guarded-kernel".into();
    a["channels"] = 16.into();
    a["jump_scale"] = 300.0.into();
    a["error_unit"] = 0.001.into();
    a["log_error_bound"] = 6.0.into();
}

#[test]
fn malformed_apply_entries_are_refused_by_name() {
    let cases: [(&str, Edit); 15] = [
        (
            "apply.kind \"sharpen\"",
            Box::new(|m| m["graphs"]["refine"]["apply"]["kind"] = "sharpen".into()),
        ),
        (
            "a hybrid-kernel head has 13",
            Box::new(|m| m["graphs"]["refine"]["apply"]["kind"] = "hybrid-kernel".into()),
        ),
        (
            "apply.jump_scale belongs to \"hybrid-kernel\" and \"guarded-kernel\", not \"gated-kernel\"",
            Box::new(|m| m["graphs"]["refine"]["apply"]["jump_scale"] = 300.0.into()),
        ),
        (
            "apply.jump_on belongs to \"hybrid-kernel\" and \"guarded-kernel\", not \"gated-kernel\"",
            Box::new(|m| m["graphs"]["refine"]["apply"]["jump_on"] = "replaced".into()),
        ),
        (
            "unknown variant `smoothed`, expected `every-pixel` or `replaced`",
            Box::new(|m| {
                guarded(m);
                m["graphs"]["refine"]["apply"]["jump_on"] = "smoothed".into();
            }),
        ),
        (
            "apply.error_unit belongs to \"guarded-kernel\", not \"gated-kernel\"",
            Box::new(|m| m["graphs"]["refine"]["apply"]["error_unit"] = 0.001.into()),
        ),
        (
            "a guarded-kernel head has 16",
            Box::new(|m| m["graphs"]["refine"]["apply"]["kind"] = "guarded-kernel".into()),
        ),
        (
            "apply.error_unit is required for \"guarded-kernel\"",
            Box::new(|m| {
                let a = &mut m["graphs"]["refine"]["apply"];
                a["kind"] = "guarded-kernel".into();
                a["channels"] = 16.into();
                a["jump_scale"] = 300.0.into();
            }),
        ),
        (
            "apply.error_floor belongs to \"guarded-kernel\", not \"gated-kernel\"",
            Box::new(|m| {
                m["graphs"]["refine"]["apply"]["error_floor"] =
                    serde_json::json!({"scale": 1.0, "radius": 2, "cap_m": 0.16});
            }),
        ),
        (
            "apply.error_floor.radius 9 must be 1 to 8",
            Box::new(|m| {
                guarded(m);
                m["graphs"]["refine"]["apply"]["error_floor"] =
                    serde_json::json!({"scale": 1.0, "radius": 9, "cap_m": 0.16});
            }),
        ),
        (
            "apply.error_floor.cap_m 0 is not a positive number",
            Box::new(|m| {
                guarded(m);
                m["graphs"]["refine"]["apply"]["error_floor"] =
                    serde_json::json!({"scale": 1.0, "radius": 2, "cap_m": 0.0});
            }),
        ),
        (
            "apply.stride 3",
            Box::new(|m| m["graphs"]["refine"]["apply"]["stride"] = 3.into()),
        ),
        (
            "apply.max_bias",
            Box::new(|m| m["graphs"]["refine"]["apply"]["max_bias"] = (-1.0).into()),
        ),
        (
            "needs format_version 2",
            Box::new(|m| m["format_version"] = 1.into()),
        ),
        (
            "only the refine graph",
            Box::new(|m| {
                m["graphs"]["flow"]["apply"] = m["graphs"]["refine"]["apply"].clone();
            }),
        ),
    ];
    for (needle, edit) in cases {
        let dir = gated_bundle(edit);
        let err = ModelBundle::load(dir.path()).expect_err(needle).to_string();
        assert!(err.contains(needle), "{needle}: {err}");
        assert!(
            err.contains("model.json"),
            "the error names the manifest: {err}"
        );
    }
}
