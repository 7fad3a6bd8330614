//! Middlebury `.flo` optical-flow files: the magic float 202021.25 ("PIEH"), width and height
//! as little-endian i32, then `(u, v)` pairs as little-endian f32, row-major.
//!
//! Values with magnitude above 1e9 mean "unknown" in the Middlebury convention; the reader
//! returns them as they are and [`UNKNOWN_FLOW`] is what writers use for invalid pixels. NaN and
//! infinity are not a convention of the format: a file holding them is refused (by the Python
//! reader too), so no ground truth reaches a metric or a loss as NaN.

use std::fs;
use std::io::Read;
use std::path::Path;

use ndarray::Array2;

use crate::error::CaptureError;
use crate::frame::Flow;
use crate::manifest::MAX_SIDE;

const MAGIC: f32 = 202021.25;
/// Middlebury's "unknown flow" value (anything above 1e9 is treated as unknown).
pub const UNKNOWN_FLOW: f32 = 1e10;
/// Magic, width, height.
const HEADER_BYTES: usize = 12;
/// One `(u, v)` pair of f32.
const PIXEL_BYTES: u64 = 8;

/// Reads a `.flo` file. `size` = expected `(width, height)`; with none, each side must be at
/// most [`MAX_SIDE`].
///
/// The header is read and checked first, then the file's length against what the header
/// declares, and only then the data: a corrupt or hostile header cannot make the reader
/// allocate more than the file holds, nor read a huge file it would refuse anyway.
pub fn read_flo(path: &Path, size: Option<(u32, u32)>) -> Result<Flow, CaptureError> {
    let format_err = |expected: &str, found: String| CaptureError::Format {
        path: path.to_owned(),
        expected: expected.to_string(),
        found,
    };
    let mut file = crate::input::open_regular(path).map_err(|e| CaptureError::io(path, e))?;
    let file_len = file
        .metadata()
        .map_err(|e| CaptureError::io(path, e))?
        .len();
    let mut header = [0u8; HEADER_BYTES];
    if file_len < HEADER_BYTES as u64 {
        return Err(format_err(
            "a 12-byte .flo header",
            format!("{file_len} bytes"),
        ));
    }
    file.read_exact(&mut header)
        .map_err(|e| CaptureError::io(path, e))?;
    let word = |i: usize| [header[i], header[i + 1], header[i + 2], header[i + 3]];
    let magic = f32::from_le_bytes(word(0));
    if magic != MAGIC {
        return Err(format_err("the .flo magic 202021.25", format!("{magic}")));
    }
    let (w, h) = (i32::from_le_bytes(word(4)), i32::from_le_bytes(word(8)));
    let side = |v: i32| u32::try_from(v).ok().filter(|s| (1..=MAX_SIDE).contains(s));
    let (Some(w), Some(h)) = (side(w), side(h)) else {
        return Err(format_err(
            &format!("a size of 1..={MAX_SIDE} per side"),
            format!("{w}x{h}"),
        ));
    };
    if let Some(expected) = size.filter(|&expected| expected != (w, h)) {
        return Err(CaptureError::resolution(path, expected, (w, h)));
    }
    // Checked although the sides are bounded: every size read from a file is.
    let expected_len = u64::from(w)
        .checked_mul(u64::from(h))
        .and_then(|n| n.checked_mul(PIXEL_BYTES))
        .and_then(|n| n.checked_add(HEADER_BYTES as u64));
    let Some(expected_len) = expected_len.filter(|&n| n == file_len) else {
        return Err(format_err(
            &format!(
                "{} bytes for {w}x{h}",
                expected_len.map_or("more than 2^64".to_string(), |n| n.to_string())
            ),
            format!("{file_len} bytes"),
        ));
    };
    let data_len = usize::try_from(expected_len - HEADER_BYTES as u64)
        .map_err(|_| format_err("a flow that fits in memory", format!("{w}x{h}")))?;
    let mut data = Vec::with_capacity(data_len);
    // `take`: a file that grew since `metadata` cannot make the read go past the checked size.
    file.take(data_len as u64)
        .read_to_end(&mut data)
        .map_err(|e| CaptureError::io(path, e))?;
    if data.len() != data_len {
        // It shrank between `metadata` and the read.
        return Err(format_err(
            &format!("{expected_len} bytes for {w}x{h}"),
            format!("{} bytes", HEADER_BYTES + data.len()),
        ));
    }
    let n = data_len / PIXEL_BYTES as usize;
    let mut u = Vec::with_capacity(n);
    let mut v = Vec::with_capacity(n);
    for (i, pair) in data.chunks_exact(PIXEL_BYTES as usize).enumerate() {
        let pu = f32::from_le_bytes([pair[0], pair[1], pair[2], pair[3]]);
        let pv = f32::from_le_bytes([pair[4], pair[5], pair[6], pair[7]]);
        if let Some(bad) = [pu, pv].into_iter().find(|x| !x.is_finite()) {
            let (row, col) = (i / w as usize, i % w as usize);
            return Err(format_err(
                "finite flow values (1e10 marks unknown)",
                format!("{bad} at row {row}, column {col}"),
            ));
        }
        u.push(pu);
        v.push(pv);
    }
    let shape = (h as usize, w as usize);
    Ok(Flow {
        u: Array2::from_shape_vec(shape, u).expect("flow size"),
        v: Array2::from_shape_vec(shape, v).expect("flow size"),
    })
}

/// Writes a `.flo` file. A side larger than [`MAX_SIDE`] is refused: [`read_flo`] would not
/// read the file back (and the i32 header could not hold a much larger one).
pub fn write_flo(path: &Path, flow: &Flow) -> Result<(), CaptureError> {
    let (h, w) = flow.dim();
    let side = |s: usize| i32::try_from(s).ok().filter(|&s| s <= MAX_SIDE as i32);
    let (Some(w32), Some(h32)) = (side(w), side(h)) else {
        return Err(CaptureError::Encode {
            path: path.to_owned(),
            message: format!("flow is {w}x{h}, a .flo file holds at most {MAX_SIDE}x{MAX_SIDE}"),
        });
    };
    // Bounded by MAX_SIDE above: at most 12 + 8 * 8192 * 8192 bytes, which fits a usize.
    let mut bytes = Vec::with_capacity(HEADER_BYTES + PIXEL_BYTES as usize * w * h);
    bytes.extend_from_slice(&MAGIC.to_le_bytes());
    bytes.extend_from_slice(&w32.to_le_bytes());
    bytes.extend_from_slice(&h32.to_le_bytes());
    for (u, v) in flow.u.iter().zip(flow.v.iter()) {
        bytes.extend_from_slice(&u.to_le_bytes());
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    fs::write(path, bytes).map_err(|e| CaptureError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_non_finite_flow_value_is_refused_naming_file_and_pixel() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("000000.flow.flo");
        let mut flow = Flow::zeros(2, 3);
        flow.u[(0, 2)] = UNKNOWN_FLOW;
        write_flo(&path, &flow).unwrap();
        assert_eq!(
            read_flo(&path, Some((3, 2))).unwrap(),
            flow,
            "1e10 is a value"
        );
        flow.v[(1, 1)] = f32::NAN;
        write_flo(&path, &flow).unwrap();
        let msg = read_flo(&path, Some((3, 2))).unwrap_err().to_string();
        assert!(
            msg.contains("000000.flow.flo") && msg.contains("NaN at row 1, column 1"),
            "{msg}"
        );
    }
}
