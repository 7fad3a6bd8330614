//! The Rust reader against the capture fixtures both languages check (fixtures/capture/README.md;
//! the Python side is train/tests/test_capture_cross_language.py): it reads `samples/demo` as
//! `demo_digest.json` says, reads the capture the Python writer wrote (`python_written/`) value
//! for value, and refuses every manifest of `bad_manifests.json`.

use std::fs;
use std::path::{Path, PathBuf};

use dear_capture::manifest::CaptureManifest;
use dear_capture::{png, Calibration, CaptureDir, CaptureError, Flow, Sample};
use serde_json::Value;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn fixture(name: &str) -> PathBuf {
    repo().join("fixtures/capture").join(name)
}

fn load(name: &str) -> Value {
    let path = fixture(name);
    let text = fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn f32_of(v: &Value) -> f32 {
    v.as_f64().unwrap_or_else(|| panic!("{v} is not a number")) as f32
}

fn u64_of(v: &Value) -> u64 {
    v.as_u64().unwrap_or_else(|| panic!("{v} is not a u64"))
}

fn calibration(v: &Value) -> Option<Calibration> {
    (!v.is_null()).then(|| Calibration {
        tx: f32_of(&v["tx"]),
        ty: f32_of(&v["ty"]),
        cx: f32_of(&v["cx"]),
        cy: f32_of(&v["cy"]),
    })
}

/// The manifest's numbers as the fixture gives them (each rounded to f32, as serde reads them).
fn check_manifest(m: &CaptureManifest, want: &Value) {
    assert_eq!(u64::from(m.width), u64_of(&want["width"]));
    assert_eq!(u64::from(m.height), u64_of(&want["height"]));
    let k = &want["intrinsics"];
    assert_eq!(
        [
            m.intrinsics.fx,
            m.intrinsics.fy,
            m.intrinsics.cx,
            m.intrinsics.cy
        ],
        [
            f32_of(&k["fx"]),
            f32_of(&k["fy"]),
            f32_of(&k["cx"]),
            f32_of(&k["cy"])
        ]
    );
    assert_eq!(
        Some(m.initial_calibration),
        calibration(&want["initial_calibration"])
    );
    assert_eq!(m.depth_scale, f32_of(&want["depth_scale"]));
    let distortion = want["distortion"]
        .as_array()
        .map(|d| <[f32; 5]>::try_from(d.iter().map(f32_of).collect::<Vec<_>>()).unwrap());
    assert_eq!(m.distortion, distortion);
    let freqs: Vec<f64> = want["modulation_frequencies_hz"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_f64().unwrap())
        .collect();
    assert_eq!(m.modulation_frequencies_hz, freqs);
}

/// The stored 16-bit units of a depth plane the reader gave in metres; the reader's metres
/// must be exactly `units · depth_scale` in f32 (the format's definition).
fn depth_units(depth: &ndarray::Array2<f32>, scale: f32) -> Vec<u64> {
    depth
        .iter()
        .map(|&d| {
            let units = (d / scale).round();
            assert!((0.0..=65535.0).contains(&units), "{d} m");
            assert_eq!(
                (units as u16 as f32 * scale).to_bits(),
                d.to_bits(),
                "{d} m is not a whole number of depth units"
            );
            units as u64
        })
        .collect()
}

/// Raw amplitude as the whole numbers stored.
fn amplitude_units(amplitude: &ndarray::Array2<f32>) -> Vec<u64> {
    amplitude
        .iter()
        .map(|&a| {
            assert!(a.fract() == 0.0 && (0.0..=65535.0).contains(&a), "{a}");
            a as u64
        })
        .collect()
}

/// `{"sum", "weighted"}` of make_capture_fixtures.py's `plane_digest`: Σ v and
/// Σ v[k] · (k mod 65521 + 1) over the row-major flat index k.
fn digest(values: impl IntoIterator<Item = u64>) -> Value {
    let (sum, weighted) = values
        .into_iter()
        .enumerate()
        .fold((0u64, 0u64), |(s, w), (k, v)| {
            (s + v, w + v * (k as u64 % 65521 + 1))
        });
    serde_json::json!({ "sum": sum, "weighted": weighted })
}

/// The frame's planes as the integers stored, under the fixtures' names (`None`: no file).
fn stored_planes(s: &Sample, scale: f32) -> [(&'static str, Option<Vec<u64>>); 5] {
    let (f, truth) = (&s.frame, &s.truth);
    let bytes = |v: &u8| u64::from(*v);
    [
        ("rgb", Some(f.rgb.iter().map(bytes).collect())),
        ("amplitude", Some(amplitude_units(&f.amplitude))),
        ("depth_units", Some(depth_units(&f.depth, scale))),
        (
            "gt_depth_units",
            truth.depth.as_ref().map(|g| depth_units(g, scale)),
        ),
        (
            "mask",
            truth
                .mask
                .as_ref()
                .map(|m| m.iter().map(|&v| u64::from(v)).collect()),
        ),
    ]
}

/// Id, timestamp and perturbation of the frame as the fixture lists them.
fn check_entry(s: &Sample, want: &Value) {
    let id = s.frame.index;
    assert_eq!(id, u64_of(&want["id"]));
    assert_eq!(
        s.frame.timestamp_ns,
        u64_of(&want["timestamp_ns"]),
        "frame {id}"
    );
    let perturbation = calibration(&want["perturbation"]);
    assert_eq!(s.truth.perturbation, perturbation, "frame {id}");
}

#[test]
fn rust_reads_samples_demo_as_the_digest_says() {
    let want = load("demo_digest.json");
    assert_eq!(want["weight_modulus"], 65521);
    let cap = CaptureDir::open(repo().join("samples/demo")).unwrap();
    check_manifest(cap.manifest(), &want["manifest"]);
    let frames = want["frames"].as_array().unwrap();
    assert_eq!(cap.len(), frames.len());
    let (w, h) = cap.size();
    let scale = cap.manifest().depth_scale;
    for (i, want) in frames.iter().enumerate() {
        let s = cap.read_sample(i).unwrap();
        check_entry(&s, want);
        let f = &s.frame;
        assert_eq!(s.truth.flow.is_some(), want["has_flow"].as_bool().unwrap());
        assert_eq!(f.rgb.dim(), (h as usize, w as usize, 3));
        assert_eq!(f.depth.dim(), (h as usize, w as usize));
        for (name, got) in stored_planes(&s, scale) {
            let got = got.map_or(Value::Null, digest);
            assert_eq!(got, want[name], "frame {}: {name}", f.index);
        }
    }
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn as_f64(values: impl IntoIterator<Item = u64>) -> Vec<f64> {
    values.into_iter().map(|v| v as f64).collect()
}

/// Compares a plane with a fixture's flat list (`null`: the file must be absent).
fn check_values(id: u64, name: &str, got: Option<Vec<f64>>, want: &Value) {
    let want = (!want.is_null()).then(|| numbers(want));
    assert_eq!(got, want, "frame {id}: {name}");
}

fn check_known_frame(s: &Sample, want: &Value, scale: f32) {
    check_entry(s, want);
    let f = &s.frame;
    for (name, got) in stored_planes(s, scale) {
        check_values(f.index, name, got.map(as_f64), &want[name]);
    }
    let flow = |component: fn(&Flow) -> &ndarray::Array2<f32>| {
        s.truth
            .flow
            .as_ref()
            .map(|fl| component(fl).iter().map(|&x| f64::from(x)).collect())
    };
    check_values(f.index, "flow_u", flow(|fl| &fl.u), &want["flow_u"]);
    check_values(f.index, "flow_v", flow(|fl| &fl.v), &want["flow_v"]);
}

#[test]
fn rust_reads_the_capture_python_wrote_value_for_value() {
    let want = load("python_written.json");
    let cap = CaptureDir::open(fixture("python_written")).unwrap();
    let m = cap.manifest();
    check_manifest(m, &want["manifest"]);
    assert_eq!(m.source, want["manifest"]["source"]);
    let frames = want["frames"].as_array().unwrap();
    assert_eq!(cap.len(), frames.len());
    for (i, want) in frames.iter().enumerate() {
        check_known_frame(&cap.read_sample(i).unwrap(), want, m.depth_scale);
    }
}

/// The Rust writer stores the same units as the Python writer for the same depths and
/// amplitudes: ties, the ends of the 16-bit range and invalid depths included.
#[test]
fn both_writers_round_depth_and_amplitude_alike() {
    let want = &load("python_written.json")["rounding"];
    let f32s = |v: &Value| -> Vec<f32> { numbers(v).into_iter().map(|x| x as f32).collect() };
    let depth = ndarray::Array1::from(f32s(&want["depth_m"]));
    let n = depth.len();
    let units = png::depth_to_u16(
        depth.into_shape_with_order((1, n)).unwrap().view(),
        f32_of(&want["depth_scale"]),
    );
    assert_eq!(
        as_f64(units.iter().map(|&u| u64::from(u))),
        numbers(&want["depth_units"])
    );
    let amplitude: Vec<f64> = f32s(&want["amplitude"])
        .into_iter()
        .map(|a| f64::from(png::amplitude_to_u16(a)))
        .collect();
    assert_eq!(amplitude, numbers(&want["amplitude_units"]));
}

/// `case`'s edit applied to `base`: a `text` replaces it, `set` puts values at JSON pointers
/// (adding a key to an object), `remove` deletes keys.
fn bad_manifest_text(base: &str, case: &Value) -> String {
    if let Some(text) = case["text"].as_str() {
        return text.to_owned();
    }
    let mut doc: Value = serde_json::from_str(base).unwrap();
    let split = |pointer: &str| {
        let (parent, key) = pointer.rsplit_once('/').unwrap();
        (parent.to_owned(), key.to_owned())
    };
    for (pointer, value) in case["set"].as_object().into_iter().flatten() {
        let (parent, key) = split(pointer);
        match doc.pointer_mut(&parent).unwrap() {
            Value::Object(map) => {
                map.insert(key, value.clone());
            }
            Value::Array(items) => items[key.parse::<usize>().unwrap()] = value.clone(),
            other => panic!("{pointer}: cannot set inside {other}"),
        }
    }
    for pointer in case["remove"].as_array().into_iter().flatten() {
        let (parent, key) = split(pointer.as_str().unwrap());
        let map = doc.pointer_mut(&parent).unwrap().as_object_mut().unwrap();
        assert!(map.remove(&key).is_some(), "{pointer}: nothing to remove");
    }
    serde_json::to_string_pretty(&doc).unwrap()
}

#[test]
fn rust_refuses_every_bad_manifest_naming_the_field() {
    let doc = load("bad_manifests.json");
    let base = fs::read_to_string(fixture(doc["base"].as_str().unwrap())).unwrap();
    let cases = doc["cases"].as_array().unwrap();
    assert!(cases.len() >= 20, "the list lost cases");
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("capture.json");
    for case in cases {
        let name = case["name"].as_str().unwrap();
        let text = bad_manifest_text(&base, case);
        assert_ne!(text.trim(), base.trim(), "{name}: the edit changes nothing");
        fs::write(&path, &text).unwrap();
        let err = CaptureDir::open(tmp.path()).expect_err(name);
        assert!(
            matches!(&err, CaptureError::Manifest { path: p, .. } if *p == path),
            "{name}: {err:?}"
        );
        let msg = err.to_string();
        for word in case["expect"].as_array().unwrap() {
            assert!(msg.contains(word.as_str().unwrap()), "{name}: {msg}");
        }
    }
    // The base itself is good: each case fails by its edit alone.
    fs::write(&path, &base).unwrap();
    CaptureDir::open(tmp.path()).unwrap();
}
