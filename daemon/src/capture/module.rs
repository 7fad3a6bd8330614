//! A live module's calibration file (`[capture.v4l] calibration`): both cameras' intrinsics, the
//! ToF → RGB rotation and translation, and the ToF depth scale. `daemon/module.example.toml`
//! documents every key.
//!
//! From it the daemon takes the [`Registration`] (rotation and intrinsics, undone on every ToF
//! frame) and the chain's initial calibration: the translation's flow `t / z` with
//! `t = (−f_x T_x, −f_y T_y)` (the RGB pixel `p` sees the point the ToF camera sees at
//! `p − f T / z`), `c = 0` — or the `[initial_calibration]` the file gives, e.g. one the
//! online estimator settled on.

use std::path::{Path, PathBuf};

use dear_capture::{Calibration, Intrinsics};
use dear_pipeline::geometry::register::Registration;
use dear_proto::CameraIntrinsics;
use serde::{Deserialize, Serialize};

/// The file as written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModuleCalibration {
    /// Metres per unit of a `Z16 `/`Y16 ` depth image (RealSense: 0.001).
    #[serde(default = "default_depth_scale")]
    pub depth_scale_m: f32,
    /// The farthest z-depth the module measures, metres (its data sheet's range): depth beyond
    /// it is marked invalid as frames arrive ([`DepthLimit`](super::DepthLimit)). None: no
    /// limit but the modulation's unambiguous range, where `[capture.v4l.tof] modulation_hz`
    /// gives one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_range_m: Option<f32>,
    pub tof: Camera,
    pub rgb: Camera,
    pub extrinsics: Extrinsics,
    /// Overrides the calibration derived from the translation.
    pub initial_calibration: Option<Calibration>,
}

fn default_depth_scale() -> f32 {
    0.001
}

/// One camera: its image size and pinhole intrinsics (pixel centres at integer coordinates),
/// and for the RGB camera optionally its lens distortion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    /// Brown–Conrady `[k1, k2, p1, p2, k3]` (OpenCV's order; `rs-enumerate-devices -c` and
    /// OpenCV's calibrateCamera give them so). Only `[rgb]` may have it: deard publishes it in
    /// the frame header for clients' point clouds; the ToF image is registered as a pinhole.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<[f32; 5]>,
}

impl Camera {
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics {
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
        }
    }
}

/// `X_rgb = R · X_tof + T`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Extrinsics {
    /// Row-major; a proper rotation (orthonormal, determinant 1) within 1e-3.
    pub rotation: [[f32; 3]; 3],
    /// Metres.
    pub translation_m: [f32; 3],
}

/// Why a calibration file cannot be used; every message names the file and the key.
#[derive(Debug, thiserror::Error)]
pub enum ModuleCalibrationError {
    #[error("{}: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: {source}", path.display())]
    Parse {
        path: PathBuf,
        #[source]
        source: toml::de::Error,
    },
    #[error("{}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },
}

impl ModuleCalibration {
    /// Reads and checks `path`.
    pub fn load(path: &Path) -> Result<Self, ModuleCalibrationError> {
        let text =
            dear_capture::input::read_text_limited(path, dear_capture::input::SETTINGS_LIMIT)
                .map_err(|source| ModuleCalibrationError::Read {
                    path: path.to_path_buf(),
                    source,
                })?;
        let cal: ModuleCalibration =
            toml::from_str(&text).map_err(|source| ModuleCalibrationError::Parse {
                path: path.to_path_buf(),
                source,
            })?;
        cal.check()
            .map_err(|message| ModuleCalibrationError::Invalid {
                path: path.to_path_buf(),
                message,
            })?;
        Ok(cal)
    }

