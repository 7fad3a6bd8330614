//! Middlebury `.flo` optical-flow files: the magic float 202021.25 ("PIEH"), width and height
//! as little-endian i32, then `(u, v)` pairs as little-endian f32, row-major.
//!
//! Values with magnitude above 1e9 mean "unknown" in the Middlebury convention; the reader
//! returns them as they are and [`UNKNOWN_FLOW`] is what writers use for invalid pixels.

use std::fs;
use std::path::Path;

use ndarray::Array2;

use super::error::CaptureError;
use crate::frame::Flow;

const MAGIC: f32 = 202021.25;
/// Middlebury's "unknown flow" value (anything above 1e9 is treated as unknown).
pub const UNKNOWN_FLOW: f32 = 1e10;

/// Reads a `.flo` file. `size` = expected `(width, height)`.
pub fn read_flo(path: &Path, size: Option<(u32, u32)>) -> Result<Flow, CaptureError> {
    let bytes = fs::read(path).map_err(|e| CaptureError::io(path, e))?;
    let format_err = |expected: &str, found: String| CaptureError::Format {
        path: path.to_owned(),
        expected: expected.to_string(),
        found,
    };
    if bytes.len() < 12 {
        return Err(format_err(
            "a 12-byte .flo header",
            format!("{} bytes", bytes.len()),
        ));
    }
    let word = |i: usize| -> [u8; 4] { bytes[i..i + 4].try_into().expect("4 bytes") };
    let magic = f32::from_le_bytes(word(0));
    if magic != MAGIC {
        return Err(format_err("the .flo magic 202021.25", format!("{magic}")));
    }
    let (w, h) = (i32::from_le_bytes(word(4)), i32::from_le_bytes(word(8)));
    if w <= 0 || h <= 0 || w > 1 << 16 || h > 1 << 16 {
        return Err(format_err("a positive size", format!("{w}x{h}")));
    }
    let (w, h) = (w as u32, h as u32);
    if let Some((width, height)) = size {
        if (w, h) != (width, height) {
            return Err(CaptureError::Resolution {
                path: path.to_owned(),
                width,
                height,
                found_w: w,
                found_h: h,
            });
        }
    }
    let n = w as usize * h as usize;
    let expected_len = 12 + 8 * n;
    if bytes.len() != expected_len {
        return Err(format_err(
            &format!("{expected_len} bytes for {w}x{h}"),
            format!("{} bytes", bytes.len()),
        ));
    }
    let mut u = Vec::with_capacity(n);
    let mut v = Vec::with_capacity(n);
    for pair in bytes[12..].chunks_exact(8) {
        u.push(f32::from_le_bytes(pair[0..4].try_into().expect("4 bytes")));
        v.push(f32::from_le_bytes(pair[4..8].try_into().expect("4 bytes")));
    }
    let shape = (h as usize, w as usize);
    Ok(Flow {
        u: Array2::from_shape_vec(shape, u).expect("flow size"),
        v: Array2::from_shape_vec(shape, v).expect("flow size"),
    })
}

/// Writes a `.flo` file.
pub fn write_flo(path: &Path, flow: &Flow) -> Result<(), CaptureError> {
    let (h, w) = flow.dim();
    let mut bytes = Vec::with_capacity(12 + 8 * w * h);
    bytes.extend_from_slice(&MAGIC.to_le_bytes());
    bytes.extend_from_slice(&(w as i32).to_le_bytes());
    bytes.extend_from_slice(&(h as i32).to_le_bytes());
    for (u, v) in flow.u.iter().zip(flow.v.iter()) {
        bytes.extend_from_slice(&u.to_le_bytes());
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    fs::write(path, bytes).map_err(|e| CaptureError::io(path, e))
}
