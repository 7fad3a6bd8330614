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

/// One frame of a ToF RGB-D module: the sensor planes a camera delivers, what the daemon
/// processes and a recording holds. Ground truth, which only a simulator or a lab knows, is a
/// separate [`GroundTruth`]; the two travel together as a [`Sample`].
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
}

impl RgbdFrame {
    /// A frame of sensor planes.
    pub fn new(
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
        }
    }

    /// `(height, width)`.
    pub fn dim(&self) -> (usize, usize) {
        self.depth.dim()
    }
}

/// What is known about a frame beyond its sensor planes (a simulator's output, a lab capture):
/// each part is optional, as each is an optional file of a capture.
#[derive(Debug, Clone, Default)]
pub struct GroundTruth {
    /// Ground-truth depth in the RGB view, metres (`0` = unknown).
    pub depth: Option<Array2<f32>>,
    /// Pixels where the ground truth is trusted.
    pub mask: Option<Array2<bool>>,
    /// Ground-truth flow RGB → ToF.
    pub flow: Option<Flow>,
    /// The true misalignment parameters of this frame.
    pub perturbation: Option<Calibration>,
}

/// A frame with its ground truth: what evaluation and training read, and the simulator writes.
#[derive(Debug, Clone)]
pub struct Sample {
    /// The sensor planes.
    pub frame: RgbdFrame,
    /// What is known about them.
    pub truth: GroundTruth,
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
