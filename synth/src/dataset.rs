//! Writing simulated samples as capture directories (`dear-synth generate`).
//!
//! Amplitude is stored in sensor DN (see [`crate::sensor`]): with the default exposure a white
//! surface 1 m away reads `electrons_per_unit / gain = 5000` DN, so 0.3–7 m of 5–95 % albedo
//! spans ~10–55 000 DN of the 16-bit range. The gain and every other parameter are in
//! `capture.json`'s `source`.

use std::path::Path;

use anyhow::{Context, Result};
use dear_capture::{CaptureManifest, CaptureWriter, Intrinsics, Sample};
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::scene::{Camera, Scene, SceneConfig};
use crate::simulate::{simulate, SimConfig};

/// Frame interval written into the manifests, ns (30 fps).
pub const FRAME_INTERVAL_NS: u64 = 33_333_333;

/// Parameters of a generated dataset.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GenerateParams {
    pub width: usize,
    pub height: usize,
    pub hfov_deg: f64,
    pub count: usize,
    pub seed: u64,
    pub sim: SimConfig,
    pub scene: SceneConfig,
}

impl GenerateParams {
    pub fn camera(&self) -> Camera {
        Camera::from_hfov(self.width, self.height, self.hfov_deg)
    }

    /// Frame `i` of these settings (deterministic in `(seed, i)`), as [`generate`] writes it.
    pub fn sample(&self, i: u64) -> Sample {
        let scene = Scene::random(self.camera(), &self.scene, self.seed, i);
        simulate(&scene, &self.sim, self.seed, i).into_capture_sample(i, i * FRAME_INTERVAL_NS)
    }
}

/// The manifest of a capture made by this simulator, with `source` describing it.
pub fn manifest(camera: &Camera, sim: &SimConfig, source: serde_json::Value) -> CaptureManifest {
    let mut m = CaptureManifest::new(
        camera.width as u32,
        camera.height as u32,
        Intrinsics {
            fx: camera.fx as f32,
            fy: camera.fy as f32,
            cx: camera.cx as f32,
            cy: camera.cy as f32,
        },
    );
    m.modulation_frequencies_hz = sim.render.frequencies_hz.clone();
    m.source = json!({
        "generator": "dear-synth",
        "version": env!("CARGO_PKG_VERSION"),
        "amplitude_unit": "DN: 0.5·|(D0−D2, D1−D3)| of the 4 taps; electrons = DN · gain_e_per_dn",
        "amplitude_gain_e_per_dn": sim.sensor.gain_e_per_dn,
        "depth": "z-depth (plane-corrected from the radial ToF distance), metres in memory, mm on disk",
        "sim": sim,
        "details": source,
    });
    m
}

/// Renders `params.count` random scenes into a new capture directory `out`; `progress` is
/// called after each frame.
pub fn generate(
    out: &Path,
    params: &GenerateParams,
    mut progress: impl FnMut(usize),
) -> Result<()> {
    let camera = params.camera();
    let mut writer = CaptureWriter::create(
        out,
        manifest(
            &camera,
            &params.sim,
            json!({ "kind": "aligned", "params": params }),
        ),
    )
    .with_context(|| format!("creating {}", out.display()))?;
    for i in 0..params.count {
        let sample = params.sample(i as u64);
        writer
            .write_sample(&sample.frame, &sample.truth)
            .with_context(|| format!("writing frame {i}"))?;
        progress(i + 1);
    }
    writer.finish().context("writing capture.json")?;
    Ok(())
}
