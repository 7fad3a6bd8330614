//! Colour formats into interleaved RGB8 `(H, W, 3)`, the layout of
//! `dear_capture::RgbdFrame::rgb`, so a capture loop decodes straight into a frame.
//!
//! `YUYV` and `NV12` are converted as BT.601 limited-range ("studio swing") YCbCr, what UVC and
//! most CSI colour cameras deliver: Y in 16..235 and Cb, Cr in 16..240 around 128, with the
//! standard 8-bit fixed-point coefficients
//! `R = (298·(Y−16) + 409·(Cr−128) + 128) >> 8`,
//! `G = (298·(Y−16) − 100·(Cb−128) − 208·(Cr−128) + 128) >> 8`,
//! `B = (298·(Y−16) + 516·(Cb−128) + 128) >> 8`, clamped to 0..255.

use image::ImageFormat;
use ndarray::{Array3, ArrayViewMut2, ArrayViewMut3, Axis};

use super::{check_even, check_output, DecodeError, FrameFormat, PixelFormat};

/// One BT.601 limited-range YCbCr sample as RGB8 (see the module documentation).
#[inline]
pub fn ycbcr_to_rgb(y: u8, cb: u8, cr: u8) -> [u8; 3] {
    let c = 298 * (i32::from(y) - 16) + 128;
    let d = i32::from(cb) - 128;
    let e = i32::from(cr) - 128;
    let clamp = |v: i32| (v >> 8).clamp(0, 255) as u8;
    [
        clamp(c + 409 * e),
        clamp(c - 100 * d - 208 * e),
        clamp(c + 516 * d),
    ]
}

/// Fills one output row `(W, 3)` with `pixel(x)`, through a slice when the row is contiguous.
fn fill_row(mut row: ArrayViewMut2<u8>, mut pixel: impl FnMut(usize) -> [u8; 3]) {
    if let Some(slice) = row.as_slice_mut() {
        for (x, px) in slice.chunks_exact_mut(3).enumerate() {
            px.copy_from_slice(&pixel(x));
        }
    } else {
        for (x, mut px) in row.outer_iter_mut().enumerate() {
            let [r, g, b] = pixel(x);
            px[0] = r;
            px[1] = g;
            px[2] = b;
        }
    }
}

/// Decodes a colour buffer (`YUYV`, `NV12`, `RGB3`, `MJPG`) into `out`, shaped
/// `(height, width, 3)`. An MJPG image whose size differs from the negotiated one is an error
/// ([`DecodeError::SizeMismatch`]), not a resize: the calibration belongs to the negotiated size.
pub fn rgb_into(
    frame: &FrameFormat,
    data: &[u8],
    mut out: ArrayViewMut3<u8>,
) -> Result<(), DecodeError> {
    let (h, w) = (frame.height, frame.width);
    let (oh, ow, oc) = out.dim();
    if oc != 3 {
        return Err(DecodeError::OutputShape {
            expected: (h, w),
            actual: (oh, ow),
        });
    }
    check_output((h, w), (oh, ow))?;
    match frame.format {
        PixelFormat::Yuyv => {
            check_even(frame.format, "width", w)?;
            let layout = frame.layout(data)?;
            for (y, row_out) in out.axis_iter_mut(Axis(0)).enumerate() {
                let row = layout.row(data, y, 2 * w);
                fill_row(row_out, |x| {
                    let g = &row[4 * (x / 2)..4 * (x / 2) + 4];
                    ycbcr_to_rgb(g[2 * (x % 2)], g[1], g[3])
                });
            }
        }
        PixelFormat::Nv12 => {
            check_even(frame.format, "width", w)?;
            check_even(frame.format, "height", h)?;
            let layout = frame.layout(data)?;
            for (y, row_out) in out.axis_iter_mut(Axis(0)).enumerate() {
                let luma = layout.row(data, y, w);
                let chroma = layout.row(data, h + y / 2, w);
                fill_row(row_out, |x| {
                    let c = 2 * (x / 2);
                    ycbcr_to_rgb(luma[x], chroma[c], chroma[c + 1])
                });
            }
        }
        PixelFormat::Rgb3 => {
            let layout = frame.layout(data)?;
            for (y, row_out) in out.axis_iter_mut(Axis(0)).enumerate() {
                let row = layout.row(data, y, 3 * w);
                fill_row(row_out, |x| [row[3 * x], row[3 * x + 1], row[3 * x + 2]]);
            }
        }
        PixelFormat::Mjpg => {
            let image = image::load_from_memory_with_format(data, ImageFormat::Jpeg)
                .map_err(|e| DecodeError::Jpeg {
                    format: frame.format,
                    message: e.to_string(),
                })?
                .into_rgb8();
            let (iw, ih) = (image.width() as usize, image.height() as usize);
            if (iw, ih) != (w, h) {
                return Err(DecodeError::SizeMismatch {
                    format: frame.format,
                    width: w,
                    height: h,
                    actual_width: iw,
                    actual_height: ih,
                });
            }
            let pixels = image.as_raw();
            for (y, row_out) in out.axis_iter_mut(Axis(0)).enumerate() {
                let row = &pixels[3 * w * y..3 * w * (y + 1)];
                fill_row(row_out, |x| [row[3 * x], row[3 * x + 1], row[3 * x + 2]]);
            }
        }
        PixelFormat::Z16
        | PixelFormat::Y16
        | PixelFormat::Y12
        | PixelFormat::Y12P
        | PixelFormat::Grey => {
            return Err(DecodeError::UnsupportedFormat {
                format: frame.format,
                wanted: "RGB",
            })
        }
    }
    Ok(())
}

