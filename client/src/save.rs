//! Turning a received depth frame into files a person can look at or a tool can read back.
//!
//! Every function takes plain `ndarray` views, so it works on a [`crate::Frame`]
//! (`frame.depth_view()`, `frame.rgb_view()`) as well as on a `dear_capture::RgbdFrame`'s. The
//! pictures are `dear_picture`'s, the same as `dear eval`'s figures and `dear-synth preview`'s
//! panels; this module adds the files.
//!
//! - [`save_depth_png16`]: the capture format's 16-bit millimetre PNG (lossless to 0.5 mm).
//! - [`colorize_depth`] / [`save_depth_colorized`]: a turbo-coloured depth image with a
//!   labelled colour bar, for eyes.
//! - [`blend_rgb_depth`] / [`save_rgb_depth_blend`]: depth over RGB, to judge alignment.

use std::path::{Path, PathBuf};

use dear_capture::{png, CaptureError};
use image::{Rgb, RgbImage};
use ndarray::{ArrayView2, ArrayView3};

pub use dear_picture::blend::{blend_rgb_depth, ShapeMismatch, EDGE_COLOR};
pub use dear_picture::depth::{auto_depth_range, colorize_depth, depth_colors};
pub use dear_picture::legend::Legend;

/// Metres per unit of the 16-bit depth PNGs (millimetres), as in the capture format.
pub const DEPTH_PNG_SCALE: f32 = 0.001;

/// Colour of invalid depth (`0`, negative or non-finite) in every rendering.
pub const INVALID_COLOR: Rgb<u8> = Rgb(dear_picture::colormap::INVALID);

/// Errors of the save helpers; each names the file or the mismatching inputs.
#[derive(Debug, thiserror::Error)]
pub enum SaveError {
    #[error(transparent)]
    Capture(#[from] CaptureError),
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
    #[error(transparent)]
    Shape(#[from] ShapeMismatch),
}

/// Writes depth (metres, 0 = invalid) as a 16-bit PNG in millimetres, exactly as the capture
/// format's `NNNNNN.depth.png` (rounded to the nearest millimetre, saturating at 65.535 m;
/// invalid, negative or non-finite depth → 0).
pub fn save_depth_png16(path: impl AsRef<Path>, depth: ArrayView2<f32>) -> Result<(), SaveError> {
    Ok(png::write_depth(path.as_ref(), depth, DEPTH_PNG_SCALE)?)
}

/// [`colorize_depth`] written as an 8-bit RGB PNG.
pub fn save_depth_colorized(
    path: impl AsRef<Path>,
    depth: ArrayView2<f32>,
    range: Option<(f32, f32)>,
) -> Result<(), SaveError> {
    save_image(path.as_ref(), &colorize_depth(depth, range))
}

/// [`blend_rgb_depth`] written as an 8-bit RGB PNG.
pub fn save_rgb_depth_blend(
    path: impl AsRef<Path>,
    rgb: ArrayView3<u8>,
    depth: ArrayView2<f32>,
    alpha: f32,
) -> Result<(), SaveError> {
    save_image(path.as_ref(), &blend_rgb_depth(rgb, depth, alpha)?)
}

fn save_image(path: &Path, image: &RgbImage) -> Result<(), SaveError> {
    image.save(path).map_err(|e| SaveError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, Array3};

    fn ramp(h: usize, w: usize, near: f32, far: f32) -> Array2<f32> {
        Array2::from_shape_fn((h, w), |(_, c)| {
            near + (far - near) * c as f32 / (w - 1) as f32
        })
    }

    #[test]
    fn png16_round_trip_is_within_half_a_millimetre() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.png");
        let depth = Array2::from_shape_fn((7, 9), |(r, c)| {
            if (r + c) % 5 == 0 {
                0.0
            } else {
                0.3 + 0.0123456 * (r * 9 + c) as f32
            }
        });
        save_depth_png16(&path, depth.view()).unwrap();
        let back = png::read_depth(&path, Some((9, 7)), DEPTH_PNG_SCALE).unwrap();
        for (a, b) in depth.iter().zip(back.iter()) {
            if *a == 0.0 {
                assert_eq!(*b, 0.0);
            } else {
                assert!((a - b).abs() <= 0.0005 + 1e-6, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn png16_error_names_the_path() {
        let err = save_depth_png16("/nonexistent-dir/d.png", Array2::zeros((2, 2)).view())
            .unwrap_err()
            .to_string();
        assert!(err.contains("/nonexistent-dir/d.png"), "{err}");
    }

    #[test]
    fn saved_images_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let depth = ramp(30, 40, 1.0, 3.0);
        let rgb = Array3::from_elem((30, 40, 3), 7u8);
        let d = dir.path().join("depth.png");
        let b = dir.path().join("blend.png");
        save_depth_colorized(&d, depth.view(), None).unwrap();
        save_rgb_depth_blend(&b, rgb.view(), depth.view(), 0.4).unwrap();
        let d_img = image::open(&d).unwrap().into_rgb8();
        assert_eq!(d_img, colorize_depth(depth.view(), None));
        let b_img = image::open(&b).unwrap().into_rgb8();
        assert_eq!((b_img.width(), b_img.height()), (40, 30));
        assert_eq!(
            b_img,
            blend_rgb_depth(rgb.view(), depth.view(), 0.4).unwrap()
        );
    }

    #[test]
    fn a_mismatched_blend_is_not_written_and_the_error_names_both_shapes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("blend.png");
        let err = save_rgb_depth_blend(
            &path,
            Array3::zeros((2, 3, 3)).view(),
            Array2::zeros((3, 2)).view(),
            0.5,
        )
        .unwrap_err();
        assert!(matches!(err, SaveError::Shape(_)), "{err:?}");
        let message = err.to_string();
        assert!(
            message.contains("(2, 3, 3)") && message.contains("(3, 2)"),
            "{message}"
        );
        assert!(!path.exists());
    }
}
