//! Times the per-frame stages of the daemon's steady-state (`Cached`) frame path on frame 0 of
//! a capture, repeated: preprocessing, alignment (splat + flow), the two warps, confidence and
//! the edge check, and with `--full` the classical filter and the refine graph as well.
//!
//! ```text
//! cargo build --release -p dear-tools --bin stage_profile
//! target/release/stage_profile CAPTURE [BUNDLE] [--full] [--iters N] [--dump DIR]
//!     [--worker N] [--tract-threads N]
//! ```
//!
//! Prints the median (and minimum) milliseconds per stage. The bundle is needed (and loaded)
//! only with `--full` or `--worker`. `--worker N` also times, N times, the parts of the
//! background worker's measurement (`DearChain::measure`) on the same frame: the rough-flow
//! network, the robust least squares of its flow and the direct fit to the edges, and prints
//! the fitted calibrations' bit patterns (to check an optimisation leaves them unchanged).
//! `--tract-threads N` runs the refine graph on a pool of N threads (build with
//! `--features dear-pipeline/multithread`; without it the option has no effect). `--dump DIR`
//! writes every geometry stage's output for the frame as raw little-endian bytes (and the edge
//! check's numbers as bit patterns), so an optimisation can be checked to leave them
//! bit-identical with `cmp`; with `--full` also the classical filter's output and the refined
//! depth.
//! The dumped confidence is computed against the aligned (splatted) depth rather than the
//! refine graph's output, so the dump depends only on the geometry code.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, ensure, Context};
use clap::Parser;
use dear_capture::frame::Flow;
use dear_capture::Calibration;
use dear_capture::CaptureDir;
use dear_pipeline::align::StaticAligner;
use dear_pipeline::chain::confidence::confidence_into;
use dear_pipeline::chain::preprocess::{normalize_amplitude_into, rgb_planes_into};
use dear_pipeline::filter::ClassicalRefiner;
use dear_pipeline::geometry::{warp_depth, warp_depth_and_bilinear};
use dear_pipeline::model::{BundleRunner, ClassicalEstimate, ModelBundle, RunnerOptions};
use dear_pipeline::recalibration::direct::{estimate_calibration_direct, DirectFitParams};
use dear_pipeline::recalibration::residual::EdgeCheck;
use dear_pipeline::recalibration::Measurement;
use dear_pipeline::recalibration::RobustOptions;
use ndarray::Array2;

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

const NAMES: [&str; 7] = [
    "preprocess",
    "align(splat+flow)",
    "warp",
    "classical",
    "refine graph+tail",
    "confidence",
    "edge check",
];

/// Time per stage of the daemon's steady-state frame path on frame 0 of a capture.
#[derive(Debug, Parser)]
#[command(version)]
struct Cli {
    /// Capture directory (its frame 0 is profiled).
    capture: PathBuf,
    /// Model bundle directory (e.g. models/edge); needed by --full and --worker.
    bundle: Option<PathBuf>,
    /// Also time the classical filter and the refine graph (needs BUNDLE).
    #[arg(long)]
    full: bool,
    /// Timed repetitions of the frame (after three untimed ones).
    #[arg(long, default_value_t = 20)]
    iters: usize,
    /// Write every stage's output for the frame to this directory, as raw little-endian bytes.
    #[arg(long)]
    dump: Option<PathBuf>,
    /// Also time the background worker's measurement this many times (needs BUNDLE).
    #[arg(long, default_value_t = 0)]
    worker: usize,
    /// Threads of the refine graph's pool (only with --features dear-pipeline/multithread).
    #[arg(long, default_value_t = 1)]
    tract_threads: usize,
}

