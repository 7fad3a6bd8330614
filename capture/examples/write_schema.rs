//! Rewrites the checked-in JSON Schema of `capture.json` (`capture/schema/capture.schema.json`)
//! from the Rust types, after a change of the manifest's types or bounds:
//!
//! `cargo run -p dear-capture --example write_schema`

use std::path::Path;

use dear_capture::schema::{manifest_schema_text, SCHEMA_FILE};

fn main() -> std::io::Result<()> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(SCHEMA_FILE);
    std::fs::write(&path, manifest_schema_text())?;
    println!("wrote {}", path.display());
    Ok(())
}
