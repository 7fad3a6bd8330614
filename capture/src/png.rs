//! PNG codecs for the per-frame images, with the checks the format promises: bit depth,
//! channel count and resolution are verified and reported with the file's name.
//!
//! The checks come before any pixel is decoded: the declared size is read from the IHDR chunk
//! and compared with the capture's, and the decoder runs under [`Limits`] sized for the expected
//! image. A small file that declares 16000x16000 is refused in microseconds instead of costing
//! seconds and half a gigabyte, and behind it the good frames keep flowing.

use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use image::codecs::png::PngDecoder;
use image::{ColorType, DynamicImage, ImageBuffer, ImageDecoder, Limits, Luma, Rgb};
use ndarray::{Array2, Array3, ArrayView2, ArrayView3, ArrayViewMut2};

use crate::error::CaptureError;
use crate::manifest::MAX_SIDE;

/// Bytes the decoder may hold besides the image itself: metadata chunks it keeps (text, ICC
/// profile) and row buffers. A camera writes a few KiB of metadata; the bound stops a crafted
/// chunk from asking for gigabytes before the first pixel.
const METADATA_BUDGET: u64 = 16 << 20;

/// The 8 bytes every PNG file starts with.
const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];

/// What one image plane's PNG must decode to: the colour type fixes channels and bit depth.
#[derive(Debug, Clone, Copy)]
struct Plane {
    color: ColorType,
    /// How errors describe it.
    name: &'static str,
}

const RGB8: Plane = Plane {
    color: ColorType::Rgb8,
    name: "8-bit RGB",
};
const GREY16: Plane = Plane {
    color: ColorType::L16,
    name: "16-bit grey",
};
const GREY8: Plane = Plane {
    color: ColorType::L8,
    name: "8-bit grey",
};

fn decode_err(path: &Path, message: impl std::fmt::Display) -> CaptureError {
    CaptureError::Decode {
        path: path.to_owned(),
        message: message.to_string(),
    }
}

/// The declared `(width, height)` of a PNG, from its IHDR chunk. The format fixes where it is:
/// the 8-byte signature, then the first chunk, which must be IHDR (4-byte length, `IHDR`, then
/// width and height as big-endian u32). Reading these 24 bytes allocates nothing; the decoder
/// checks the rest of the chunk (CRC, bit depth, colour type) afterwards.
fn declared_size(path: &Path, file: &mut impl Read) -> Result<(u32, u32), CaptureError> {
    let mut head = [0u8; 24];
    file.read_exact(&mut head).map_err(|e| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            decode_err(path, "file too short for a PNG header (24 bytes)")
        } else {
            CaptureError::io(path, e)
        }
    })?;
    if head[..8] != PNG_SIGNATURE {
        return Err(decode_err(path, "not a PNG file (no PNG signature)"));
    }
    if &head[12..16] != b"IHDR" {
        return Err(decode_err(path, "the first chunk is not IHDR"));
    }
    let be = |i: usize| u32::from_be_bytes([head[i], head[i + 1], head[i + 2], head[i + 3]]);
    Ok((be(16), be(20)))
}

/// Decodes the PNG at `path` as `plane`, after checking its declared size against `size`
/// (expected `(width, height)`; with none, each side must be at most [`MAX_SIDE`]) and its
/// colour type against the plane's. Only an image of the expected size and type is decoded.
fn decode(
    path: &Path,
    size: Option<(u32, u32)>,
    plane: Plane,
) -> Result<DynamicImage, CaptureError> {
    let mut file = crate::input::open_regular(path).map_err(|e| CaptureError::io(path, e))?;
    let (w, h) = declared_size(path, &mut file)?;
    match size {
        Some(expected) if (w, h) != expected => {
            return Err(CaptureError::resolution(path, expected, (w, h)));
        }
        None if w > MAX_SIDE || h > MAX_SIDE => {
            return Err(CaptureError::Format {
                path: path.to_owned(),
                expected: format!("an image of at most {MAX_SIDE}x{MAX_SIDE}"),
                found: format!("{w}x{h}"),
            });
        }
        _ => {}
    }
    file.seek(SeekFrom::Start(0))
        .map_err(|e| CaptureError::io(path, e))?;
    // Checked although the sides are bounded here: every size read from a file is.
    let budget = u64::from(w)
        .checked_mul(u64::from(h))
        .and_then(|n| n.checked_mul(u64::from(plane.color.bytes_per_pixel())))
        .and_then(|n| n.checked_add(METADATA_BUDGET))
        .ok_or_else(|| decode_err(path, format!("{w}x{h} overflows a byte count")))?;
    // Defence in depth: the decoder itself refuses any other size and any allocation beyond
    // the expected image plus its metadata budget.
    let mut limits = Limits::default();
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    limits.max_alloc = Some(budget);
    let decoder =
        PngDecoder::with_limits(BufReader::new(file), limits).map_err(|e| decode_err(path, e))?;
    // `with_limits` has read the chunks before the pixel data, not the pixels: the colour type
    // is known and nothing image-sized is allocated yet.
    if decoder.color_type() != plane.color {
        return Err(CaptureError::Format {
            path: path.to_owned(),
            expected: plane.name.into(),
            found: format!("{:?}", decoder.color_type()),
        });
    }
    DynamicImage::from_decoder(decoder).map_err(|e| decode_err(path, e))
}

