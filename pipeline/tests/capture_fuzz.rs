//! Hostile and damaged capture directories (issue 16): whatever `capture.json`, a PNG plane or a
//! `.flo` file holds, the reader returns a frame or an error naming the file (and, for the
//! manifest, the field) — it never panics, and it never allocates more than the capture's own
//! frame size calls for, whatever size a file declares.
//!
//! The inputs are real files on disk: `samples/demo`'s manifest and frame 0, truncated,
//! bit-flipped and edited (see `mutate`), plus arbitrary bytes and arbitrary JSON. Allocation
//! is measured by a global allocator that records the largest single request per thread.

mod mutate;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::fs;
use std::path::{Path, PathBuf};

use dear_capture::Flow;
use dear_capture::{flo, png, CaptureDir, CaptureError, FramePaths};
use mutate::{apply_bytes, apply_json, arbitrary_json, byte_edits, json_edit, top_key};
use ndarray::Array2;
use proptest::prelude::*;
use serde_json::Value;

// ---- allocation tracking -------------------------------------------------------------------

/// The system allocator, recording the largest single allocation each thread asks for (the
/// test harness runs tests on separate threads, so one test's frames do not count in another's).
struct Tracking;

thread_local! {
    // `const` and no destructor: using it from inside the allocator never allocates.
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn note(size: usize) {
    // `try_with`: the allocator also runs while a thread's locals are torn down.
    let _ = LARGEST.try_with(|l| l.set(l.get().max(size)));
}

// SAFETY: every call is forwarded unchanged to `System`; the bookkeeping does not allocate.
unsafe impl GlobalAlloc for Tracking {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static ALLOCATOR: Tracking = Tracking;

/// `f()` and the largest single allocation this thread made during it.
fn largest_allocation<T>(f: impl FnOnce() -> T) -> (T, usize) {
    LARGEST.with(|l| l.set(0));
    let out = f();
    (out, LARGEST.with(Cell::get))
}

/// The most one read of a demo frame (320x240) may allocate at once: its largest plane
/// decoded (RGB, 230 KB) plus the decoder's buffers, with room to spare. A hostile header
/// asking for 16000x16000 (512 MB) or a .flo for 65536x65536 is far beyond it.
const FRAME_ALLOC_BOUND: usize = 4 << 20;

// ---- a demo capture on disk ----------------------------------------------------------------

fn demo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/demo")
}

/// The five planes of demo frame `id`, as (path inside a capture, original bytes).
struct Planes {
    files: Vec<(PathBuf, Vec<u8>)>,
}

impl Planes {
    fn of(paths: &FramePaths) -> Vec<PathBuf> {
        vec![
            paths.rgb.clone(),
            paths.amplitude.clone(),
            paths.depth.clone(),
            paths.gt_depth.clone(),
            paths.mask.clone(),
        ]
    }

    /// Copies demo frames `ids` and the demo manifest into `dir`; remembers frame `ids[0]`'s
    /// planes.
    fn copy_demo(dir: &Path, ids: &[u64]) -> Planes {
        fs::create_dir_all(dir.join("frames")).unwrap();
        fs::copy(demo().join("capture.json"), dir.join("capture.json")).unwrap();
        let mut files = Vec::new();
        for &id in ids {
            let from = Planes::of(&FramePaths::new(&demo(), id));
            let to = Planes::of(&FramePaths::new(dir, id));
            for (from, to) in from.iter().zip(&to) {
                let bytes = fs::read(from).unwrap();
                fs::write(to, &bytes).unwrap();
                if id == ids[0] {
                    files.push((to.clone(), bytes));
                }
            }
        }
        Planes { files }
    }

    fn restore(&self) {
        for (path, bytes) in &self.files {
            fs::write(path, bytes).unwrap();
        }
    }
}

/// The contract for a capture whose manifest opened: frame 0 reads, or fails naming one of
/// the capture's frame files; either way within the allocation bound of its declared size.
fn check_frame_zero(cap: &CaptureDir) -> Result<(), TestCaseError> {
    if cap.is_empty() {
        return Ok(());
    }
    let (w, h) = cap.size();
    let bound = FRAME_ALLOC_BOUND.max(w as usize * h as usize * 3 * 2);
    let (result, largest) = largest_allocation(|| cap.read_sample(0));
    prop_assert!(largest <= bound, "allocated {largest} bytes at once");
    match result {
        Ok(sample) => {
            prop_assert_eq!(sample.frame.rgb.dim(), (h as usize, w as usize, 3));
            prop_assert_eq!(sample.frame.depth.dim(), (h as usize, w as usize));
        }
        Err(e) => {
            let frames = cap.root().join("frames");
            prop_assert!(e.path().starts_with(&frames), "{e}");
            let name = e.path().file_name().unwrap().to_string_lossy().into_owned();
            prop_assert!(e.to_string().contains(&name), "{e}");
        }
    }
    Ok(())
}

/// Every number the reader hands on from an accepted manifest is finite: a calibration of
/// `inf` (from `1e39` in an f32 field) would align nothing and publish frames without depth.
fn check_finite(cap: &CaptureDir) -> Result<(), TestCaseError> {
    let m = cap.manifest();
    let k = m.intrinsics;
    let c = m.initial_calibration;
    let mut numbers = vec![
        m.depth_scale,
        k.fx,
        k.fy,
        k.cx,
        k.cy,
        c.tx,
        c.ty,
        c.cx,
        c.cy,
    ];
    for p in m.frames.iter().filter_map(|f| f.perturbation) {
        numbers.extend([p.tx, p.ty, p.cx, p.cy]);
    }
    prop_assert!(numbers.iter().all(|v| v.is_finite()), "{numbers:?}");
    Ok(())
}

/// Opens `dir` after `capture.json` was replaced: an accepted manifest meets the contract
/// above, a refused one is a [`CaptureError::Manifest`] (or, for text that is not UTF-8, an
/// I/O error) about `capture.json`. Returns the error message, if any.
fn open_checked(dir: &Path) -> Result<Option<String>, TestCaseError> {
    match CaptureDir::open(dir) {
        Ok(cap) => {
            check_finite(&cap)?;
            check_frame_zero(&cap)?;
            Ok(None)
        }
        Err(e) => {
            let manifest = dir.join("capture.json");
            prop_assert_eq!(e.path(), manifest.as_path());
            prop_assert!(
                matches!(e, CaptureError::Manifest { .. } | CaptureError::Io { .. }),
                "{e:?}"
            );
            let msg = e.to_string();
            prop_assert!(msg.contains("capture.json"), "{msg}");
            Ok(Some(msg))
        }
    }
}

// ---- capture.json ---------------------------------------------------------------------------

#[test]
fn capture_json_of_arbitrary_bytes_or_json_is_an_error_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    Planes::copy_demo(dir, &[0]);
    let manifest = dir.join("capture.json");
    proptest!(mutate::config(256), |(bytes in prop::collection::vec(any::<u8>(), 0..512), json in arbitrary_json())| {
        fs::write(&manifest, &bytes).unwrap();
        open_checked(dir)?;
        fs::write(&manifest, serde_json::to_vec(&json).unwrap()).unwrap();
        open_checked(dir)?;
    });
}