/// Writes `bytes` to `dir/name`.
fn write_bytes(dir: &Path, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
    let path = dir.join(name);
    std::fs::write(&path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

fn write_f32(dir: &Path, name: &str, a: &Array2<f32>) -> anyhow::Result<()> {
    let bytes: Vec<u8> = a.iter().flat_map(|v| v.to_le_bytes()).collect();
    write_bytes(dir, name, &bytes)
}

fn main() -> anyhow::Result<()> {
    let Cli {
        capture,
        bundle: bundle_path,
        full,
        iters,
        dump,
        worker,
        tract_threads,
    } = Cli::parse();
    let cap = CaptureDir::open(&capture)
        .with_context(|| format!("cannot open the capture {}", capture.display()))?;
    ensure!(
        !cap.is_empty(),
        "the capture {} has no frames",
        capture.display()
    );
    let f = cap
        .read_frame(0)
        .with_context(|| format!("cannot read frame 0 of the capture {}", capture.display()))?;
    let (h, w) = f.dim();
    // Before the measurement, so that a bad --dump fails at once.
    if let Some(dir) = &dump {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the dump directory {}", dir.display()))?;
    }
    let bundle = match (&bundle_path, full || worker > 0) {
        (Some(path), true) => Some(
            ModelBundle::load(path)
                .with_context(|| format!("cannot load the model bundle {}", path.display()))?,
        ),
        (None, true) => {
            bail!("--full and --worker need the model bundle: give BUNDLE after CAPTURE")
        }
        (_, false) => None,
    };
    // For the errors.
    let bundle_name = bundle_path
        .as_deref()
        .map(|p| p.display().to_string())
        .unwrap_or_default();
    let mut runner = match bundle.as_ref().filter(|_| full) {
        Some(b) => {
            let options = RunnerOptions {
                threads: tract_threads,
            };
            Some(
                BundleRunner::with_options(b, w, h, options).with_context(|| {
                    format!("cannot prepare the bundle {bundle_name}'s graphs for {w}x{h} frames")
                })?,
            )
        }
        None => None,
    };
    let calib = Calibration {
        tx: 6.0,
        ty: -2.0,
        cx: 3.0,
        cy: 1.0,
    };
    let mut aligner = StaticAligner::new(h, w);
    let mut drgb = Array2::<f32>::zeros((h, w));
    let mut dw = Array2::<f32>::zeros((h, w));
    let mut aw = Array2::<f32>::zeros((h, w));
    let mut amp = Array2::<f32>::zeros((h, w));
    let mut rgbp = [
        Array2::<f32>::zeros((h, w)),
        Array2::zeros((h, w)),
        Array2::zeros((h, w)),
    ];
    let mut scratch = Vec::new();
    let mut cl = ClassicalRefiner::default();
    let mut cd = Array2::<f32>::zeros((h, w));
    let mut cc = Array2::<u8>::zeros((h, w));
    let mut out = Array2::<f32>::zeros((h, w));
    let mut conf = Array2::<u8>::zeros((h, w));
    let mut ec = EdgeCheck::new(3);
    let mut t: Vec<Vec<f64>> = vec![Vec::new(); NAMES.len()];
    let mut edge = None;
    for i in 0..iters + 3 {
        let mut c = Instant::now();
        let mut lap = |k: usize, t: &mut Vec<Vec<f64>>| {
            let now = Instant::now();
            if i >= 3 {
                t[k].push((now - c).as_secs_f64() * 1e3);
            }
            c = now;
        };
        rgb_planes_into(f.rgb.view(), &mut rgbp);
        normalize_amplitude_into(
            f.amplitude.view(),
            f.depth.view(),
            99.0,
            &mut scratch,
            amp.view_mut(),
        );
        lap(0, &mut t);
        aligner.align_into(f.depth.view(), &calib, drgb.view_mut());
        lap(1, &mut t);
        warp_depth_and_bilinear(
            f.depth.view(),
            amp.view(),
            aligner.flow(),
            dw.view_mut(),
            aw.view_mut(),
        );
        lap(2, &mut t);
        let refined = match runner.as_mut() {
            Some(runner) => {
                cl.refine_into(dw.view(), f.rgb.view(), cd.view_mut(), cc.view_mut());
                lap(3, &mut t);
                let [r, g, b] = &rgbp;
                let rgb = runner
                    .refine_uses_rgb()
                    .then(|| [r.view(), g.view(), b.view()]);
                let classical = ClassicalEstimate {
                    depth: cd.view(),
                    confidence: cc.view(),
                };
                runner
                    .refine(aw.view(), dw.view(), rgb, Some(classical), out.view_mut())
                    .with_context(|| format!("the refine graph of {bundle_name} failed"))?;
                lap(4, &mut t);
                out.view()
            }
            None => drgb.view(),
        };
        confidence_into(dw.view(), refined, conf.view_mut());
        lap(5, &mut t);
        edge = ec.measure(f.rgb.view(), aw.view(), dw.view());
        lap(6, &mut t);
    }
    println!("{w}x{h}, {iters} iterations: median (min) ms");
    let mut total = 0.0;
    for (k, name) in NAMES.iter().enumerate() {
        let v = &mut t[k];
        if v.is_empty() {
            continue;
        }
        v.sort_by(f64::total_cmp);
        let median = v[v.len() / 2];
        if k != 3 && k != 4 {
            total += median;
        }
        println!("{name:20} {median:8.2} ({:.2})", v[0]);
    }
    println!("{:20} {total:8.2}", "geometry total");

    if let Some(bundle) = bundle.as_ref().filter(|_| worker > 0) {
        profile_worker(bundle, &bundle_name, &f, worker)?;
    }

    if let Some(dir) = dump {
        for (k, p) in rgbp.iter().enumerate() {
            write_f32(&dir, &format!("pre_rgb{k}.f32"), p)?;
        }
        write_f32(&dir, "pre_amp.f32", &amp)?;
        write_f32(&dir, "align_depth.f32", &drgb)?;
        write_f32(&dir, "align_flow_u.f32", &aligner.flow().u)?;
        write_f32(&dir, "align_flow_v.f32", &aligner.flow().v)?;
        write_f32(&dir, "warp_depth.f32", &dw)?;
        write_f32(&dir, "warp_amp.f32", &aw)?;
        if runner.is_some() {
            // With --full: the classical filter's output and the refiner's (graph and tail).
            write_f32(&dir, "classical_depth.f32", &cd)?;
            write_bytes(&dir, "classical_conf.u8", cc.as_slice().unwrap())?;
            write_f32(&dir, "refined_depth.f32", &out)?;
        }
        confidence_into(dw.view(), drgb.view(), conf.view_mut());
        write_bytes(&dir, "confidence.u8", conf.as_slice().unwrap())?;
        let edge = edge.map(|e| {
            let s = e.shift.map(|s| {
                (
                    s.du.to_bits(),
                    s.dv.to_bits(),
                    s.peak_ncc.to_bits(),
                    s.gain.to_bits(),
                    s.at_limit,
                )
            });
            (e.disagreement.to_bits(), s, format!("{e:?}"))
        });
        write_bytes(&dir, "edge.txt", format!("{edge:?}\n").as_bytes())?;
        println!("dumped to {}", dir.display());
    }
    Ok(())
}

/// Times the parts of the worker's measurement on `f`, `n` times, and prints the fits' bits.
/// `name` is the bundle's path, for the errors.
fn profile_worker(
    bundle: &ModelBundle,
    name: &str,
    f: &dear_capture::RgbdFrame,
    n: usize,
) -> anyhow::Result<()> {
    let (h, w) = f.dim();
    let mut runner = BundleRunner::new(bundle, w, h)
        .with_context(|| format!("cannot prepare the bundle {name}'s graphs for {w}x{h} frames"))?;
    let norm = bundle.normalisation();
    let mut rgbp = [
        Array2::<f32>::zeros((h, w)),
        Array2::zeros((h, w)),
        Array2::zeros((h, w)),
    ];
    let mut amp = Array2::<f32>::zeros((h, w));
    let mut scratch = Vec::new();
    let mut flow = Flow::zeros(h, w);
    let mut drgb = Array2::<f32>::zeros((h, w));
    let mut t = [Vec::new(), Vec::new(), Vec::new(), Vec::new()];
    let mut fits = None;
    for _ in 0..n {
        let c = Instant::now();
        rgb_planes_into(f.rgb.view(), &mut rgbp);
        normalize_amplitude_into(
            f.amplitude.view(),
            f.depth.view(),
            norm.amplitude_percentile,
            &mut scratch,
            amp.view_mut(),
        );
        let [r, g, b] = &rgbp;
        runner
            .flow([r.view(), g.view(), b.view()], amp.view(), &mut flow)
            .with_context(|| format!("the rough-flow graph of {name} failed"))?;
        let c0 = Instant::now();
        warp_depth(f.depth.view(), &flow, drgb.view_mut());
        let c1 = Instant::now();
        let fit = Measurement::from_flow(&flow, drgb.view(), RobustOptions::default(), 3.0)
            .with_context(|| format!("no calibration fits the rough flow of {name}"))?;
        let c2 = Instant::now();
        let direct = estimate_calibration_direct(
            f.rgb.view(),
            f.amplitude.view(),
            f.depth.view(),
            fit.calibration,
            &DirectFitParams::default(),
        );
        let c3 = Instant::now();
        for (k, (a, b)) in [(c, c0), (c0, c1), (c1, c2), (c2, c3)]
            .into_iter()
            .enumerate()
        {
            t[k].push((b - a).as_secs_f64() * 1e3);
        }
        fits = Some((fit.calibration, direct));
    }
    println!("worker measurement, {n} iterations: median (min) ms");
    for (name, v) in [
        "rough-flow network",
        "D_rgb (warp)",
        "least squares",
        "direct fit",
    ]
    .iter()
    .zip(&mut t)
    {
        v.sort_by(f64::total_cmp);
        println!("{name:20} {:8.2} ({:.2})", v[v.len() / 2], v[0]);
    }
    if let Some((lsq, direct)) = fits {
        let bits = |c: Calibration| [c.tx, c.ty, c.cx, c.cy].map(f32::to_bits);
        println!("least squares {lsq:?} bits {:x?}", bits(lsq));
        println!(
            "direct fit {:?} correlation {} fell back {} bits {:x?}",
            direct.calibration,
            direct.correlation,
            direct.fell_back,
            bits(direct.calibration)
        );
    }
    Ok(())
}
