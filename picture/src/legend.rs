//! The colour bar drawn right of a colourised depth image, with round ticks labelled in metres.

use image::{Rgb, RgbImage};

use crate::colormap::depth_color;
use crate::text;

/// Colour of the legend's ticks and labels.
pub const INK: Rgb<u8> = Rgb([255, 255, 255]);
/// Background of the legend panel: not black, so it is not mistaken for invalid depth.
pub const BACKGROUND: Rgb<u8> = Rgb([40, 40, 40]);

/// The colour bar of a depth picture.
///
/// Layout, left to right: a gap, the bar, ticks, labels. The bar runs from `margin` below the
/// top to `margin` above the bottom of the image, far at the top, so labels centred on the end
/// ticks still fit. Everything scales with the image height (font pixels double from 240 rows).
#[derive(Debug, Clone)]
pub struct Legend {
    scale: u32,
    height: u32,
    near: f32,
    far: f32,
    ticks: Vec<(f32, String)>,
}

impl Legend {
    pub(crate) const GAP: u32 = 6;
    pub(crate) const BAR: u32 = 12;
    pub(crate) const TICK: u32 = 4;
    pub(crate) const LABEL_GAP: u32 = 3;
    const RIGHT_MARGIN: u32 = 4;

    /// A legend for an image `height` rows tall, colouring `[near, far]` metres.
    pub fn new(height: u32, near: f32, far: f32) -> Self {
        let scale = if height >= 240 { 2 } else { 1 };
        let mut legend = Legend {
            scale,
            height,
            near,
            far,
            ticks: Vec::new(),
        };
        // About one label per 18 rows of bar (2.5 glyph heights at any scale), at least two.
        let wanted = (legend.bar_len() / (18 * scale)).clamp(2, 8) as usize;
        legend.ticks = nice_ticks(near, far, wanted);
        legend
    }

    fn margin(&self) -> u32 {
        // Half a glyph plus a pixel, so end labels are not clipped.
        (text::HEIGHT * self.scale).div_ceil(2) + self.scale
    }

    /// Bar top and bottom rows (inclusive) in the output image.
    pub(crate) fn bar_rows(&self) -> (u32, u32) {
        let height = self.height.max(self.min_height());
        (self.margin(), height - 1 - self.margin())
    }

    fn bar_len(&self) -> u32 {
        let (top, bottom) = self.bar_rows();
        bottom - top
    }

    /// Smallest output height that leaves room for a readable bar.
    pub fn min_height(&self) -> u32 {
        48 * self.scale
    }

    /// Width of the legend panel in pixels.
    pub fn width(&self) -> u32 {
        let label_chars = self.ticks.iter().map(|(_, s)| s.len()).max().unwrap_or(0) as u32;
        (Self::GAP + Self::BAR + Self::TICK + Self::LABEL_GAP + Self::RIGHT_MARGIN) * self.scale
            + label_chars * text::ADVANCE * self.scale
    }

    /// The ticks: value in metres and its label (e.g. `"1.5m"`).
    pub fn ticks(&self) -> &[(f32, String)] {
        &self.ticks
    }

    /// Row of the bar showing depth `z`.
    pub(crate) fn row_of(&self, z: f32) -> u32 {
        let (top, bottom) = self.bar_rows();
        let t = ((self.far - z) / (self.far - self.near)).clamp(0.0, 1.0);
        top + (t * (bottom - top) as f32).round() as u32
    }

