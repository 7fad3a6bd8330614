//! Misaligned samples with ground-truth flow, from aligned ones (`dear-synth perturb`).
//!
//! A perturbation `P = (t_x, t_y, c_x, c_y)` means: in the new RGB view, RGB pixel `p` sees ToF
//! pixel `p + W(p)` with `W(p) = (t_x / z(p) + c_x, t_y / z(p) + c_y)` (`dear_pipeline`'s flow
//! convention). The ToF amplitude and depth stay as rendered; the RGB image, the ground-truth
//! depth and the mask are replaced by the RGB camera's view, and the flow is written as
//! `.flow.flo`. The view is rendered again from the scene ([`apply_rendered`], the default for
//! captures this simulator wrote: what a camera sees, no holes) or splatted from the aligned
//! RGB with a z-buffer ([`apply`], `dear_pipeline::geometry::synthesize_view`: disocclusions
//! and borders stay black, a contour cue no camera gives).
//!
//! How σ is applied (the Table 1 protocol, "perturbations ~ N(0, σ)"), per frame, independently
//! per axis:
//! - `c_x, c_y ~ N(0, σ)` px;
//! - `t_x = z̃ · a`, `t_y = z̃ · b` with `a, b ~ N(0, σ)` px and `z̃` the median valid
//!   ground-truth depth of the frame (m), i.e. the baseline term `t/z` has standard deviation σ
//!   px at the median depth of the scene.
//!
//! The two terms are independent, so at the median depth the flow of one axis has standard
//! deviation `σ·√2`. The uniform training ranges (the paper's augmentation) are
//! `c_x ~ U(±2.5 % · W)`, `c_y ~ U(±2.5 % · H)` px and `t_x, t_y ~ U(±30 % · f_x·B)` px·m, where
//! `B` is the module's largest RGB–ToF baseline (default 2 cm).

use std::path::Path;

use anyhow::{ensure, Context, Result};
use dear_capture::{Calibration, CaptureDir, CaptureWriter, Flow, GroundTruth, RgbdFrame, Sample};
use dear_pipeline::geometry::{synthesize_view, SynthesizedView};
use ndarray::Array2;
use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::dataset::GenerateParams;
use crate::rng::{keyed_rng, Stream};
use crate::scene::Scene;
use crate::simulate::{render_rgb_view, SimConfig};

/// How perturbations are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "mode", rename_all = "snake_case")]
pub enum PerturbMode {
    /// Test sets: `c ~ N(0, σ)` px, `t = z̃·N(0, σ)` px·m (see the module documentation).
    Gaussian { sigma_px: f64 },
    /// Training ranges: `c ~ U(±c_fraction · size)`, `t ~ U(±t_fraction · f_x · baseline_m)`.
    Uniform {
        c_fraction: f64,
        t_fraction: f64,
        baseline_m: f64,
    },
}

impl PerturbMode {
    /// The paper's training ranges with a module baseline of `baseline_m` metres.
    pub fn paper_uniform(baseline_m: f64) -> Self {
        PerturbMode::Uniform {
            c_fraction: 0.025,
            t_fraction: 0.30,
            baseline_m,
        }
    }
}

/// Median of the valid (`> 0`) values, the upper middle one for an even count
/// ([`dear_stats::upper_median`]: the perturbation's scale, not a reported figure; a data set's
/// perturbations depend on it); `None` if there are none.
pub fn median_valid(depth: &ndarray::Array2<f32>) -> Option<f64> {
    let mut v: Vec<f32> = depth
        .iter()
        .copied()
        .filter(|&z| dear_capture::is_valid_depth(z))
        .collect();
    dear_stats::upper_median(&mut v).map(f64::from)
}

/// Draws the perturbation of frame `frame` (keyed by `(seed, frame)`).
pub fn draw(
    mode: &PerturbMode,
    seed: u64,
    frame: u64,
    width: usize,
    height: usize,
    fx: f64,
    median_depth: f64,
) -> Calibration {
    let mut rng = keyed_rng(seed, Stream::Perturbation, frame, 0);
    match *mode {
        PerturbMode::Gaussian { sigma_px } => {
            let n = Normal::new(0.0, sigma_px).expect("finite σ");
            let cx = n.sample(&mut rng);
            let cy = n.sample(&mut rng);
            let tx = median_depth * n.sample(&mut rng);
            let ty = median_depth * n.sample(&mut rng);
            Calibration {
                tx: tx as f32,
                ty: ty as f32,
                cx: cx as f32,
                cy: cy as f32,
            }
        }
        PerturbMode::Uniform {
            c_fraction,
            t_fraction,
            baseline_m,
        } => {
            let mut sym = |half: f64| {
                if half > 0.0 {
                    rng.random_range(-half..=half)
                } else {
                    0.0
                }
            };
            let t_half = t_fraction * fx * baseline_m;
            let cx = sym(c_fraction * width as f64);
            let cy = sym(c_fraction * height as f64);
            let tx = sym(t_half);
            let ty = sym(t_half);
            Calibration {
                tx: tx as f32,
                ty: ty as f32,
                cx: cx as f32,
                cy: cy as f32,
            }
        }
    }
}

