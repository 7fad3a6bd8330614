//! Depth profiles: depth along a line of pixels (a row of an image), one curve per source, as
//! `dear eval`'s scan-line figure shows what the refinement did to MPI and flying pixels.
//!
//! Plotters maps depth to rows and draws the (anti-aliased) segments; there is no text, so it
//! runs without any of plotters' font back ends.

use dear_capture::is_valid_depth;
use image::{Rgb, RgbImage};
use ndarray::ArrayView1;
use plotters::prelude::*;

/// Background of a plot.
pub const PAPER: Rgb<u8> = Rgb([255, 255, 255]);
/// Colour of the horizontal grid lines, one every [`GRID_STEP_M`].
pub const GRID: Rgb<u8> = Rgb([225, 225, 225]);
/// Depth between grid lines, metres.
pub const GRID_STEP_M: f32 = 0.5;
/// Space above the highest and below the lowest depth plotted, metres.
const MARGIN_M: f32 = 0.1;
/// Depth range of a plot without a single valid sample, metres: the working range of a ToF
/// module, so an empty plot still has its grid.
const RANGE_WITHOUT_DATA: (f32, f32) = (0.0, 4.0);

/// One curve: depth samples in metres (invalid ones leave a gap) and its colour.
#[derive(Debug, Clone)]
pub struct Curve<'a> {
    pub depth: ArrayView1<'a, f32>,
    pub color: Rgb<u8>,
}

/// The depth range a profile plot of `curves` shows: every valid sample with 10 cm above and
/// below, `0 … 4 m` when no sample is valid.
pub fn profile_range(curves: &[Curve]) -> (f32, f32) {
    let valid = curves
        .iter()
        .flat_map(|c| c.depth.iter().copied())
        .filter(|&z| is_valid_depth(z));
    let (lo, hi) = valid.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), z| {
        (lo.min(z), hi.max(z))
    });
    if lo <= hi {
        (lo - MARGIN_M, hi + MARGIN_M)
    } else {
        RANGE_WITHOUT_DATA
    }
}

/// The curves on [`PAPER`] with a [`GRID`] line every [`GRID_STEP_M`], far at the top, on
/// [`profile_range`]; sample `i` at column `px_per_sample · i`, so the plot is
/// `px_per_sample ×` the longest curve wide and `height` tall. Curves are drawn in order, the
/// last on top; each valid sample is a pixel of its curve's colour, consecutive valid samples
/// are joined.
pub fn depth_profile(curves: &[Curve], px_per_sample: u32, height: u32) -> RgbImage {
    let samples = curves.iter().map(|c| c.depth.len()).max().unwrap_or(0);
    let px_per_sample = px_per_sample.max(1);
    let width = (px_per_sample * samples as u32).max(1);
    let mut img = RgbImage::from_pixel(width, height.max(1), PAPER);
    // The backend draws into `img`'s own buffer, which has exactly the size it is given; that
    // is the only way drawing into memory can fail.
    draw(&mut img, curves, px_per_sample)
        .expect("plotters draws into a buffer of the size it was given");
    img
}