#[test]
fn mutated_demo_manifest_is_accepted_whole_or_refused_naming_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    Planes::copy_demo(dir, &[0]);
    let manifest = dir.join("capture.json");
    let original: Value = serde_json::from_slice(&fs::read(&manifest).unwrap()).unwrap();
    proptest!(mutate::config(512), |(edits in prop::collection::vec(json_edit(), 1..=3))| {
        let mut doc = original.clone();
        let mut keys = Vec::new();
        for edit in &edits {
            let (next, path) = apply_json(&doc, edit);
            doc = next;
            keys.extend(top_key(&path).map(str::to_owned));
        }
        fs::write(&manifest, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
        if let Some(msg) = open_checked(dir)? {
            // Only the edited fields can be wrong, and the message says which.
            prop_assert!(
                keys.iter().any(|k| msg.contains(k.as_str())),
                "edited {keys:?}, error: {msg}"
            );
        }
    });
}

#[test]
fn byte_mutated_demo_manifest_never_panics() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    Planes::copy_demo(dir, &[0]);
    let manifest = dir.join("capture.json");
    let original = fs::read(&manifest).unwrap();
    proptest!(mutate::config(512), |(edits in byte_edits())| {
        fs::write(&manifest, apply_bytes(&original, &edits)).unwrap();
        open_checked(dir)?;
    });
}

// ---- PNG planes -----------------------------------------------------------------------------

#[test]
fn damaged_png_planes_are_errors_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let planes = Planes::copy_demo(dir, &[0]);
    let cap = CaptureDir::open(dir).unwrap();
    proptest!(mutate::config(128), |(plane in 0..planes.files.len(), edits in byte_edits())| {
        planes.restore();
        let (path, original) = &planes.files[plane];
        fs::write(path, apply_bytes(original, &edits)).unwrap();
        // With its ground truth: every one of the five planes is decoded.
        let (result, largest) = largest_allocation(|| cap.read_sample(0));
        prop_assert!(largest <= FRAME_ALLOC_BOUND, "allocated {largest} bytes at once");
        match result {
            // A flip in an ancillary chunk or in a CRC the decoder does not need can leave the
            // image readable; then it has the capture's size.
            Ok(sample) => prop_assert_eq!(sample.frame.depth.dim(), (240, 320)),
            Err(e) => {
                prop_assert_eq!(e.path(), path.as_path(), "{}", e);
                let name = path.file_name().unwrap().to_string_lossy().into_owned();
                prop_assert!(e.to_string().contains(&name), "{e}");
            }
        }
    });
}