/// Misaligns an aligned frame by `p`: RGB, ground truth and mask move to the synthesized view;
/// ToF amplitude and depth stay. The sample must have ground-truth depth.
pub fn apply(sample: &Sample, p: Calibration) -> Result<Sample> {
    let frame = &sample.frame;
    let gt = sample
        .truth
        .depth
        .as_ref()
        .context("frame has no ground-truth depth to splat")?;
    let view = synthesize_view(frame.rgb.view(), gt.view(), &p);
    Ok(seen_through(frame, view, p))
}

/// `frame` misaligned by `p`: the RGB image, ground truth and mask of the RGB camera's `view`,
/// the ToF amplitude and depth of `frame`.
fn seen_through(frame: &RgbdFrame, view: SynthesizedView, p: Calibration) -> Sample {
    Sample {
        frame: RgbdFrame::new(
            frame.index,
            frame.timestamp_ns,
            view.rgb,
            frame.amplitude.clone(),
            frame.depth.clone(),
        ),
        truth: GroundTruth {
            depth: Some(view.depth),
            mask: Some(view.valid),
            flow: Some(view.flow),
            perturbation: Some(p),
        },
    }
}

/// How far (relative) the ToF view's ground truth at `q + W(q)` may lie from the RGB view's at
/// `q` for the point to count as seen by both cameras: a z-buffer test's tolerance, loose
/// enough for the nearest-pixel lookup on a slanted surface (4 % is ~25° of slant over one
/// pixel at 320 px across 70°), tight enough to reject a surface in front of it.
const COVISIBLE_REL_TOLERANCE: f32 = 0.04;

/// Misaligns an aligned simulated frame by `p` the way a camera would see it: the RGB image
/// and its ground-truth depth are rendered again from the RGB camera of calibration `p`
/// ([`render_rgb_view`]), so the view has no holes; ToF amplitude and depth stay. A pixel is
/// valid (mask, flow) where both cameras see the same point: its ToF pixel `q + W(q)` lies
/// inside the image and the ToF view's ground truth there agrees with this view's depth.
pub fn apply_rendered(
    sample: &Sample,
    scene: &Scene,
    sim: &SimConfig,
    seed: u64,
    p: Calibration,
) -> Result<Sample> {
    let frame = &sample.frame;
    let tof_gt = sample
        .truth
        .depth
        .as_ref()
        .context("frame has no ground-truth depth")?;
    let (h, w) = frame.dim();
    ensure!(
        (scene.camera.height, scene.camera.width) == (h, w),
        "the scene's camera is {}×{} but the frame is {w}×{h}",
        scene.camera.width,
        scene.camera.height
    );
    let (rgb, depth) = render_rgb_view(scene, sim, seed, frame.index, &p);
    let mut flow = Flow::zeros(h, w);
    let mut valid = Array2::from_elem((h, w), false);
    for ((y, x), &z) in depth.indexed_iter() {
        let Some((fu, fv)) = p.flow_at(z) else {
            continue;
        };
        flow.u[(y, x)] = fu;
        flow.v[(y, x)] = fv;
        let (qx, qy) = ((x as f32 + fu).round(), (y as f32 + fv).round());
        if qx < 0.0 || qy < 0.0 || qx > (w - 1) as f32 || qy > (h - 1) as f32 {
            continue;
        }
        let zt = tof_gt[(qy as usize, qx as usize)];
        valid[(y, x)] =
            dear_capture::is_valid_depth(zt) && (zt - z).abs() <= COVISIBLE_REL_TOLERANCE * z;
    }
    let view = SynthesizedView {
        rgb,
        depth,
        flow,
        valid,
    };
    Ok(seen_through(frame, view, p))
}

/// `capture.json`'s `source.view` (or `source.details.view` of a sequence) for views made by
/// [`apply_rendered`]; `scripts/results.sh` looks for it to tell such sets from splatted ones.
pub const RENDERED_VIEW: &str = "rendered from the RGB camera of each frame's calibration";

