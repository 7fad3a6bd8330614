//! Point clouds: a frame's aligned depth back-projected with the RGB camera's intrinsics its
//! header carries (frame format 3). The one definition of this math: the C library
//! (`dear_frame_point_cloud`) and the Python package (`Frame.point_cloud`) call it.
//!
//! A pixel `(u, v)` (pixel centres at integer coordinates, as OpenCV) with z-depth `z` is the
//! point `(x·z, y·z, z)` in the RGB camera's optical frame (x right, y down, z forward,
//! metres), where `(x, y)` is the pixel's normalised ray:
//! - pinhole: `x = (u − cx) / fx`, `y = (v − cy) / fy`;
//! - Brown–Conrady (`[k1, k2, p1, p2, k3]`): the undistorted `(x, y)` whose distortion
//!   ([`distort`]) lands on `((u − cx) / fx, (v − cy) / fy)`, found by Newton's method in `f64`
//!   (to 1e-9 in normalised units, ~1e-6 px). A pixel whose ray does not converge (far outside
//!   the calibrated field, where the polynomial folds over) gets no point.
//!
//! The depth is z-depth along the optical axis (not the distance along the ray), in metres
//! (`FrameHeader::depth_unit_m` is 1). A pixel without valid depth (0, negative, NaN, ∞) is not
//! a point: its `valid` entry is false and its coordinates are NaN, never `(0, 0, 0)`.

use std::sync::{Arc, Mutex};

use dear_proto::{CameraIntrinsics, FrameHeader, IntrinsicsError};

use crate::frame::Frame;

/// Newton steps allowed when inverting the distortion.
const MAX_NEWTON_STEPS: usize = 50;
/// A ray is accepted when distorting it lands within this of the pixel (normalised units).
const UNDISTORT_TOLERANCE: f64 = 1e-9;

/// Why a point cloud cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PointCloudError {
    /// The frame says its intrinsics are unknown (`rgb_camera_model` 0): the publisher was given
    /// none, so there is nothing honest to back-project with.
    #[error(
        "frame {frame_id} carries no intrinsics (`rgb_camera_model` is 0, unknown): its \
         publisher knows none of the RGB camera (give deard a capture or module file with \
         intrinsics, docs/protocol.md \"Format 3\")"
    )]
    NoIntrinsics { frame_id: u64 },
    /// The header's intrinsics cannot be used (the message names the field).
    #[error("frame {frame_id}: {source}")]
    Intrinsics {
        frame_id: u64,
        #[source]
        source: IntrinsicsError,
    },
    /// A plane or output buffer has the wrong length for `width`×`height`.
    #[error("{what} has {found} values, but a {width}×{height} frame needs {expected}")]
    Length {
        what: &'static str,
        found: usize,
        expected: usize,
        width: usize,
        height: usize,
    },
}

/// Brown–Conrady distortion of a normalised point (OpenCV's model, ROS's `plumb_bob`), `d` =
/// `[k1, k2, p1, p2, k3]`: `x' = x·r + 2·p1·x·y + p2·(ρ² + 2x²)`, `y' = y·r + p1·(ρ² + 2y²) +
/// 2·p2·x·y`, with `ρ² = x² + y²` and `r = 1 + k1·ρ² + k2·ρ⁴ + k3·ρ⁶`.
pub fn distort(d: &[f32; 5], x: f64, y: f64) -> (f64, f64) {
    let [k1, k2, p1, p2, k3] = d.map(f64::from);
    let r2 = x * x + y * y;
    let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    (
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    )
}

