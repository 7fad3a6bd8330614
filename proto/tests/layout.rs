//! docs/protocol.md documents the frame header byte by byte for C and Python clients. This test
//! reads that table and checks every row against the real `#[repr(C)]` struct, so the documentation
//! cannot drift from the code.

use std::mem::{offset_of, size_of};

use dear_proto::{
    camera_model, random_run_id, CameraIntrinsics, FrameHeader, HeaderError, IntrinsicsError,
    PayloadLayout, FORMAT_VERSION, HEADER_SIZE,
};

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
        field!(run_id),
        field!(sequence),
        field!(calib_health),
        field!(calib_constrained),
        field!(rgb_camera_model),
        field!(depth_unit_m),
        field!(rgb_fx),
        field!(rgb_fy),
        field!(rgb_cx),
        field!(rgb_cy),
        field!(rgb_distortion),
        field!(reserved),
    ]
}

/// Rows of docs/protocol.md's table between the `frame-header-table` markers.
fn documented_fields() -> Vec<(String, usize, usize)> {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/protocol.md"))
        .expect("docs/protocol.md");
    let start = doc
        .find("<!-- frame-header-table -->")
        .expect("docs/protocol.md has the frame-header-table marker");
    let end = doc
        .find("<!-- /frame-header-table -->")
        .expect("docs/protocol.md closes the frame-header-table");
    doc[start..end]
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
fn the_protocol_doc_table_matches_the_struct() {
    let real = real_fields();
    let documented = documented_fields();
    assert_eq!(
        documented.len(),
        real.len(),
        "docs/protocol.md documents {} fields, the struct has {}",
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

/// Offsets of the fields added since version 1, fixed by the protocol: a client in another
/// language reads them at these bytes, so moving them is a format change (and a
/// `FORMAT_VERSION` bump). Format 3 kept every format-2 field where it was.
#[test]
fn newer_fields_sit_where_the_protocol_puts_them() {
    assert_eq!(FORMAT_VERSION, 3);
    assert_eq!(
        offset_of!(FrameHeader, frames_dropped),
        160,
        "older fields unmoved"
    );
    assert_eq!(offset_of!(FrameHeader, run_id), 168);
    assert_eq!(offset_of!(FrameHeader, sequence), 176);
    // Issue 32: the calibration health and its observability, from the reserved bytes too
    // (0 = unknown, what an older publisher sends).
    assert_eq!(offset_of!(FrameHeader, calib_health), 184);
    assert_eq!(offset_of!(FrameHeader, calib_constrained), 185);
    // Format 3 (issue 35): the RGB camera's intrinsics and the depth unit.
    assert_eq!(offset_of!(FrameHeader, rgb_camera_model), 186);
    assert_eq!(offset_of!(FrameHeader, depth_unit_m), 188);
    assert_eq!(offset_of!(FrameHeader, rgb_fx), 192);
    assert_eq!(offset_of!(FrameHeader, rgb_cy), 204);
    assert_eq!(offset_of!(FrameHeader, rgb_distortion), 208);
    assert_eq!(offset_of!(FrameHeader, reserved), 228);
    assert_eq!(size_of::<FrameHeader>(), 256);
    assert_eq!(HEADER_SIZE, 256);
    let h = FrameHeader::new(7, 4, 3);
    assert_eq!((h.run_id, h.sequence, h.reserved), (0, 0, [0; 28]));
    assert_eq!((h.calib_health, h.calib_constrained), (0, 0));
    assert_eq!(
        h.calibration_health(),
        dear_proto::CalibrationHealth::Unknown
    );
    // A new header knows no intrinsics and says so; its depth is in metres.
    assert_eq!(h.rgb_camera_model, camera_model::UNKNOWN);
    assert_eq!(h.intrinsics(), Ok(None));
    assert_eq!(h.depth_unit_m, 1.0);
}

#[test]
fn intrinsics_round_trip_and_bad_ones_are_named() {
    let mut h = FrameHeader::new(1, 640, 480);
    let pinhole = CameraIntrinsics::pinhole(500.0, 510.0, 319.5, 239.5);
    h.set_intrinsics(Some(&pinhole));
    assert_eq!(h.rgb_camera_model, camera_model::PINHOLE);
    assert_eq!(h.intrinsics(), Ok(Some(pinhole)));
    let distorted = CameraIntrinsics {
        distortion: Some([0.1, -0.05, 0.001, -0.002, 0.01]),
        ..pinhole
    };
    h.set_intrinsics(Some(&distorted));
    assert_eq!(h.rgb_camera_model, camera_model::BROWN_CONRADY);
    assert_eq!(h.rgb_distortion, [0.1, -0.05, 0.001, -0.002, 0.01]);
    assert_eq!(h.intrinsics(), Ok(Some(distorted)));
    h.set_intrinsics(None);
    assert_eq!(
        (h.rgb_camera_model, h.rgb_fx, h.rgb_distortion),
        (0, 0.0, [0.0; 5])
    );
    assert_eq!(h.intrinsics(), Ok(None));

    let mut bad = FrameHeader::new(1, 640, 480);
    bad.set_intrinsics(Some(&distorted));
    bad.rgb_camera_model = 9;
    let err = bad.intrinsics().unwrap_err();
    assert_eq!(err, IntrinsicsError::Model { found: 9 });
    assert!(err.to_string().contains("`rgb_camera_model` is 9"), "{err}");
    for (field, spoil) in [
        (
            "`rgb_fx`",
            (|h: &mut FrameHeader| h.rgb_fx = 0.0) as fn(&mut FrameHeader),
        ),
        ("`rgb_fy`", |h| h.rgb_fy = f32::NAN),
        ("`rgb_cy`", |h| h.rgb_cy = f32::INFINITY),
        ("`rgb_distortion[3]`", |h| h.rgb_distortion[3] = f32::NAN),
    ] {
        let mut h = FrameHeader::new(1, 640, 480);
        h.set_intrinsics(Some(&distorted));
        spoil(&mut h);
        let msg = h.intrinsics().unwrap_err().to_string();
        assert!(msg.contains(field), "{field} not named in {msg}");
        // The layout is still fine: the frame is received, only its intrinsics are refused.
        assert!(h.validate(8 * 640 * 480).is_ok());
    }
}

#[test]
fn a_depth_unit_other_than_metres_is_refused() {
    let mut h = FrameHeader::new(1, 4, 3);
    h.depth_unit_m = 0.001;
    let err = h.validate(96).unwrap_err();
    assert_eq!(err, HeaderError::DepthUnit { found: 0.001 });
    assert!(err.to_string().contains("`depth_unit_m` is 0.001"), "{err}");
}

#[test]
fn payload_layout_of_vga() {
    let l = PayloadLayout::new(640, 480).unwrap();
    assert_eq!(
        (l.depth_offset, l.rgb_offset, l.confidence_offset, l.size),
        (0, 1_228_800, 2_150_400, 2_457_600)
    );
    let h = FrameHeader::new(1, 640, 480);
    assert_eq!(h.validate(l.size), Ok(l));
    assert_eq!(
        h.validate(l.size - 1),
        Err(HeaderError::PayloadTooShort {
            len: l.size - 1,
            payload_size: l.size
        })
    );
    let mut bad = h;
    bad.magic = 0;
    assert!(bad
        .validate(l.size)
        .unwrap_err()
        .to_string()
        .contains("`magic`"));
}

/// The largest frames the u32 `payload_size` can describe are accepted, one pixel more is a
/// typed error naming the size: never an overflow, whatever `width` and `height` are.
#[test]
fn payload_size_limit_is_exact_and_checked() {
    // 8 · 536_870_911 = 4_294_967_288 ≤ u32::MAX; 8 · 536_870_912 = 2³² > u32::MAX.
    let largest = PayloadLayout::new(536_870_911, 1).unwrap();
    assert_eq!(largest.size, 4_294_967_288);
    assert_eq!(largest.confidence_offset, 7 * 536_870_911);
    let err = PayloadLayout::new(536_870_912, 1).unwrap_err();
    assert_eq!(err.pixels, 536_870_912);
    let msg = err.to_string();
    assert!(
        msg.contains("536870912×1") && msg.contains("`payload_size`"),
        "{msg}"
    );
    // Products that overflow a u64 once multiplied by 8, and the extreme.
    for (w, h) in [(u32::MAX, u32::MAX), (1 << 31, 1 << 30), (65_536, 65_536)] {
        let err = PayloadLayout::new(w, h).unwrap_err();
        assert_eq!(err.pixels, u64::from(w) * u64::from(h));
        assert!(FrameHeader::try_new(0, w, h).is_err());
    }
}

#[test]
fn another_format_version_is_refused_naming_both_versions() {
    let mut h = FrameHeader::new(1, 4, 3);
    h.version = 1;
    let err = h.validate(96).unwrap_err();
    assert_eq!(
        err,
        HeaderError::Version {
            found: 1,
            supported: 3
        }
    );
    let msg = err.to_string();
    assert!(
        msg.contains("version 1") && msg.contains("version 3"),
        "{msg}"
    );
    // A format-2 header (192 bytes, read at format 3's size) says version 2 in the same bytes.
    h.version = 2;
    let msg = h.validate(96).unwrap_err().to_string();
    assert!(
        msg.contains("version 2") && msg.contains("version 3"),
        "{msg}"
    );
}

#[test]
fn run_ids_are_random_and_never_zero() {
    let ids: Vec<u64> = (0..64).map(|_| random_run_id().unwrap()).collect();
    assert!(ids.iter().all(|&id| id != 0));
    let distinct: std::collections::HashSet<_> = ids.iter().collect();
    // Equal 64-bit random values would mean the source is not random (p ≈ 1e-16).
    assert_eq!(distinct.len(), ids.len(), "{ids:?}");
}

#[test]
fn bundle_name_round_trips_and_truncates_on_a_char_boundary() {
    let mut h = FrameHeader::default();
    h.set_bundle_name("edge");
    assert_eq!(h.bundle_name(), "edge");
    h.set_bundle_name(&"é".repeat(20));
    assert_eq!(h.bundle_name(), "é".repeat(16));
}
