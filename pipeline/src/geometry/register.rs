//! Registration of a live ToF image onto the RGB grid with the module's factory calibration:
//! the step that turns a real module's two cameras into the *weakly calibrated* pair the DEAR
//! chain expects.
//!
//! The ToF camera (intrinsics `K_t`) and the RGB camera (`K_c`) differ by a rotation `R` and a
//! translation `T` (ToF → RGB). Rotation and intrinsics move every pixel independently of depth
//! (the homography `K_c R K_t⁻¹`), so they are undone here; the translation moves a point at
//! depth `z` by `(f_x T_x / z, f_y T_y / z)` — exactly the flow `t / z + c` of the paper's model
//! — and is left to the chain as its initial calibration `{t = (f_x T_x, f_y T_y), c = 0}`,
//! which the online estimator then tracks as the module drifts. (`T_z` is ignored: a few
//! millimetres of it scale depth by well under 1 % at working range.)
//!
//! For each RGB pixel `q` the ToF pixel is `p = K_t Rᵀ K_c⁻¹ q̃` (backward: every output pixel is
//! written once, no holes from the resampling). Depth takes the nearest ToF pixel — bilinear
//! weights would invent depths between a foreground and a background — and is converted to
//! the rotated camera's `z`: `z' = z · (R K_t⁻¹ p̃)_z`. Amplitude is sampled bilinearly.
//! Outside the ToF image, depth is 0 (invalid) and amplitude 0.

use ndarray::{ArrayView2, ArrayViewMut2, Axis};
use rayon::prelude::*;

use crate::geometry::is_valid_depth;
use dear_capture::Intrinsics;

/// Rotation (row-major, ToF → RGB) and the two cameras' intrinsics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Registration {
    pub tof: Intrinsics,
    pub rgb: Intrinsics,
    /// `R` with `X_rgb = R · X_tof + T`.
    pub rotation: [[f32; 3]; 3],
}

impl Registration {
    /// Whether this registration is the identity (same intrinsics, no rotation): the ToF image
    /// is already on the RGB grid and can be used as it is.
    pub fn is_identity(&self) -> bool {
        const I: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        self.tof == self.rgb && self.rotation == I
    }

    /// `(A, b)` with ToF pixel `p = (A q̃)_{xy} / (A q̃)_z` for RGB pixel `q̃ = (x, y, 1)`, and the
    /// row `b` with `z' = z · b · K_t⁻¹ p̃`.
    fn maps(&self) -> ([[f32; 3]; 3], [f32; 3]) {
        let (t, c, r) = (&self.tof, &self.rgb, &self.rotation);
        // K_c⁻¹
        let kc_inv = [
            [1.0 / c.fx, 0.0, -c.cx / c.fx],
            [0.0, 1.0 / c.fy, -c.cy / c.fy],
            [0.0, 0.0, 1.0],
        ];
        let kt = [[t.fx, 0.0, t.cx], [0.0, t.fy, t.cy], [0.0, 0.0, 1.0]];
        let rt = [
            [r[0][0], r[1][0], r[2][0]],
            [r[0][1], r[1][1], r[2][1]],
            [r[0][2], r[1][2], r[2][2]],
        ];
        (mul(&mul(&kt, &rt), &kc_inv), r[2])
    }
}