/// The error for a decoded image that is not `plane` (cannot happen after [`decode`]'s check;
/// kept as an error, not a panic, should the decoder ever disagree with itself).
fn wrong_plane(path: &Path, img: &DynamicImage, plane: Plane) -> CaptureError {
    CaptureError::Format {
        path: path.to_owned(),
        expected: plane.name.into(),
        found: format!("{:?}", img.color()),
    }
}

/// Reads an 8-bit RGB PNG as `(H, W, 3)`. `size` = expected `(width, height)`.
pub fn read_rgb(path: &Path, size: Option<(u32, u32)>) -> Result<Array3<u8>, CaptureError> {
    let img = decode(path, size, RGB8)?;
    let DynamicImage::ImageRgb8(buf) = img else {
        return Err(wrong_plane(path, &img, RGB8));
    };
    let (w, h) = buf.dimensions();
    Ok(
        Array3::from_shape_vec((h as usize, w as usize, 3), buf.into_raw())
            .expect("RGB buffer size"),
    )
}

/// Reads a 16-bit single-channel PNG as `(H, W)` raw values.
pub fn read_u16(path: &Path, size: Option<(u32, u32)>) -> Result<Array2<u16>, CaptureError> {
    let img = decode(path, size, GREY16)?;
    let DynamicImage::ImageLuma16(buf) = img else {
        return Err(wrong_plane(path, &img, GREY16));
    };
    let (w, h) = buf.dimensions();
    Ok(Array2::from_shape_vec((h as usize, w as usize), buf.into_raw()).expect("grey buffer size"))
}

/// Reads an 8-bit single-channel PNG as a mask (`true` where non-zero).
pub fn read_mask(path: &Path, size: Option<(u32, u32)>) -> Result<Array2<bool>, CaptureError> {
    let img = decode(path, size, GREY8)?;
    let DynamicImage::ImageLuma8(buf) = img else {
        return Err(wrong_plane(path, &img, GREY8));
    };
    let (w, h) = buf.dimensions();
    let data = buf.into_raw().into_iter().map(|v| v != 0).collect();
    Ok(Array2::from_shape_vec((h as usize, w as usize), data).expect("mask buffer size"))
}

/// Reads a 16-bit depth PNG and converts it to metres (`value · scale`; 0 stays 0 = invalid).
pub fn read_depth(
    path: &Path,
    size: Option<(u32, u32)>,
    scale: f32,
) -> Result<Array2<f32>, CaptureError> {
    Ok(read_u16(path, size)?.mapv(|v| v as f32 * scale))
}

