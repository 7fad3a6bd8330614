//! Depth as colour: the display range, the turbo-coloured depth tile, the preview annotated
//! with its colour bar, and signed depth errors on the diverging map.
//!
//! Depth is in metres; a pixel without a measurement (0, negative or non-finite, the capture
//! format's rule [`dear_capture::is_valid_depth`]) is drawn [`INVALID`] black.

use dear_capture::is_valid_depth;
use image::RgbImage;
use ndarray::ArrayView2;

use crate::colormap::{depth_color, diverging, INVALID};
use crate::legend::Legend;
use crate::tile::map_image;

/// Narrowest display range in metres: a flat scene would otherwise divide by zero.
const MIN_RANGE_M: f32 = 1e-3;

/// A robust display range of the valid depth: the 1st to the 99th percentile (nearest rank,
/// as every reported percentile), so a few flying pixels do not squeeze the whole scene into
/// one colour. `None` when no pixel is valid.
pub fn auto_depth_range(depth: ArrayView2<f32>) -> Option<(f32, f32)> {
    let mut valid: Vec<f32> = depth
        .iter()
        .copied()
        .filter(|&z| is_valid_depth(z))
        .collect();
    let near = dear_stats::select_percentile(&mut valid, 0.01)?;
    let far = dear_stats::select_percentile(&mut valid, 0.99)?;
    Some((near, far))
}

/// The range a picture of `depth` is coloured on: `requested` as given when usable (reversed
/// bounds are swapped), otherwise [`auto_depth_range`], `0 … 1 m` when nothing is valid; an
/// empty range is widened to 1 mm so the map is defined. Never panics on a bad request: it
/// falls back to the automatic range.
///
/// Tiles that should be comparable (a result and its ground truth) share
/// `display_range(reference, None)`.
pub fn display_range(depth: ArrayView2<f32>, requested: Option<(f32, f32)>) -> (f32, f32) {
    let given = requested
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (a.min(b), a.max(b)));
    let (near, far) = given
        .or_else(|| auto_depth_range(depth))
        .unwrap_or((0.0, 1.0));
    if far - near < MIN_RANGE_M {
        (near, near + MIN_RANGE_M)
    } else {
        (near, far)
    }
}

/// Depth coloured with turbo (near blue, far red) on [`display_range`]`(depth, range)`, same
/// size as `depth`, invalid pixels black. No legend; see [`colorize_depth`] for the annotated
/// image.
pub fn depth_colors(depth: ArrayView2<f32>, range: Option<(f32, f32)>) -> RgbImage {
    let (near, far) = display_range(depth, range);
    map_image(depth, |z| {
        if is_valid_depth(z) {
            depth_color(z, near, far)
        } else {
            INVALID
        }
    })
}

/// Colourised depth (turbo; near blue, far red; invalid black) with a legend: a vertical colour
/// bar on the right, far at the top, with ticks at round values labelled in metres.
///
/// `range = (near, far)` in metres fixes the colour scale (use the same range for every frame of
/// a sequence so colours are comparable); `None` chooses a robust one per image. The result is
/// wider than `depth` by the legend, and at least [`Legend::min_height`] tall (padded with
/// black below a very small image).
pub fn colorize_depth(depth: ArrayView2<f32>, range: Option<(f32, f32)>) -> RgbImage {
    let (near, far) = display_range(depth, range);
    let colors = depth_colors(depth, Some((near, far)));
    let legend = Legend::new(colors.height(), near, far);
    let width = colors.width() + legend.width();
    let height = colors.height().max(legend.min_height());
    let mut out = RgbImage::from_pixel(width, height, image::Rgb(INVALID));
    image::imageops::replace(&mut out, &colors, 0, 0);
    legend.draw(&mut out, colors.width());
    out
}

