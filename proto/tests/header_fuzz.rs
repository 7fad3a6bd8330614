//! Property tests of the checks a client runs on every received frame: arbitrary header bytes
//! and payload lengths go through `FrameHeader::validate` and `PayloadLayout::new`, and each
//! answer is compared with an independent reference written in `u128` arithmetic (which cannot
//! overflow for any `u32` input). Properties:
//! - neither function panics, on any input (a corrupt header must not crash a client);
//! - `validate` accepts exactly the well-formed headers, and every header `FrameHeader::new`
//!   makes (whatever the fields that do not describe the layout hold) is accepted, also after a
//!   round trip through its 256 bytes;
//! - every rejection is the first failing check of the reference and its message names the
//!   offending field in backticks.
//!
//! Bounded (`CASES` per property) so it runs in `cargo test` in seconds; proptest prints the
//! minimal failing input, which then becomes a fixed test in `layout.rs`.

use std::mem::size_of;

use dear_proto::header::{BYTES_PER_PIXEL, MAX_PAYLOAD_SIZE};
use dear_proto::{FrameHeader, HeaderError, PayloadLayout, FORMAT_VERSION, MAGIC};
use proptest::prelude::*;

const CASES: u32 = 2_000;
const HEADER_BYTES: usize = size_of::<FrameHeader>();

/// A header from raw bytes, as a client sees a sample's user header in shared memory.
fn from_bytes(bytes: &[u8; HEADER_BYTES]) -> FrameHeader {
    // SAFETY: FrameHeader is `repr(C)` of integers, floats and byte arrays, for which every bit
    // pattern is a valid value; `read_unaligned` needs no alignment of the byte array.
    unsafe { std::ptr::read_unaligned(bytes.as_ptr().cast::<FrameHeader>()) }
}

fn to_bytes(header: &FrameHeader) -> [u8; HEADER_BYTES] {
    // SAFETY: the header has no padding (tests/layout.rs checks the fields are contiguous), so
    // all 256 bytes are initialised.
    unsafe { std::ptr::read_unaligned((header as *const FrameHeader).cast::<[u8; HEADER_BYTES]>()) }
}