/// The undistorted normalised ray whose distortion is `(xd, yd)`, by Newton's method on
/// [`distort`] from `(xd, yd)`; `None` when it does not converge.
pub fn undistort(d: &[f32; 5], xd: f64, yd: f64) -> Option<(f64, f64)> {
    let [k1, k2, p1, p2, k3] = d.map(f64::from);
    let (mut x, mut y) = (xd, yd);
    for _ in 0..MAX_NEWTON_STEPS {
        let (fx, fy) = distort(d, x, y);
        let (ex, ey) = (fx - xd, fy - yd);
        if ex.abs().max(ey.abs()) < UNDISTORT_TOLERANCE {
            return Some((x, y));
        }
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        // d(radial)/d(r2)
        let dr = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3);
        let j11 = radial + 2.0 * x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x;
        let j12 = 2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y;
        let j21 = 2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y;
        let j22 = radial + 2.0 * y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x;
        let det = j11 * j22 - j12 * j21;
        // NaN (a non-finite Jacobian) fails the test too.
        if det.abs().is_nan() || det.abs() <= 1e-12 {
            return None;
        }
        x -= (j22 * ex - j12 * ey) / det;
        y -= (j11 * ey - j21 * ex) / det;
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
    }
    let (fx, fy) = distort(d, x, y);
    ((fx - xd).abs().max((fy - yd).abs()) < UNDISTORT_TOLERANCE).then_some((x, y))
}

/// Whether a depth value is a measurement: positive and finite (0 marks "no depth").
pub fn is_valid_depth(z: f32) -> bool {
    z > 0.0 && z.is_finite()
}

/// The normalised ray `(x, y)` (point = `(x·z, y·z, z)`) of every pixel of a
/// `width`×`height` grid with given intrinsics: made once, used for every frame of that camera
/// (the undistortion is the costly part).
#[derive(Debug, Clone, PartialEq)]
pub struct Rays {
    intrinsics: CameraIntrinsics,
    width: usize,
    height: usize,
    /// Row-major; NaN where the undistortion did not converge.
    xy: Vec<[f32; 2]>,
}

impl Rays {
    /// The rays of `intrinsics` at `width`×`height`; the intrinsics are checked first.
    pub fn new(
        intrinsics: &CameraIntrinsics,
        width: usize,
        height: usize,
    ) -> Result<Self, IntrinsicsError> {
        intrinsics.check()?;
        let k = intrinsics;
        let (fx, fy, cx, cy) = (
            f64::from(k.fx),
            f64::from(k.fy),
            f64::from(k.cx),
            f64::from(k.cy),
        );
        let mut xy = Vec::with_capacity(width * height);
        for v in 0..height {
            let yd = (v as f64 - cy) / fy;
            for u in 0..width {
                let xd = (u as f64 - cx) / fx;
                let ray = match &k.distortion {
                    None => Some((xd, yd)),
                    Some(d) => undistort(d, xd, yd),
                };
                xy.push(match ray {
                    Some((x, y)) => [x as f32, y as f32],
                    None => [f32::NAN; 2],
                });
            }
        }
        Ok(Rays {
            intrinsics: *intrinsics,
            width,
            height,
            xy,
        })
    }

    /// [`Rays::new`], but the last rays made by this function in this process are reused when
    /// the intrinsics and size are the same (a stream's every frame): the undistortion is then
    /// paid once per camera, not per frame. What [`point_cloud`] and the C and Python SDKs use.
    pub fn shared(
        intrinsics: &CameraIntrinsics,
        width: usize,
        height: usize,
    ) -> Result<Arc<Self>, IntrinsicsError> {
        static LAST: Mutex<Option<Arc<Rays>>> = Mutex::new(None);
        // A panic elsewhere while holding the lock leaves a valid `Option`: use it anyway.
        let mut last = LAST.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(rays) = last.as_ref() {
            if rays.intrinsics == *intrinsics && rays.size() == (width, height) {
                return Ok(Arc::clone(rays));
            }
        }
        let rays = Arc::new(Rays::new(intrinsics, width, height)?);
        *last = Some(Arc::clone(&rays));
        Ok(rays)
    }

    pub fn intrinsics(&self) -> &CameraIntrinsics {
        &self.intrinsics
    }

    /// `(width, height)`.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The normalised ray of pixel `(u, v)`; NaN where it could not be undistorted.
    pub fn ray(&self, u: usize, v: usize) -> [f32; 2] {
        self.xy[v * self.width + u]
    }

    /// The point of pixel `i` (row-major) at z-depth `z`; `None` when the depth is not valid
    /// or the pixel has no ray.
    #[inline]
    pub fn point(&self, i: usize, z: f32) -> Option<[f32; 3]> {
        let [x, y] = self.xy[i];
        (is_valid_depth(z) && x.is_finite()).then_some([x * z, y * z, z])
    }

