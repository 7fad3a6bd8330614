//! The checked-in JSON Schema of `capture.json` is the one the Rust types generate: a change of
//! the manifest's fields or bounds without regenerating it would leave the Python reader
//! validating by old rules.

use std::path::Path;

use dear_capture::manifest::{FORMAT_NAME, FORMAT_VERSION, MAX_FRAME_ID, MAX_SIDE};
use dear_capture::schema::{manifest_schema, manifest_schema_text, SCHEMA_FILE};

#[test]
fn the_checked_in_schema_is_the_generated_one() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(SCHEMA_FILE);
    let on_disk =
        std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        on_disk == manifest_schema_text(),
        "{} is not what the Rust types generate; regenerate it with \
         `cargo run -p dear-capture --example write_schema` (and commit it)",
        path.display()
    );
}

/// The rules the reader enforces that the schema must carry, looked up where a validator finds
/// them: a regenerated schema that lost one (an attribute removed, a bound changed) fails here.
#[test]
fn the_schema_carries_the_readers_bounds() {
    let s = manifest_schema();
    let def = |name: &str| &s["$defs"][name];
    let prop = |v: &serde_json::Value, name: &str| v["properties"][name].clone();
    for object in [&s, def("Intrinsics"), def("FrameEntry"), def("Calibration")] {
        assert_eq!(object["additionalProperties"], false, "{object}");
    }
    assert_eq!(prop(&s, "format")["const"], FORMAT_NAME);
    assert_eq!(prop(&s, "version")["const"], FORMAT_VERSION);
    for side in ["width", "height"] {
        assert_eq!(prop(&s, side)["minimum"], 1);
        assert_eq!(prop(&s, side)["maximum"], MAX_SIDE);
    }
    assert_eq!(prop(def("FrameEntry"), "id")["maximum"], MAX_FRAME_ID);
    for focal in ["fx", "fy"] {
        assert_eq!(prop(def("Intrinsics"), focal)["exclusiveMinimum"], 0);
    }
    assert_eq!(prop(&s, "depth_scale")["exclusiveMinimum"], 0);
    assert_eq!(
        prop(&s, "depth_scale")["maximum"].as_f64(),
        Some(f64::from(dear_capture::manifest::MAX_DEPTH_SCALE))
    );
    assert_eq!(
        prop(&s, "modulation_frequencies_hz")["items"]["exclusiveMinimum"],
        0
    );
    for p in ["tx", "ty", "cx", "cy"] {
        assert_eq!(
            prop(def("Calibration"), p)["maximum"].as_f64(),
            Some(f64::from(f32::MAX))
        );
    }
    let required = |v: &serde_json::Value| v["required"].clone();
    assert_eq!(
        required(&s),
        serde_json::json!([
            "format",
            "version",
            "width",
            "height",
            "intrinsics",
            "depth_scale",
            "frames"
        ])
    );
    assert_eq!(
        required(def("FrameEntry")),
        serde_json::json!(["id", "timestamp_ns"])
    );
}
