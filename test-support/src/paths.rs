//! Where the workspace's binaries and sample data are.

use std::path::{Path, PathBuf};

/// The workspace's root directory (the parent of this crate's directory).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("test-support/ lies in the workspace")
        .to_path_buf()
}

/// `samples/demo`: the bundled sample capture (320×240, 30 frames, real module data).
pub fn demo_capture() -> PathBuf {
    workspace_root().join("samples/demo")
}

/// The directory holding the workspace's binaries (`target/<profile>`), found from the running
/// test executable (`target/<profile>/deps/<test>`).
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the running test's path");
    exe.parent()
        .and_then(Path::parent)
        .unwrap_or_else(|| panic!("{} is not in target/<profile>/deps/", exe.display()))
        .to_path_buf()
}

/// Path of a workspace binary in [`bin_dir`]; panics saying how to build it if it is missing.
/// (A test of the crate that owns the binary uses `env!("CARGO_BIN_EXE_<name>")` instead:
/// cargo builds it first.)
#[track_caller]
pub fn binary(name: &str) -> PathBuf {
    let path = bin_dir().join(name);
    assert!(
        path.is_file(),
        "{} not found: build the workspace binaries first (`cargo test --workspace` or `cargo build --workspace`)",
        path.display()
    );
    path
}
