//! Loading and running model bundles: the committed untrained smoke bundle loads; tampered,
//! truncated, incomplete or mislabelled bundles are refused with errors that name the file;
//! padding to the size multiple is invisible to the caller.
#![cfg(feature = "inference")]

use std::path::{Path, PathBuf};

use dear_capture::Flow;
use dear_pipeline::model::{BundleError, BundleRunner, ModelBundle};
use ndarray::Array2;

fn smoke_bundle() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/bundles/smoke-edge")
}

/// A writable copy of the smoke bundle.
fn copy_bundle() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for f in ["model.json", "flow.onnx", "fuse.onnx", "refine.onnx"] {
        std::fs::copy(smoke_bundle().join(f), dir.path().join(f)).unwrap();
    }
    dir
}

fn edit_manifest(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join("model.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut v);
    std::fs::write(&path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

fn load_err(dir: &Path) -> BundleError {
    match ModelBundle::load(dir) {
        Ok(_) => panic!("{} loaded but should have been refused", dir.display()),
        Err(e) => e,
    }
}

#[test]
fn loads_the_committed_smoke_bundle() {
    let b = ModelBundle::load(smoke_bundle()).unwrap();
    let m = b.manifest();
    assert_eq!(m.tier, "edge");
    assert_eq!(b.input_size_multiple(), 8);
    assert_eq!(b.normalisation().max_depth_m, 10.0);
    assert_eq!(b.normalisation().amplitude_percentile, 99.0);
    assert!(b.refine_uses_rgb());
}

#[test]
fn a_flipped_byte_is_refused_naming_the_file_and_both_hashes() {
    let dir = copy_bundle();
    let path = dir.path().join("fuse.onnx");
    let mut bytes = std::fs::read(&path).unwrap();
    let i = bytes.len() / 2;
    bytes[i] ^= 0x01;
    std::fs::write(&path, &bytes).unwrap();
    let err = load_err(dir.path());
    let msg = err.to_string();
    match &err {
        BundleError::Checksum {
            path: p,
            expected,
            actual,
        } => {
            assert_eq!(p, &path);
            assert_ne!(expected, actual);
            assert!(
                msg.contains(expected.as_str()) && msg.contains(actual.as_str()),
                "{msg}"
            );
            assert!(msg.contains("fuse.onnx"), "{msg}");
        }
        other => panic!("expected a checksum error, got {other}"),
    }
}

#[test]
fn a_truncated_file_is_refused() {
    let dir = copy_bundle();
    let path = dir.path().join("refine.onnx");
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() - 100]).unwrap();
    let err = load_err(dir.path());
    assert!(
        matches!(&err, BundleError::Checksum { path: p, .. } if p == &path),
        "{err}"
    );
}

#[test]
fn missing_pieces_give_clear_errors() {
    let err = load_err(Path::new("/nonexistent/bundle"));
    assert!(matches!(err, BundleError::Missing { .. }), "{err}");

    let dir = copy_bundle();
    std::fs::remove_file(dir.path().join("model.json")).unwrap();
    let err = load_err(dir.path());
    assert!(
        matches!(&err, BundleError::Missing { path } if path.ends_with("model.json")),
        "{err}"
    );

    let dir = copy_bundle();
    std::fs::remove_file(dir.path().join("refine.onnx")).unwrap();
    let err = load_err(dir.path());
    assert!(
        matches!(&err, BundleError::Missing { path } if path.ends_with("refine.onnx")),
        "{err}"
    );

    let dir = copy_bundle();
    edit_manifest(dir.path(), |v| {
        v["graphs"].as_object_mut().unwrap().remove("fuse");
    });
    let err = load_err(dir.path());
    assert!(matches!(err, BundleError::Manifest { .. }), "{err}");
    assert!(err.to_string().contains("\"fuse\""), "{err}");
}

#[test]
fn invalid_manifests_are_refused() {
    let dir = copy_bundle();
    std::fs::write(dir.path().join("model.json"), "{ not json").unwrap();
    let err = load_err(dir.path());
    assert!(err.to_string().contains("not valid JSON"), "{err}");

    let dir = copy_bundle();
    edit_manifest(dir.path(), |v| v["format_version"] = 3.into());
    let err = load_err(dir.path());
    assert!(err.to_string().contains("format_version 3"), "{err}");

    // Format 2 without the refine graph's "apply" (what the chain would do with its output).
    let dir = copy_bundle();
    edit_manifest(dir.path(), |v| v["format_version"] = 2.into());
    let err = load_err(dir.path());
    assert!(err.to_string().contains("needs \"apply\""), "{err}");

    let dir = copy_bundle();
    edit_manifest(dir.path(), |v| v["format"] = "something-else".into());
    let err = load_err(dir.path());
    assert!(err.to_string().contains("something-else"), "{err}");

    // A graph file name that escapes the bundle directory.
    let dir = copy_bundle();
    edit_manifest(dir.path(), |v| {
        v["graphs"]["flow"]["file"] = "../flow.onnx".into()
    });
    let err = load_err(dir.path());
    assert!(
        matches!(err, BundleError::Contract { graph: "flow", .. }),
        "{err}"
    );
}

#[test]
fn a_wrong_input_name_is_refused() {
    // In the manifest.
    let dir = copy_bundle();
    edit_manifest(dir.path(), |v| {
        v["graphs"]["flow"]["inputs"][1]["name"] = "amp".into()
    });
    let err = load_err(dir.path());
    assert!(
        matches!(err, BundleError::Contract { graph: "flow", .. }),
        "{err}"
    );
    assert!(err.to_string().contains("\"amp\""), "{err}");

    // In the ONNX file (the manifest is right, the file is another graph): fuse.onnx shipped
    // as flow.onnx with a matching checksum.
    let dir = copy_bundle();
    std::fs::copy(dir.path().join("fuse.onnx"), dir.path().join("flow.onnx")).unwrap();
    let fuse = serde_json::from_str::<serde_json::Value>(
        &std::fs::read_to_string(dir.path().join("model.json")).unwrap(),
    )
    .unwrap()["graphs"]["fuse"]
        .clone();
    edit_manifest(dir.path(), |v| {
        v["graphs"]["flow"]["sha256"] = fuse["sha256"].clone();
        v["graphs"]["flow"]["bytes"] = fuse["bytes"].clone();
    });
    let err = load_err(dir.path());
    assert!(
        matches!(&err, BundleError::Contract { graph: "flow", path, .. } if path.ends_with("flow.onnx")),
        "{err}"
    );
    assert!(err.to_string().contains("flow_rough"), "{err}");
}

/// A smooth test flow with structure in both directions.
fn test_flow(h: usize, w: usize, k: f32) -> Flow {
    Flow {
        u: Array2::from_shape_fn((h, w), |(y, x)| {
            k * (x as f32 * 0.3).sin() + 0.05 * y as f32
        }),
        v: Array2::from_shape_fn((h, w), |(y, x)| {
            k * (y as f32 * 0.2).cos() - 0.03 * x as f32
        }),
    }
}

/// Replicate-pads a plane to `(hp, wp)`.
fn pad(a: &Array2<f32>, hp: usize, wp: usize) -> Array2<f32> {
    let (h, w) = a.dim();
    Array2::from_shape_fn((hp, wp), |(y, x)| a[[y.min(h - 1), x.min(w - 1)]])
}

#[test]
fn padding_to_the_size_multiple_is_invisible() {
    let bundle = ModelBundle::load(smoke_bundle()).unwrap();
    let (h, w) = (45, 61); // neither a multiple of 8
    let mut odd = BundleRunner::new(&bundle, w, h).unwrap();
    assert_eq!(odd.dim(), (45, 61));
    assert_eq!(odd.padded_dim(), (48, 64));
    let (rough, convt) = (test_flow(h, w, 2.0), test_flow(h, w, -1.5));
    let mut out = Flow::zeros(h, w);
    odd.fuse(&rough, &convt, &mut out).unwrap();

    // The same graph at the padded size, fed the replicate-padded inputs by hand.
    let mut exact = BundleRunner::new(&bundle, 64, 48).unwrap();
    assert_eq!(exact.padded_dim(), (48, 64));
    let padf = |f: &Flow| Flow {
        u: pad(&f.u, 48, 64),
        v: pad(&f.v, 48, 64),
    };
    let mut full = Flow::zeros(48, 64);
    exact.fuse(&padf(&rough), &padf(&convt), &mut full).unwrap();
    let mut max = 0.0f32;
    for y in 0..h {
        for x in 0..w {
            max = max
                .max((out.u[[y, x]] - full.u[[y, x]]).abs())
                .max((out.v[[y, x]] - full.v[[y, x]]).abs());
        }
    }
    assert!(
        max < 1e-5,
        "cropped output differs from the padded run by {max}"
    );
    assert!(out.u.iter().all(|v| v.is_finite()));
}

#[test]
fn bad_sizes_and_shapes_are_errors_not_panics() {
    let bundle = ModelBundle::load(smoke_bundle()).unwrap();
    let err = BundleRunner::new(&bundle, 0, 10).unwrap_err();
    assert!(matches!(err, BundleError::Resolution { .. }), "{err}");
    let err = BundleRunner::new(&bundle, 100_000, 10).unwrap_err();
    assert!(matches!(err, BundleError::Resolution { .. }), "{err}");

    let mut runner = BundleRunner::new(&bundle, 32, 24).unwrap();
    let good = Array2::<f32>::zeros((24, 32));
    let bad = Array2::<f32>::zeros((24, 31));
    let mut out = Flow::zeros(24, 32);
    let err = runner
        .flow(
            [good.view(), good.view(), bad.view()],
            good.view(),
            &mut out,
        )
        .unwrap_err();
    assert!(
        matches!(
            err,
            BundleError::InputShape {
                graph: "flow",
                input: "rgb",
                ..
            }
        ),
        "{err}"
    );
    let mut depth = Array2::zeros((24, 32));
    let err = runner
        .refine(good.view(), good.view(), None, None, depth.view_mut())
        .unwrap_err();
    assert!(err.to_string().contains("RGB"), "{err}");
}

#[test]
fn runners_can_move_to_another_thread() {
    fn assert_send<T: Send>() {}
    assert_send::<BundleRunner>();
    assert_send::<dear_pipeline::chain::DearChain>();
}
