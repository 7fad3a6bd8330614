//! The weak calibration DEAR estimates: the parameters of the RGB→ToF flow model
//! `W(p) = (t_x / z(p) + c_x, t_y / z(p) + c_y)`.
//!
//! Units: `t_x, t_y` in pixel·metres (the focal length is absorbed into the baseline, as in the
//! paper), `c_x, c_y` in pixels, `z` in metres. A pixel `p` of the RGB image sees the ToF pixel
//! `p + W(p)`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Parameters of the depth-dependent flow between the RGB and the ToF image.
///
/// In `capture.json` each parameter must be finite as an f32: serde reads `1e39` as infinity,
/// which aligns no pixel, so the reader refuses it and the schema bounds it.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// Horizontal baseline times focal length, px·m.
    #[schemars(range(min = -f32::MAX, max = f32::MAX))]
    pub tx: f32,
    /// Vertical baseline times focal length, px·m.
    #[schemars(range(min = -f32::MAX, max = f32::MAX))]
    pub ty: f32,
    /// Horizontal principal-point offset, px.
    #[schemars(range(min = -f32::MAX, max = f32::MAX))]
    pub cx: f32,
    /// Vertical principal-point offset, px.
    #[schemars(range(min = -f32::MAX, max = f32::MAX))]
    pub cy: f32,
}

impl Calibration {
    /// The identity: no flow at any depth.
    pub const IDENTITY: Calibration = Calibration {
        tx: 0.0,
        ty: 0.0,
        cx: 0.0,
        cy: 0.0,
    };

    /// The flow `(u, v)` this calibration predicts for a point at depth `z` metres.
    /// Returns `None` for a non-positive or non-finite depth (no valid flow there).
    #[inline]
    pub fn flow_at(&self, z: f32) -> Option<(f32, f32)> {
        crate::frame::is_valid_depth(z).then(|| self.flow_formula(z))
    }

    /// The formula of [`flow_at`](Self::flow_at) evaluated at any `z` (infinite or NaN at an
    /// invalid depth), for loops that compute every pixel and select the valid ones without
    /// a branch.
    #[inline(always)]
    pub fn flow_formula(&self, z: f32) -> (f32, f32) {
        (self.tx / z + self.cx, self.ty / z + self.cy)
    }
}
