//! The plain tiles of a panel: the RGB image, the amplitude as grey, and any 2-D array coloured
//! pixel by pixel.

use image::{Rgb, RgbImage};
use ndarray::{ArrayView2, ArrayView3};

/// Percentile of the positive amplitude that is drawn white: a few specular pixels would
/// darken everything else under a max scaling.
pub const AMPLITUDE_WHITE_PERCENTILE: f64 = 0.99;

/// `values` coloured pixel by pixel with `color`, same size (row = y, column = x).
pub fn map_image(values: ArrayView2<f32>, color: impl Fn(f32) -> [u8; 3]) -> RgbImage {
    let (h, w) = values.dim();
    RgbImage::from_fn(w as u32, h as u32, |x, y| {
        Rgb(color(values[(y as usize, x as usize)]))
    })
}

/// An `(H, W, 3)` RGB array as an image.
///
/// # Panics
///
/// When the last axis is not 3 long: the callers pass a frame's RGB, which the capture format
/// guarantees to be `(H, W, 3)` ([`crate::blend::blend_rgb_depth`] checks arbitrary input).
pub fn rgb_image(rgb: ArrayView3<u8>) -> RgbImage {
    let (h, w, channels) = rgb.dim();
    assert_eq!(
        channels,
        3,
        "RGB array is {:?} (H, W, C); expected C = 3",
        rgb.dim()
    );
    RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let (r, c) = (y as usize, x as usize);
        Rgb([0, 1, 2].map(|k| rgb[(r, c, k)]))
    })
}

/// The amplitude as grey `√(a / a₉₉)`, white from the 99th percentile of the positive
/// amplitude (nearest rank) up; zero, negative and non-finite amplitude is black.
///
/// The square root because the amplitude falls with the square of the distance: on a linear
/// scale a room's far wall is black next to a near hand, under the root both are readable.
pub fn amplitude_image(amplitude: ArrayView2<f32>) -> RgbImage {
    let mut positive: Vec<f32> = amplitude.iter().copied().filter(|&a| a > 0.0).collect();
    let white = dear_stats::select_percentile(&mut positive, AMPLITUDE_WHITE_PERCENTILE)
        .unwrap_or(1.0)
        .max(1e-6);
    map_image(amplitude, |a| {
        // `max` turns NaN into 0 (black) before the root.
        let g = ((a / white).max(0.0).sqrt().min(1.0) * 255.0) as u8;
        [g, g, g]
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, Array3};

    #[test]
    fn rgb_keeps_every_channel_in_place() {
        let rgb = Array3::from_shape_fn((2, 3, 3), |(r, c, k)| (100 * r + 10 * c + k) as u8);
        let img = rgb_image(rgb.view());
        assert_eq!((img.width(), img.height()), (3, 2));
        assert_eq!(img.get_pixel(2, 1).0, [120, 121, 122]);
        assert_eq!(img.get_pixel(0, 0).0, [0, 1, 2]);
    }

    #[test]
    #[should_panic(expected = "expected C = 3")]
    fn rgb_with_four_channels_is_refused() {
        rgb_image(Array3::zeros((2, 2, 4)).view());
    }

    #[test]
    fn amplitude_is_the_root_of_its_share_of_the_99th_percentile() {
        // 100 positive values 1..=99 and one hot pixel of 10,000: the 99th percentile (nearest
        // rank) is 99, the hot pixel does not darken the rest. A last row without amplitude.
        let mut amplitude =
            Array2::from_shape_fn(
                (11, 10),
                |(r, c)| {
                    if r < 10 {
                        (10 * r + c + 1) as f32
                    } else {
                        0.0
                    }
                },
            );
        amplitude[(9, 9)] = 10_000.0;
        amplitude[(10, 1)] = f32::NAN;
        amplitude[(10, 2)] = -5.0;
        let img = amplitude_image(amplitude.view());
        let grey = |x, y| img.get_pixel(x, y).0;
        // a = 25 (row 2, column 4): √(25/99) · 255 = 128.1.
        assert_eq!(grey(4, 2), [128, 128, 128]);
        assert_eq!(grey(9, 9), [255, 255, 255], "above a₉₉ is white");
        assert_eq!(grey(8, 9), [255, 255, 255], "a₉₉ itself is white");
        for x in 0..3 {
            assert_eq!(grey(x, 10), [0, 0, 0], "column {x}: no amplitude is black");
        }
    }

    #[test]
    fn map_image_puts_rows_down_and_columns_across() {
        let values = Array2::from_shape_fn((2, 3), |(r, c)| (10 * r + c) as f32);
        let img = map_image(values.view(), |v| [v as u8, 0, 7]);
        assert_eq!((img.width(), img.height()), (3, 2));
        assert_eq!(img.get_pixel(2, 1).0, [12, 0, 7]);
    }
}
