//! `dear-synth`: the ToF simulator's command line. See `synth/README.md`.

#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use dear_capture::CaptureDir;
use indicatif::{ProgressBar, ProgressStyle};

use dear_synth::dataset::{generate, GenerateParams};
use dear_synth::family::{shard_dir_name, Family};
use dear_synth::perturb::{perturb_dir, PerturbMode, ViewSource};
use dear_synth::preview::panel;
use dear_synth::scene::SceneConfig;
use dear_synth::sequence::{generate_sequence, DriftParams, SequenceParams};
use dear_synth::simulate::SimConfig;

#[derive(Parser)]
#[command(
    name = "dear-synth",
    version,
    about = "AMCW ToF simulator and dataset generator"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render aligned random scenes into a capture directory.
    Generate {
        #[arg(long, default_value_t = 10)]
        count: usize,
        #[command(flatten)]
        common: Common,
    },
    /// Render a family of sensor and scene settings (synth/src/family.rs) as shards: one
    /// capture directory per draw of the settings, `OUT/shard-NNN`, aligned frames.
    Family {
        #[arg(long, value_enum)]
        family: Family,
        #[arg(long, default_value_t = 10)]
        shards: usize,
        #[arg(long, default_value_t = 100)]
        frames_per_shard: usize,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        #[arg(long)]
        out: PathBuf,
        #[arg(long, default_value_t = 320)]
        width: usize,
        #[arg(long, default_value_t = 240)]
        height: usize,
    },
    /// Write the daemon's classical refiner output beside every frame of a capture
    /// (`frames/NNNNNN.classical.png`): the extra training input of `hybrid` refiners.
    Classical {
        /// Capture directories (e.g. every shard of a family).
        #[arg(long, required = true, num_args = 1..)]
        capture: Vec<PathBuf>,
    },
    /// Misalign an aligned capture: new RGB view, GT depth, mask and flow per frame.
    Perturb {
        #[arg(long = "in")]
        input: PathBuf,
        #[arg(long)]
        out: PathBuf,
        /// σ in px of the N(0, σ) protocol (see synth/README.md for how it applies to c and t).
        #[arg(long, default_value_t = 4.0, conflicts_with = "uniform")]
        sigma: f64,
        /// Use the paper's uniform training ranges instead (c ±2.5 % of the size, t ±30 % of
        /// f·baseline).
        #[arg(long)]
        uniform: bool,
        /// Largest RGB–ToF baseline of the module, metres (for --uniform).
        #[arg(long, default_value_t = 0.02)]
        baseline: f64,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// How the RGB view is made: rendered again from each frame's scene (captures this
        /// simulator wrote) or splatted from the aligned RGB (any capture with ground truth;
        /// leaves disocclusions black).
        #[arg(long, value_enum, default_value_t = ViewSource::Render)]
        view: ViewSource,
    },
    /// Render a moving scene with drifting calibration.
    Sequence {
        #[arg(long, default_value_t = 60)]
        frames: usize,
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        /// Peak principal-point drift of the sinusoids, px.
        #[arg(long, default_value_t = 4.0)]
        drift_px: f64,
        /// Leave out the .flow.flo files (the flow is perturbation.flow_at(gt)); keeps a
        /// committed sample small.
        #[arg(long)]
        no_flow: bool,
        #[command(flatten)]
        common: Common,
    },
    /// Write the RGB | amplitude | ToF depth | ground truth | error panel of one frame.
    Preview {
        #[arg(long)]
        capture: PathBuf,
        /// Position of the frame in the capture.
        #[arg(long, default_value_t = 0)]
        frame: usize,
        #[arg(long)]
        out: PathBuf,
        /// Colour-scale limit of the error map, metres.
        #[arg(long, default_value_t = 0.1)]
        error_range: f32,
        /// Scale factor of each panel.
        #[arg(long, default_value_t = 1.0)]
        scale: f64,
    },
}

/// Options shared by the rendering commands.
#[derive(Args)]
struct Common {
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[arg(long)]
    out: PathBuf,
    #[arg(long, default_value_t = 640)]
    width: usize,
    #[arg(long, default_value_t = 480)]
    height: usize,
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 70.0)]
    hfov: f64,
    /// Primary samples per pixel.
    #[arg(long, default_value_t = 4)]
    spp: usize,
    /// Indirect (MPI) paths per pixel.
    #[arg(long, default_value_t = 2)]
    indirect_spp: usize,
    /// Longest path in surface reflections (1 = no MPI).
    #[arg(long, default_value_t = 3)]
    bounces: usize,
    /// Modulation frequency in MHz; repeat for multi-frequency unwrapping.
    #[arg(long = "freq-mhz", default_values_t = [20.0])]
    freq_mhz: Vec<f64>,
    /// Disable shot and read noise.
    #[arg(long)]
    no_noise: bool,
    /// Electrons per tap from a white surface at 1 m (exposure).
    #[arg(long, default_value_t = 20_000.0)]
    electrons: f64,
    /// Invalidate pixels below this amplitude (DN); 0 keeps all.
    #[arg(long, default_value_t = 8.0)]
    min_amplitude: f64,
    /// Horizontal offset of the ToF illuminator from the camera centre, millimetres.
    #[arg(long, default_value_t = 0.0)]
    light_offset_mm: f64,
    #[arg(long, default_value_t = 5)]
    min_objects: usize,
    #[arg(long, default_value_t = 25)]
    max_objects: usize,
}

