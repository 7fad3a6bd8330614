//! Writes the geometry test vectors shared with the Python training package to
//! `fixtures/geometry/*.json` (or to the directory given as the first argument).
//!
//! `cargo run -p dear-pipeline --example write_geometry_fixtures`

use std::path::PathBuf;

#[path = "../tests/support/geometry_cases.rs"]
mod geometry_cases;

fn main() -> std::io::Result<()> {
    let dir = std::env::args_os()
        .nth(1)
        .map_or_else(geometry_cases::fixtures_dir, PathBuf::from);
    for path in geometry_cases::write_all(&dir)? {
        println!("wrote {}", path.display());
    }
    Ok(())
}
