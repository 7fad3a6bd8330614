//! Panels: tiles side by side, as `dear eval`'s figures and `dear-synth preview` show a frame.

use image::{imageops, Rgb, RgbImage};

/// Gap between tiles in pixels.
pub const GAP: u32 = 4;
/// Colour of the gaps and of the space below shorter tiles: dark, so the tiles' colours stand
/// out, but not the black of invalid depth, so a tile's holes are not mistaken for its border.
pub const BACKGROUND: Rgb<u8> = Rgb([24, 24, 24]);

/// `tiles` left to right, top-aligned, [`GAP`] apart on [`BACKGROUND`]; as tall as the tallest
/// tile. No tiles give a 1×1 background pixel (an image cannot be empty).
pub fn hstack(tiles: &[RgbImage]) -> RgbImage {
    let gaps = GAP * (tiles.len().max(1) as u32 - 1);
    let width = (tiles.iter().map(RgbImage::width).sum::<u32>() + gaps).max(1);
    let height = tiles.iter().map(RgbImage::height).max().unwrap_or(1).max(1);
    let mut out = RgbImage::from_pixel(width, height, BACKGROUND);
    let mut x = 0;
    for tile in tiles {
        imageops::replace(&mut out, tile, i64::from(x), 0);
        x += tile.width() + GAP;
    }
    out
}

/// `tile` resized by `scale` (each side rounded, at least 1 pixel; triangle filter, which
/// averages when shrinking); the tile itself when the size does not change.
pub fn scaled(tile: RgbImage, scale: f64) -> RgbImage {
    let side = |n: u32| ((f64::from(n) * scale).round() as u32).max(1);
    let (w, h) = (side(tile.width()), side(tile.height()));
    if (w, h) == tile.dimensions() {
        tile
    } else {
        imageops::resize(&tile, w, h, imageops::FilterType::Triangle)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn solid(w: u32, h: u32, v: u8) -> RgbImage {
        RgbImage::from_pixel(w, h, Rgb([v, v, v]))
    }

    #[test]
    fn tiles_sit_side_by_side_top_aligned_with_gaps() {
        let img = hstack(&[solid(3, 2, 100), solid(2, 5, 200), solid(1, 1, 50)]);
        assert_eq!(img.dimensions(), (3 + GAP + 2 + GAP + 1, 5));
        let px = |x, y| img.get_pixel(x, y).0;
        assert_eq!(px(0, 0), [100; 3]);
        assert_eq!(px(2, 1), [100; 3]);
        assert_eq!(px(2, 2), BACKGROUND.0, "below the shorter first tile");
        assert_eq!(px(3, 0), BACKGROUND.0, "the gap");
        assert_eq!(px(3 + GAP - 1, 4), BACKGROUND.0);
        assert_eq!(px(3 + GAP, 0), [200; 3]);
        assert_eq!(px(3 + GAP + 1, 4), [200; 3]);
        assert_eq!(px(3 + GAP + 2 + GAP, 0), [50; 3]);
        assert_eq!(px(3 + GAP + 2 + GAP, 1), BACKGROUND.0);
    }

    #[test]
    fn one_tile_is_itself_and_none_is_one_pixel() {
        let tile = RgbImage::from_fn(3, 2, |x, y| Rgb([x as u8, y as u8, 9]));
        assert_eq!(hstack(std::slice::from_ref(&tile)), tile);
        assert_eq!(hstack(&[]).dimensions(), (1, 1));
    }

    #[test]
    fn scaling_rounds_each_side_and_keeps_a_flat_colour() {
        let tile = solid(5, 3, 80);
        assert_eq!(scaled(tile.clone(), 1.0), tile);
        let half = scaled(tile.clone(), 0.5);
        assert_eq!(half.dimensions(), (3, 2));
        assert!(half.pixels().all(|p| p.0 == [80; 3]));
        assert_eq!(scaled(tile.clone(), 2.0).dimensions(), (10, 6));
        assert_eq!(scaled(tile, 0.01).dimensions(), (1, 1));
    }
}