// ---- .flo -----------------------------------------------------------------------------------

/// The contract of `read_flo` on any file: a flow of the expected size, or an error about
/// this file; and no allocation beyond the file's own size (plus slack).
fn check_flo(path: &Path, size: Option<(u32, u32)>) -> Result<(), TestCaseError> {
    let file_len = fs::metadata(path).unwrap().len() as usize;
    let (result, largest) = largest_allocation(|| flo::read_flo(path, size));
    prop_assert!(
        largest <= file_len + (64 << 10),
        "allocated {largest} bytes at once for a {file_len}-byte file"
    );
    match result {
        Ok(flow) => {
            if let Some((w, h)) = size {
                prop_assert_eq!(flow.dim(), (h as usize, w as usize));
            }
            prop_assert_eq!(12 + 8 * flow.u.len(), file_len);
        }
        Err(e) => prop_assert_eq!(e.path(), path, "{}", e),
    }
    Ok(())
}

fn small_flow() -> Flow {
    Flow {
        u: Array2::from_shape_fn((6, 8), |(r, c)| r as f32 - 0.5 * c as f32),
        v: Array2::from_shape_fn((6, 8), |(r, c)| (r * c) as f32 * 0.25),
    }
}

#[test]
fn flo_of_arbitrary_bytes_or_mutated_headers_is_an_error_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("000000.flow.flo");
    flo::write_flo(&path, &small_flow()).unwrap();
    let original = fs::read(&path).unwrap();
    let header_and_data = (
        any::<i32>(),
        any::<i32>(),
        prop::collection::vec(any::<u8>(), 0..256),
    );
    proptest!(mutate::config(512), |(
        bytes in prop::collection::vec(any::<u8>(), 0..128),
        edits in byte_edits(),
        (w, h, data) in header_and_data.clone(),
    )| {
        fs::write(&path, &bytes).unwrap();
        check_flo(&path, Some((8, 6)))?;
        check_flo(&path, None)?;
        fs::write(&path, apply_bytes(&original, &edits)).unwrap();
        check_flo(&path, Some((8, 6)))?;
        check_flo(&path, None)?;
        let mut forged = original[..4].to_vec();
        forged.extend(w.to_le_bytes());
        forged.extend(h.to_le_bytes());
        forged.extend(&data);
        fs::write(&path, forged).unwrap();
        check_flo(&path, Some((8, 6)))?;
        check_flo(&path, None)?;
    });
}

// ---- regressions ----------------------------------------------------------------------------

/// CRC-32 of PNG chunks (ISO 3309), to forge a header the decoder would accept.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// `png` (a real PNG) with its IHDR declaring `width`x`height`, CRC recomputed: a small file
/// whose pixel data is far too short for what it declares.
fn declaring(png: &[u8], width: u32, height: u32) -> Vec<u8> {
    let mut out = png.to_vec();
    assert_eq!(&out[12..16], b"IHDR");
    out[16..20].copy_from_slice(&width.to_be_bytes());
    out[20..24].copy_from_slice(&height.to_be_bytes());
    let crc = crc32(&out[12..29]);
    out[29..33].copy_from_slice(&crc.to_be_bytes());
    out
}

/// Audit item 6: a 500 KB depth PNG declaring 16000x16000 was decoded (3.5 s, a 512 MB
/// buffer) before its size was compared with the capture's, and the frames behind it were
/// dropped while it ran. Now the declared size is read from the header and refused before the
/// decoder allocates anything; the next frame reads as usual.
#[test]
fn png_declaring_16000x16000_is_refused_before_decoding() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let planes = Planes::copy_demo(dir, &[0, 1]);
    let cap = CaptureDir::open(dir).unwrap();
    let (depth, bytes) = &planes.files[2];
    assert!(depth.ends_with("000000.depth.png"));
    fs::write(depth, declaring(bytes, 16_000, 16_000)).unwrap();

    let (result, largest) = largest_allocation(|| cap.read_frame(0));
    assert!(
        largest < 1 << 20,
        "reading the frame allocated {largest} bytes at once; the declared image is 512 MB"
    );
    let err = result.expect_err("a 16000x16000 depth plane in a 320x240 capture");
    assert!(
        matches!(
            err,
            CaptureError::Resolution {
                width: 320,
                height: 240,
                found_w: 16_000,
                found_h: 16_000,
                ..
            }
        ),
        "{err:?}"
    );
    assert_eq!(err.path(), depth.as_path());
    let msg = err.to_string();
    assert!(
        msg.contains("000000.depth.png") && msg.contains("16000x16000") && msg.contains("320x240"),
        "{msg}"
    );
    let next = cap.read_frame(1).expect("the frame after the bad one");
    assert_eq!(next.index, 1);
}

