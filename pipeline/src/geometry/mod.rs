//! Geometry of the RGB↔ToF alignment: everything that moves pixels around.
//!
//! Conventions shared by every sub-module (and by the Python training package, which checks
//! itself against the test vectors in `fixtures/geometry/`):
//! - images are row-major `(row, column)`; pixel centres sit at integer coordinates;
//! - a [`Flow`](dear_capture::Flow) is defined on the grid of the image being produced: `u` moves along
//!   columns (x), `v` along rows (y);
//! - backward warping reads `out(p) = src(p + W(p))`; a sample point outside the convex hull of
//!   the source's pixel centres is *invalid*, never clamped and never read as a zero depth.
//!
//! Modules:
//! - [`warp`]: backward warping of depth (discontinuity-aware), amplitude and RGB;
//! - [`flow`]: depth → flow through a [`Calibration`](dear_capture::Calibration);
//! - [`splat`]: forward splatting with a z-buffer, to synthesise a perturbed RGB view;
//! - [`register`]: a live ToF image onto the RGB grid with the module's factory rotation and
//!   intrinsics (the translation is left to the chain's calibration).
//!
//! Fitting the calibration `(t, c)` to a flow or to a frame's edges is
//! [`recalibration`](crate::recalibration)'s.

pub mod flow;
pub mod register;
pub mod splat;
pub mod surface;
pub mod warp;

pub use flow::{flow_from_depth, flow_from_depth_into};
pub use splat::{
    splat_depth_into, splat_depth_with, synthesize_view, SplatScratch, SynthesizedView,
};
pub(crate) use surface::is_valid_depth;
pub use warp::{warp_bilinear, warp_depth, warp_depth_and_bilinear, warp_rgb};
