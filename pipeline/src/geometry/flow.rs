//! Depth → flow through the calibration model: `W(p) = (t_x/D(p) + c_x, t_y/D(p) + c_y)`.
//!
//! This is the paper's `W_convt` (step 5) and the daemon's cheap per-frame flow between runs
//! of the rough-flow network.

use ndarray::{Array2, ArrayView2, ArrayViewMut2, Zip};

use dear_capture::calibration::Calibration;
use dear_capture::frame::Flow;

/// The flow the calibration predicts from a depth map on the RGB grid, and where it is
/// defined. Invalid depth (`≤ 0` or non-finite) → flow `(0, 0)`, `valid = false`.
pub fn flow_from_depth(depth: ArrayView2<f32>, calib: &Calibration) -> (Flow, Array2<bool>) {
    let (h, w) = depth.dim();
    let mut flow = Flow::zeros(h, w);
    let mut valid = Array2::from_elem((h, w), false);
    flow_from_depth_into(
        depth,
        calib,
        flow.u.view_mut(),
        flow.v.view_mut(),
        Some(valid.view_mut()),
    );
    (flow, valid)
}

/// [`flow_from_depth`] writing into caller-provided planes (and optionally a validity mask).
///
/// # Panics
/// If `u`, `v` (or `valid`) do not have the depth's shape.
pub fn flow_from_depth_into(
    depth: ArrayView2<f32>,
    calib: &Calibration,
    mut u: ArrayViewMut2<f32>,
    mut v: ArrayViewMut2<f32>,
    valid: Option<ArrayViewMut2<bool>>,
) {
    let dim = depth.dim();
    assert_eq!(
        u.dim(),
        dim,
        "flow_from_depth_into: u has shape {:?}, depth {:?}",
        u.dim(),
        dim
    );
    assert_eq!(
        v.dim(),
        dim,
        "flow_from_depth_into: v has shape {:?}, depth {:?}",
        v.dim(),
        dim
    );
    let flow_of = |z: f32| calib.flow_at(z);
    match valid {
        Some(mut valid) => {
            assert_eq!(
                valid.dim(),
                dim,
                "flow_from_depth_into: valid has shape {:?}, depth {:?}",
                valid.dim(),
                dim
            );
            Zip::from(&depth)
                .and(&mut u)
                .and(&mut v)
                .and(&mut valid)
                .par_for_each(|&z, u, v, m| {
                    let f = flow_of(z);
                    (*u, *v) = f.unwrap_or((0.0, 0.0));
                    *m = f.is_some();
                });
        }
        None => Zip::from(&depth)
            .and(&mut u)
            .and(&mut v)
            .par_for_each(|&z, u, v| {
                (*u, *v) = flow_of(z).unwrap_or((0.0, 0.0));
            }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn analytic_flow_and_invalid_pixels() {
        let calib = Calibration {
            tx: 4.0,
            ty: -2.0,
            cx: 1.0,
            cy: 0.5,
        };
        let depth = array![[2.0f32, 0.0], [0.5, f32::NAN]];
        let (flow, valid) = flow_from_depth(depth.view(), &calib);
        assert_eq!(flow.u, array![[3.0, 0.0], [9.0, 0.0]]);
        assert_eq!(flow.v, array![[-0.5, 0.0], [-3.5, 0.0]]);
        assert_eq!(valid, array![[true, false], [true, false]]);
    }
}
