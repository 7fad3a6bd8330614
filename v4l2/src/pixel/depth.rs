//! Single-channel planes: depth computed on the camera (`Z16 `, `Y16 `) and intensity
//! (amplitude / IR: `GREY`, `Y16 `, `Y12 `, `Y12P`), plus the `Y12P` packing.

use ndarray::{Array2, ArrayViewMut2};

use super::{check_output, DecodeError, FrameFormat, PixelFormat};

/// Calls `f(x, sample)` for the first `width` samples of one row of a single-channel format.
/// `row` holds at least `min_bytes_per_line(width)` bytes (checked by the caller's layout).
pub(crate) fn for_each_sample(
    format: PixelFormat,
    row: &[u8],
    width: usize,
    mut f: impl FnMut(usize, u16),
) {
    match format {
        PixelFormat::Z16 | PixelFormat::Y16 => {
            for (x, b) in row.chunks_exact(2).take(width).enumerate() {
                f(x, u16::from_le_bytes([b[0], b[1]]));
            }
        }
        // 12 bits in the low bits of a little-endian word; the high nibble is padding (0 by
        // the kernel's definition) and is masked so stray bits cannot exceed the 12-bit range.
        PixelFormat::Y12 => {
            for (x, b) in row.chunks_exact(2).take(width).enumerate() {
                f(x, u16::from_le_bytes([b[0], b[1]]) & 0x0FFF);
            }
        }
        // V4L2_PIX_FMT_Y12P (the MIPI CSI-2 RAW12 packing): byte 0 = p0 bits 11..4, byte 1 =
        // p1 bits 11..4, byte 2 = p1 bits 3..0 << 4 | p0 bits 3..0.
        PixelFormat::Y12P => {
            for (g, b) in row.chunks(3).enumerate() {
                let x = 2 * g;
                if x >= width {
                    break;
                }
                f(x, (u16::from(b[0]) << 4) | u16::from(b[2] & 0x0F));
                if x + 1 < width {
                    f(x + 1, (u16::from(b[1]) << 4) | u16::from(b[2] >> 4));
                }
            }
        }
        PixelFormat::Grey => {
            for (x, &b) in row.iter().take(width).enumerate() {
                f(x, u16::from(b));
            }
        }
        // Multi-channel formats never reach here: the callers check the format first.
        PixelFormat::Yuyv | PixelFormat::Nv12 | PixelFormat::Rgb3 | PixelFormat::Mjpg => {}
    }
}

/// Decodes each row of `data` (checked against `frame`) into `out` as `convert(sample)`.
fn plane_into(
    frame: &FrameFormat,
    data: &[u8],
    mut out: ArrayViewMut2<f32>,
    convert: impl Fn(u16) -> f32,
) -> Result<(), DecodeError> {
    let layout = frame.layout(data)?;
    check_output((frame.height, frame.width), out.dim())?;
    let row_bytes = frame
        .format
        .min_bytes_per_line(frame.width)
        .unwrap_or_default();
    for (y, mut out_row) in out.rows_mut().into_iter().enumerate() {
        let row = layout.row(data, y, row_bytes);
        for_each_sample(frame.format, row, frame.width, |x, v| {
            out_row[x] = convert(v)
        });
    }
    Ok(())
}

/// Depth computed on the camera (`Z16 `, or `Y16 ` on modules that label depth as grey) into
/// metres: `raw × scale_m_per_unit` (RealSense D4xx: 0.001, from the device's depth-units
/// option). Raw 0 is the camera's "no depth" and stays 0, the pipeline's invalid value.
pub fn depth_into(
    frame: &FrameFormat,
    data: &[u8],
    scale_m_per_unit: f32,
    out: ArrayViewMut2<f32>,
) -> Result<(), DecodeError> {
    frame.require(&[PixelFormat::Z16, PixelFormat::Y16], "depth")?;
    if !(scale_m_per_unit.is_finite() && scale_m_per_unit > 0.0) {
        return Err(DecodeError::InvalidParameter(format!(
            "depth scale must be positive and finite, got {scale_m_per_unit} m/unit"
        )));
    }
    plane_into(frame, data, out, |raw| f32::from(raw) * scale_m_per_unit)
}

