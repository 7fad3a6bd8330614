//! The pictures of `dear eval`: a panel per chosen frame like the paper's figures, RGB/depth
//! blends before and after, and a scan-line plot showing what happens to a row of depth.

use std::path::Path;

use anyhow::Context;
use dear_client::save::{blend_rgb_depth, colorize_depth, depth_colors};
use dear_pipeline::RgbdFrame;
use image::{imageops, Rgb, RgbImage};
use ndarray::{Array2, ArrayView2};

/// Largest error the error maps colour (deeper red above), metres.
pub const ERROR_MAP_MAX_M: f32 = 0.2;
/// Gap between tiles.
const GAP: u32 = 4;
const BACKGROUND: Rgb<u8> = Rgb([24, 24, 24]);

/// Colours of the scan-line plot's curves.
pub const SCANLINE_TOF: Rgb<u8> = Rgb([150, 150, 150]);
pub const SCANLINE_RESULT: Rgb<u8> = Rgb([230, 60, 40]);
pub const SCANLINE_GT: Rgb<u8> = Rgb([60, 200, 90]);

/// Tiles side by side, top-aligned, on a dark background.
fn hstack(tiles: &[RgbImage]) -> RgbImage {
    let width = tiles.iter().map(|t| t.width()).sum::<u32>() + GAP * (tiles.len() as u32 - 1);
    let height = tiles.iter().map(|t| t.height()).max().unwrap_or(1);
    let mut out = RgbImage::from_pixel(width, height, BACKGROUND);
    let mut x = 0;
    for t in tiles {
        imageops::replace(&mut out, t, i64::from(x), 0);
        x += t.width() + GAP;
    }
    out
}

fn rgb_image(frame: &RgbdFrame) -> RgbImage {
    let (h, w) = frame.dim();
    RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let (r, c) = (y as usize, x as usize);
        Rgb([
            frame.rgb[(r, c, 0)],
            frame.rgb[(r, c, 1)],
            frame.rgb[(r, c, 2)],
        ])
    })
}

/// The amplitude as grey, scaled to its 99th percentile (a few specular pixels would darken
/// the rest under a max scaling).
fn amplitude_image(amplitude: ArrayView2<f32>) -> RgbImage {
    let mut values: Vec<f32> = amplitude.iter().copied().filter(|a| *a > 0.0).collect();
    values.sort_by(f32::total_cmp);
    let top = values
        .get(values.len() * 99 / 100)
        .copied()
        .unwrap_or(1.0)
        .max(1e-6);
    let (h, w) = amplitude.dim();
    RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let g = (amplitude[(y as usize, x as usize)] / top * 255.0).clamp(0.0, 255.0) as u8;
        Rgb([g, g, g])
    })
}

/// `|result − gt|` where both are valid, else 0 (drawn black).
pub fn error_map(result: ArrayView2<f32>, gt: ArrayView2<f32>) -> Array2<f32> {
    ndarray::Zip::from(result).and(gt).map_collect(|&r, &g| {
        if dear_pipeline::is_valid_depth(r) && dear_pipeline::is_valid_depth(g) {
            // Exactly zero error would read as invalid (black); keep it visible.
            (r - g).abs().max(1e-4)
        } else {
            0.0
        }
    })
}

/// RGB | amplitude | ToF depth | result | ground truth | error, depths on one colour scale
/// (the ground truth's range), the error on `0 … ERROR_MAP_MAX_M`.
pub fn panel(frame: &RgbdFrame, result: ArrayView2<f32>) -> RgbImage {
    let gt = frame
        .gt_depth
        .as_ref()
        .expect("evaluated frames have ground truth");
    let range = dear_client::save::auto_depth_range(gt.view());
    hstack(&[
        rgb_image(frame),
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
        let valid: Vec<f32> = row.iter().copied().filter(|z| *z > 0.0).collect();
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

/// Depth along `row`: ToF input (grey), result (red), ground truth (green), on white with a
/// light grid every 0.5 m. Two plot pixels per image column.
pub fn scanline_plot(frame: &RgbdFrame, result: ArrayView2<f32>, row: usize) -> RgbImage {
    let gt = frame
        .gt_depth
        .as_ref()
        .expect("evaluated frames have ground truth");
    let curves = [
        (frame.depth.row(row), SCANLINE_TOF),
        (gt.row(row), SCANLINE_GT),
        (result.row(row), SCANLINE_RESULT),
    ];
    let valid = curves
        .iter()
        .flat_map(|(c, _)| c.iter().copied())
        .filter(|z| dear_pipeline::is_valid_depth(*z));
    let (lo, hi) = valid.fold((f32::INFINITY, 0.0f32), |(lo, hi), z| {
        (lo.min(z), hi.max(z))
    });
    let (lo, hi) = if lo < hi {
        (lo - 0.1, hi + 0.1)
    } else {
        (0.0, 4.0)
    };
    let width = 2 * result.ncols() as u32;
    let height = 220u32;
    let mut img = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    let y_of = |z: f32| ((hi - z) / (hi - lo) * (height - 1) as f32).round() as i64;
    let mut grid = (lo / 0.5).ceil() * 0.5;
    while grid < hi {
        let y = y_of(grid);
        for x in 0..width {
            put(&mut img, i64::from(x), y, Rgb([225, 225, 225]));
        }
        grid += 0.5;
    }
    for (curve, colour) in curves {
        let mut last: Option<(i64, i64)> = None;
        for (c, &z) in curve.iter().enumerate() {
            if !dear_pipeline::is_valid_depth(z) {
                last = None;
                continue;
            }
            let p = (2 * c as i64, y_of(z));
            if let Some(q) = last {
                line(&mut img, q, p, colour);
            }
            put(&mut img, p.0, p.1, colour);
            last = Some(p);
        }
    }
    img
}

fn put(img: &mut RgbImage, x: i64, y: i64, colour: Rgb<u8>) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, colour);
    }
}

/// A straight segment (DDA; plots need nothing fancier).
fn line(img: &mut RgbImage, a: (i64, i64), b: (i64, i64), colour: Rgb<u8>) {
    let steps = (b.0 - a.0).abs().max((b.1 - a.1).abs()).max(1);
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let x = a.0 as f64 + t * (b.0 - a.0) as f64;
        let y = a.1 as f64 + t * (b.1 - a.1) as f64;
        put(img, x.round() as i64, y.round() as i64, colour);
    }
}

/// Writes `img` as PNG, naming the file in any error.
pub fn save(img: &RgbImage, path: &Path) -> anyhow::Result<()> {
    img.save(path)
        .with_context(|| format!("cannot write {}", path.display()))
}