fn encode_err(path: &Path, e: impl std::fmt::Display) -> CaptureError {
    CaptureError::Encode {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

/// Writes `(H, W, 3)` RGB as an 8-bit PNG.
pub fn write_rgb(path: &Path, rgb: ArrayView3<u8>) -> Result<(), CaptureError> {
    let (h, w, c) = rgb.dim();
    if c != 3 {
        return Err(encode_err(
            path,
            format!("RGB image has {c} channels, expected 3"),
        ));
    }
    let data: Vec<u8> = rgb.iter().copied().collect();
    let buf =
        ImageBuffer::<Rgb<u8>, _>::from_raw(w as u32, h as u32, data).expect("RGB buffer size");
    buf.save(path).map_err(|e| encode_err(path, e))
}

/// Writes raw 16-bit values.
pub fn write_u16(path: &Path, values: ArrayView2<u16>) -> Result<(), CaptureError> {
    let (h, w) = values.dim();
    let data: Vec<u16> = values.iter().copied().collect();
    let buf =
        ImageBuffer::<Luma<u16>, _>::from_raw(w as u32, h as u32, data).expect("grey buffer size");
    buf.save(path).map_err(|e| encode_err(path, e))
}

/// Writes a mask as an 8-bit PNG (255 = valid).
pub fn write_mask(path: &Path, mask: ArrayView2<bool>) -> Result<(), CaptureError> {
    let (h, w) = mask.dim();
    let data: Vec<u8> = mask.iter().map(|&m| if m { 255 } else { 0 }).collect();
    let buf =
        ImageBuffer::<Luma<u8>, _>::from_raw(w as u32, h as u32, data).expect("mask buffer size");
    buf.save(path).map_err(|e| encode_err(path, e))
}

/// Converts metres to the 16-bit on-disk unit (`round(z / scale)`, saturating; invalid,
/// negative or non-finite depth → 0).
pub fn depth_to_u16(depth: ArrayView2<f32>, scale: f32) -> Array2<u16> {
    depth.mapv(|z| {
        if crate::frame::is_valid_depth(z) {
            (z / scale).round().clamp(0.0, 65535.0) as u16
        } else {
            0
        }
    })
}

/// Writes a depth map in metres as 16-bit units of `scale` metres.
pub fn write_depth(path: &Path, depth: ArrayView2<f32>, scale: f32) -> Result<(), CaptureError> {
    write_u16(path, depth_to_u16(depth, scale).view())
}

/// Converts raw amplitude (f32 sensor units) to the 16-bit on-disk unit: rounded and clamped
/// to `0..=65535`, non-finite → 0.
pub fn amplitude_to_u16(a: f32) -> u16 {
    if a.is_finite() {
        a.round().clamp(0.0, 65535.0) as u16
    } else {
        0
    }
}

/// Writes raw amplitude (f32 sensor units) as 16-bit ([`amplitude_to_u16`]).
pub fn write_amplitude(path: &Path, amplitude: ArrayView2<f32>) -> Result<(), CaptureError> {
    write_u16(path, amplitude.mapv(amplitude_to_u16).view())
}

/// Rounds a frame's depth (to units of `depth_scale`) and amplitude (to whole units) to what a
/// capture directory stores, in place: a live source that does this processes exactly the
/// values its recording replays ([`read_depth`] gives back `u16 · scale`, bit for bit).
pub fn quantize_as_stored(
    mut depth: ArrayViewMut2<f32>,
    mut amplitude: ArrayViewMut2<f32>,
    depth_scale: f32,
) {
    depth.mapv_inplace(|z| {
        if crate::frame::is_valid_depth(z) {
            (z / depth_scale).round().clamp(0.0, 65535.0) as u16 as f32 * depth_scale
        } else {
            0.0
        }
    });
    amplitude.mapv_inplace(|a| amplitude_to_u16(a) as f32);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantized_planes_are_what_a_written_and_read_capture_gives_back() {
        let dir = tempfile::tempdir().unwrap();
        let mut depth =
            Array2::from_shape_fn((6, 7), |(y, x)| 0.3 + 0.123_456 * (x + 7 * y) as f32);
        depth[(0, 0)] = 0.0;
        depth[(1, 1)] = f32::NAN;
        let mut amplitude = depth.mapv(|d| d * 97.3);
        let scale = 0.001;
        quantize_as_stored(depth.view_mut(), amplitude.view_mut(), scale);
        let (dp, ap) = (dir.path().join("d.png"), dir.path().join("a.png"));
        write_depth(&dp, depth.view(), scale).unwrap();
        write_amplitude(&ap, amplitude.view()).unwrap();
        let back = read_depth(&dp, Some((7, 6)), scale).unwrap();
        let amp_back = read_u16(&ap, Some((7, 6))).unwrap().mapv(|v| v as f32);
        // Bit for bit: a live frame processed after quantising equals its replay.
        assert!(back
            .iter()
            .zip(&depth)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        assert!(amp_back
            .iter()
            .zip(&amplitude)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        assert_eq!(depth[(1, 1)], 0.0, "invalid depth is stored as 0");
    }
}
