//! One simulated sample: render the scene, run the sensor, tone-map the RGB image, and package
//! everything as a `dear_pipeline` [`RgbdFrame`] on the ToF grid (an *aligned* sample).

use dear_capture::{Calibration, GroundTruth, RgbdFrame};
use ndarray::{Array2, Array3};
use serde::{Deserialize, Serialize};

use crate::scene::Scene;
use crate::sensor::{sense, SensorConfig, TofImage};
use crate::transport::{render, RenderOptions, SignalImage};

/// Everything that defines how samples are simulated (recorded in `capture.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimConfig {
    pub render: RenderOptions,
    pub sensor: SensorConfig,
    /// RGB exposure: linear radiance `x` becomes `1 − exp(−exposure·x)` (a soft shoulder
    /// instead of hard clipping) before the sRGB curve.
    pub rgb_exposure: f64,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            render: RenderOptions::default(),
            sensor: SensorConfig::default(),
            rgb_exposure: 1.5,
        }
    }
}

/// A simulated, aligned sample: every image on the same (ToF = RGB) pixel grid.
#[derive(Debug, Clone)]
pub struct Sample {
    /// 8-bit sRGB `(H, W, 3)`.
    pub rgb: Array3<u8>,
    pub tof: TofImage,
    /// Ground-truth z-depth, metres (0 where nothing was hit).
    pub gt_depth: Array2<f32>,
    /// Valid pixels: ground truth exists and the ToF measurement was not invalidated.
    pub mask: Array2<bool>,
}

/// Linear [0, 1] → 8-bit sRGB.
pub fn linear_to_srgb8(v: f64) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

fn rgb_image(signal: &SignalImage, exposure: f64) -> Array3<u8> {
    Array3::from_shape_fn((signal.height, signal.width, 3), |(y, x, c)| {
        linear_to_srgb8(1.0 - (-signal.pixels[y * signal.width + x].rgb[c] * exposure).exp())
    })
}

/// Simulates frame `frame` of `scene`; all randomness is keyed by `(seed, frame, pixel)`.
pub fn simulate(scene: &Scene, cfg: &SimConfig, seed: u64, frame: u64) -> Sample {
    let signal = render(scene, &cfg.render, seed, frame);
    let tof = sense(
        &signal,
        &scene.camera,
        &cfg.render.frequencies_hz,
        &cfg.sensor,
        seed,
        frame,
    );
    let gt_depth = gt_depth(&signal);
    let mask = Array2::from_shape_fn(gt_depth.dim(), |p| gt_depth[p] > 0.0 && tof.depth[p] > 0.0);
    Sample {
        rgb: rgb_image(&signal, cfg.rgb_exposure),
        tof,
        gt_depth,
        mask,
    }
}

/// What the RGB camera of a module with calibration `p` sees of `scene` (whose camera is the
/// ToF sensor): the tone-mapped RGB image and the ground-truth z-depth of that view, rendered
/// from the scene itself, so disocclusions and the borders show what is there instead of
/// holes. Only the RGB shading is computed (no ToF light transport).
pub fn render_rgb_view(
    scene: &Scene,
    cfg: &SimConfig,
    seed: u64,
    frame: u64,
    p: &Calibration,
) -> (Array3<u8>, Array2<f32>) {
    let mut moved = scene.clone();
    moved.camera = scene.camera.rgb_camera_of(p);
    let opts = RenderOptions {
        rgb: true,
        indirect_spp: 0,
        max_bounces: 1,
        indirect_filter_radius: 0,
        ..cfg.render.clone()
    };
    let signal = render(&moved, &opts, seed, frame);
    (rgb_image(&signal, cfg.rgb_exposure), gt_depth(&signal))
}

/// The ground-truth z-depth through each pixel centre, metres (0 where nothing was hit).
fn gt_depth(signal: &SignalImage) -> Array2<f32> {
    Array2::from_shape_fn((signal.height, signal.width), |(y, x)| {
        signal.pixels[y * signal.width + x].gt_z as f32
    })
}

impl Sample {
    /// The sample as a frame of the capture format with its ground truth. It is aligned by
    /// construction, so its perturbation is recorded as exactly zero (training treats a frame
    /// without a known perturbation as unusable) and it has no flow file.
    pub fn into_capture_sample(self, index: u64, timestamp_ns: u64) -> dear_capture::Sample {
        dear_capture::Sample {
            frame: RgbdFrame::new(
                index,
                timestamp_ns,
                self.rgb,
                self.tof.amplitude,
                self.tof.depth,
            ),
            truth: GroundTruth {
                depth: Some(self.gt_depth),
                mask: Some(self.mask),
                flow: None,
                perturbation: Some(Calibration::default()),
            },
        }
    }
}