/// Signed depth errors (metres, e.g. ToF − ground truth) on the diverging map: blue too near,
/// white right, red too far, saturating at ±`limit_m`; NaN (no error defined) is black.
pub fn signed_error_colors(error: ArrayView2<f32>, limit_m: f32) -> RgbImage {
    map_image(error, |e| {
        if e.is_nan() {
            INVALID
        } else {
            diverging(f64::from(e / limit_m))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    fn ramp(h: usize, w: usize, near: f32, far: f32) -> Array2<f32> {
        Array2::from_shape_fn((h, w), |(_, c)| {
            near + (far - near) * c as f32 / (w - 1) as f32
        })
    }

    /// Turbo from colorous directly, independent of `colormap`, over the used part.
    fn turbo(t: f64) -> [u8; 3] {
        let c = colorous::TURBO.eval_continuous(0.1 + 0.9 * t);
        [c.r, c.g, c.b]
    }

    #[test]
    fn colours_follow_turbo_and_invalid_is_black() {
        let mut depth = Array2::from_elem((2, 3), 1.0f32);
        depth[(0, 0)] = 1.0; // near end
        depth[(0, 1)] = 2.0; // middle
        depth[(0, 2)] = 3.0; // far end
        depth[(1, 0)] = 0.0;
        depth[(1, 1)] = f32::NAN;
        depth[(1, 2)] = 9.0; // beyond the range: clamps to far
        let img = depth_colors(depth.view(), Some((1.0, 3.0)));
        assert_eq!(img.get_pixel(0, 0).0, turbo(0.0));
        assert_eq!(img.get_pixel(1, 0).0, turbo(0.5));
        assert_eq!(img.get_pixel(2, 0).0, turbo(1.0));
        assert_eq!(img.get_pixel(0, 1).0, [0, 0, 0]);
        assert_eq!(img.get_pixel(1, 1).0, [0, 0, 0]);
        assert_eq!(img.get_pixel(2, 1).0, turbo(1.0));
        // Valid depth is never rendered dark enough to pass for a hole.
        for t in [0.0, 0.5, 1.0] {
            assert!(
                turbo(t).iter().map(|&v| u32::from(v)).sum::<u32>() > 120,
                "{t}"
            );
        }
    }

    #[test]
    fn reversed_or_bad_ranges_do_not_panic() {
        let depth = ramp(4, 5, 1.0, 2.0);
        let a = depth_colors(depth.view(), Some((2.0, 1.0)));
        let b = depth_colors(depth.view(), Some((1.0, 2.0)));
        assert_eq!(a, b);
        assert_eq!(
            display_range(depth.view(), Some((f32::NAN, 1.0))),
            auto_depth_range(depth.view()).unwrap()
        );
        assert_eq!(display_range(depth.view(), Some((1.5, 1.5))), (1.5, 1.501));
        assert_eq!(
            display_range(Array2::zeros((3, 3)).view(), None),
            (0.0, 1.0)
        );
        let _ = colorize_depth(depth.view(), Some((f32::NAN, 1.0)));
        let _ = colorize_depth(depth.view(), Some((1.5, 1.5)));
        let _ = colorize_depth(Array2::zeros((3, 3)).view(), None);
        let _ = colorize_depth(Array2::zeros((0, 0)).view(), None);
    }

    #[test]
    fn auto_range_ignores_invalid_and_outliers() {
        let mut depth = ramp(10, 101, 1.0, 2.0);
        depth[(0, 0)] = 0.0;
        depth[(0, 1)] = 50.0;
        let (near, far) = auto_depth_range(depth.view()).unwrap();
        assert!((1.0..1.05).contains(&near), "{near}");
        assert!((1.95..=2.0).contains(&far), "{far}");
        assert_eq!(auto_depth_range(Array2::zeros((2, 2)).view()), None);
    }

    #[test]
    fn legend_is_a_labelled_colour_bar() {
        let (h, w) = (120, 160);
        let depth = ramp(h, w, 0.5, 4.0);
        let img = colorize_depth(depth.view(), Some((0.5, 4.0)));
        let legend = Legend::new(h as u32, 0.5, 4.0);
        assert_eq!(img.width(), w as u32 + legend.width());
        assert_eq!(img.height(), h as u32);
        // The image part is untouched.
        assert_eq!(
            img.get_pixel(0, 0).0,
            depth_colors(depth.view(), Some((0.5, 4.0)))
                .get_pixel(0, 0)
                .0
        );
        // The bar: far (turbo 1) at the top, near (turbo 0.1, where the used part starts) at the
        // bottom, varying in between.
        let bar_x = w as u32 + Legend::GAP + Legend::BAR / 2;
        let (top, bottom) = legend.bar_rows();
        assert_eq!(img.get_pixel(bar_x, top).0, turbo(1.0));
        assert_eq!(img.get_pixel(bar_x, bottom).0, turbo(0.0));
        let distinct: std::collections::HashSet<_> =
            (top..=bottom).map(|y| img.get_pixel(bar_x, y).0).collect();
        assert!(distinct.len() > 20, "bar has {} colours", distinct.len());
        // Round ticks, labelled in metres: 1, 2, 3, 4 m for a 0.5–4 m range at this height.
        let labels: Vec<_> = legend.ticks().iter().map(|(_, s)| s.as_str()).collect();
        assert_eq!(labels, ["1m", "2m", "3m", "4m"]);
        // Each tick has white ink right of the bar on its row, and its label has ink pixels.
        let ink = crate::legend::INK.0;
        let tick_x = w as u32 + Legend::GAP + Legend::BAR;
        let label_x = tick_x + Legend::TICK + Legend::LABEL_GAP;
        for (value, _) in legend.ticks() {
            let y = legend.row_of(*value);
            assert_eq!(img.get_pixel(tick_x, y).0, ink);
            let inked = (label_x..img.width())
                .flat_map(|x| (y.saturating_sub(4)..y + 4).map(move |y| (x, y)))
                .filter(|&(x, y)| img.get_pixel(x, y).0 == ink)
                .count();
            assert!(inked > 10, "label at {value} m has {inked} ink pixels");
        }
        // Labels differ from each other as drawn (not the same glyphs repeated).
        let row_pixels = |v: f32| -> Vec<[u8; 3]> {
            let y = legend.row_of(v);
            (y - 3..=y + 3)
                .flat_map(|y| (label_x..img.width()).map(move |x| (x, y)))
                .map(|(x, y)| img.get_pixel(x, y).0)
                .collect()
        };
        assert_ne!(row_pixels(1.0), row_pixels(2.0));
    }

    #[test]
    fn tiny_images_get_a_padded_legend() {
        let img = colorize_depth(ramp(4, 4, 1.0, 2.0).view(), None);
        let legend = Legend::new(4, 1.0, 2.0);
        assert_eq!(img.height(), legend.min_height());
        assert_eq!(
            img.get_pixel(0, 10).0,
            [0, 0, 0],
            "padding below the image is black"
        );
    }

    #[test]
    fn signed_errors_are_blue_near_white_at_zero_red_far() {
        let error = Array2::from_shape_vec((1, 5), vec![-0.2, -0.05, 0.0, 0.3, f32::NAN]).unwrap();
        let img = signed_error_colors(error.view(), 0.1);
        let px = |x| img.get_pixel(x, 0).0;
        assert_eq!(px(0), diverging(-1.0), "saturates at -limit");
        assert_eq!(px(1), diverging(-0.5));
        assert_eq!(px(2), [255, 255, 255]);
        assert_eq!(px(3), diverging(1.0));
        assert_eq!(px(4), INVALID);
        assert!(px(1)[2] > px(1)[0], "too near is blue");
    }
}
