//! Turning a received depth frame into files a person can look at or a tool can read back.
//!
//! Every function takes plain `ndarray` views, so it works on a [`crate::Frame`]
//! (`frame.depth_view()`, `frame.rgb_view()`) as well as on `dear_pipeline` arrays.
//!
//! - [`save_depth_png16`]: the capture format's 16-bit millimetre PNG (lossless to 0.5 mm).
//! - [`colorize_depth`] / [`save_depth_colorized`]: a turbo-coloured depth image with a
//!   labelled colour bar, for eyes.
//! - [`blend_rgb_depth`] / [`save_rgb_depth_blend`]: depth over RGB, to judge alignment.

use std::path::{Path, PathBuf};

use dear_pipeline::capture::{png, CaptureError};
use image::{Rgb, RgbImage};
use ndarray::{ArrayView2, ArrayView3};

/// Metres per unit of the 16-bit depth PNGs (millimetres), as in the capture format.
pub const DEPTH_PNG_SCALE: f32 = 0.001;

/// Colour of invalid depth (`0`, negative or non-finite) in every rendering.
pub const INVALID_COLOR: Rgb<u8> = Rgb(dear_picture::INVALID);

/// Colour of the depth-discontinuity lines of [`blend_rgb_depth`]: magenta occurs neither in
/// the turbo map nor often in natural scenes, so the lines stay visible over both.
pub const EDGE_COLOR: Rgb<u8> = Rgb([255, 0, 255]);

/// Colour of the legend's ticks and labels.
const LEGEND_INK: Rgb<u8> = Rgb([255, 255, 255]);
/// Background of the legend panel: not black, so it is not mistaken for invalid depth.
const LEGEND_BACKGROUND: Rgb<u8> = Rgb([40, 40, 40]);

/// Relative depth jump between neighbouring pixels that [`blend_rgb_depth`] draws as an edge
/// (4 %: well above ToF noise at working range, well below a typical object/background step).
const EDGE_RELATIVE_JUMP: f32 = 0.04;

/// Errors of the save helpers; each names the file or the mismatching inputs.
#[derive(Debug, thiserror::Error)]
pub enum SaveError {
    #[error(transparent)]
    Capture(#[from] CaptureError),
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
    #[error("RGB image is {rgb:?} (H, W, C) but depth is {depth:?} (H, W); expected (H, W, 3)")]
    Shape {
        rgb: (usize, usize, usize),
        depth: (usize, usize),
    },
}

/// Writes depth (metres, 0 = invalid) as a 16-bit PNG in millimetres, exactly as the capture
/// format's `NNNNNN.depth.png` (rounded to the nearest millimetre, saturating at 65.535 m;
/// invalid, negative or non-finite depth → 0).
pub fn save_depth_png16(path: impl AsRef<Path>, depth: ArrayView2<f32>) -> Result<(), SaveError> {
    Ok(png::write_depth(path.as_ref(), depth, DEPTH_PNG_SCALE)?)
}

/// The capture format's rule (0, negative or non-finite = no measurement).
fn is_valid(z: f32) -> bool {
    dear_pipeline::is_valid_depth(z)
}

/// A robust display range of the valid depth: the 1st to the 99th percentile, so a few flying
/// pixels do not squeeze the whole scene into one colour. `None` when no pixel is valid.
pub fn auto_depth_range(depth: ArrayView2<f32>) -> Option<(f32, f32)> {
    let mut valid: Vec<f32> = depth.iter().copied().filter(|&z| is_valid(z)).collect();
    // Nearest rank, as every reported percentile (`dear_stats`).
    dear_stats::sort(&mut valid);
    let at = |q| dear_stats::percentile_nearest_rank(&valid, q);
    Some((at(0.01)?, at(0.99)?))
}

/// The range actually used for colouring: a usable `range` as given (reversed bounds are
/// swapped), otherwise the automatic one; an empty range is widened to 1 mm so the map is
/// defined. A bad range never panics: it falls back to the automatic range.
fn effective_range(depth: ArrayView2<f32>, range: Option<(f32, f32)>) -> (f32, f32) {
    let given = range
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (a.min(b), a.max(b)));
    let (near, far) = given
        .or_else(|| auto_depth_range(depth))
        .unwrap_or((0.0, 1.0));
    if far - near < 1e-3 {
        (near, near + 1e-3)
    } else {
        (near, far)
    }
}

