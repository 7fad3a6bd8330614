//! Model bundles for tests, made from the committed fixtures: the untrained smoke bundle with
//! another refine graph in place of its own (e.g. `fixtures/bundles/broken-refine`'s graphs
//! with absurd outputs), its manifest's size and checksum updated so the bundle verifies —
//! what a broken export, or a tampering with access to the manifest, produces.

use std::path::{Path, PathBuf};

use crate::sha256_hex;

/// `fixtures/bundles` of the repository.
pub fn fixture_bundles() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/bundles")
}

/// `fixtures/bundles/broken-refine/<name>.onnx` (`scaled`: depth ×1000, `nan`, `negative`).
pub fn broken_refine_graph(name: &str) -> PathBuf {
    fixture_bundles().join(format!("broken-refine/{name}.onnx"))
}

/// Writes into `dest` (created if missing) the smoke bundle with `refine_graph` as its refine
/// graph, and returns `dest`.
pub fn smoke_bundle_with_refine(dest: &Path, refine_graph: &Path) -> PathBuf {
    let smoke = fixture_bundles().join("smoke-edge");
    std::fs::create_dir_all(dest).expect("bundle directory");
    for f in ["model.json", "flow.onnx", "fuse.onnx"] {
        std::fs::copy(smoke.join(f), dest.join(f)).expect("copy the smoke bundle");
    }
    let graph = std::fs::read(refine_graph)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", refine_graph.display()));
    std::fs::write(dest.join("refine.onnx"), &graph).expect("write refine.onnx");
    let path = dest.join("model.json");
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("model.json"))
            .expect("model.json is JSON");
    let refine = &mut manifest["graphs"]["refine"];
    refine["bytes"] = graph.len().into();
    refine["sha256"] = sha256_hex(&graph).into();
    std::fs::write(&path, serde_json::to_string_pretty(&manifest).unwrap()).expect("model.json");
    dest.to_path_buf()
}
