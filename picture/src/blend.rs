//! Depth over RGB, to judge alignment (the paper's "DEAR + RGB" column, made sharper).

use dear_capture::is_valid_depth;
use image::{Rgb, RgbImage};
use ndarray::{ArrayView2, ArrayView3};

use crate::depth::depth_colors;
use crate::tile::rgb_image;

/// Colour of the depth-discontinuity lines of [`blend_rgb_depth`]: magenta occurs neither in
/// the turbo map nor often in natural scenes, so the lines stay visible over both.
pub const EDGE_COLOR: Rgb<u8> = Rgb([255, 0, 255]);

/// Relative depth jump between neighbouring pixels that [`blend_rgb_depth`] draws as an edge
/// (4 %: well above ToF noise at working range, well below a typical object/background step).
const EDGE_RELATIVE_JUMP: f32 = 0.04;

/// The RGB and the depth given to [`blend_rgb_depth`] do not cover the same pixels.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("RGB image is {rgb:?} (H, W, C) but depth is {depth:?} (H, W); expected (H, W, 3)")]
pub struct ShapeMismatch {
    pub rgb: (usize, usize, usize),
    pub depth: (usize, usize),
}

/// Depth over RGB, to judge alignment.
///
/// Each valid pixel is the RGB blended with its turbo depth colour (on the depth's own
/// automatic range) at opacity `alpha` (clamped to `[0, 1]`; invalid depth leaves the RGB
/// untouched), and depth discontinuities (a jump of more than 4 % between 4-neighbours) are
/// drawn opaque in [`EDGE_COLOR`] on the *near* side, i.e. along the silhouette of the
/// foreground as the depth sees it.
///
/// Why both and why edges matter most: misalignment is a *shift between two boundaries* — the
/// object's outline in the RGB and its outline in the depth. An alpha blend alone mixes the two
/// images, so at the boundary the colours smear into each other and a 5 px offset is hard to
/// read; a one-pixel depth-edge line over undimmed RGB shows that offset directly as a gap
/// between the line and the RGB outline. The light tint (`alpha` ≈ 0.3–0.5) is kept for
/// context: it shows which side of an edge is near and where depth is missing. `alpha = 0`
/// gives the edges alone.
pub fn blend_rgb_depth(
    rgb: ArrayView3<u8>,
    depth: ArrayView2<f32>,
    alpha: f32,
) -> Result<RgbImage, ShapeMismatch> {
    let (h, w) = depth.dim();
    if rgb.dim() != (h, w, 3) {
        return Err(ShapeMismatch {
            rgb: rgb.dim(),
            depth: depth.dim(),
        });
    }
    let alpha = if alpha.is_finite() {
        alpha.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let tints = depth_colors(depth, None);
    let mut out = rgb_image(rgb);
    for (x, y, pixel) in out.enumerate_pixels_mut() {
        if !is_valid_depth(depth[(y as usize, x as usize)]) {
            continue;
        }
        let tint = tints.get_pixel(x, y).0;
        pixel.0 = std::array::from_fn(|i| {
            (f32::from(pixel.0[i]) * (1.0 - alpha) + f32::from(tint[i]) * alpha).round() as u8
        });
    }
    for (r, c) in depth_edges(depth) {
        out.put_pixel(c as u32, r as u32, EDGE_COLOR);
    }
    Ok(out)
}

/// The pixels `(row, col)` on the near side of a depth discontinuity between 4-neighbours.
/// Jumps to or from invalid depth are not edges: holes are not object boundaries.
fn depth_edges(depth: ArrayView2<f32>) -> Vec<(usize, usize)> {
    let (h, w) = depth.dim();
    let mut edges = Vec::new();
    let mut check = |a: (usize, usize), b: (usize, usize)| {
        let (za, zb) = (depth[a], depth[b]);
        if is_valid_depth(za)
            && is_valid_depth(zb)
            && (za - zb).abs() > EDGE_RELATIVE_JUMP * za.min(zb)
        {
            edges.push(if za < zb { a } else { b });
        }
    };
    for r in 0..h {
        for c in 0..w {
            if c + 1 < w {
                check((r, c), (r, c + 1));
            }
            if r + 1 < h {
                check((r, c), (r + 1, c));
            }
        }
    }
    edges
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, Array3};

    #[test]
    fn blend_mixes_with_alpha_and_keeps_rgb_where_depth_is_invalid() {
        let rgb = Array3::from_shape_fn((2, 2, 3), |(r, c, k)| (10 * (r * 6 + c * 3 + k)) as u8);
        let mut depth = Array2::from_elem((2, 2), 1.0f32);
        depth[(1, 1)] = 0.0;
        let tint = depth_colors(depth.view(), None).get_pixel(0, 0).0;
        let plain = blend_rgb_depth(rgb.view(), depth.view(), 0.0).unwrap();
        let full = blend_rgb_depth(rgb.view(), depth.view(), 1.0).unwrap();
        let half = blend_rgb_depth(rgb.view(), depth.view(), 0.5).unwrap();
        for (x, y) in [(0u32, 0u32), (1, 0), (0, 1)] {
            let base: [u8; 3] = std::array::from_fn(|k| rgb[(y as usize, x as usize, k)]);
            assert_eq!(plain.get_pixel(x, y).0, base);
            assert_eq!(full.get_pixel(x, y).0, tint);
            let mid: [u8; 3] = std::array::from_fn(|k| {
                ((f32::from(base[k]) + f32::from(tint[k])) / 2.0).round() as u8
            });
            assert_eq!(half.get_pixel(x, y).0, mid);
        }
        for img in [&plain, &full, &half] {
            assert_eq!(
                img.get_pixel(1, 1).0,
                [90, 100, 110],
                "invalid depth keeps the RGB"
            );
        }
    }

    #[test]
    fn blend_draws_edges_on_the_near_side_only() {
        // Left half at 1 m, right half at 2 m, one hole far from the step.
        let mut depth = Array2::from_shape_fn((4, 6), |(_, c)| if c < 3 { 1.0 } else { 2.0 });
        depth[(0, 0)] = 0.0;
        let rgb = Array3::from_elem((4, 6, 3), 100u8);
        let img = blend_rgb_depth(rgb.view(), depth.view(), 0.0).unwrap();
        for y in 0..4 {
            for x in 0..6 {
                let expected = if x == 2 {
                    EDGE_COLOR.0
                } else {
                    [100, 100, 100]
                };
                assert_eq!(img.get_pixel(x, y).0, expected, "({x}, {y})");
            }
        }
    }

    #[test]
    fn blend_rejects_mismatched_shapes() {
        let err = blend_rgb_depth(
            Array3::zeros((2, 3, 3)).view(),
            Array2::zeros((3, 2)).view(),
            0.5,
        )
        .unwrap_err();
        assert_eq!(
            err,
            ShapeMismatch {
                rgb: (2, 3, 3),
                depth: (3, 2)
            }
        );
        assert!(err.to_string().contains("(2, 3, 3)"), "{err}");
    }
}