/// The colour of depth `z` in `[near, far]` (clamped) on the shared depth map (turbo: near is
/// blue, far is red; `dear_picture`).
fn turbo(z: f32, near: f32, far: f32) -> Rgb<u8> {
    Rgb(dear_picture::depth_color(z, near, far))
}

/// Depth coloured with turbo, same size as `depth`, invalid pixels black. No legend; see
/// [`colorize_depth`] for the annotated image.
pub fn depth_colors(depth: ArrayView2<f32>, range: Option<(f32, f32)>) -> RgbImage {
    let (near, far) = effective_range(depth, range);
    let (h, w) = depth.dim();
    RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let z = depth[(y as usize, x as usize)];
        if is_valid(z) {
            turbo(z, near, far)
        } else {
            INVALID_COLOR
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
    let (near, far) = effective_range(depth, range);
    let colors = depth_colors(depth, Some((near, far)));
    let legend = Legend::new(colors.height(), near, far);
    let width = colors.width() + legend.width();
    let height = colors.height().max(legend.min_height());
    let mut out = RgbImage::from_pixel(width, height, INVALID_COLOR);
    image::imageops::replace(&mut out, &colors, 0, 0);
    legend.draw(&mut out, colors.width());
    out
}

/// [`colorize_depth`] written as an 8-bit RGB PNG.
pub fn save_depth_colorized(
    path: impl AsRef<Path>,
    depth: ArrayView2<f32>,
    range: Option<(f32, f32)>,
) -> Result<(), SaveError> {
    save_image(path.as_ref(), &colorize_depth(depth, range))
}

/// Depth over RGB, to judge alignment (the paper's "DEAR + RGB" column, made sharper).
///
/// Each valid pixel is the RGB blended with its turbo depth colour at opacity `alpha`
/// (clamped to `[0, 1]`; invalid depth leaves the RGB untouched), and depth discontinuities
/// (a jump of more than 4 % between 4-neighbours) are drawn opaque in [`EDGE_COLOR`] on the
/// *near* side, i.e. along the silhouette of the foreground as the depth sees it.
///
/// Why both and why edges matter most: misalignment is a *shift between two boundaries* — the
/// object's outline in the RGB and its outline in the depth. An alpha blend alone mixes the two
/// images, so at the boundary the colours smear into each other and a 5 px offset is hard to
/// read; a one-pixel depth-edge line over undimmed RGB shows that offset directly as a gap
/// between the line and the RGB outline. The light tint (`alpha` ≈ 0.3–0.5) is kept for
/// context: it shows which side of an edge is near and where depth is missing. `alpha = 0`
/// gives the edges alone.
pub fn blend_rgb_depth(
    rgb: ArrayView3<u8>,
    depth: ArrayView2<f32>,
    alpha: f32,
) -> Result<RgbImage, SaveError> {
    let (h, w) = depth.dim();
    if rgb.dim() != (h, w, 3) {
        return Err(SaveError::Shape {
            rgb: rgb.dim(),
            depth: depth.dim(),
        });
    }
    let alpha = if alpha.is_finite() {
        alpha.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let colors = depth_colors(depth, None);
    let mut out = RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let (r, c) = (y as usize, x as usize);
        let base = [rgb[(r, c, 0)], rgb[(r, c, 1)], rgb[(r, c, 2)]];
        if !is_valid(depth[(r, c)]) {
            return Rgb(base);
        }
        let tint = colors.get_pixel(x, y).0;
        Rgb(std::array::from_fn(|i| {
            (f32::from(base[i]) * (1.0 - alpha) + f32::from(tint[i]) * alpha).round() as u8
        }))
    });
    for (r, c) in depth_edges(depth) {
        out.put_pixel(c as u32, r as u32, EDGE_COLOR);
    }
    Ok(out)
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

/// The pixels `(row, col)` on the near side of a depth discontinuity between 4-neighbours.
/// Jumps to or from invalid depth are not edges: holes are not object boundaries.
fn depth_edges(depth: ArrayView2<f32>) -> Vec<(usize, usize)> {
    let (h, w) = depth.dim();
    let mut edges = Vec::new();
    let mut check = |a: (usize, usize), b: (usize, usize)| {
        let (za, zb) = (depth[a], depth[b]);
        if is_valid(za) && is_valid(zb) && (za - zb).abs() > EDGE_RELATIVE_JUMP * za.min(zb) {
            edges.push(if za < zb { a } else { b });
        }
    };
    for r in 0..h {
        for c in 0..w {
            if c + 1 < w {
                check((r, c), (r, c + 1));
            }
            if r + 1 < h {
                check((r, c), (r + 1, c));
            }
        }
    }
    edges
}

fn save_image(path: &Path, image: &RgbImage) -> Result<(), SaveError> {
    image.save(path).map_err(|e| SaveError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    })
}

