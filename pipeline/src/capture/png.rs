//! PNG codecs for the per-frame images, with the checks the format promises: bit depth,
//! channel count and resolution are verified and reported with the file's name.

use std::path::Path;

use image::{DynamicImage, ImageBuffer, ImageReader, Luma, Rgb};
use ndarray::{Array2, Array3, ArrayView2, ArrayView3};

use super::error::CaptureError;

fn decode(path: &Path) -> Result<DynamicImage, CaptureError> {
    let reader = ImageReader::open(path).map_err(|e| CaptureError::io(path, e))?;
    let reader = reader
        .with_guessed_format()
        .map_err(|e| CaptureError::io(path, e))?;
    reader.decode().map_err(|e| CaptureError::Decode {
        path: path.to_owned(),
        message: e.to_string(),
    })
}

fn check_size(
    path: &Path,
    img: &DynamicImage,
    size: Option<(u32, u32)>,
) -> Result<(), CaptureError> {
    if let Some((width, height)) = size {
        if img.width() != width || img.height() != height {
            return Err(CaptureError::Resolution {
                path: path.to_owned(),
                width,
                height,
                found_w: img.width(),
                found_h: img.height(),
            });
        }
    }
    Ok(())
}

fn color_name(img: &DynamicImage) -> String {
    format!("{:?}", img.color())
}

/// Reads an 8-bit RGB PNG as `(H, W, 3)`. `size` = expected `(width, height)`.
pub fn read_rgb(path: &Path, size: Option<(u32, u32)>) -> Result<Array3<u8>, CaptureError> {
    let img = decode(path)?;
    check_size(path, &img, size)?;
    let DynamicImage::ImageRgb8(buf) = img else {
        return Err(CaptureError::Format {
            path: path.to_owned(),
            expected: "8-bit RGB".into(),
            found: color_name(&img),
        });
    };
    let (w, h) = buf.dimensions();
    Ok(
        Array3::from_shape_vec((h as usize, w as usize, 3), buf.into_raw())
            .expect("RGB buffer size"),
    )
}

/// Reads a 16-bit single-channel PNG as `(H, W)` raw values.
pub fn read_u16(path: &Path, size: Option<(u32, u32)>) -> Result<Array2<u16>, CaptureError> {
    let img = decode(path)?;
    check_size(path, &img, size)?;
    let DynamicImage::ImageLuma16(buf) = img else {
        return Err(CaptureError::Format {
            path: path.to_owned(),
            expected: "16-bit grey".into(),
            found: color_name(&img),
        });
    };
    let (w, h) = buf.dimensions();
    Ok(Array2::from_shape_vec((h as usize, w as usize), buf.into_raw()).expect("grey buffer size"))
}

/// Reads an 8-bit single-channel PNG as a mask (`true` where non-zero).
pub fn read_mask(path: &Path, size: Option<(u32, u32)>) -> Result<Array2<bool>, CaptureError> {
    let img = decode(path)?;
    check_size(path, &img, size)?;
    let DynamicImage::ImageLuma8(buf) = img else {
        return Err(CaptureError::Format {
            path: path.to_owned(),
            expected: "8-bit grey".into(),
            found: color_name(&img),
        });
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
        if z > 0.0 && z.is_finite() {
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

/// Writes raw amplitude (f32 sensor units) as 16-bit, rounded and clamped to `0..=65535`.
pub fn write_amplitude(path: &Path, amplitude: ArrayView2<f32>) -> Result<(), CaptureError> {
    let values = amplitude.mapv(|a| {
        if a.is_finite() {
            a.round().clamp(0.0, 65535.0) as u16
        } else {
            0
        }
    });
    write_u16(path, values.view())
}