    /// Draws the legend into `img` starting at column `x0` (the image must be `x0 + width()`
    /// wide and at least `min_height()` tall).
    pub(crate) fn draw(&self, img: &mut RgbImage, x0: u32) {
        let s = self.scale;
        for y in 0..img.height() {
            for x in x0..img.width() {
                img.put_pixel(x, y, BACKGROUND);
            }
        }
        let bar_x = x0 + Self::GAP * s;
        let (top, bottom) = self.bar_rows();
        for y in top..=bottom {
            let t = (bottom - y) as f32 / (bottom - top).max(1) as f32;
            let z = self.near + t * (self.far - self.near);
            let color = Rgb(depth_color(z, self.near, self.far));
            for x in bar_x..bar_x + Self::BAR * s {
                img.put_pixel(x, y, color);
            }
        }
        let tick_x = bar_x + Self::BAR * s;
        let label_x = tick_x + (Self::TICK + Self::LABEL_GAP) * s;
        for (value, label) in &self.ticks {
            let y = self.row_of(*value);
            for dy in 0..s {
                for x in tick_x..tick_x + Self::TICK * s {
                    if x < img.width() && y + dy < img.height() {
                        img.put_pixel(x, y + dy, INK);
                    }
                }
            }
            let text_top = (y + s / 2).saturating_sub(text::HEIGHT * s / 2);
            text::draw_text(img, label, label_x, text_top, s, INK);
        }
    }
}

/// Round tick values in `[near, far]`: multiples of 1, 2 or 5 × 10^k chosen so that about
/// `wanted` fall in the range, labelled with just enough decimals to tell them apart.
fn nice_ticks(near: f32, far: f32, wanted: usize) -> Vec<(f32, String)> {
    let span = f64::from(far - near);
    let raw = span / wanted.max(1) as f64;
    let magnitude = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * magnitude)
        // Tolerance: an f32 span like 0.08000004 must still take the 0.02 step.
        .find(|&s| s >= raw * (1.0 - 1e-5))
        .unwrap_or(10.0 * magnitude);
    let decimals = (-step.log10().floor()).clamp(0.0, 4.0) as usize;
    let first = (f64::from(near) / step).ceil() as i64;
    let last = (f64::from(far) / step).floor() as i64;
    let ticks: Vec<_> = (first..=last)
        .map(|k| {
            let v = k as f64 * step;
            (v as f32, format!("{v:.decimals$}m"))
        })
        .collect();
    if ticks.len() >= 2 {
        return ticks;
    }
    // No two round values fall inside (a narrow range between steps): label the ends instead.
    let decimals = (1.0 - span.log10().floor()).clamp(0.0, 4.0) as usize;
    [near, far]
        .into_iter()
        .map(|v| (v, format!("{v:.decimals$}m")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_ticks_pick_round_steps_and_decimals() {
        let labels =
            |n, f, k| -> Vec<String> { nice_ticks(n, f, k).into_iter().map(|(_, s)| s).collect() };
        assert_eq!(labels(0.5, 4.0, 4), ["1m", "2m", "3m", "4m"]);
        assert_eq!(
            labels(0.0, 1.0, 5),
            ["0.0m", "0.2m", "0.4m", "0.6m", "0.8m", "1.0m"]
        );
        assert_eq!(labels(1.01, 1.09, 4), ["1.02m", "1.04m", "1.06m", "1.08m"]);
        // 2.01 m wide, two wanted: the 5 m step has no multiple inside, so the ends are used.
        assert_eq!(labels(5.5, 7.51, 2), ["5.5m", "7.5m"]);
    }

    #[test]
    fn font_and_layout_double_from_240_rows() {
        let small = Legend::new(120, 0.5, 4.0);
        let large = Legend::new(240, 0.5, 4.0);
        assert_eq!(small.min_height(), 48);
        assert_eq!(large.min_height(), 96);
        // Same labels' width in font pixels, twice the screen pixels.
        let chars = |l: &Legend| l.ticks().iter().map(|(_, s)| s.len()).max().unwrap() as u32;
        assert_eq!(
            small.width() - chars(&small) * text::ADVANCE,
            (large.width() - chars(&large) * text::ADVANCE * 2) / 2
        );
        // The bar keeps half a glyph and a pixel above and below: end labels are not clipped.
        assert_eq!(small.bar_rows(), (5, 114));
        assert_eq!(large.bar_rows(), (9, 230));
        assert_eq!(small.row_of(4.0), 5);
        assert_eq!(small.row_of(0.5), 114);
        assert_eq!(small.row_of(99.0), 5, "beyond far clamps to the top");
    }
}
