//! Damaged and hostile `model.json` (issue 16): whatever the manifest of a model bundle holds,
//! [`Manifest::parse`] returns a manifest the chain can use or an error naming the file and
//! what is wrong in it (the field, or the graph whose contract breaks) — never a panic.
//!
//! The inputs are the shipped `models/edge/model.json` edited (a value replaced by arbitrary
//! JSON, a key removed or added, bytes flipped, inserted, removed, the text truncated), plus
//! arbitrary bytes and arbitrary JSON.

mod mutate;

use std::fs;
use std::path::{Path, PathBuf};

use dear_pipeline::model::GraphRole;
use dear_pipeline::model::{BundleError, Manifest};
use mutate::{apply_bytes, apply_json, arbitrary_json, byte_edits, json_edit, Step};
use proptest::prelude::*;
use serde_json::Value;

fn shipped() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/edge/model.json")
}

/// The contract of [`Manifest::parse`] on any text: an accepted manifest has every graph the
/// chain runs and reads back the same after being written out; a refused one is a manifest or
/// contract error about `path`. Returns the error message, if any.
fn parse_checked(text: &str, path: &Path) -> Result<Option<String>, TestCaseError> {
    match Manifest::parse(text, path) {
        Ok(m) => {
            for role in GraphRole::ALL {
                prop_assert!(m.graph(role).is_some(), "accepted without graph {role}");
            }
            // Written back, it is accepted again with the same content. (The informational
            // `training`, `validation` and `software` values are left out of the comparison:
            // serde_json's default float parsing does not always round-trip an f64 exactly.)
            let again = Manifest::parse(&serde_json::to_string(&m).unwrap(), path)
                .map_err(|e| TestCaseError::fail(format!("written back: {e}")))?;
            let chain_view = |m: &Manifest| {
                (
                    m.format.clone(),
                    m.format_version,
                    m.tier.clone(),
                    m.variant.clone(),
                    m.input_size_multiple,
                    m.normalisation,
                    m.graphs.clone(),
                )
            };
            prop_assert_eq!(chain_view(&again), chain_view(&m));
            Ok(None)
        }
        Err(e) => {
            let about = match &e {
                BundleError::Manifest { path, .. } | BundleError::Contract { path, .. } => path,
                other => return Err(TestCaseError::fail(format!("unexpected {other:?}"))),
            };
            prop_assert_eq!(about.as_path(), path);
            let msg = e.to_string();
            prop_assert!(msg.contains("model.json"), "{msg}");
            Ok(Some(msg))
        }
    }
}

/// What an error about an edit at `path` must mention: its top-level key, or for an edit
/// inside `graphs.<role>`, that role (contract errors name the graph, not the key).
fn names_for(path: &[Step]) -> Vec<String> {
    match path {
        [Step::Key(top), Step::Key(role), ..] if top == "graphs" => {
            vec![top.clone(), role.clone()]
        }
        [Step::Key(top), ..] => vec![top.clone()],
        _ => Vec::new(),
    }
}

#[test]
fn arbitrary_bytes_or_json_as_model_json_is_an_error_naming_the_file() {
    let path = shipped();
    proptest!(mutate::config(512), |(
        bytes in prop::collection::vec(any::<u8>(), 0..512),
        json in arbitrary_json(),
    )| {
        parse_checked(&String::from_utf8_lossy(&bytes), &path)?;
        parse_checked(&serde_json::to_string(&json).unwrap(), &path)?;
    });
}

#[test]
fn mutated_shipped_manifest_is_accepted_whole_or_refused_naming_what_is_wrong() {
    let path = shipped();
    let original: Value = serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
    proptest!(mutate::config(1024), |(edits in prop::collection::vec(json_edit(), 1..=3))| {
        let mut doc = original.clone();
        let mut names = Vec::new();
        for edit in &edits {
            let (next, at) = apply_json(&doc, edit);
            doc = next;
            names.extend(names_for(&at));
        }
        if let Some(msg) = parse_checked(&serde_json::to_string_pretty(&doc).unwrap(), &path)? {
            prop_assert!(
                names.iter().any(|n| msg.contains(n.as_str())),
                "edited {names:?}, error: {msg}"
            );
        }
    });
}

#[test]
fn byte_mutated_shipped_manifest_never_panics() {
    let path = shipped();
    let original = fs::read(&path).unwrap();
    proptest!(mutate::config(512), |(edits in byte_edits())| {
        let bytes = apply_bytes(&original, &edits);
        parse_checked(&String::from_utf8_lossy(&bytes), &path)?;
    });
}

/// Found by the property test above: a tensor dimension that is neither a symbol nor a
/// positive integer (`-4.9e-15` as the batch size of the flow graph's amplitude input) was
/// accepted; only the rank and the channel count were checked. It is now a contract error
/// naming the graph, the tensor and the rule.
#[test]
fn tensor_dimensions_must_be_symbols_or_positive_integers() {
    let path = shipped();
    let original: Value = serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
    for bad in [
        serde_json::json!(-4.899083878494248e-15),
        serde_json::json!(0),
        serde_json::json!(2.5),
        serde_json::json!(null),
        serde_json::json!(""),
        serde_json::json!(["H"]),
    ] {
        let mut doc = original.clone();
        doc["graphs"]["flow"]["inputs"][1]["shape"][2] = bad.clone();
        let err = Manifest::parse(&doc.to_string(), &path).expect_err("a broken dimension");
        assert!(
            matches!(err, BundleError::Contract { graph: "flow", .. }),
            "{bad}: {err:?}"
        );
        let msg = err.to_string();
        assert!(
            msg.contains("model.json")
                && msg.contains("\"amplitude\"")
                && msg.contains("each dimension must be a symbol"),
            "{bad}: {msg}"
        );
    }
}