/// The colour bar drawn right of a colourised depth image.
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
    const GAP: u32 = 6;
    const BAR: u32 = 12;
    const TICK: u32 = 4;
    const LABEL_GAP: u32 = 3;
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
        (font::HEIGHT * self.scale).div_ceil(2) + self.scale
    }

    /// Bar top and bottom rows (inclusive) in the output image.
    fn bar_rows(&self) -> (u32, u32) {
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
            + label_chars * font::ADVANCE * self.scale
    }

    /// The ticks: value in metres and its label (e.g. `"1.5m"`).
    pub fn ticks(&self) -> &[(f32, String)] {
        &self.ticks
    }

    /// Row of the bar showing depth `z`.
    fn row_of(&self, z: f32) -> u32 {
        let (top, bottom) = self.bar_rows();
        let t = ((self.far - z) / (self.far - self.near)).clamp(0.0, 1.0);
        top + (t * (bottom - top) as f32).round() as u32
    }

    /// Draws the legend into `img` starting at column `x0` (the image must be `x0 + width()`
    /// wide and at least `min_height()` tall).
    fn draw(&self, img: &mut RgbImage, x0: u32) {
        let s = self.scale;
        for y in 0..img.height() {
            for x in x0..img.width() {
                img.put_pixel(x, y, LEGEND_BACKGROUND);
            }
        }
        let bar_x = x0 + Self::GAP * s;
        let (top, bottom) = self.bar_rows();
        for y in top..=bottom {
            let t = (bottom - y) as f32 / (bottom - top).max(1) as f32;
            let color = turbo(self.near + t * (self.far - self.near), self.near, self.far);
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
                    put_clipped(img, x, y + dy, LEGEND_INK);
                }
            }
            let text_top = (y + s / 2).saturating_sub(font::HEIGHT * s / 2);
            font::draw_text(img, label, label_x, text_top, s, LEGEND_INK);
        }
    }
}