    fn check(&self) -> Result<(), String> {
        if !(self.depth_scale_m.is_finite() && self.depth_scale_m > 0.0) {
            return Err(format!(
                "depth_scale_m = {} must be a positive number of metres per unit",
                self.depth_scale_m
            ));
        }
        if let Some(r) = self.max_range_m {
            if !(r.is_finite() && r > 0.0) {
                return Err(format!(
                    "max_range_m = {r} must be a positive number of metres (leave it out for no limit)"
                ));
            }
        }
        for (name, cam) in [("tof", &self.tof), ("rgb", &self.rgb)] {
            let max = dear_capture::manifest::MAX_SIDE;
            if !(1..=max).contains(&cam.width) || !(1..=max).contains(&cam.height) {
                return Err(format!(
                    "[{name}] width = {}, height = {} must be within 1..={max}",
                    cam.width, cam.height
                ));
            }
            for (key, f) in [("fx", cam.fx), ("fy", cam.fy)] {
                if !(f.is_finite() && f > 0.0) {
                    return Err(format!(
                        "[{name}] {key} = {f} must be a positive focal length in pixels"
                    ));
                }
            }
            for (key, c) in [("cx", cam.cx), ("cy", cam.cy)] {
                if !c.is_finite() {
                    return Err(format!("[{name}] {key} = {c} must be finite"));
                }
            }
        }
        if self.tof.distortion.is_some() {
            return Err(
                "[tof] distortion is not used: deard registers the ToF image as a \
                 pinhole (give the rectified camera's fx, fy, cx, cy); only [rgb] may have \
                 distortion"
                    .into(),
            );
        }
        if let Some(d) = self.rgb.distortion {
            if let Some((i, k)) = d.iter().enumerate().find(|(_, k)| !k.is_finite()) {
                let name = ["k1", "k2", "p1", "p2", "k3"][i];
                return Err(format!(
                    "[rgb] distortion[{i}] ({name}) = {k} must be finite: distortion = [k1, k2, \
                     p1, p2, k3], Brown–Conrady in OpenCV's order"
                ));
            }
        }
        let r = &self.extrinsics.rotation;
        if r.iter().flatten().any(|v| !v.is_finite()) {
            return Err("[extrinsics] rotation must be finite".into());
        }
        for i in 0..3 {
            for j in 0..3 {
                let dot: f32 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                if (dot - want).abs() > 1e-3 {
                    return Err(format!(
                        "[extrinsics] rotation is not a rotation: row {i} · row {j} = {dot} (rows must be orthonormal)"
                    ));
                }
            }
        }
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        if det < 0.0 {
            return Err(
                "[extrinsics] rotation has determinant -1 (a reflection, not a rotation)".into(),
            );
        }
        if self.extrinsics.translation_m.iter().any(|v| !v.is_finite()) {
            return Err("[extrinsics] translation_m must be finite".into());
        }
        if let Some(c) = &self.initial_calibration {
            if [c.tx, c.ty, c.cx, c.cy].iter().any(|v| !v.is_finite()) {
                return Err("[initial_calibration] must be finite".into());
            }
        }
        Ok(())
    }

    /// The RGB camera's intrinsics as the frame header carries them: the pinhole, and the
    /// Brown–Conrady distortion when the file gives one.
    pub fn rgb_intrinsics(&self) -> CameraIntrinsics {
        let r = &self.rgb;
        CameraIntrinsics {
            distortion: r.distortion,
            ..CameraIntrinsics::pinhole(r.fx, r.fy, r.cx, r.cy)
        }
    }

    /// The rotation and intrinsics registration of ToF frames onto the RGB grid.
    pub fn registration(&self) -> Registration {
        Registration {
            tof: self.tof.intrinsics(),
            rgb: self.rgb.intrinsics(),
            rotation: self.extrinsics.rotation,
        }
    }

