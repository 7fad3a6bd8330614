//! Short videos with moving objects, a moving camera and drifting calibration
//! (`dear-synth sequence`): what the daemon's online recalibration is measured on.
//!
//! Motion: every object translates with a constant velocity (≤ 0.25 m/s, mostly sideways) and
//! spins (≤ 40°/s); the camera sways on low-frequency sinusoids (a few cm, ≤ 2°), as a hand-held
//! module does. The room stays put.
//!
//! Calibration drift (the true `perturbation` of each frame; each frame's RGB view is rendered
//! from the RGB camera of that calibration, `perturb::apply_rendered`): per axis,
//! `c(t) = Σ₂ Aᵢ sin(2π t / Tᵢ + φᵢ) + w(t)`, two sinusoids
//! (periods 1.5–6 s, amplitudes so the sum peaks at `c_amplitude_px`) plus a smoothed random
//! walk `w` (OIS wander), and `t(t) = t₀ + ṫ·t`, a slow linear drift from a random factory
//! baseline term `t₀`. `capture.json`'s `initial_calibration` is the perturbation of frame 0 —
//! the factory calibration the daemon starts from — and each frame entry carries its own.

use std::f64::consts::TAU;
use std::path::Path;

use anyhow::{Context, Result};
use dear_capture::{Calibration, CaptureWriter};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::dataset::manifest;
use crate::geometry::Pose;
use crate::math::{Mat3, Vec3};
use crate::perturb::{apply_rendered, RENDERED_VIEW};
use crate::rng::{keyed_rng, Stream};
use crate::scene::{Camera, Scene, SceneConfig};
use crate::simulate::{simulate, SimConfig};
use crate::texture::random_unit;

/// Parameters of a sequence.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SequenceParams {
    pub width: usize,
    pub height: usize,
    pub hfov_deg: f64,
    pub frames: usize,
    pub fps: f64,
    pub seed: u64,
    pub sim: SimConfig,
    pub scene: SceneConfig,
    pub drift: DriftParams,
    /// Write `.flow.flo` files. The flow is exactly `perturbation.flow_at(gt_depth)` on the
    /// valid pixels, so a capture that must stay small (`samples/demo`) can leave it out.
    pub write_flow: bool,
}

/// Calibration drift ranges.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DriftParams {
    /// Peak principal-point excursion of the sinusoids, px.
    pub c_amplitude_px: f64,
    /// Standard deviation of the random walk's increments per second, px.
    pub c_walk_px_per_sqrt_s: f64,
    /// The factory baseline term `t₀` is drawn from `U(±t0_fraction · f_x · baseline_m)`.
    pub baseline_m: f64,
    pub t0_fraction: f64,
    /// Largest drift rate of `t`, px·m per second.
    pub t_rate_pxm_per_s: f64,
}

impl Default for DriftParams {
    fn default() -> Self {
        DriftParams {
            c_amplitude_px: 4.0,
            c_walk_px_per_sqrt_s: 1.0,
            baseline_m: 0.02,
            t0_fraction: 0.3,
            t_rate_pxm_per_s: 0.5,
        }
    }
}

/// The drifting calibration of a sequence: a function of time.
#[derive(Debug, Clone)]
pub struct Drift {
    /// Per axis (x, y): two `(amplitude, period, phase)` sinusoids.
    waves: [[(f64, f64, f64); 2]; 2],
    /// Per axis: the smoothed random walk sampled at the frame times.
    walk: [Vec<f64>; 2],
    t0: [f64; 2],
    t_rate: [f64; 2],
    fps: f64,
}

impl Drift {
    /// Draws the drift of a sequence of `frames` frames.
    pub fn random(params: &DriftParams, fx: f64, frames: usize, fps: f64, seed: u64) -> Drift {
        let mut rng = keyed_rng(seed, Stream::Sequence, 0, 1);
        let mut waves = [[(0.0, 1.0, 0.0); 2]; 2];
        for axis in &mut waves {
            let split: f64 = rng.random_range(0.3..0.7);
            for (i, w) in axis.iter_mut().enumerate() {
                let share = if i == 0 { split } else { 1.0 - split };
                *w = (
                    params.c_amplitude_px * share,
                    rng.random_range(1.5..6.0),
                    rng.random_range(0.0..TAU),
                );
            }
        }
        // Random walk of the given diffusion, smoothed by an exponential filter (τ = 0.5 s)
        // so it has no frame-to-frame jitter.
        let dt = 1.0 / fps;
        let step = Normal::new(0.0, params.c_walk_px_per_sqrt_s * dt.sqrt()).expect("finite");
        let alpha = dt / (0.5 + dt);
        let mut walk = [Vec::with_capacity(frames), Vec::with_capacity(frames)];
        for w in &mut walk {
            let (mut raw, mut smooth) = (0.0, 0.0);
            for _ in 0..frames {
                raw += step.sample(&mut rng);
                smooth += alpha * (raw - smooth);
                w.push(smooth);
            }
        }
        let t_half = params.t0_fraction * fx * params.baseline_m;
        let mut sym = |h: f64| {
            if h > 0.0 {
                rng.random_range(-h..=h)
            } else {
                0.0
            }
        };
        let t0 = [sym(t_half), sym(t_half)];
        let t_rate = [sym(params.t_rate_pxm_per_s), sym(params.t_rate_pxm_per_s)];
        Drift {
            waves,
            walk,
            t0,
            t_rate,
            fps,
        }
    }