/// [`rgb_into`] into a new `(height, width, 3)` array.
pub fn rgb(frame: &FrameFormat, data: &[u8]) -> Result<Array3<u8>, DecodeError> {
    let mut out = Array3::zeros((frame.height, frame.width, 3));
    rgb_into(frame, data, out.view_mut())?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::s;

    /// BT.601 limited-range YCbCr of full-range colours (rounded, as encoders produce them).
    const RED: (u8, u8, u8) = (81, 90, 240);
    const GREEN: (u8, u8, u8) = (145, 54, 34);
    const BLUE: (u8, u8, u8) = (41, 240, 110);
    const GREY: (u8, u8, u8) = (126, 128, 128);
    const WHITE: (u8, u8, u8) = (235, 128, 128);
    const BLACK: (u8, u8, u8) = (16, 128, 128);

    fn assert_close(got: [u8; 3], want: [u8; 3], what: &str) {
        for c in 0..3 {
            assert!(
                got[c].abs_diff(want[c]) <= 2,
                "{what}: got {got:?}, want {want:?}"
            );
        }
    }

    #[test]
    fn known_colours_convert_within_rounding() {
        let cases = [
            (RED, [255, 0, 0], "red"),
            (GREEN, [0, 255, 0], "green"),
            (BLUE, [0, 0, 255], "blue"),
            (GREY, [128, 128, 128], "grey"),
            (WHITE, [255, 255, 255], "white"),
            (BLACK, [0, 0, 0], "black"),
        ];
        for ((y, cb, cr), want, what) in cases {
            assert_close(ycbcr_to_rgb(y, cb, cr), want, what);
        }
        // Out-of-range codes clamp instead of wrapping.
        assert_eq!(ycbcr_to_rgb(255, 255, 255)[0], 255);
        assert_eq!(ycbcr_to_rgb(0, 0, 0), [0, 135, 0]);
    }

    #[test]
    fn yuyv_decodes_pairs_with_their_shared_chroma_and_skips_padding() {
        // Row 0: red, red, green, green; row 1: blue, blue, white, black. Stride 10 (2 padding).
        let mut data = Vec::new();
        for (a, b) in [(RED, RED), (GREEN, GREEN), (BLUE, BLUE), (WHITE, BLACK)] {
            data.extend_from_slice(&[a.0, a.1, b.0, a.2]);
            if data.len() % 10 == 8 {
                data.extend_from_slice(&[0xEE, 0xEE]);
            }
        }
        let frame = FrameFormat::new(PixelFormat::Yuyv, 4, 2, 10);
        let decoded = rgb(&frame, &data).unwrap();
        let px = |y: usize, x: usize| [decoded[[y, x, 0]], decoded[[y, x, 1]], decoded[[y, x, 2]]];
        assert_close(px(0, 0), [255, 0, 0], "red");
        assert_close(px(0, 1), [255, 0, 0], "red");
        assert_close(px(0, 3), [0, 255, 0], "green");
        assert_close(px(1, 1), [0, 0, 255], "blue");
        assert_close(px(1, 2), [255, 255, 255], "white");
        assert_close(px(1, 3), [0, 0, 0], "black (second Y of a pair)");
    }

    #[test]
    fn yuyv_rejects_odd_width_and_short_buffers() {
        assert!(matches!(
            rgb(&FrameFormat::unpadded(PixelFormat::Yuyv, 3, 1), &[0; 8]),
            Err(DecodeError::OddDimension {
                what: "width",
                value: 3,
                ..
            })
        ));
        let frame = FrameFormat::new(PixelFormat::Yuyv, 4, 2, 10);
        assert!(matches!(
            rgb(&frame, &[0; 17]),
            Err(DecodeError::ShortBuffer {
                expected: 18,
                actual: 17,
                ..
            })
        ));
    }

    #[test]
    fn nv12_shares_chroma_over_2x2_blocks() {
        // 4×2: left block red, right block blue; stride 6.
        let (w, h, stride) = (4, 2, 6);
        let mut data = vec![0xEEu8; stride * (h + h / 2)];
        for y in 0..h {
            data[y * stride..y * stride + 4].copy_from_slice(&[RED.0, RED.0, BLUE.0, BLUE.0]);
        }
        data[h * stride..h * stride + 4].copy_from_slice(&[RED.1, RED.2, BLUE.1, BLUE.2]);
        let frame = FrameFormat::new(PixelFormat::Nv12, w, h, stride);
        let decoded = rgb(&frame, &data).unwrap();
        for y in 0..h {
            for x in 0..w {
                let got = [decoded[[y, x, 0]], decoded[[y, x, 1]], decoded[[y, x, 2]]];
                let want = if x < 2 { [255, 0, 0] } else { [0, 0, 255] };
                assert_close(got, want, &format!("({x}, {y})"));
            }
        }
        // The chroma plane is part of the buffer.
        assert!(matches!(
            rgb(&frame, &data[..2 * stride + 3]),
            Err(DecodeError::ShortBuffer { expected: 16, .. })
        ));
        assert!(matches!(
            rgb(&FrameFormat::unpadded(PixelFormat::Nv12, 4, 3), &[0; 24]),
            Err(DecodeError::OddDimension { what: "height", .. })
        ));
    }

    #[test]
    fn rgb3_copies_with_stride_and_fills_non_contiguous_outputs() {
        let data = [1u8, 2, 3, 4, 5, 6, 0xEE, 7, 8, 9, 10, 11, 12];
        let frame = FrameFormat::new(PixelFormat::Rgb3, 2, 2, 7);
        let got = rgb(&frame, &data).unwrap();
        assert_eq!(
            got.as_slice().unwrap(),
            &[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]
        );
        // An output whose rows are not contiguous (every other column of a wider array)
        // takes the same pixels.
        let mut wide = Array3::<u8>::zeros((2, 4, 3));
        rgb_into(&frame, &data, wide.slice_mut(s![.., ..;2, ..])).unwrap();
        assert_eq!(wide.slice(s![.., ..;2, ..]), got);
        assert_eq!(wide.slice(s![.., 1..;2, ..]).sum(), 0);
        assert!(rgb(&frame, &data[..12]).is_err());
        let mut wrong = Array3::<u8>::zeros((2, 2, 4));
        assert!(matches!(
            rgb_into(&frame, &data, wrong.view_mut()),
            Err(DecodeError::OutputShape { .. })
        ));
    }

    fn jpeg_of(width: u32, height: u32) -> (image::RgbImage, Vec<u8>) {
        // Smooth gradients: JPEG keeps them within a few levels at high quality.
        let img = image::RgbImage::from_fn(width, height, |x, y| {
            image::Rgb([(x * 8) as u8, (y * 8) as u8, 128])
        });
        let mut bytes = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 95)
            .encode_image(&img)
            .unwrap();
        (img, bytes)
    }

    #[test]
    fn mjpg_round_trips_within_jpeg_tolerance() {
        let (img, bytes) = jpeg_of(32, 16);
        let frame = FrameFormat::unpadded(PixelFormat::Mjpg, 32, 16);
        let got = rgb(&frame, &bytes).unwrap();
        let mut worst = 0u8;
        for (x, y, p) in img.enumerate_pixels() {
            for c in 0..3 {
                worst = worst.max(got[[y as usize, x as usize, c]].abs_diff(p[c]));
            }
        }
        assert!(worst <= 8, "largest channel error {worst}");
    }

    #[test]
    fn mjpg_of_another_size_or_truncated_is_an_error() {
        let (_, bytes) = jpeg_of(32, 16);
        assert_eq!(
            rgb(&FrameFormat::unpadded(PixelFormat::Mjpg, 16, 16), &bytes).unwrap_err(),
            DecodeError::SizeMismatch {
                format: PixelFormat::Mjpg,
                width: 16,
                height: 16,
                actual_width: 32,
                actual_height: 16
            }
        );
        let frame = FrameFormat::unpadded(PixelFormat::Mjpg, 32, 16);
        assert!(matches!(
            rgb(&frame, &bytes[..20]),
            Err(DecodeError::Jpeg { .. })
        ));
        assert!(matches!(rgb(&frame, &[]), Err(DecodeError::Jpeg { .. })));
    }

    #[test]
    fn depth_formats_are_not_colour() {
        assert!(matches!(
            rgb(&FrameFormat::unpadded(PixelFormat::Z16, 2, 2), &[0; 8]),
            Err(DecodeError::UnsupportedFormat { .. })
        ));
    }
}