fn draw(
    img: &mut RgbImage,
    curves: &[Curve],
    px_per_sample: u32,
) -> DrawResult<(), BitMapBackend<'static>> {
    let size = img.dimensions();
    let (lo, hi) = profile_range(curves);
    let root = BitMapBackend::with_buffer(img, size).into_drawing_area();
    // The chart maps its x range onto columns 0 … width − 1; ending the range half a sample
    // step (for two pixels per sample) short of the sample count puts sample i exactly at
    // column px_per_sample · i.
    let x_end = (size.0 - 1) as f32 / px_per_sample as f32;
    let mut chart = ChartBuilder::on(&root).build_cartesian_2d(0f32..x_end.max(1.0), lo..hi)?;
    let color = |c: Rgb<u8>| RGBColor(c.0[0], c.0[1], c.0[2]);

    let first_grid = (lo / GRID_STEP_M).ceil() as i32;
    let grid_lines = (first_grid..)
        .map(|k| k as f32 * GRID_STEP_M)
        .take_while(|&z| z < hi)
        .map(|z| PathElement::new([(0.0, z), (x_end, z)], color(GRID)));
    chart.draw_series(grid_lines)?;

    for curve in curves {
        let points: Vec<Option<(f32, f32)>> = curve
            .depth
            .iter()
            .enumerate()
            .map(|(i, &z)| is_valid_depth(z).then_some((i as f32, z)))
            .collect();
        let runs = points
            .split(Option::is_none)
            .filter(|run| run.len() >= 2)
            .map(|run| LineSeries::new(run.iter().flatten().copied(), color(curve.color)));
        for run in runs {
            chart.draw_series(run)?;
        }
        // The samples themselves, full colour: an isolated one has no segment, and the
        // anti-aliased ends of segments may be lighter.
        let samples = points
            .iter()
            .flatten()
            .map(|&p| Pixel::new(p, color(curve.color)));
        chart.draw_series(samples)?;
    }
    root.present()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array1;

    const FLAT: Rgb<u8> = Rgb([200, 30, 30]);
    const RAMP: Rgb<u8> = Rgb([30, 30, 200]);

    /// A flat curve at 2 m and a ramp 1.0, 1.1, … 2.0 m with no sample at 1.5 m, 11 samples;
    /// the plot shows 0.9 … 2.1 m on 121 rows, so 1 cm is 1 row and depth `z` is on row
    /// `120 − 100 (z − 0.9)`.
    fn two_curves() -> (Array1<f32>, Array1<f32>) {
        let flat = Array1::from_elem(11, 2.0f32);
        let mut ramp = Array1::from_shape_fn(11, |i| 1.0 + 0.1 * i as f32);
        ramp[5] = f32::NAN;
        (flat, ramp)
    }

    fn plot(flat: &Array1<f32>, ramp: &Array1<f32>) -> RgbImage {
        let curves = [
            Curve {
                depth: flat.view(),
                color: FLAT,
            },
            Curve {
                depth: ramp.view(),
                color: RAMP,
            },
        ];
        assert_eq!(profile_range(&curves), (1.0 - 0.1, 2.0 + 0.1));
        depth_profile(&curves, 2, 121)
    }

    #[test]
    fn samples_land_on_their_column_and_depth_row() {
        let (flat, ramp) = two_curves();
        let img = plot(&flat, &ramp);
        assert_eq!(img.dimensions(), (22, 121));
        // The flat curve is one unbroken row at 2 m from the first sample on; the ramp, drawn
        // later, ends on it at column 20 and covers it there.
        assert_eq!(img.get_pixel(20, 10).0, RAMP.0);
        for x in 0..20 {
            assert_eq!(img.get_pixel(x, 10).0, FLAT.0, "column {x}");
        }
        // Each ramp sample at column 2i, row 120 − 100 (0.1 + 0.1 i) = 110 − 10 i.
        for i in (0..11u32).filter(|&i| i != 5) {
            assert_eq!(img.get_pixel(2 * i, 110 - 10 * i).0, RAMP.0, "sample {i}");
        }
    }

    #[test]
    fn segments_join_valid_neighbours_and_stop_at_a_gap() {
        let (flat, ramp) = two_curves();
        let img = plot(&flat, &ramp);
        let bluish = |p: &Rgb<u8>| u16::from(p.0[2]) > u16::from(p.0[0]) + 40;
        // Between samples 0 and 1 (rows 110 … 100) every row has ramp ink in columns 0 … 2.
        for y in 100..=110 {
            assert!(
                (0..=2).any(|x| bluish(img.get_pixel(x, y))),
                "row {y} has no ramp segment"
            );
        }
        // Sample 5 is missing: nothing of the ramp between sample 4 (column 8) and 6 (12).
        for x in 9..=11 {
            assert!(
                (0..img.height()).all(|y| !bluish(img.get_pixel(x, y))),
                "column {x} has ramp ink across the gap"
            );
        }
    }

    #[test]
    fn grid_every_half_metre_on_white() {
        let (flat, ramp) = two_curves();
        let img = plot(&flat, &ramp);
        // 1.5 m is row 60; the ramp's 1.5 m sample is missing, so the grid line is whole.
        for x in 0..22 {
            assert_eq!(img.get_pixel(x, 60).0, GRID.0, "column {x}");
        }
        // 1.0 m (row 110) is grid right of the ramp's first sample; between lines is paper.
        assert_eq!(img.get_pixel(21, 110).0, GRID.0);
        assert_eq!(img.get_pixel(21, 100).0, PAPER.0);
        assert_eq!(img.get_pixel(21, 85).0, PAPER.0);
    }

    #[test]
    fn ranges_without_data_or_with_one_depth_stay_usable() {
        let none = Array1::from_elem(4, 0.0f32);
        fn curve(depth: &Array1<f32>) -> Curve<'_> {
            Curve {
                depth: depth.view(),
                color: FLAT,
            }
        }
        assert_eq!(profile_range(&[curve(&none)]), (0.0, 4.0));
        let one = Array1::from_elem(4, 3.0f32);
        let (lo, hi) = profile_range(&[curve(&one), curve(&none)]);
        assert!(
            (lo - 2.9).abs() < 1e-6 && (hi - 3.1).abs() < 1e-6,
            "{lo} … {hi}"
        );
        // Grid lines at 0, 0.5, … 3.5 m (10 rows apart) and nothing else on an empty plot.
        let img = depth_profile(&[curve(&none)], 2, 81);
        assert_eq!(img.dimensions(), (8, 81));
        let grid_rows: Vec<u32> = (0..81)
            .filter(|&y| img.get_pixel(0, y).0 == GRID.0)
            .collect();
        assert_eq!(grid_rows, [10, 20, 30, 40, 50, 60, 70, 80]);
        assert!(img.pixels().all(|p| p.0 == GRID.0 || p.0 == PAPER.0));
        assert_eq!(depth_profile(&[], 2, 10).dimensions(), (1, 10));
    }
}