    /// The true calibration of frame `i`.
    pub fn at(&self, i: usize) -> Calibration {
        let time = i as f64 / self.fps;
        let c = |axis: usize| {
            self.waves[axis]
                .iter()
                .map(|&(a, period, phase)| a * (TAU * time / period + phase).sin())
                .sum::<f64>()
                + self.walk[axis].get(i).copied().unwrap_or(0.0)
        };
        let t = |axis: usize| self.t0[axis] + self.t_rate[axis] * time;
        Calibration {
            tx: t(0) as f32,
            ty: t(1) as f32,
            cx: c(0) as f32,
            cy: c(1) as f32,
        }
    }
}

/// Object and camera motion of a sequence.
#[derive(Debug, Clone)]
pub struct Motion {
    base: Scene,
    /// Per object: linear velocity (m/s), rotation axis and angular speed (rad/s).
    objects: Vec<(Vec3, Vec3, f64)>,
    /// Camera sway: per translation axis and per rotation axis, `(amplitude, angular freq,
    /// phase)`.
    cam_trans: [(f64, f64, f64); 3],
    cam_rot: [(f64, f64, f64); 2],
}

impl Motion {
    pub fn random(base: Scene, seed: u64) -> Motion {
        let mut rng = keyed_rng(seed, Stream::Sequence, 0, 2);
        let objects = base
            .objects
            .iter()
            .map(|o| {
                if matches!(o.kind, crate::scene::ObjectKind::Wall) {
                    return (Vec3::ZERO, Vec3::Z, 0.0);
                }
                let speed = rng.random_range(0.0..0.25);
                let heading = rng.random_range(0.0..TAU);
                // Mostly sideways: little motion along the viewing axis.
                let v = Vec3::new(heading.cos(), 0.6 * heading.sin(), 0.0) * speed
                    + Vec3::new(0.0, 0.0, rng.random_range(-0.05..0.05));
                (
                    v,
                    random_unit(&mut rng),
                    rng.random_range(0.0f64..40.0).to_radians(),
                )
            })
            .collect();
        let mut sway = |amp: f64| {
            (
                rng.random_range(0.3..1.0) * amp,
                TAU / rng.random_range(2.0..6.0),
                rng.random_range(0.0..TAU),
            )
        };
        let cam_trans = [sway(0.06), sway(0.03), sway(0.05)];
        let cam_rot = [sway(2f64.to_radians()), sway(2f64.to_radians())];
        Motion {
            base,
            objects,
            cam_trans,
            cam_rot,
        }
    }

    /// The scene at time `t` seconds.
    pub fn at(&self, t: f64) -> Scene {
        let mut scene = self.base.clone();
        for (o, &(v, axis, w)) in scene.objects.iter_mut().zip(&self.objects) {
            o.pose = Pose::new(Mat3::rotation(axis, w * t) * o.pose.rot, o.pose.pos + v * t);
        }
        let s = |(a, f, p): (f64, f64, f64)| a * (f * t + p).sin() - a * p.sin();
        let pos = Vec3::new(
            s(self.cam_trans[0]),
            s(self.cam_trans[1]),
            s(self.cam_trans[2]),
        );
        let rot = Mat3::from_euler(s(self.cam_rot[0]), s(self.cam_rot[1]), 0.0);
        scene.camera.pose = self.base.camera.pose.compose(&Pose::new(rot, pos));
        scene.rebuild();
        scene
    }
}

/// Renders a sequence into a new capture directory; `progress` after each frame.
pub fn generate_sequence(
    out: &Path,
    params: &SequenceParams,
    mut progress: impl FnMut(usize),
) -> Result<()> {
    let camera = Camera::from_hfov(params.width, params.height, params.hfov_deg);
    // Objects start at least 0.6 m away so their motion keeps them in front of the camera.
    let mut scene_cfg = params.scene.clone();
    scene_cfg.min_depth = scene_cfg.min_depth.max(0.6);
    let base = Scene::random(camera, &scene_cfg, params.seed, 0);
    let motion = Motion::random(base, params.seed);
    let drift = Drift::random(
        &params.drift,
        camera.fx,
        params.frames,
        params.fps,
        params.seed,
    );
    let mut m = manifest(
        &camera,
        &params.sim,
        json!({
            "kind": "sequence",
            "params": params,
            "drift_model": "c(t) = two sinusoids (periods 1.5–6 s) + smoothed random walk; t(t) = t0 + rate·t; initial_calibration = frame 0",
            "view": RENDERED_VIEW,
        }),
    );
    m.initial_calibration = drift.at(0);
    let mut writer =
        CaptureWriter::create(out, m).with_context(|| format!("creating {}", out.display()))?;
    let interval_ns = (1e9 / params.fps).round() as u64;
    for i in 0..params.frames {
        let scene = motion.at(i as f64 / params.fps);
        let sample = simulate(&scene, &params.sim, params.seed, i as u64);
        let aligned = sample.into_capture_sample(i as u64, i as u64 * interval_ns);
        let mut drifted = apply_rendered(&aligned, &scene, &params.sim, params.seed, drift.at(i))?;
        if !params.write_flow {
            drifted.truth.flow = None;
        }
        writer
            .write_sample(&drifted.frame, &drifted.truth)
            .with_context(|| format!("writing frame {i}"))?;
        progress(i + 1);
    }
    writer.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drift_is_smooth_and_bounded() {
        let d = Drift::random(&DriftParams::default(), 450.0, 300, 30.0, 5);
        let mut prev = d.at(0);
        for i in 1..300 {
            let c = d.at(i);
            // OIS-like: a few px in all, well under a px per frame.
            assert!(c.cx.abs() < 8.0 && c.cy.abs() < 8.0);
            assert!((c.cx - prev.cx).abs() < 0.5 && (c.cy - prev.cy).abs() < 0.5);
            assert!((c.tx - prev.tx).abs() < 0.05);
            prev = c;
        }
    }
}
