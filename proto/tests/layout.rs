//! The README documents the frame header byte by byte for C and Python clients. This test reads
//! that table and checks every row against the real `#[repr(C)]` struct, so the documentation
//! cannot drift from the code.

use std::mem::{offset_of, size_of};

use dear_proto::{FrameHeader, PayloadLayout};

/// `(field, offset, size)` of the real struct.
fn real_fields() -> Vec<(&'static str, usize, usize)> {
    macro_rules! field {
        ($name:ident) => {{
            let h = FrameHeader::default();
            (
                stringify!($name),
                offset_of!(FrameHeader, $name),
                std::mem::size_of_val(&h.$name),
            )
        }};
    }
    vec![
        field!(magic),
        field!(version),
        field!(frame_id),
        field!(capture_timestamp_ns),
        field!(publish_timestamp_ns),
        field!(width),
        field!(height),
        field!(calib_tx),
        field!(calib_ty),
        field!(calib_cx),
        field!(calib_cy),
        field!(calib_residual_px),
        field!(calib_quality),
        field!(flags),
        field!(calib_age_frames),
        field!(bundle),
        field!(stage_latency_us),
        field!(depth_offset),
        field!(rgb_offset),
        field!(confidence_offset),
        field!(payload_size),
        field!(frames_skipped),
        field!(frames_dropped),
        field!(reserved),
    ]
}

/// Rows of the README table between the `frame-header-table` markers.
fn documented_fields() -> Vec<(String, usize, usize)> {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md"))
        .expect("README.md");
    let start = readme
        .find("<!-- frame-header-table -->")
        .expect("README has the frame-header-table marker");
    let end = readme
        .find("<!-- /frame-header-table -->")
        .expect("README closes the frame-header-table");
    readme[start..end]
        .lines()
        .filter(|l| l.starts_with('|'))
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            // | offset | size | type | field | meaning |
            let offset = cells.get(1)?.parse().ok()?;
            let size = cells.get(2)?.parse().ok()?;
            Some((cells.get(4)?.trim_matches('`').to_string(), offset, size))
        })
        .collect()
}

#[test]
fn readme_table_matches_the_struct() {
    let real = real_fields();
    let documented = documented_fields();
    assert_eq!(
        documented.len(),
        real.len(),
        "README documents {} fields, the struct has {}",
        documented.len(),
        real.len()
    );
    for ((name, offset, size), (doc_name, doc_offset, doc_size)) in real.iter().zip(&documented) {
        assert_eq!(name, doc_name, "field order");
        assert_eq!(
            (offset, size),
            (doc_offset, doc_size),
            "field {name}: (offset, size)"
        );
    }
    let (last, offset, size) = real.last().unwrap();
    assert_eq!(
        offset + size,
        size_of::<FrameHeader>(),
        "{last} ends the struct: no trailing padding"
    );
}

#[test]
fn fields_are_contiguous_without_padding() {
    let real = real_fields();
    for pair in real.windows(2) {
        assert_eq!(
            pair[0].1 + pair[0].2,
            pair[1].1,
            "padding between {} and {}",
            pair[0].0,
            pair[1].0
        );
    }
}

#[test]
fn payload_layout_of_vga() {
    let l = PayloadLayout::new(640, 480);
    assert_eq!(
        (l.depth_offset, l.rgb_offset, l.confidence_offset, l.size),
        (0, 1_228_800, 2_150_400, 2_457_600)
    );
    let h = FrameHeader::new(1, 640, 480);
    assert!(h.validate(l.size).is_ok());
    assert!(h.validate(l.size - 1).is_err());
    let mut bad = h;
    bad.magic = 0;
    assert!(bad.validate(l.size).unwrap_err().contains("magic"));
}

#[test]
fn bundle_name_round_trips_and_truncates_on_a_char_boundary() {
    let mut h = FrameHeader::default();
    h.set_bundle_name("edge");
    assert_eq!(h.bundle_name(), "edge");
    h.set_bundle_name(&"é".repeat(20));
    assert_eq!(h.bundle_name(), "é".repeat(16));
}
