//! Capture directories made from `samples/demo`'s real frames, with frames a test breaks on
//! purpose. (An analytic scene written by the capture writer is in [`crate::scene`].)

use std::path::{Path, PathBuf};

use dear_capture::{CaptureDir, FramePaths};

use crate::paths::demo_capture;

/// Writes a capture directory at `root` with one entry per `(timestamp_ns, readable)`: readable
/// frames are copies of `samples/demo`'s first frame, unreadable ones have a truncated depth
/// PNG (and their other files), so reading them fails. Returns `root`.
pub fn write_demo_copies(root: &Path, frames: &[(u64, bool)]) -> PathBuf {
    let demo = CaptureDir::open(demo_capture()).expect("samples/demo opens");
    let source = demo.frame_paths(0);
    let mut manifest = demo.manifest().clone();
    let template = manifest.frames[0].clone();
    manifest.frames.clear();
    let frames_dir = root.join("frames");
    std::fs::create_dir_all(&frames_dir)
        .unwrap_or_else(|e| panic!("cannot create {}: {e}", frames_dir.display()));
    for (id, &(timestamp_ns, readable)) in frames.iter().enumerate() {
        let paths = FramePaths::new(root, id as u64);
        for (from, to) in [
            (&source.rgb, &paths.rgb),
            (&source.amplitude, &paths.amplitude),
            (&source.depth, &paths.depth),
        ] {
            std::fs::copy(from, to).unwrap_or_else(|e| {
                panic!("cannot copy {} to {}: {e}", from.display(), to.display())
            });
        }
        if !readable {
            std::fs::write(&paths.depth, b"\x89PNG truncated").unwrap();
        }
        let mut entry = template.clone();
        entry.id = id as u64;
        entry.timestamp_ns = timestamp_ns;
        manifest.frames.push(entry);
    }
    std::fs::write(
        root.join("capture.json"),
        serde_json::to_string_pretty(&manifest).expect("the manifest serialises"),
    )
    .unwrap();
    root.to_path_buf()
}