fn mul(a: &[[f32; 3]; 3], b: &[[f32; 3]; 3]) -> [[f32; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

/// Registers a ToF `depth` (metres, 0 = invalid) and `amplitude` onto the RGB grid of
/// `depth_out` / `amplitude_out` (both the RGB image's shape).
///
/// # Panics
/// When the two outputs differ in shape, or the two inputs do.
pub fn register_tof(
    reg: &Registration,
    depth: ArrayView2<f32>,
    amplitude: ArrayView2<f32>,
    mut depth_out: ArrayViewMut2<f32>,
    mut amplitude_out: ArrayViewMut2<f32>,
) {
    assert_eq!(depth.dim(), amplitude.dim(), "ToF planes differ in shape");
    assert_eq!(
        depth_out.dim(),
        amplitude_out.dim(),
        "RGB-grid planes differ in shape"
    );
    let (ht, wt) = depth.dim();
    let (a, b) = reg.maps();
    let t = reg.tof;
    depth_out
        .axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(amplitude_out.axis_iter_mut(Axis(0)).into_par_iter())
        .enumerate()
        .for_each(|(y, (mut drow, mut arow))| {
            let yf = y as f32;
            for (x, (d, am)) in drow.iter_mut().zip(arow.iter_mut()).enumerate() {
                let xf = x as f32;
                let w = a[2][0] * xf + a[2][1] * yf + a[2][2];
                let px = (a[0][0] * xf + a[0][1] * yf + a[0][2]) / w;
                let py = (a[1][0] * xf + a[1][1] * yf + a[1][2]) / w;
                // Outside the convex hull of the ToF pixel centres: nothing was measured.
                if !(px >= 0.0 && py >= 0.0 && px <= (wt - 1) as f32 && py <= (ht - 1) as f32) {
                    *d = 0.0;
                    *am = 0.0;
                    continue;
                }
                let (nx, ny) = (px.round() as usize, py.round() as usize);
                let z = depth[(ny, nx)];
                *d = if is_valid_depth(z) {
                    let rx = (nx as f32 - t.cx) / t.fx;
                    let ry = (ny as f32 - t.cy) / t.fy;
                    z * (b[0] * rx + b[1] * ry + b[2])
                } else {
                    0.0
                };
                let (x0, y0) = (px.floor() as usize, py.floor() as usize);
                let (x1, y1) = ((x0 + 1).min(wt - 1), (y0 + 1).min(ht - 1));
                let (fx, fy) = (px - x0 as f32, py - y0 as f32);
                let top = amplitude[(y0, x0)] * (1.0 - fx) + amplitude[(y0, x1)] * fx;
                let bottom = amplitude[(y1, x0)] * (1.0 - fx) + amplitude[(y1, x1)] * fx;
                *am = top * (1.0 - fy) + bottom * fy;
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    fn intrinsics(f: f32, cx: f32, cy: f32) -> Intrinsics {
        Intrinsics {
            fx: f,
            fy: f,
            cx,
            cy,
        }
    }

    const IDENTITY: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

    #[test]
    fn the_same_camera_without_rotation_copies_the_images() {
        let k = intrinsics(100.0, 15.5, 11.5);
        let reg = Registration {
            tof: k,
            rgb: k,
            rotation: IDENTITY,
        };
        assert!(reg.is_identity());
        let depth = Array2::from_shape_fn((24, 32), |(y, x)| 1.0 + (x + 3 * y) as f32 * 0.01);
        let amp = depth.mapv(|d| d * 10.0);
        let (mut d, mut a) = (Array2::zeros((24, 32)), Array2::zeros((24, 32)));
        register_tof(&reg, depth.view(), amp.view(), d.view_mut(), a.view_mut());
        assert_eq!(d, depth);
        assert_eq!(a, amp);
    }

    #[test]
    fn a_low_resolution_tof_camera_is_upsampled_onto_the_rgb_grid() {
        // A 2x coarser ToF camera with the same field of view: RGB pixel (2x+½, 2y+½) is ToF
        // pixel (x, y).
        let tof = intrinsics(50.0, 7.5, 5.5);
        let rgb = intrinsics(100.0, 15.5, 11.5);
        let reg = Registration {
            tof,
            rgb,
            rotation: IDENTITY,
        };
        let depth = Array2::from_shape_fn((12, 16), |(y, x)| 1.0 + x as f32 + 100.0 * y as f32);
        let amp = Array2::from_shape_fn((12, 16), |(_, x)| x as f32);
        let (mut d, mut a) = (Array2::zeros((24, 32)), Array2::zeros((24, 32)));
        register_tof(&reg, depth.view(), amp.view(), d.view_mut(), a.view_mut());
        // RGB (x=9, y=7) → ToF (4.25, 3.25): nearest depth (4, 3), amplitude interpolated.
        assert_eq!(d[(7, 9)], depth[(3, 4)]);
        assert!((a[(7, 9)] - 4.25).abs() < 1e-5, "{}", a[(7, 9)]);
        // RGB column 0 maps to ToF x = -0.25: outside the ToF image, invalid.
        assert_eq!(d[(7, 0)], 0.0);
        assert_eq!(a[(7, 0)], 0.0);
    }

    #[test]
    fn a_rotated_tof_camera_sees_a_plane_where_the_rgb_camera_does() {
        // A plane at z = 2 m in the RGB camera; the ToF camera is rotated 3° about y. Render
        // the ToF depth of that plane exactly, register it, and the RGB grid must read 2 m.
        let k = intrinsics(200.0, 31.5, 23.5);
        let th = 3.0f32.to_radians();
        // R: ToF → RGB coordinates (rotation about y).
        let r = [
            [th.cos(), 0.0, th.sin()],
            [0.0, 1.0, 0.0],
            [-th.sin(), 0.0, th.cos()],
        ];
        let reg = Registration {
            tof: k,
            rgb: k,
            rotation: r,
        };
        let (h, w) = (48, 64);
        // ToF pixel p: ray d_t = K⁻¹ p̃ in ToF coordinates, R d_t in RGB coordinates; the plane
        // z_rgb = 2 is hit at s = 2 / (R d_t)_z; the ToF depth is s · (d_t)_z = s.
        let depth = Array2::from_shape_fn((h, w), |(y, x)| {
            let d = [(x as f32 - k.cx) / k.fx, (y as f32 - k.cy) / k.fy, 1.0];
            let rz = r[2][0] * d[0] + r[2][1] * d[1] + r[2][2] * d[2];
            2.0 / rz
        });
        let amp = Array2::from_elem((h, w), 1.0);
        let (mut d, mut a) = (Array2::zeros((h, w)), Array2::zeros((h, w)));
        register_tof(&reg, depth.view(), amp.view(), d.view_mut(), a.view_mut());
        let valid: Vec<f32> = d.iter().copied().filter(|&z| z > 0.0).collect();
        assert!(valid.len() > h * w * 3 / 4, "{} valid", valid.len());
        // Nearest-pixel sampling moves the point by up to half a pixel on a tilted plane:
        // a few millimetres at 2 m.
        for z in valid {
            assert!((z - 2.0).abs() < 5e-3, "{z}");
        }
        // The rotation shifts the image sideways by f·tan 3° ≈ 10.5 px: the columns on one
        // side see nothing.
        assert!(d.column(w - 1).iter().all(|&z| z == 0.0) || d.column(0).iter().all(|&z| z == 0.0));
    }
}
