//! A 5×7 bitmap font for the colour bar's labels: digits, `.`, `-` and `m` are all a label
//! needs, and a dozen glyphs are smaller and easier to trust than a font-rendering dependency.

use image::{Rgb, RgbImage};

/// Glyph width in font pixels.
pub const WIDTH: u32 = 5;
/// Glyph height in font pixels.
pub const HEIGHT: u32 = 7;
/// Glyph width plus one column of spacing.
pub const ADVANCE: u32 = WIDTH + 1;

/// Rows top to bottom; bit 4 is the leftmost column. `None` for a character without a glyph.
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
/// characters without a glyph are drawn as blanks, pixels outside the image are clipped.
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

    #[test]
    fn unknown_characters_leave_a_blank_and_text_is_clipped() {
        let mut img = RgbImage::new(8, 4);
        // 'x' has no glyph; the '-' after it would start at column 6 and runs off the image.
        draw_text(&mut img, "x-", 0, 0, 1, Rgb([9, 9, 9]));
        for x in 0..6 {
            assert_eq!(img.get_pixel(x, 3).0, [0, 0, 0], "column {x}");
        }
        assert_eq!(img.get_pixel(6, 3).0, [9, 9, 9]);
        assert_eq!(img.get_pixel(7, 3).0, [9, 9, 9]);
    }
}
