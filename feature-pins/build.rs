//! Empty: cargo resolves a crate's `[build-dependencies]` only when it has a build script, and
//! the pins of the host's crates (Cargo.toml) are build-dependencies.

fn main() {}