    /// Back-projects a depth plane (`width·height` metres, row-major): calls `emit(i, point)`
    /// for every pixel in order, `None` where there is no point.
    pub fn back_project_with(
        &self,
        depth: &[f32],
        mut emit: impl FnMut(usize, Option<[f32; 3]>),
    ) -> Result<(), PointCloudError> {
        self.check_len("the depth plane", depth.len(), 1)?;
        for (i, &z) in depth.iter().enumerate() {
            emit(i, self.point(i, z));
        }
        Ok(())
    }

    /// Back-projects a depth plane into an organised cloud of `width·height` points (see
    /// [`PointCloud`]), without colour or confidence.
    pub fn back_project(&self, depth: &[f32]) -> Result<PointCloud, PointCloudError> {
        let n = self.width * self.height;
        let mut points = Vec::with_capacity(n);
        let mut valid = Vec::with_capacity(n);
        self.back_project_with(depth, |_, p| {
            valid.push(p.is_some());
            points.push(p.unwrap_or([f32::NAN; 3]));
        })?;
        Ok(PointCloud {
            width: self.width,
            height: self.height,
            points,
            valid,
            colors: None,
            confidence: None,
        })
    }

    /// Checks that a buffer has `per_pixel` values for every pixel.
    pub fn check_len(
        &self,
        what: &'static str,
        found: usize,
        per_pixel: usize,
    ) -> Result<(), PointCloudError> {
        let expected = self.width * self.height * per_pixel;
        if found != expected {
            return Err(PointCloudError::Length {
                what,
                found,
                expected,
                width: self.width,
                height: self.height,
            });
        }
        Ok(())
    }
}

/// An organised point cloud: one entry per pixel, row-major (`i = v·width + u`), as the
/// frame's planes. Where `valid[i]` is false the point is NaN (no depth, or no ray); take
/// `valid` to keep only the measured points.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud {
    pub width: usize,
    pub height: usize,
    /// `(x, y, z)` metres in the RGB camera's optical frame (x right, y down, z forward).
    pub points: Vec<[f32; 3]>,
    pub valid: Vec<bool>,
    /// Each point's colour, the aligned RGB pixel it came from (when asked for).
    pub colors: Option<Vec<[u8; 3]>>,
    /// Each point's confidence byte (when asked for; decode with [`crate::confidence`] when
    /// the frame has `CONFIDENCE_EXPECTED_ERROR`).
    pub confidence: Option<Vec<u8>>,
}

impl PointCloud {
    /// How many points are valid.
    pub fn valid_count(&self) -> usize {
        self.valid.iter().filter(|&&v| v).count()
    }
}

/// What to put in a [`PointCloud`] besides the points.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PointCloudOptions {
    /// The RGB colour of each point.
    pub colors: bool,
    /// The confidence byte of each point.
    pub confidence: bool,
}

/// The header's intrinsics, or why there are none to use.
pub fn header_intrinsics(header: &FrameHeader) -> Result<CameraIntrinsics, PointCloudError> {
    let frame_id = header.frame_id;
    header
        .intrinsics()
        .map_err(|source| PointCloudError::Intrinsics { frame_id, source })?
        .ok_or(PointCloudError::NoIntrinsics { frame_id })
}

/// The point cloud of a frame's planes with its header's intrinsics (what
/// [`Frame::point_cloud`] does with a received frame; this takes the planes from anywhere).
pub fn point_cloud(
    header: &FrameHeader,
    depth: &[f32],
    rgb: &[u8],
    confidence: &[u8],
    options: PointCloudOptions,
) -> Result<PointCloud, PointCloudError> {
    let k = header_intrinsics(header)?;
    let rays =
        Rays::shared(&k, header.width as usize, header.height as usize).map_err(|source| {
            PointCloudError::Intrinsics {
                frame_id: header.frame_id,
                source,
            }
        })?;
    let mut cloud = rays.back_project(depth)?;
    if options.colors {
        rays.check_len("the RGB plane", rgb.len(), 3)?;
        cloud.colors = Some(rgb.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect());
    }
    if options.confidence {
        rays.check_len("the confidence plane", confidence.len(), 1)?;
        cloud.confidence = Some(confidence.to_vec());
    }
    Ok(cloud)
}