/// What the reference expects of a header: the field the first failing check is about (in
/// `validate`'s order), or the layout `(pixels, size)` when it is well formed.
#[derive(Debug, PartialEq)]
enum Verdict {
    Valid { pixels: u128, size: u128 },
    Rejected(&'static str),
}

fn reference(h: &FrameHeader, payload_len: usize) -> Verdict {
    if h.magic != u32::from_le_bytes(*b"DEAR") {
        return Verdict::Rejected("magic");
    }
    if h.version != 3 {
        return Verdict::Rejected("version");
    }
    // `validate` compares with 1.0, which no other bit pattern equals (NaN included).
    if h.depth_unit_m.to_bits() != 1.0f32.to_bits() {
        return Verdict::Rejected("depth_unit_m");
    }
    let pixels = u128::from(h.width) * u128::from(h.height);
    let size = 8 * pixels;
    if size > u128::from(u32::MAX) {
        return Verdict::Rejected("width");
    }
    for (field, found, expected) in [
        ("depth_offset", h.depth_offset, 0),
        ("rgb_offset", h.rgb_offset, 4 * pixels),
        ("confidence_offset", h.confidence_offset, 7 * pixels),
        ("payload_size", h.payload_size, size),
    ] {
        if u128::from(found) != expected {
            return Verdict::Rejected(field);
        }
    }
    if (payload_len as u128) < size {
        return Verdict::Rejected("payload_size");
    }
    Verdict::Valid { pixels, size }
}

/// Runs `validate` and checks its answer against the reference.
fn check(h: &FrameHeader, payload_len: usize) -> Result<(), TestCaseError> {
    let got = h.validate(payload_len);
    match (reference(h, payload_len), got) {
        (Verdict::Valid { pixels, size }, Ok(layout)) => {
            prop_assert_eq!(layout.size as u128, size);
            prop_assert_eq!(layout.pixels() as u128, pixels);
            prop_assert_eq!(
                (layout.width, layout.height),
                (h.width as usize, h.height as usize)
            );
            // The planes a client slices: in order, adjacent, inside the payload.
            prop_assert_eq!(layout.depth_offset, 0);
            prop_assert_eq!(layout.rgb_offset, layout.depth_offset + 4 * layout.pixels());
            prop_assert_eq!(
                layout.confidence_offset,
                layout.rgb_offset + 3 * layout.pixels()
            );
            prop_assert_eq!(layout.size, layout.confidence_offset + layout.pixels());
            prop_assert!(layout.size <= payload_len);
        }
        (Verdict::Rejected(field), Err(err)) => {
            let msg = err.to_string();
            let named = |f: &str| msg.contains(&format!("`{f}`"));
            let variant_fits = match (&err, field) {
                (HeaderError::Magic { found }, "magic") => *found == h.magic,
                (HeaderError::Version { found, supported }, "version") => {
                    *found == h.version && *supported == FORMAT_VERSION
                }
                (HeaderError::DepthUnit { found }, "depth_unit_m") => {
                    found.to_bits() == h.depth_unit_m.to_bits()
                }
                (HeaderError::Size(e), "width") => (e.width, e.height) == (h.width, h.height),
                (HeaderError::Layout { field: f, .. }, _) => *f == field,
                (HeaderError::PayloadTooShort { len, .. }, "payload_size") => *len == payload_len,
                _ => false,
            };
            prop_assert!(variant_fits, "expected a {field} error, got {err:?}");
            if field == "width" {
                prop_assert!(named("width") && named("height"), "{msg}");
            } else {
                prop_assert!(named(field), "{field} not named in {msg:?}");
            }
        }
        (verdict, got) => {
            prop_assert!(false, "reference {verdict:?}, validate {got:?} for {h:?}");
        }
    }
    Ok(())
}

/// Frame sizes biased towards the interesting places: small frames, the edge of the u32
/// payload limit, and anything at all (most of which overflows the limit).
fn dimension() -> impl Strategy<Value = u32> {
    prop_oneof![
        0u32..=64,
        160u32..=4_096,
        Just(536_870_911u32),
        Just(536_870_912u32),
        Just(23_170u32),
        Just(23_171u32),
        any::<u32>(),
    ]
}

/// A well-formed header for `(w, h)` with a payload of `size + extra` bytes, then with the
/// fields that describe the layout mutated, each with some probability: so that every check of
/// `validate` is reached (random bytes alone almost never get past `magic`).
fn mutated_header() -> impl Strategy<Value = (FrameHeader, usize)> {
    (
        (dimension(), dimension()),
        any::<[u8; HEADER_BYTES]>(),
        0usize..=16,
        proptest::option::weighted(0.1, any::<u32>()),
        proptest::option::weighted(0.1, prop_oneof![Just(1u32), Just(3), any::<u32>()]),
        proptest::option::weighted(0.15, any::<u32>()),
        proptest::option::weighted(0.15, any::<u32>()),
        proptest::option::weighted(0.15, any::<u32>()),
        proptest::option::weighted(0.15, any::<u32>()),
        proptest::option::weighted(0.2, 0usize..=1),
        proptest::option::weighted(
            0.1,
            prop_oneof![Just(0.001f32), Just(f32::NAN), any::<f32>()],
        ),
    )
        .prop_map(
            |((w, hgt), noise, extra, magic, version, d, r, c, p, short, unit)| {
                let mut h = from_bytes(&noise);
                h.magic = MAGIC;
                h.version = FORMAT_VERSION;
                h.depth_unit_m = unit.unwrap_or(1.0);
                h.width = w;
                h.height = hgt;
                let size = match PayloadLayout::new(w, hgt) {
                    Ok(l) => {
                        h.depth_offset = l.depth_offset as u32;
                        h.rgb_offset = l.rgb_offset as u32;
                        h.confidence_offset = l.confidence_offset as u32;
                        h.payload_size = l.size as u32;
                        l.size
                    }
                    Err(_) => 64,
                };
                let mut len = size + extra;
                if let Some(short) = short {
                    len = size.saturating_sub(1 + short);
                }
                if let Some(v) = magic {
                    h.magic = v;
                }
                if let Some(v) = version {
                    h.version = v;
                }
                for (field, v) in [
                    (&mut h.depth_offset, d),
                    (&mut h.rgb_offset, r),
                    (&mut h.confidence_offset, c),
                    (&mut h.payload_size, p),
                ] {
                    if let Some(v) = v {
                        *field = v;
                    }
                }
                (h, len)
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(CASES))]

    /// Any 256 bytes and any payload length: no panic, the reference's verdict.
    #[test]
    fn arbitrary_header_bytes(bytes in any::<[u8; HEADER_BYTES]>(), len in any::<usize>()) {
        check(&from_bytes(&bytes), len)?;
    }

    /// Valid headers with one or more layout fields or the payload length spoiled: each check
    /// of `validate` is reached and answers as the reference does.
    #[test]
    fn mutated_headers((header, len) in mutated_header()) {
        check(&header, len)?;
    }

    /// `FrameHeader::new` makes only valid headers, whatever the other fields hold, and they
    /// survive a round trip through their bytes (what crosses shared memory).
    #[test]
    fn headers_from_new_are_valid(
        (w, h) in (0u32..=2_048, 0u32..=2_048),
        frame_id in any::<u64>(),
        run_id in any::<u64>(),
        sequence in any::<u64>(),
        calib in any::<[f32; 6]>(),
        counters in any::<(u64, u64, u32, u32)>(),
        extra in 0usize..=4_096,
    ) {
        let mut header = FrameHeader::new(frame_id, w, h);
        header.run_id = run_id;
        header.sequence = sequence;
        [header.calib_tx, header.calib_ty, header.calib_cx, header.calib_cy,
         header.calib_residual_px, header.calib_quality] = calib;
        (header.frames_skipped, header.frames_dropped, header.flags, header.calib_age_frames) =
            counters;
        header.set_bundle_name("edge");
        let layout = PayloadLayout::new(w, h).unwrap();
        let back = from_bytes(&to_bytes(&header));
        prop_assert_eq!(back.validate(layout.size + extra), Ok(layout));
        prop_assert_eq!(header.validate(layout.size), Ok(layout));
        check(&back, layout.size + extra)?;
    }

    /// `PayloadLayout::new` on any size: a layout exactly when the payload fits a u32, else a
    /// typed error with the pixel count; never an overflow.
    #[test]
    fn payload_layout_of_any_size(w in dimension(), h in dimension()) {
        let pixels = u128::from(w) * u128::from(h);
        let fits = u128::from(BYTES_PER_PIXEL) * pixels <= u128::from(MAX_PAYLOAD_SIZE);
        match PayloadLayout::new(w, h) {
            Ok(l) => {
                prop_assert!(fits);
                prop_assert_eq!(l.size as u128, 8 * pixels);
                prop_assert_eq!(FrameHeader::try_new(0, w, h).map(|x| x.payload_size as usize),
                    Ok(l.size));
            }
            Err(e) => {
                prop_assert!(!fits);
                prop_assert_eq!(u128::from(e.pixels), pixels);
                prop_assert_eq!((e.width, e.height), (w, h));
                prop_assert!(FrameHeader::try_new(0, w, h).is_err());
            }
        }
    }
}