/// How `perturb_dir` makes the RGB view of a misaligned frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ViewSource {
    /// Render it again from the scene (captures written by `dear-synth generate` / `family`,
    /// whose `capture.json` holds what drew each scene): what a camera sees, no holes.
    Render,
    /// Splat the aligned RGB with its ground-truth depth ([`synthesize_view`]): for any
    /// capture with ground truth; disocclusions and borders stay black.
    Splat,
}

/// The parameters that drew an aligned capture's scenes, when `dear-synth` wrote it.
fn generate_params(manifest: &dear_capture::CaptureManifest) -> Option<GenerateParams> {
    let details = manifest.source.get("details")?;
    if details.get("kind")?.as_str()? != "aligned" {
        return None;
    }
    serde_json::from_value(details.get("params")?.clone()).ok()
}

/// Reads the aligned capture `input` and writes its misaligned version to `output`.
pub fn perturb_dir(
    input: &Path,
    output: &Path,
    mode: &PerturbMode,
    seed: u64,
    view: ViewSource,
    mut progress: impl FnMut(usize, usize),
) -> Result<()> {
    let dir = CaptureDir::open(input).with_context(|| format!("opening {}", input.display()))?;
    let src = dir.manifest().clone();
    let scenes = match view {
        ViewSource::Splat => None,
        ViewSource::Render => Some(generate_params(&src).with_context(|| {
            format!(
                "{}: capture.json has no dear-synth scene parameters (source.details.params of \
                 kind \"aligned\"), so its views cannot be rendered again; use --view splat",
                input.display()
            )
        })?),
    };
    ensure!(
        src.frames
            .iter()
            .all(|f| f.perturbation.is_none_or(|p| p == Calibration::default())),
        "{} is already misaligned (frames carry non-zero perturbations)",
        input.display()
    );
    let mut manifest = src.clone();
    manifest.source = json!({
        "generator": "dear-synth perturb",
        "from": input.display().to_string(),
        "perturbation": mode,
        "perturbation_seed": seed,
        "view": match view {
            ViewSource::Render => RENDERED_VIEW,
            ViewSource::Splat => "splatted from the aligned RGB with the ground-truth depth",
        },
        "sigma_definition": "c_x, c_y ~ N(0, σ) px; t_x, t_y = median valid GT depth · N(0, σ) px·m (each axis independent)",
        "aligned_source": src.source,
    });
    let mut writer = CaptureWriter::create(output, manifest)
        .with_context(|| format!("creating {}", output.display()))?;
    let n = dir.len();
    for pos in 0..n {
        let sample = dir
            .read_sample(pos)
            .with_context(|| format!("reading frame {pos}"))?;
        let frame = &sample.frame;
        let gt = sample
            .truth
            .depth
            .as_ref()
            .with_context(|| format!("frame {pos} has no ground truth"))?;
        let median = median_valid(gt).unwrap_or(1.0);
        let (h, w) = frame.dim();
        let p = draw(
            mode,
            seed,
            frame.index,
            w,
            h,
            src.intrinsics.fx as f64,
            median,
        );
        let perturbed = match &scenes {
            None => apply(&sample, p)?,
            Some(params) => {
                let scene = Scene::random(params.camera(), &params.scene, params.seed, frame.index);
                apply_rendered(&sample, &scene, &params.sim, params.seed, p)
                    .with_context(|| format!("frame {pos}"))?
            }
        };
        writer.write_sample(&perturbed.frame, &perturbed.truth)?;
        progress(pos + 1, n);
    }
    writer.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaussian_draws_have_the_defined_spread() {
        let mode = PerturbMode::Gaussian { sigma_px: 4.0 };
        let n = 4000;
        let (mut scx, mut stz) = (0.0, 0.0);
        for i in 0..n {
            let p = draw(&mode, 9, i, 640, 480, 450.0, 2.0);
            scx += (p.cx as f64).powi(2);
            // t / z̃ is N(0, σ).
            stz += (p.tx as f64 / 2.0).powi(2);
        }
        let (sc, st) = ((scx / n as f64).sqrt(), (stz / n as f64).sqrt());
        assert!(
            (sc - 4.0).abs() < 0.2 && (st - 4.0).abs() < 0.2,
            "{sc} {st}"
        );
    }

    #[test]
    fn uniform_draws_stay_in_the_paper_ranges() {
        let mode = PerturbMode::paper_uniform(0.02);
        for i in 0..1000 {
            let p = draw(&mode, 1, i, 640, 480, 450.0, 2.0);
            assert!(p.cx.abs() <= 16.0 && p.cy.abs() <= 12.0);
            assert!(p.tx.abs() <= 0.3 * 450.0 * 0.02 + 1e-4);
        }
    }
}
