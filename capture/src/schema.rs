//! The JSON Schema of `capture.json`, generated from [`CaptureManifest`] and the types in it:
//! `deny_unknown_fields` becomes `additionalProperties: false`, fields with a serde default are
//! optional, and the `#[schemars(...)]` bounds of [`crate::manifest`] become `minimum`,
//! `maximum`, `exclusiveMinimum` and `const`.
//!
//! The schema is checked in as `capture/schema/capture.schema.json` ([`SCHEMA_FILE`]), where
//! the Python reader (`train/dear_train/data/capture.py`) validates every manifest with it. A
//! test fails when the checked-in file is not what [`manifest_schema_text`] generates;
//! `cargo run -p dear-capture --example write_schema` rewrites it.

use schemars::generate::SchemaSettings;

use crate::manifest::CaptureManifest;

/// Where the checked-in schema lives, relative to the repository root.
pub const SCHEMA_FILE: &str = "capture/schema/capture.schema.json";

/// The JSON Schema (draft 2020-12) of `capture.json` as the reader deserialises it.
pub fn manifest_schema() -> serde_json::Value {
    SchemaSettings::draft2020_12()
        .for_deserialize()
        .into_generator()
        .into_root_schema_for::<CaptureManifest>()
        .to_value()
}

/// [`manifest_schema`] as the checked-in file holds it: pretty-printed, ending in a newline.
pub fn manifest_schema_text() -> String {
    let mut text =
        serde_json::to_string_pretty(&manifest_schema()).expect("a JSON value serialises");
    text.push('\n');
    text
}
