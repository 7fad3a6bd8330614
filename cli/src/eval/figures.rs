//! The pictures of `dear eval`: a panel per chosen frame like the paper's figures, RGB/depth
//! blends before and after, and a scan-line plot showing what happens to a row of depth.

use std::path::Path;

use anyhow::Context;
use dear_capture::{is_valid_depth, RgbdFrame};
use dear_picture::blend::blend_rgb_depth;
use dear_picture::depth::{colorize_depth, depth_colors, display_range};
use dear_picture::panel::hstack;
use dear_picture::plot::{depth_profile, Curve};
use dear_picture::tile::{amplitude_image, rgb_image};
use image::{Rgb, RgbImage};
use ndarray::{Array2, ArrayView2};

/// Largest error the error maps colour (deeper red above), metres.
pub const ERROR_MAP_MAX_M: f32 = 0.2;

/// Colours of the scan-line plot's curves.
pub const SCANLINE_TOF: Rgb<u8> = Rgb([150, 150, 150]);
pub const SCANLINE_RESULT: Rgb<u8> = Rgb([230, 60, 40]);
pub const SCANLINE_GT: Rgb<u8> = Rgb([60, 200, 90]);
/// Plot pixels per image column of the scan-line plot, and its height.
const SCANLINE_PX_PER_COLUMN: u32 = 2;
const SCANLINE_HEIGHT: u32 = 220;

/// `|result − gt|` where both are valid, else 0 (drawn black).
pub fn error_map(result: ArrayView2<f32>, gt: ArrayView2<f32>) -> Array2<f32> {
    ndarray::Zip::from(result).and(gt).map_collect(|&r, &g| {
        if is_valid_depth(r) && is_valid_depth(g) {
            // Exactly zero error would read as invalid (black); keep it visible.
            (r - g).abs().max(1e-4)
        } else {
            0.0
        }
    })
}

/// RGB | amplitude | ToF depth | result | ground truth | error, depths on one colour scale
/// (the ground truth's display range), the error on `0 … ERROR_MAP_MAX_M`.
pub fn panel(frame: &RgbdFrame, gt: ArrayView2<f32>, result: ArrayView2<f32>) -> RgbImage {
    let range = Some(display_range(gt.view(), None));
    hstack(&[
        rgb_image(frame.rgb.view()),
        amplitude_image(frame.amplitude.view()),
        depth_colors(frame.depth.view(), range),
        depth_colors(result, range),
        colorize_depth(gt.view(), range),
        colorize_depth(
            error_map(result, gt.view()).view(),
            Some((0.0, ERROR_MAP_MAX_M)),
        ),
    ])
}

/// Depth over RGB before (the ToF depth as delivered) and after (the result).
pub fn blends(frame: &RgbdFrame, result: ArrayView2<f32>) -> anyhow::Result<RgbImage> {
    Ok(hstack(&[
        blend_rgb_depth(frame.rgb.view(), frame.depth.view(), 0.4)?,
        blend_rgb_depth(frame.rgb.view(), result, 0.4)?,
    ]))
}

/// The row with the most depth structure (largest spread of valid ground truth): where MPI and
/// flying pixels show.
pub fn scanline_row(gt: ArrayView2<f32>) -> usize {
    let mut best = (0.0f32, gt.nrows() / 2);
    for (r, row) in gt.outer_iter().enumerate() {
        let valid: Vec<f32> = row.iter().copied().filter(|&z| is_valid_depth(z)).collect();
        if valid.len() < row.len() / 2 {
            continue;
        }
        let lo = valid.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = valid.iter().copied().fold(0.0, f32::max);
        if hi - lo > best.0 {
            best = (hi - lo, r);
        }
    }
    best.1
}

/// Depth along `row`: ToF input (grey), ground truth (green) and result (red, on top), on
/// white with a light grid every 0.5 m. Two plot pixels per image column.
pub fn scanline_plot(
    frame: &RgbdFrame,
    gt: ArrayView2<f32>,
    result: ArrayView2<f32>,
    row: usize,
) -> RgbImage {
    let curves = [
        (frame.depth.row(row), SCANLINE_TOF),
        (gt.row(row), SCANLINE_GT),
        (result.row(row), SCANLINE_RESULT),
    ]
    .map(|(depth, color)| Curve { depth, color });
    depth_profile(&curves, SCANLINE_PX_PER_COLUMN, SCANLINE_HEIGHT)
}

/// Writes `img` as PNG, naming the file in any error.
pub fn save(img: &RgbImage, path: &Path) -> anyhow::Result<()> {
    img.save(path)
        .with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use dear_picture::panel::GAP;
    use ndarray::Array3;

    /// 4×5 frame and its ground truth: 2 m except row 2, a 1 … 3 m ramp; the ToF 5 cm too far.
    fn frame() -> (RgbdFrame, Array2<f32>) {
        let gt = Array2::from_shape_fn(
            (4, 5),
            |(r, c)| {
                if r == 2 {
                    1.0 + 0.5 * c as f32
                } else {
                    2.0
                }
            },
        );
        let frame = RgbdFrame::new(
            7,
            0,
            Array3::from_elem((4, 5, 3), 60u8),
            Array2::from_elem((4, 5), 1.0),
            gt.mapv(|z| z + 0.05),
        );
        (frame, gt)
    }

    #[test]
    fn panel_is_six_tiles_with_legends_on_ground_truth_and_error() {
        let (frame, gt) = frame();
        let result = gt.view();
        let img = panel(&frame, gt.view(), result);
        let range = Some(display_range(gt.view(), None));
        let gt_tile = colorize_depth(gt.view(), range);
        let error_tile = colorize_depth(
            error_map(result, gt.view()).view(),
            Some((0.0, ERROR_MAP_MAX_M)),
        );
        assert_eq!(
            img.dimensions(),
            (
                4 * 5 + gt_tile.width() + error_tile.width() + 5 * GAP,
                gt_tile.height().max(error_tile.height())
            )
        );
        // The result tile (fourth) equals the ground truth's colours: same depth, same scale.
        let result_x = 3 * (5 + GAP);
        assert_eq!(img.get_pixel(result_x + 4, 2).0, gt_tile.get_pixel(4, 2).0);
        assert_eq!(img.get_pixel(0, 0).0, [60, 60, 60], "RGB first");
    }

    #[test]
    fn scanline_follows_the_row_with_most_structure() {
        let (frame, gt) = frame();
        let row = scanline_row(gt.view());
        assert_eq!(row, 2);
        let img = scanline_plot(&frame, gt.view(), gt.view(), row);
        assert_eq!(img.dimensions(), (2 * 5, SCANLINE_HEIGHT));
        // The result is drawn last: its samples are in its colour at columns 0, 2, … 8.
        for c in 0..5u32 {
            let column: Vec<_> = (0..SCANLINE_HEIGHT)
                .map(|y| img.get_pixel(2 * c, y).0)
                .collect();
            assert!(column.contains(&SCANLINE_RESULT.0), "sample {c}");
        }
    }
}
