//! In-memory images of one RGB-D frame: what the capture reader yields and every stage of the
//! pipeline shares.
//!
//! Layouts (row-major, `(row, column)` indexing as ndarray does):
//! - depth maps: `Array2<f32>` `(H, W)`, metres, `0.0` = invalid;
//! - amplitude: `Array2<f32>` `(H, W)`, raw sensor units (the 16-bit PNG value as f32);
//! - RGB: `Array3<u8>` `(H, W, 3)`, 8-bit sRGB;
//! - masks: `Array2<bool>` `(H, W)`, `true` = valid;
//! - flow: [`Flow`], two `(H, W)` planes in pixels.

use ndarray::{Array2, Array3};

use crate::calibration::Calibration;

/// A depth sample is valid when it is positive and finite: `0` marks "no measurement" on disk
/// and in memory, and a writer stores any other invalid value as `0`.
#[inline]
pub fn is_valid_depth(z: f32) -> bool {
    z > 0.0 && z.is_finite()
}

/// A dense 2-D flow on a pixel grid: pixel `p` of the grid maps to `p + (u(p), v(p))`.
#[derive(Debug, Clone, PartialEq)]
pub struct Flow {
    /// Horizontal component (columns), px.
    pub u: Array2<f32>,
    /// Vertical component (rows), px.
    pub v: Array2<f32>,
}

impl Flow {
    /// A zero flow of the given `(height, width)`.
    pub fn zeros(height: usize, width: usize) -> Self {
        Flow {
            u: Array2::zeros((height, width)),
            v: Array2::zeros((height, width)),
        }
    }

    /// `(height, width)`.
    pub fn dim(&self) -> (usize, usize) {
        self.u.dim()
    }
}

/// One frame of a ToF RGB-D module as recorded or simulated, plus optional ground truth.
#[derive(Debug, Clone)]
pub struct RgbdFrame {
    /// Frame number within its capture.
    pub index: u64,
    /// Capture time, nanoseconds since the start of the capture (or the epoch for live sources).
    pub timestamp_ns: u64,
    /// RGB image `(H, W, 3)`.
    pub rgb: Array3<u8>,
    /// Raw ToF amplitude `(H, W)`.
    pub amplitude: Array2<f32>,
    /// ToF depth `(H, W)` in metres, `0` = invalid, on the (weakly calibrated) RGB grid.
    pub depth: Array2<f32>,
    /// Optional ground-truth depth in the RGB view, metres.
    pub gt_depth: Option<Array2<f32>>,
    /// Optional confidence / validity mask.
    pub mask: Option<Array2<bool>>,
    /// Optional ground-truth flow RGB → ToF.
    pub flow: Option<Flow>,
    /// The true misalignment parameters of this frame, when known.
    pub perturbation: Option<Calibration>,
}

impl RgbdFrame {
    /// A frame of sensor planes only, as a camera or a replay of its planes yields it (no
    /// ground truth, no known perturbation).
    pub fn sensor(
        index: u64,
        timestamp_ns: u64,
        rgb: Array3<u8>,
        amplitude: Array2<f32>,
        depth: Array2<f32>,
    ) -> Self {
        RgbdFrame {
            index,
            timestamp_ns,
            rgb,
            amplitude,
            depth,
            gt_depth: None,
            mask: None,
            flow: None,
            perturbation: None,
        }
    }

    /// A copy of the sensor planes (ground truth and perturbation left out).
    pub fn sensor_copy(&self) -> Self {
        RgbdFrame::sensor(
            self.index,
            self.timestamp_ns,
            self.rgb.clone(),
            self.amplitude.clone(),
            self.depth.clone(),
        )
    }

    /// `(height, width)`.
    pub fn dim(&self) -> (usize, usize) {
        self.depth.dim()
    }
}

#[cfg(test)]
mod tests {
    use super::is_valid_depth;

    #[test]
    fn valid_depth_is_positive_and_finite() {
        assert!(is_valid_depth(0.5));
        assert!(!is_valid_depth(0.0));
        assert!(!is_valid_depth(-1.0));
        assert!(!is_valid_depth(f32::NAN));
        assert!(!is_valid_depth(f32::INFINITY));
    }
}
