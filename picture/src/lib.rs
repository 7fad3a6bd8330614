//! Every DEAR picture, drawn once: the SDK's depth previews and blends (`dear_client::save`),
//! `dear eval`'s figures and `dear-synth preview`'s panels are built from these functions, so
//! the same depth gets the same colour, amplitude the same grey and a panel the same layout in
//! all of them.
//!
//! - [`colormap`]: depth turbo, the diverging error map, the invalid colour.
//! - [`depth`]: the display range of a depth image, depth and signed errors as colour tiles,
//!   the annotated preview with its colour bar.
//! - [`legend`]: the colour bar with round, labelled ticks.
//! - [`text`]: the bitmap font of the labels.
//! - [`tile`]: RGB and amplitude as tiles, any per-pixel colouring of a 2-D array.
//! - [`panel`]: tiles side by side.
//! - [`blend`]: depth over RGB with depth edges, to judge alignment.
//! - `plot` (feature `plot`): depth profiles along a row, one curve per source.

#![forbid(unsafe_code)]

pub mod blend;
pub mod colormap;
pub mod depth;
pub mod legend;
pub mod panel;
#[cfg(feature = "plot")]
pub mod plot;
pub mod text;
pub mod tile;