    /// The chain's calibration at start: the file's `[initial_calibration]`, or the flow of
    /// the translation.
    pub fn initial_calibration(&self) -> Calibration {
        self.initial_calibration.unwrap_or_else(|| {
            let t = self.extrinsics.translation_m;
            Calibration {
                tx: -self.rgb.fx * t[0],
                ty: -self.rgb.fy * t[1],
                cx: 0.0,
                cy: 0.0,
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = include_str!("../../module.example.toml");

    fn parse(text: &str) -> Result<ModuleCalibration, ModuleCalibrationError> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("module.toml");
        std::fs::write(&path, text).unwrap();
        ModuleCalibration::load(&path)
    }

    #[test]
    fn the_documented_example_loads() {
        let cal = parse(EXAMPLE).unwrap();
        assert_eq!(cal.depth_scale_m, 0.001);
        assert_eq!(cal.max_range_m, Some(4.0));
        assert!(cal.initial_calibration().tx.is_finite());
    }

    #[test]
    fn the_rgb_intrinsics_and_distortion_are_what_the_header_carries() {
        let cal = parse(EXAMPLE).unwrap();
        assert_eq!(
            cal.rgb_intrinsics(),
            CameraIntrinsics::pinhole(457.0, 457.0, 319.5, 239.5),
            "without distortion: a pinhole"
        );
        let text = EXAMPLE.replacen(
            "# distortion = [0.1, -0.25, 0.001, -0.0005, 0.1]",
            "distortion = [0.1, -0.25, 0.001, -0.0005, 0.1]",
            1,
        );
        let k = parse(&text).unwrap().rgb_intrinsics();
        assert_eq!(k.distortion, Some([0.1, -0.25, 0.001, -0.0005, 0.1]));
        let mut header = dear_proto::FrameHeader::new(0, 640, 480);
        header.set_intrinsics(Some(&k));
        assert_eq!(
            header.rgb_camera_model,
            dear_proto::camera_model::BROWN_CONRADY
        );
        assert_eq!(header.intrinsics(), Ok(Some(k)));
    }

    #[test]
    fn the_translation_becomes_the_flow_of_the_baseline() {
        let text = EXAMPLE.replace(
            "translation_m = [0.015, 0.0, 0.0]",
            "translation_m = [0.02, -0.01, 0.0]",
        );
        let cal = parse(&text).unwrap();
        let c = cal.initial_calibration();
        // The RGB pixel sees the ToF pixel f·T/z closer to the ToF camera's side.
        assert!((c.tx - (-cal.rgb.fx * 0.02)).abs() < 1e-4);
        assert!((c.ty - cal.rgb.fy * 0.01).abs() < 1e-4);
        assert_eq!((c.cx, c.cy), (0.0, 0.0));
    }

    #[test]
    fn bad_values_are_named_with_the_file() {
        let cases = [
            (
                "depth_scale_m = 0.001",
                "depth_scale_m = 0.0",
                "depth_scale_m",
            ),
            (
                "max_range_m = 4.0",
                "max_range_m = -4.0",
                "max_range_m = -4 must be a positive number of metres",
            ),
            (
                "max_range_m = 4.0",
                "max_range_m = nan",
                "max_range_m = NaN must be a positive number of metres",
            ),
            (
                "rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]",
                "rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 2.0]]",
                "not a rotation",
            ),
            (
                "rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]",
                "rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]",
                "reflection",
            ),
        ];
        for (from, to, says) in cases {
            assert!(EXAMPLE.contains(from), "{from}");
            let err = parse(&EXAMPLE.replacen(from, to, 1))
                .unwrap_err()
                .to_string();
            assert!(err.contains(says) && err.contains("module.toml"), "{err}");
        }
        let err = parse(&EXAMPLE.replacen("fx = ", "focal = ", 1))
            .unwrap_err()
            .to_string();
        assert!(err.contains("focal"), "unknown key named: {err}");
        // The optional [rgb] distortion: five finite numbers, and only for the RGB camera.
        let with =
            |line: &str, section: &str| EXAMPLE.replacen(section, &format!("{section}\n{line}"), 1);
        for (text, says) in [
            (
                with("distortion = [0.1, nan, 0.0, 0.0, 0.0]", "[rgb]"),
                "[rgb] distortion[1] (k2) = NaN must be finite",
            ),
            (
                with("distortion = [0.1, 0.2, 0.0, 0.0]", "[rgb]"),
                "distortion",
            ),
            (
                with("distortion = [0.1, 0.2, 0.0, 0.0, 0.0]", "[tof]"),
                "[tof] distortion is not used",
            ),
        ] {
            let err = parse(&text).unwrap_err().to_string();
            assert!(err.contains(says) && err.contains("module.toml"), "{err}");
        }
        let missing = ModuleCalibration::load(Path::new("/nonexistent/module.toml"))
            .unwrap_err()
            .to_string();
        assert!(missing.contains("/nonexistent/module.toml"), "{missing}");
    }
}