/// [`depth_into`] into a new `(height, width)` array.
pub fn depth(
    frame: &FrameFormat,
    data: &[u8],
    scale_m_per_unit: f32,
) -> Result<Array2<f32>, DecodeError> {
    let mut out = Array2::zeros((frame.height, frame.width));
    depth_into(frame, data, scale_m_per_unit, out.view_mut())?;
    Ok(out)
}

/// An amplitude / IR plane (`GREY`, `Y16 `, `Y12 `, `Y12P`) as raw sample values in `f32`
/// (no normalisation: the pipeline's amplitude is in the sensor's own units).
pub fn intensity_into(
    frame: &FrameFormat,
    data: &[u8],
    out: ArrayViewMut2<f32>,
) -> Result<(), DecodeError> {
    frame.require(
        &[
            PixelFormat::Grey,
            PixelFormat::Y16,
            PixelFormat::Y12,
            PixelFormat::Y12P,
        ],
        "intensity",
    )?;
    plane_into(frame, data, out, f32::from)
}

/// [`intensity_into`] into a new `(height, width)` array.
pub fn intensity(frame: &FrameFormat, data: &[u8]) -> Result<Array2<f32>, DecodeError> {
    let mut out = Array2::zeros((frame.height, frame.width));
    intensity_into(frame, data, out.view_mut())?;
    Ok(out)
}

