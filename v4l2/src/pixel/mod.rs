//! The pixel formats ToF and RGB modules deliver over V4L2, and their decoders.
//!
//! Every decoder takes the buffer exactly as the driver filled it (`data`), the negotiated
//! `width` and `height` and the driver's `bytes_per_line` (stride; rows may be padded beyond
//! `width × bytes per pixel`), checks the buffer against them and returns a [`DecodeError`]
//! instead of panicking: the bytes come from a device and may be short or malformed (a truncated
//! USB transfer, a format changed under us). Decoders come as `_into` functions writing into a
//! caller-owned output, so a capture loop decodes every frame without allocating, and as
//! convenience wrappers that allocate the output.
//!
//! - [`depth`]: `Z16 ` / `Y16 ` depth with a depth scale; `GREY` / `Y16 ` / `Y12 ` / `Y12P`
//!   intensity (amplitude, IR) planes; the `Y12P` packing.
//! - [`phase`]: host-side demodulation of 4-phase ToF raw frames (`Y12 `, `Y12P`), and radial
//!   distance → z-depth.
//! - [`colour`]: `YUYV`, `NV12`, `RGB3` and `MJPG` into `(H, W, 3)` RGB8, the layout of
//!   `dear_capture::RgbdFrame::rgb`.

pub mod colour;
pub mod depth;
pub mod phase;

use std::fmt;

use thiserror::Error;

/// A V4L2 pixel format this crate decodes, named by its FourCC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PixelFormat {
    /// `Z16 `: 16-bit little-endian depth, one unit = the device's depth scale (RealSense).
    Z16,
    /// `Y16 `: 16-bit little-endian grey (IR / amplitude, or depth on some modules).
    Y16,
    /// `Y12 `: 12-bit grey in the low bits of little-endian 16-bit words (Arducam ToF raw
    /// phase frames on a Raspberry Pi 4).
    Y12,
    /// `Y12P`: MIPI CSI-2 packed 12-bit grey, 2 pixels in 3 bytes (Arducam ToF raw phase frames
    /// on a Raspberry Pi 5, Arducam VGA ToF with its 4 phases stacked in one buffer).
    Y12P,
    /// `GREY`: 8-bit grey (IR).
    Grey,
    /// `YUYV`: packed 4:2:2 YCbCr, `Y0 Cb Y1 Cr` per 2 pixels.
    Yuyv,
    /// `NV12`: 4:2:0 YCbCr, a Y plane followed by an interleaved `Cb Cr` plane of half height.
    Nv12,
    /// `RGB3`: packed 8-bit `R G B`.
    Rgb3,
    /// `MJPG`: one JPEG image per buffer.
    Mjpg,
}

impl PixelFormat {
    /// Every format, in declaration order (for listing what the decoders support).
    pub const ALL: [PixelFormat; 9] = [
        PixelFormat::Z16,
        PixelFormat::Y16,
        PixelFormat::Y12,
        PixelFormat::Y12P,
        PixelFormat::Grey,
        PixelFormat::Yuyv,
        PixelFormat::Nv12,
        PixelFormat::Rgb3,
        PixelFormat::Mjpg,
    ];

    /// The format with this FourCC, `None` for one this crate cannot decode.
    pub fn from_fourcc(fourcc: &[u8; 4]) -> Option<Self> {
        Self::ALL.into_iter().find(|f| &f.fourcc() == fourcc)
    }

    /// The FourCC as V4L2 spells it (`v4l2_fourcc('Z', '1', '6', ' ')`).
    pub fn fourcc(self) -> [u8; 4] {
        match self {
            PixelFormat::Z16 => *b"Z16 ",
            PixelFormat::Y16 => *b"Y16 ",
            PixelFormat::Y12 => *b"Y12 ",
            PixelFormat::Y12P => *b"Y12P",
            PixelFormat::Grey => *b"GREY",
            PixelFormat::Yuyv => *b"YUYV",
            PixelFormat::Nv12 => *b"NV12",
            PixelFormat::Rgb3 => *b"RGB3",
            PixelFormat::Mjpg => *b"MJPG",
        }
    }

    /// The fewest bytes one row of `width` pixels takes (the smallest valid bytes-per-line),
    /// `None` for a compressed format (MJPG has no rows) or a width whose row would overflow.
    /// For `NV12` this is the Y plane's row; its chroma rows have the same length.
    pub fn min_bytes_per_line(self, width: usize) -> Option<usize> {
        match self {
            PixelFormat::Z16 | PixelFormat::Y16 | PixelFormat::Y12 | PixelFormat::Yuyv => {
                width.checked_mul(2)
            }
            // Odd widths end in a half-filled 3-byte group.
            PixelFormat::Y12P => width.div_ceil(2).checked_mul(3),
            PixelFormat::Grey | PixelFormat::Nv12 => Some(width),
            PixelFormat::Rgb3 => width.checked_mul(3),
            PixelFormat::Mjpg => None,
        }
    }

