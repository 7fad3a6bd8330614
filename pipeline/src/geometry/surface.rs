//! When are two depth samples on the same surface?
//!
//! Warping, splatting and filtering must never average a foreground depth with a background
//! one: the mean of 1 m and 3 m is a point in mid-air (a "flying pixel"). They all decide with
//! the one rule below, so that a depth the warper considers one surface is one surface for the
//! splatter too (and for the Python port, which copies these constants).

/// Relative part of the same-surface tolerance: 3 % of the reference (nearest) depth.
///
/// ToF noise is well below 1 % of depth, and a plane tilted up to ~86° from the viewing
/// direction changes depth by less than 3 % per pixel at VGA resolution, so real surfaces stay
/// within it while object boundaries (typically tens of percent) do not.
pub const DEPTH_EDGE_REL: f32 = 0.03;

/// Absolute floor of the same-surface tolerance, metres: at close range 3 % falls below the
/// sensor's noise floor (~1 cm).
pub const DEPTH_EDGE_ABS_M: f32 = 0.01;

/// The tolerance around the reference depth `z_ref` (metres) within which another sample
/// counts as the same surface: `max(DEPTH_EDGE_REL · z_ref, DEPTH_EDGE_ABS_M)`.
#[inline]
pub fn surface_tolerance(z_ref: f32) -> f32 {
    (DEPTH_EDGE_REL * z_ref).max(DEPTH_EDGE_ABS_M)
}

/// Whether `z` lies on the same surface as the reference depth `z_ref`.
#[inline]
pub fn same_surface(z_ref: f32, z: f32) -> bool {
    (z - z_ref).abs() <= surface_tolerance(z_ref)
}

/// The one validity rule of a depth sample, defined with the capture format that stores it.
pub(crate) use dear_capture::is_valid_depth;

/// [`is_valid_depth`] without short-circuits (`z > 0` and below +∞, so finite: NaN fails the
/// first comparison), for loops written with selects so that they vectorise: a short-circuit
/// is a branch, and where holes are it is mispredicted.
#[inline(always)]
pub(crate) fn is_valid_depth_branchless(z: f32) -> bool {
    (z > 0.0) & (z < f32::INFINITY)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tolerance_is_relative_with_an_absolute_floor() {
        assert!((surface_tolerance(2.0) - 0.06).abs() < 1e-7);
        assert!((surface_tolerance(0.1) - 0.01).abs() < 1e-7);
        assert!(same_surface(2.0, 2.059));
        assert!(!same_surface(2.0, 2.061));
        assert!(!same_surface(1.0, 3.0));
    }
}
