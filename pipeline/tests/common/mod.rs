//! Reading the JSON fixtures under `fixtures/` that the Rust and Python tests share: an array
//! is `{"shape": [...], "data": [...]}` (row-major), optionally with a `"dtype"`.

// Every test crate that includes this module uses a subset of it.
#![allow(dead_code)]

use std::path::Path;

use serde_json::Value;

/// `fixtures/<relative>` parsed.
pub fn load_fixture(relative: &str) -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures")
        .join(relative);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

/// An array's shape and its data as `f32`.
pub fn f32_array(v: &Value) -> (Vec<usize>, Vec<f32>) {
    (shape(v), elements(v, |x| x.as_f64().map(|f| f as f32)))
}

/// An array's shape and its data as `bool`.
pub fn bool_array(v: &Value) -> (Vec<usize>, Vec<bool>) {
    (shape(v), elements(v, Value::as_bool))
}

fn shape(v: &Value) -> Vec<usize> {
    v["shape"]
        .as_array()
        .expect("an array fixture has a shape")
        .iter()
        .map(|d| d.as_u64().expect("shape entries are integers") as usize)
        .collect()
}

fn elements<T>(v: &Value, convert: impl Fn(&Value) -> Option<T>) -> Vec<T> {
    v["data"]
        .as_array()
        .expect("an array fixture has data")
        .iter()
        .map(|x| convert(x).unwrap_or_else(|| panic!("unexpected element {x}")))
        .collect()
}