    /// How many rows of `bytes_per_line` bytes an image of `height` rows spans in the buffer:
    /// `height`, or `height + height / 2` for `NV12`'s chroma plane. `None` for MJPG.
    fn rows_in_buffer(self, height: usize) -> Option<usize> {
        match self {
            PixelFormat::Nv12 => height.checked_add(height / 2),
            PixelFormat::Mjpg => None,
            _ => Some(height),
        }
    }
}

impl fmt::Display for PixelFormat {
    /// The FourCC's four characters, trailing space included (`'Z16 '` as `v4l2-ctl` shows it).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let code = self.fourcc();
        // Every FourCC above is ASCII.
        f.write_str(std::str::from_utf8(&code).unwrap_or("????"))
    }
}

/// What a stream's buffers hold, as negotiated with the driver (`VIDIOC_S_FMT`): the decoders
/// check every buffer against it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameFormat {
    pub format: PixelFormat,
    /// Pixels per row.
    pub width: usize,
    /// Rows of the image (for 4-phase frames stacked in one buffer: of the whole buffer).
    pub height: usize,
    /// Bytes from one row's start to the next (`bytesperline`); rows may be padded. Ignored for
    /// `MJPG`.
    pub bytes_per_line: usize,
}

impl FrameFormat {
    pub fn new(format: PixelFormat, width: usize, height: usize, bytes_per_line: usize) -> Self {
        FrameFormat {
            format,
            width,
            height,
            bytes_per_line,
        }
    }

    /// Rows without padding (the smallest valid `bytes_per_line`; 0 for `MJPG` or a width
    /// too large to address, which the decoders then report).
    pub fn unpadded(format: PixelFormat, width: usize, height: usize) -> Self {
        let bytes_per_line = format.min_bytes_per_line(width).unwrap_or(0);
        FrameFormat::new(format, width, height, bytes_per_line)
    }

    /// Checks `data` against this format (see [`Layout::check`]).
    fn layout(&self, data: &[u8]) -> Result<Layout, DecodeError> {
        Layout::check(
            self.format,
            data,
            self.width,
            self.height,
            self.bytes_per_line,
        )
    }

    /// Fails unless the format is one of `allowed`; `wanted` names what the caller decodes.
    fn require(&self, allowed: &[PixelFormat], wanted: &'static str) -> Result<(), DecodeError> {
        if allowed.contains(&self.format) {
            Ok(())
        } else {
            Err(DecodeError::UnsupportedFormat {
                format: self.format,
                wanted,
            })
        }
    }
}

/// Why a buffer could not be decoded.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DecodeError {
    #[error("{format} buffer of {width}x{height} with {bytes_per_line} bytes per line needs {expected} bytes, got {actual}")]
    ShortBuffer {
        format: PixelFormat,
        width: usize,
        height: usize,
        bytes_per_line: usize,
        expected: usize,
        actual: usize,
    },
    #[error("{format} rows of {width} pixels need at least {min} bytes per line, the driver reports {bytes_per_line}")]
    StrideTooSmall {
        format: PixelFormat,
        width: usize,
        bytes_per_line: usize,
        min: usize,
    },
    #[error("{format} needs an even {what}, got {value}")]
    OddDimension {
        format: PixelFormat,
        what: &'static str,
        value: usize,
    },
    #[error("{format} image of {width}x{height} is too large to address")]
    TooLarge {
        format: PixelFormat,
        width: usize,
        height: usize,
    },
    #[error("{format} cannot be decoded as {wanted}")]
    UnsupportedFormat {
        format: PixelFormat,
        wanted: &'static str,
    },
    #[error("output of {actual:?} (rows, columns) given for a {expected:?} image")]
    OutputShape {
        expected: (usize, usize),
        actual: (usize, usize),
    },
    #[error(
        "{format} phase frames: {height} rows cannot hold 4 stacked phase images of equal height"
    )]
    PhaseStack { format: PixelFormat, height: usize },
    #[error(
        "{format} JPEG is {actual_width}x{actual_height}, the negotiated size is {width}x{height}"
    )]
    SizeMismatch {
        format: PixelFormat,
        width: usize,
        height: usize,
        actual_width: usize,
        actual_height: usize,
    },
    #[error("{format} buffer is not a decodable JPEG: {message}")]
    Jpeg {
        format: PixelFormat,
        message: String,
    },
    #[error("invalid decoder parameter: {0}")]
    InvalidParameter(String),
}

/// The geometry of one validated buffer: where each row starts and how long it is.
#[derive(Debug, Clone, Copy)]
struct Layout {
    bytes_per_line: usize,
}