impl Common {
    fn sim(&self) -> SimConfig {
        let mut sim = SimConfig::default();
        sim.render.spp = self.spp;
        sim.render.indirect_spp = self.indirect_spp;
        sim.render.max_bounces = self.bounces;
        sim.render.frequencies_hz = self.freq_mhz.iter().map(|f| f * 1e6).collect();
        sim.sensor.noise = !self.no_noise;
        sim.sensor.electrons_per_unit = self.electrons;
        sim.sensor.min_amplitude_dn = self.min_amplitude;
        sim
    }

    fn scene(&self) -> SceneConfig {
        SceneConfig {
            min_objects: self.min_objects,
            max_objects: self.max_objects,
            light_offset: dear_synth::math::Vec3::new(self.light_offset_mm * 1e-3, 0.0, 0.0),
            ..SceneConfig::default()
        }
    }
}

fn bar(len: usize, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len as u64);
    pb.set_style(
        ProgressStyle::with_template(
            "{msg} [{bar:30}] {pos}/{len} {per_sec} elapsed {elapsed_precise} eta {eta_precise}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    pb.set_message(what.to_string());
    pb
}

fn report(what: &str, n: usize, start: Instant, w: usize, h: usize) {
    let s = start.elapsed().as_secs_f64();
    eprintln!(
        "{what}: {n} frames at {w}×{h} in {s:.2} s = {:.3} samples/s ({} threads)",
        n as f64 / s,
        rayon::current_num_threads()
    );
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Generate { count, common } => {
            let params = GenerateParams {
                width: common.width,
                height: common.height,
                hfov_deg: common.hfov,
                count,
                seed: common.seed,
                sim: common.sim(),
                scene: common.scene(),
            };
            let pb = bar(count, "generate");
            let start = Instant::now();
            generate(&common.out, &params, |i| pb.set_position(i as u64))?;
            pb.finish();
            report("generate", count, start, common.width, common.height);
        }
        Command::Family {
            family,
            shards,
            frames_per_shard,
            seed,
            out,
            width,
            height,
        } => {
            let total = shards * frames_per_shard;
            let pb = bar(total, family.name());
            let start = Instant::now();
            for shard in 0..shards {
                let params = family.draw(seed, shard as u64, frames_per_shard, width, height);
                let dir = out.join(shard_dir_name(shard));
                generate(&dir, &params, |i| {
                    pb.set_position((shard * frames_per_shard + i) as u64)
                })
                .with_context(|| format!("{} shard {shard}", family.name()))?;
            }
            pb.finish();
            report(family.name(), total, start, width, height);
        }
        Command::Perturb {
            input,
            out,
            sigma,
            uniform,
            baseline,
            seed,
            view,
        } => {
            let mode = if uniform {
                PerturbMode::paper_uniform(baseline)
            } else {
                PerturbMode::Gaussian { sigma_px: sigma }
            };
            let pb = bar(0, "perturb");
            perturb_dir(&input, &out, &mode, seed, view, |i, n| {
                pb.set_length(n as u64);
                pb.set_position(i as u64);
            })?;
            pb.finish();
        }
        Command::Sequence {
            frames,
            fps,
            drift_px,
            no_flow,
            common,
        } => {
            let params = SequenceParams {
                width: common.width,
                height: common.height,
                hfov_deg: common.hfov,
                frames,
                fps,
                seed: common.seed,
                sim: common.sim(),
                scene: common.scene(),
                drift: DriftParams {
                    c_amplitude_px: drift_px,
                    ..DriftParams::default()
                },
                write_flow: !no_flow,
            };
            let pb = bar(frames, "sequence");
            let start = Instant::now();
            generate_sequence(&common.out, &params, |i| pb.set_position(i as u64))?;
            pb.finish();
            report("sequence", frames, start, common.width, common.height);
        }
        Command::Classical { capture } => {
            let start = Instant::now();
            let mut total = 0;
            for dir in &capture {
                let frames = CaptureDir::open(dir)
                    .with_context(|| format!("opening {}", dir.display()))?
                    .len();
                let pb = bar(frames, &format!("classical {}", dir.display()));
                total += dear_synth::classical::write_classical_planes(dir, |n| {
                    pb.set_position(n as u64)
                })?;
                pb.finish();
            }
            eprintln!(
                "classical: {total} frames in {:.1} s",
                start.elapsed().as_secs_f64()
            );
        }
        Command::Preview {
            capture,
            frame,
            out,
            error_range,
            scale,
        } => {
            let dir = CaptureDir::open(&capture)
                .with_context(|| format!("opening {}", capture.display()))?;
            let sample = dir.read_sample(frame)?;
            panel(&sample, error_range, scale)
                .save(&out)
                .with_context(|| format!("writing {}", out.display()))?;
            eprintln!("wrote {}", out.display());
        }
    }
    Ok(())
}
