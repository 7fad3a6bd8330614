//! The preview panel (`dear-synth preview`): RGB | amplitude | ToF depth | ground truth | error.
//!
//! Every tile and the panel are `dear_picture`'s, the same as the SDK's previews and `dear
//! eval`'s figures: ToF depth and ground truth share one colour scale (the display range of the
//! ground truth, 1st to 99th percentile of its valid depth), so equal colours mean equal
//! depths; invalid pixels are black. The error map is ToF − ground truth on the same pixel,
//! blue (too near) – white – red (too far), saturating at ±`error_range_m`; on a misaligned
//! frame it shows the misalignment as well as the ToF errors. Amplitude is shown as
//! `√(a / a₉₉)` (grey).

use dear_capture::{is_valid_depth, Sample};
use dear_picture::depth::{depth_colors, display_range, signed_error_colors};
use dear_picture::panel::{hstack, scaled};
use dear_picture::tile::{amplitude_image, rgb_image};
use image::RgbImage;
use ndarray::Zip;

/// Builds the five-tile preview of a frame, each tile scaled by `scale`. Without ground truth
/// the ToF depth is its own reference (its error tile is white where valid).
pub fn panel(sample: &Sample, error_range_m: f32, scale: f64) -> RgbImage {
    let frame = &sample.frame;
    let gt = sample.truth.depth.as_ref().unwrap_or(&frame.depth);
    let range = Some(display_range(gt.view(), None));
    let error = Zip::from(&frame.depth).and(gt).map_collect(|&tof, &gt| {
        if is_valid_depth(tof) && is_valid_depth(gt) {
            tof - gt
        } else {
            f32::NAN
        }
    });
    let tiles = [
        rgb_image(frame.rgb.view()),
        amplitude_image(frame.amplitude.view()),
        depth_colors(frame.depth.view(), range),
        depth_colors(gt.view(), range),
        signed_error_colors(error.view(), error_range_m),
    ];
    hstack(&tiles.map(|tile| scaled(tile, scale)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use dear_capture::{GroundTruth, RgbdFrame};
    use dear_picture::panel::{BACKGROUND, GAP};
    use ndarray::{Array2, Array3};

    /// A 4×6 frame: ToF 1 m left, 3 m right, 10 cm too far in the top row; ground truth 1 m
    /// left, 3 m right.
    fn frame() -> Sample {
        let gt = Array2::from_shape_fn((4, 6), |(_, c)| if c < 3 { 1.0 } else { 3.0 });
        let mut depth = gt.clone();
        depth.row_mut(0).map_inplace(|z| *z += 0.1);
        depth[(3, 5)] = 0.0;
        let frame = RgbdFrame::new(
            0,
            0,
            Array3::from_elem((4, 6, 3), 90u8),
            Array2::from_elem((4, 6), 50.0),
            depth,
        );
        let truth = GroundTruth {
            depth: Some(gt),
            ..GroundTruth::default()
        };
        Sample { frame, truth }
    }

    #[test]
    fn five_tiles_on_the_ground_truths_scale() {
        let frame = frame();
        let img = panel(&frame, 0.1, 1.0);
        assert_eq!(img.dimensions(), (5 * 6 + 4 * GAP, 4));
        let tile = |i: u32, x: u32, y: u32| img.get_pixel(i * (6 + GAP) + x, y).0;
        assert_eq!(tile(0, 0, 0), [90, 90, 90], "RGB");
        assert_eq!(tile(1, 0, 0), [255, 255, 255], "flat amplitude is white");
        assert_eq!(img.get_pixel(6, 0).0, BACKGROUND.0, "gap");
        // ToF and ground truth share the ground truth's 1 … 3 m scale: equal depth, equal colour.
        let range = display_range(frame.truth.depth.as_ref().unwrap().view(), None);
        assert_eq!(range, (1.0, 3.0));
        let gt_colors = depth_colors(frame.truth.depth.as_ref().unwrap().view(), Some(range));
        assert_eq!(tile(2, 0, 1), gt_colors.get_pixel(0, 1).0);
        assert_eq!(tile(3, 0, 1), gt_colors.get_pixel(0, 1).0);
        assert_eq!(tile(2, 5, 3), [0, 0, 0], "invalid ToF is black");
        // Error: the top row is 10 cm too far, saturated red; elsewhere white; none where the
        // ToF has no depth.
        assert_eq!(tile(4, 0, 0), dear_picture::colormap::diverging(1.0));
        assert_eq!(tile(4, 0, 1), [255, 255, 255]);
        assert_eq!(tile(4, 5, 3), [0, 0, 0]);
    }

    #[test]
    fn scale_resizes_every_tile_not_the_gaps() {
        let img = panel(&frame(), 0.1, 2.0);
        assert_eq!(img.dimensions(), (5 * 12 + 4 * GAP, 8));
        assert_eq!(img.get_pixel(12, 0).0, BACKGROUND.0);
    }
}