impl Layout {
    /// Checks that `data` holds `rows_in_buffer` rows of `format` at `bytes_per_line`. The last
    /// row need not be padded: drivers report `sizeimage` = stride × rows, but a buffer holding
    /// every pixel is all a decoder needs.
    fn check(
        format: PixelFormat,
        data: &[u8],
        width: usize,
        height: usize,
        bytes_per_line: usize,
    ) -> Result<Layout, DecodeError> {
        let too_large = DecodeError::TooLarge {
            format,
            width,
            height,
        };
        let min = format
            .min_bytes_per_line(width)
            .ok_or_else(|| too_large.clone())?;
        if bytes_per_line < min {
            return Err(DecodeError::StrideTooSmall {
                format,
                width,
                bytes_per_line,
                min,
            });
        }
        let rows = format
            .rows_in_buffer(height)
            .ok_or_else(|| too_large.clone())?;
        let expected = match rows.checked_sub(1) {
            None => 0,
            Some(full_rows) => full_rows
                .checked_mul(bytes_per_line)
                .and_then(|n| n.checked_add(min))
                .ok_or(too_large)?,
        };
        if data.len() < expected {
            return Err(DecodeError::ShortBuffer {
                format,
                width,
                height,
                bytes_per_line,
                expected,
                actual: data.len(),
            });
        }
        Ok(Layout { bytes_per_line })
    }

    /// The pixel bytes of row `y` (buffer row, so `NV12` chroma rows follow the Y rows),
    /// without the stride padding. Only valid rows are asked for after [`Layout::check`].
    fn row<'a>(&self, data: &'a [u8], y: usize, row_bytes: usize) -> &'a [u8] {
        let start = y * self.bytes_per_line;
        &data[start..start + row_bytes]
    }
}

/// Checks that a caller-owned output has the image's `(height, width)`.
fn check_output(expected: (usize, usize), actual: (usize, usize)) -> Result<(), DecodeError> {
    if expected == actual {
        Ok(())
    } else {
        Err(DecodeError::OutputShape { expected, actual })
    }
}

/// Requires an even `value` (chroma subsampling pairs pixels and rows).
fn check_even(format: PixelFormat, what: &'static str, value: usize) -> Result<(), DecodeError> {
    if value.is_multiple_of(2) {
        Ok(())
    } else {
        Err(DecodeError::OddDimension {
            format,
            what,
            value,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fourcc_round_trips_for_every_format() {
        for format in PixelFormat::ALL {
            assert_eq!(PixelFormat::from_fourcc(&format.fourcc()), Some(format));
            assert_eq!(format.to_string().as_bytes(), &format.fourcc());
        }
        assert_eq!(PixelFormat::from_fourcc(b"Z16 "), Some(PixelFormat::Z16));
        assert_eq!(PixelFormat::from_fourcc(b"Y12P"), Some(PixelFormat::Y12P));
        assert_eq!(PixelFormat::from_fourcc(b"Z16\0"), None);
        assert_eq!(PixelFormat::from_fourcc(b"BA81"), None);
        assert_eq!(PixelFormat::Y12.to_string(), "Y12 ");
    }

    #[test]
    fn min_bytes_per_line_matches_each_packing() {
        assert_eq!(PixelFormat::Z16.min_bytes_per_line(640), Some(1280));
        assert_eq!(PixelFormat::Y12P.min_bytes_per_line(240), Some(360));
        assert_eq!(PixelFormat::Y12P.min_bytes_per_line(3), Some(6));
        assert_eq!(PixelFormat::Rgb3.min_bytes_per_line(5), Some(15));
        assert_eq!(PixelFormat::Nv12.min_bytes_per_line(8), Some(8));
        assert_eq!(PixelFormat::Mjpg.min_bytes_per_line(8), None);
        assert_eq!(PixelFormat::Rgb3.min_bytes_per_line(usize::MAX), None);
    }

    #[test]
    fn layout_check_accepts_an_unpadded_last_row_and_rejects_less() {
        // 3 rows of 4 Z16 pixels at a 10-byte stride: 2 × 10 + 8 bytes.
        let data = vec![0u8; 28];
        assert!(Layout::check(PixelFormat::Z16, &data, 4, 3, 10).is_ok());
        assert_eq!(
            Layout::check(PixelFormat::Z16, &data[..27], 4, 3, 10).unwrap_err(),
            DecodeError::ShortBuffer {
                format: PixelFormat::Z16,
                width: 4,
                height: 3,
                bytes_per_line: 10,
                expected: 28,
                actual: 27
            }
        );
        assert!(matches!(
            Layout::check(PixelFormat::Z16, &data, 4, 3, 7),
            Err(DecodeError::StrideTooSmall { min: 8, .. })
        ));
        assert!(matches!(
            Layout::check(
                PixelFormat::Z16,
                &data,
                usize::MAX / 2,
                usize::MAX / 2,
                usize::MAX
            ),
            Err(DecodeError::TooLarge { .. })
        ));
        // NV12 4x4: 4 Y rows and 2 chroma rows.
        assert!(Layout::check(PixelFormat::Nv12, &[0u8; 24], 4, 4, 4).is_ok());
        assert!(Layout::check(PixelFormat::Nv12, &[0u8; 23], 4, 4, 4).is_err());
    }
}