/// Without an expected size (the codec used on its own), a declared side beyond the format's
/// bound is refused from the header too: `0x7fffffff` wide would be a 16 GB row buffer.
#[test]
fn png_declaring_an_absurd_size_is_refused_without_an_expected_size() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("amp.png");
    let bytes = fs::read(FramePaths::new(&demo(), 0).amplitude).unwrap();
    fs::write(&path, declaring(&bytes, 0x7fff_ffff, 240)).unwrap();
    let (result, largest) = largest_allocation(|| png::read_u16(&path, None));
    let err = result.expect_err("a 2^31-1 wide image");
    let msg = err.to_string();
    assert!(
        matches!(err, CaptureError::Format { .. })
            && msg.contains("2147483647x240")
            && msg.contains("at most 8192x8192"),
        "{msg}"
    );
    assert!(largest < 1 << 20, "allocated {largest} bytes at once");
}

/// A PNG of the right size but the wrong channels or bit depth is refused from its header,
/// with both named, not decoded and then compared.
#[test]
fn png_of_the_wrong_colour_type_is_refused_before_decoding() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let planes = Planes::copy_demo(dir, &[0]);
    let cap = CaptureDir::open(dir).unwrap();
    // The 8-bit grey mask where the 16-bit amplitude belongs.
    let (amp, _) = &planes.files[1];
    fs::copy(&planes.files[4].0, amp).unwrap();
    let err = cap.read_frame(0).expect_err("an 8-bit amplitude plane");
    assert_eq!(err.path(), amp.as_path());
    let msg = err.to_string();
    assert!(msg.contains("expected 16-bit grey, found L8"), "{msg}");
}

/// The old reader read a whole `.flo` file into memory before comparing its length with the
/// header: a huge file cost its size in memory just to be refused. Now the length is checked
/// from the file's metadata first. (The file is sparse: 256 MB on paper, nothing on disk.)
#[test]
fn oversized_flo_file_is_refused_without_reading_it() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("000000.flow.flo");
    flo::write_flo(&path, &small_flow()).unwrap();
    fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .unwrap()
        .set_len(256 << 20)
        .unwrap();
    let (result, largest) = largest_allocation(|| flo::read_flo(&path, Some((8, 6))));
    let msg = result.expect_err("a 256 MB file for 8x6").to_string();
    assert!(
        msg.contains("000000.flow.flo") && msg.contains("396 bytes for 8x6"),
        "{msg}"
    );
    assert!(largest < 1 << 20, "allocated {largest} bytes at once");
}

/// A `.flo` header of 65536x65536 used to pass the reader's side bound (2^16) when no size was
/// expected; the bound is now the capture format's 8192, and the size is named.
#[test]
fn flo_header_beyond_the_side_bound_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("000000.flow.flo");
    let mut bytes = 202021.25f32.to_le_bytes().to_vec();
    bytes.extend(65_536i32.to_le_bytes());
    bytes.extend(65_536i32.to_le_bytes());
    fs::write(&path, &bytes).unwrap();
    let msg = flo::read_flo(&path, None).unwrap_err().to_string();
    assert!(
        msg.contains("000000.flow.flo") && msg.contains("65536x65536") && msg.contains("8192"),
        "{msg}"
    );
}

/// An f32 field of `capture.json` written as `1e39` deserialises to infinity. The reader took
/// it: an infinite initial calibration (the daemon's default static calibration) or
/// perturbation aligns no pixel. Every calibration in the manifest must now be finite, and
/// the error names the field.
#[test]
fn manifest_calibrations_beyond_f32_are_refused_by_field() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    Planes::copy_demo(dir, &[0]);
    let manifest = dir.join("capture.json");
    let original: Value = serde_json::from_slice(&fs::read(&manifest).unwrap()).unwrap();
    for (pointer, field) in [
        ("/initial_calibration/tx", "initial_calibration.tx"),
        ("/frames/3/perturbation/cy", "frames[3].perturbation.cy"),
    ] {
        let mut doc = original.clone();
        *doc.pointer_mut(pointer).unwrap() = serde_json::json!(-1e39);
        fs::write(&manifest, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
        let msg = CaptureDir::open(dir).unwrap_err().to_string();
        assert!(
            msg.contains("capture.json") && msg.contains(field) && msg.contains("-inf"),
            "{field}: {msg}"
        );
    }
}