/// Packs row-major 12-bit samples (`width × height`, high bits ignored) as `Y12P` rows of
/// `bytes_per_line` bytes (padding zero): the inverse of the decoder, for tests and for feeding
/// recorded phase frames to a V4L2 output node. `None` if `samples` is not `width × height`
/// long or `bytes_per_line` is too small for `width`.
pub fn pack_y12p(
    samples: &[u16],
    width: usize,
    height: usize,
    bytes_per_line: usize,
) -> Option<Vec<u8>> {
    let row_bytes = PixelFormat::Y12P.min_bytes_per_line(width)?;
    if bytes_per_line < row_bytes || samples.len() != width.checked_mul(height)? {
        return None;
    }
    let mut out = vec![0u8; bytes_per_line.checked_mul(height)?];
    if width == 0 {
        return Some(out);
    }
    for (src, dst) in samples
        .chunks_exact(width)
        .zip(out.chunks_exact_mut(bytes_per_line))
    {
        for (pair, group) in src.chunks(2).zip(dst.chunks_exact_mut(3)) {
            let p0 = pair[0] & 0x0FFF;
            let p1 = pair.get(1).copied().unwrap_or(0) & 0x0FFF;
            group[0] = (p0 >> 4) as u8;
            group[1] = (p1 >> 4) as u8;
            group[2] = (((p1 & 0x0F) << 4) | (p0 & 0x0F)) as u8;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    /// Little-endian 16-bit rows of `bytes_per_line` bytes, padding filled with 0xEE so a
    /// decoder reading padding shows up.
    fn le16_rows(rows: &[&[u16]], bytes_per_line: usize) -> Vec<u8> {
        let mut out = Vec::new();
        for row in rows {
            let start = out.len();
            for v in *row {
                out.extend_from_slice(&v.to_le_bytes());
            }
            out.resize(start + bytes_per_line, 0xEE);
        }
        out
    }

    #[test]
    fn z16_depth_is_scaled_with_zero_kept_invalid_and_padding_skipped() {
        let data = le16_rows(&[&[0, 1000, 65535], &[1, 2500, 0]], 8);
        let frame = FrameFormat::new(PixelFormat::Z16, 3, 2, 8);
        let d = depth(&frame, &data, 0.001).unwrap();
        let expected = array![[0.0, 1.0, 65.535], [0.001, 2.5, 0.0]];
        for (a, e) in d.iter().zip(expected.iter()) {
            assert!((a - e).abs() < 1e-6, "{d:?}");
        }
        assert_eq!(d[[0, 0]], 0.0);
    }

    #[test]
    fn y16_depth_and_intensity_agree_on_raw_values() {
        let data = le16_rows(&[&[7, 300], &[4095, 65535]], 4);
        let frame = FrameFormat::unpadded(PixelFormat::Y16, 2, 2);
        assert_eq!(
            intensity(&frame, &data).unwrap(),
            array![[7.0, 300.0], [4095.0, 65535.0]]
        );
        assert_eq!(
            depth(&frame, &data, 0.5).unwrap(),
            array![[3.5, 150.0], [2047.5, 32767.5]]
        );
    }

    #[test]
    fn depth_rejects_short_buffers_bad_scales_and_other_formats() {
        let frame = FrameFormat::new(PixelFormat::Z16, 3, 2, 8);
        let data = le16_rows(&[&[1, 2, 3], &[4, 5, 6]], 8);
        assert_eq!(
            depth(&frame, &data[..13], 0.001).unwrap_err(),
            DecodeError::ShortBuffer {
                format: PixelFormat::Z16,
                width: 3,
                height: 2,
                bytes_per_line: 8,
                expected: 14,
                actual: 13
            }
        );
        assert!(depth(&frame, &[], 0.001).is_err());
        assert!(matches!(
            depth(&frame, &data, 0.0),
            Err(DecodeError::InvalidParameter(_))
        ));
        assert!(matches!(
            depth(&frame, &data, f32::NAN),
            Err(DecodeError::InvalidParameter(_))
        ));
        let grey = FrameFormat::unpadded(PixelFormat::Grey, 3, 2);
        assert!(matches!(
            depth(&grey, &[0; 6], 0.001),
            Err(DecodeError::UnsupportedFormat {
                format: PixelFormat::Grey,
                ..
            })
        ));
        // An odd byte count per row (stride 5 < 6) is refused, not read past.
        assert!(matches!(
            depth(&FrameFormat::new(PixelFormat::Z16, 3, 2, 5), &data, 0.001),
            Err(DecodeError::StrideTooSmall { min: 6, .. })
        ));
    }

    #[test]
    fn into_functions_check_the_output_shape() {
        let frame = FrameFormat::unpadded(PixelFormat::Grey, 3, 2);
        let mut out = Array2::zeros((3, 2));
        assert_eq!(
            intensity_into(&frame, &[0; 6], out.view_mut()).unwrap_err(),
            DecodeError::OutputShape {
                expected: (2, 3),
                actual: (3, 2)
            }
        );
    }

    #[test]
    fn grey_intensity_with_stride_padding() {
        let data = [1u8, 2, 3, 0xEE, 250, 251, 252];
        let frame = FrameFormat::new(PixelFormat::Grey, 3, 2, 4);
        assert_eq!(
            intensity(&frame, &data).unwrap(),
            array![[1.0, 2.0, 3.0], [250.0, 251.0, 252.0]]
        );
        assert!(intensity(&frame, &data[..6]).is_err());
    }

    #[test]
    fn y12_masks_the_padding_nibble() {
        let data = le16_rows(&[&[0x0ABC, 0xF123]], 4);
        let frame = FrameFormat::unpadded(PixelFormat::Y12, 2, 1);
        assert_eq!(intensity(&frame, &data).unwrap(), array![[2748.0, 291.0]]);
    }

    #[test]
    fn y12p_bytes_follow_the_kernel_layout() {
        // p0 = 0xABC, p1 = 0x123 → 0xAB, 0x12, 0x3C.
        let packed = pack_y12p(&[0xABC, 0x123], 2, 1, 3).unwrap();
        assert_eq!(packed, vec![0xAB, 0x12, 0x3C]);
        let frame = FrameFormat::unpadded(PixelFormat::Y12P, 2, 1);
        assert_eq!(
            intensity(&frame, &[0xAB, 0x12, 0x3C]).unwrap(),
            array![[2748.0, 291.0]]
        );
    }

    #[test]
    fn y12p_pack_unpack_round_trips_with_odd_width_and_padding() {
        let (w, h, stride) = (5, 3, 12);
        let samples: Vec<u16> = (0..w * h).map(|i| ((i * 977 + 13) % 4096) as u16).collect();
        let packed = pack_y12p(&samples, w, h, stride).unwrap();
        assert_eq!(packed.len(), stride * h);
        let frame = FrameFormat::new(PixelFormat::Y12P, w, h, stride);
        let plane = intensity(&frame, &packed).unwrap();
        let back: Vec<u16> = plane.iter().map(|&v| v as u16).collect();
        assert_eq!(back, samples);
        // 5 pixels need 9 bytes in the last row.
        assert!(intensity(&frame, &packed[..2 * stride + 9]).is_ok());
        assert!(matches!(
            intensity(&frame, &packed[..2 * stride + 8]),
            Err(DecodeError::ShortBuffer { expected: 33, .. })
        ));
        assert_eq!(pack_y12p(&samples, w, h, 8), None);
        assert_eq!(pack_y12p(&samples[1..], w, h, stride), None);
    }
}