fn put_clipped(img: &mut RgbImage, x: u32, y: u32, color: Rgb<u8>) {
    if x < img.width() && y < img.height() {
        img.put_pixel(x, y, color);
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

/// A 5×7 bitmap font for the legend: digits, `.`, `-` and `m` are all a label needs, and a
/// dozen glyphs are smaller and easier to trust than a font-rendering dependency.
mod font {
    use image::{Rgb, RgbImage};

    pub const WIDTH: u32 = 5;
    pub const HEIGHT: u32 = 7;
    /// Glyph width plus one column of spacing.
    pub const ADVANCE: u32 = WIDTH + 1;

    /// Rows top to bottom; bit 4 is the leftmost column.
    fn glyph(c: char) -> Option<[u8; 7]> {
        Some(match c {
            '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
            '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
            '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
            '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
            '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
            '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
            '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
            '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
            '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
            '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
            '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
            '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
            'm' => [0x00, 0x00, 0x1A, 0x15, 0x15, 0x15, 0x15],
            ' ' => [0; 7],
            _ => return None,
        })
    }

    /// Draws `text` with its top-left corner at `(x, y)`, each font pixel `scale`×`scale`;
    /// unknown characters are drawn as blanks, pixels outside the image are clipped.
    pub fn draw_text(img: &mut RgbImage, text: &str, x: u32, y: u32, scale: u32, ink: Rgb<u8>) {
        for (i, c) in text.chars().enumerate() {
            let Some(rows) = glyph(c) else { continue };
            let gx = x + i as u32 * ADVANCE * scale;
            for (row, bits) in rows.iter().enumerate() {
                for col in 0..WIDTH {
                    if bits & (0x10 >> col) == 0 {
                        continue;
                    }
                    for dy in 0..scale {
                        for dx in 0..scale {
                            let (px, py) = (gx + col * scale + dx, y + row as u32 * scale + dy);
                            if px < img.width() && py < img.height() {
                                img.put_pixel(px, py, ink);
                            }
                        }
                    }
                }
            }
        }
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn every_label_character_has_a_distinct_glyph() {
            let chars = "0123456789.-m";
            let glyphs: Vec<_> = chars.chars().map(|c| glyph(c).unwrap()).collect();
            for (i, a) in glyphs.iter().enumerate() {
                assert!(a.iter().any(|&r| r != 0), "{:?} is empty", &chars[i..=i]);
                assert!(a.iter().all(|&r| r < 0x20), "glyph wider than 5 columns");
                for b in &glyphs[i + 1..] {
                    assert_ne!(a, b);
                }
            }
        }

        #[test]
        fn draws_scaled_pixels() {
            let mut img = RgbImage::new(20, 20);
            draw_text(&mut img, "-", 1, 1, 2, Rgb([9, 9, 9]));
            // Row 3 of '-' is full: pixels (1..11, 7..9) at scale 2.
            for x in 1..11 {
                assert_eq!(img.get_pixel(x, 7).0, [9, 9, 9]);
                assert_eq!(img.get_pixel(x, 8).0, [9, 9, 9]);
            }
            assert_eq!(img.get_pixel(1, 6).0, [0, 0, 0]);
            assert_eq!(img.get_pixel(11, 7).0, [0, 0, 0]);
        }
    }
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
    fn colours_follow_turbo_and_invalid_is_black() {
        let mut depth = Array2::from_elem((2, 3), 1.0f32);
        depth[(0, 0)] = 1.0; // near end
        depth[(0, 1)] = 2.0; // middle
        depth[(0, 2)] = 3.0; // far end
        depth[(1, 0)] = 0.0;
        depth[(1, 1)] = f32::NAN;
        depth[(1, 2)] = 9.0; // beyond the range: clamps to far
        let img = depth_colors(depth.view(), Some((1.0, 3.0)));
        let rgb = |t: f64| {
            let c = colorous::TURBO.eval_continuous(0.1 + 0.9 * t);
            [c.r, c.g, c.b]
        };
        assert_eq!(img.get_pixel(0, 0).0, rgb(0.0));
        assert_eq!(img.get_pixel(1, 0).0, rgb(0.5));
        assert_eq!(img.get_pixel(2, 0).0, rgb(1.0));
        assert_eq!(img.get_pixel(0, 1).0, [0, 0, 0]);
        assert_eq!(img.get_pixel(1, 1).0, [0, 0, 0]);
        assert_eq!(img.get_pixel(2, 1).0, rgb(1.0));
        // Valid depth is never rendered dark enough to pass for a hole.
        for t in [0.0, 0.5, 1.0] {
            assert!(
                rgb(t).iter().map(|&v| u32::from(v)).sum::<u32>() > 120,
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
        let far = colorous::TURBO.eval_continuous(1.0);
        let near = colorous::TURBO.eval_continuous(0.1);
        assert_eq!(img.get_pixel(bar_x, top).0, [far.r, far.g, far.b]);
        assert_eq!(img.get_pixel(bar_x, bottom).0, [near.r, near.g, near.b]);
        let distinct: std::collections::HashSet<_> =
            (top..=bottom).map(|y| img.get_pixel(bar_x, y).0).collect();
        assert!(distinct.len() > 20, "bar has {} colours", distinct.len());
        // Round ticks, labelled in metres: 1, 2, 3, 4 m for a 0.5–4 m range at this height.
        let labels: Vec<_> = legend.ticks().iter().map(|(_, s)| s.as_str()).collect();
        assert_eq!(labels, ["1m", "2m", "3m", "4m"]);
        // Each tick has white ink right of the bar on its row, and its label has ink pixels.
        let tick_x = w as u32 + Legend::GAP + Legend::BAR;
        let label_x = tick_x + Legend::TICK + Legend::LABEL_GAP;
        for (value, _) in legend.ticks() {
            let y = legend.row_of(*value);
            assert_eq!(img.get_pixel(tick_x, y).0, LEGEND_INK.0);
            let ink = (label_x..img.width())
                .flat_map(|x| (y.saturating_sub(4)..y + 4).map(move |y| (x, y)))
                .filter(|&(x, y)| img.get_pixel(x, y).0 == LEGEND_INK.0)
                .count();
            assert!(ink > 10, "label at {value} m has {ink} ink pixels");
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
    fn blend_mixes_with_alpha_and_keeps_rgb_where_depth_is_invalid() {
        let rgb = Array3::from_shape_fn((2, 2, 3), |(r, c, k)| (10 * (r * 6 + c * 3 + k)) as u8);
        let mut depth = Array2::from_elem((2, 2), 1.0f32);
        depth[(1, 1)] = 0.0;
        let tint = depth_colors(depth.view(), None).get_pixel(0, 0).0;
        let plain = blend_rgb_depth(rgb.view(), depth.view(), 0.0).unwrap();
        let full = blend_rgb_depth(rgb.view(), depth.view(), 1.0).unwrap();
        let half = blend_rgb_depth(rgb.view(), depth.view(), 0.5).unwrap();
        for (x, y) in [(0u32, 0u32), (1, 0), (0, 1)] {
            let base: [u8; 3] = std::array::from_fn(|k| rgb[(y as usize, x as usize, k)]);
            assert_eq!(plain.get_pixel(x, y).0, base);
            assert_eq!(full.get_pixel(x, y).0, tint);
            let mid: [u8; 3] = std::array::from_fn(|k| {
                ((f32::from(base[k]) + f32::from(tint[k])) / 2.0).round() as u8
            });
            assert_eq!(half.get_pixel(x, y).0, mid);
        }
        for img in [&plain, &full, &half] {
            assert_eq!(
                img.get_pixel(1, 1).0,
                [90, 100, 110],
                "invalid depth keeps the RGB"
            );
        }
    }

    #[test]
    fn blend_draws_edges_on_the_near_side_only() {
        // Left half at 1 m, right half at 2 m, one hole far from the step.
        let mut depth = Array2::from_shape_fn((4, 6), |(_, c)| if c < 3 { 1.0 } else { 2.0 });
        depth[(0, 0)] = 0.0;
        let rgb = Array3::from_elem((4, 6, 3), 100u8);
        let img = blend_rgb_depth(rgb.view(), depth.view(), 0.0).unwrap();
        for y in 0..4 {
            for x in 0..6 {
                let expected = if x == 2 {
                    EDGE_COLOR.0
                } else {
                    [100, 100, 100]
                };
                assert_eq!(img.get_pixel(x, y).0, expected, "({x}, {y})");
            }
        }
    }

    #[test]
    fn blend_rejects_mismatched_shapes() {
        let err = blend_rgb_depth(
            Array3::zeros((2, 3, 3)).view(),
            Array2::zeros((3, 2)).view(),
            0.5,
        )
        .unwrap_err();
        assert!(err.to_string().contains("(2, 3, 3)"), "{err}");
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
    }
}