impl Frame {
    /// This frame's point cloud (see the [module](self) for the math): organised, one point
    /// per pixel, with colour and confidence as `options` asks. Fails when the header carries
    /// no intrinsics ([`PointCloudError::NoIntrinsics`]) or unusable ones.
    pub fn point_cloud(&self, options: PointCloudOptions) -> Result<PointCloud, PointCloudError> {
        point_cloud(
            self.header(),
            self.depth(),
            self.rgb(),
            self.confidence(),
            options,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(w: u32, h: u32, k: Option<&CameraIntrinsics>) -> FrameHeader {
        let mut header = FrameHeader::new(7, w, h);
        header.set_intrinsics(k);
        header
    }

    #[test]
    fn a_pinhole_pixel_is_u_minus_cx_times_z_over_fx() {
        let k = CameraIntrinsics::pinhole(500.0, 520.0, 3.25, 1.75);
        let (w, h) = (6, 4);
        let depth: Vec<f32> = (0..w * h).map(|i| 0.5 + 0.25 * i as f32).collect();
        let cloud = Rays::new(&k, w, h).unwrap().back_project(&depth).unwrap();
        for v in 0..h {
            for u in 0..w {
                let i = v * w + u;
                let z = depth[i];
                let want = [
                    (u as f32 - k.cx) * z / k.fx,
                    (v as f32 - k.cy) * z / k.fy,
                    z,
                ];
                let got = cloud.points[i];
                for c in 0..3 {
                    assert!(
                        (got[c] - want[c]).abs() <= 1e-6 * want[c].abs().max(1.0),
                        "pixel ({u}, {v}) coordinate {c}: {got:?} vs {want:?}"
                    );
                }
                assert!(cloud.valid[i]);
            }
        }
    }

    #[test]
    fn invalid_depth_is_never_a_point_at_the_origin() {
        let k = CameraIntrinsics::pinhole(100.0, 100.0, 1.0, 0.5);
        let depth = [0.0, -1.0, f32::NAN, f32::INFINITY, 2.0, 0.0];
        let cloud = Rays::new(&k, 3, 2).unwrap().back_project(&depth).unwrap();
        assert_eq!(cloud.valid, [false, false, false, false, true, false]);
        for (p, valid) in cloud.points.iter().zip(&cloud.valid) {
            assert_eq!(*valid, p.iter().all(|c| c.is_finite()), "{p:?}");
            assert_ne!(*p, [0.0; 3]);
        }
        assert_eq!(cloud.valid_count(), 1);
    }

    #[test]
    fn distortion_is_undone_to_the_true_ray() {
        // A strong wide-angle lens (OpenCV-calibrated webcams are of this order).
        let d = [-0.28, 0.09, 0.0012, -0.0007, -0.015];
        let k = CameraIntrinsics {
            distortion: Some(d),
            ..CameraIntrinsics::pinhole(420.0, 415.0, 319.2, 241.7)
        };
        let (w, h) = (640, 480);
        let rays = Rays::new(&k, w, h).unwrap();
        // Every pixel's ray, distorted and projected, lands back on the pixel.
        let mut worst = 0.0f64;
        for v in (0..h).step_by(7) {
            for u in (0..w).step_by(5) {
                let [x, y] = rays.ray(u, v);
                assert!(x.is_finite(), "pixel ({u}, {v}) has no ray");
                let (xd, yd) = distort(&d, f64::from(x), f64::from(y));
                let pu = xd * f64::from(k.fx) + f64::from(k.cx);
                let pv = yd * f64::from(k.fy) + f64::from(k.cy);
                worst = worst.max((pu - u as f64).abs()).max((pv - v as f64).abs());
            }
        }
        assert!(worst < 1e-3, "reprojection error {worst} px");
        // And a known 3-D point seen through the lens comes back where it is.
        let p = [0.9f64, -0.6, 1.7];
        let (xd, yd) = distort(&d, p[0] / p[2], p[1] / p[2]);
        let (u, v) = (
            xd * f64::from(k.fx) + f64::from(k.cx),
            yd * f64::from(k.fy) + f64::from(k.cy),
        );
        let (x, y) = undistort(
            &d,
            (u - f64::from(k.cx)) / f64::from(k.fx),
            (v - f64::from(k.cy)) / f64::from(k.fy),
        )
        .unwrap();
        assert!((x * p[2] - p[0]).abs() < 1e-6 && (y * p[2] - p[1]).abs() < 1e-6);
        // Without the undistortion the point would be off by centimetres: the test can fail.
        assert!((xd * p[2] - p[0]).abs() > 0.05);
    }

    #[test]
    fn frames_without_intrinsics_or_with_bad_ones_are_refused_by_name() {
        let depth = vec![1.0; 12];
        let rgb = vec![0; 36];
        let conf = vec![255; 12];
        let none = header(4, 3, None);
        let err = point_cloud(&none, &depth, &rgb, &conf, Default::default()).unwrap_err();
        assert_eq!(err, PointCloudError::NoIntrinsics { frame_id: 7 });
        assert!(err.to_string().contains("`rgb_camera_model` is 0"), "{err}");

        let mut bad = header(4, 3, Some(&CameraIntrinsics::pinhole(1.0, 1.0, 0.0, 0.0)));
        bad.rgb_fy = -3.0;
        let err = point_cloud(&bad, &depth, &rgb, &conf, Default::default()).unwrap_err();
        assert!(err.to_string().contains("`rgb_fy` is -3"), "{err}");

        let good = header(4, 3, Some(&CameraIntrinsics::pinhole(1.0, 1.0, 0.0, 0.0)));
        let err = point_cloud(&good, &depth[..11], &rgb, &conf, Default::default()).unwrap_err();
        assert!(
            err.to_string()
                .contains("the depth plane has 11 values, but a 4×3 frame needs 12"),
            "{err}"
        );
    }

    #[test]
    fn shared_rays_are_made_once_per_camera() {
        let a = CameraIntrinsics::pinhole(300.0, 300.0, 7.5, 5.5);
        let b = CameraIntrinsics {
            distortion: Some([0.1, 0.0, 0.0, 0.0, 0.0]),
            ..a
        };
        // Other tests may call `shared` meanwhile (one entry, process-wide): values are
        // compared, and reuse is looked for over a few back-to-back pairs of calls.
        let first = Rays::shared(&a, 16, 12).unwrap();
        assert_eq!(*first, Rays::new(&a, 16, 12).unwrap());
        let other = Rays::shared(&b, 16, 12).unwrap();
        assert_eq!(other.intrinsics(), &b);
        assert_ne!(*other, *first, "the distortion changes the rays");
        assert_eq!(Rays::shared(&a, 16, 13).unwrap().size(), (16, 13));
        let reused = (0..100).any(|_| {
            let x = Rays::shared(&b, 20, 10).unwrap();
            Arc::ptr_eq(&x, &Rays::shared(&b, 20, 10).unwrap())
        });
        assert!(reused, "the same camera's rays are reused");
    }

    #[test]
    fn colours_and_confidence_come_from_the_same_pixel() {
        let k = CameraIntrinsics::pinhole(2.0, 2.0, 1.0, 0.5);
        let h = header(3, 2, Some(&k));
        let depth = [1.0, 0.0, 2.0, 3.0, 4.0, 5.0];
        let rgb: Vec<u8> = (0..18).collect();
        let conf = [255, 0, 200, 100, 50, 10];
        let options = PointCloudOptions {
            colors: true,
            confidence: true,
        };
        let cloud = point_cloud(&h, &depth, &rgb, &conf, options).unwrap();
        assert_eq!(cloud.colors.as_ref().unwrap()[4], [12, 13, 14]);
        assert_eq!(cloud.confidence.as_deref(), Some(&conf[..]));
        assert_eq!(cloud.points[4], [0.0, 1.0, 4.0]);
        assert!(!cloud.valid[1]);
    }
}
