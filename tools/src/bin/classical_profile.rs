//! Times each stage of the classical refiner (`ClassicalRefiner::refine_into`) on a few frames
//! of a capture, calling the stage functions directly, and the whole `refine_into` as well.
//!
//! ```text
//! cargo build --release -p dear-tools --bin classical_profile
//! target/release/classical_profile CAPTURE [--frames N] [--iters N]
//!     [--dump DIR] [--check DIR]
//! ```
//!
//! Prints the median (and minimum) milliseconds per stage over all frames and repetitions.
//! `--dump DIR` writes the refiner's output for each frame as raw little-endian bytes
//! (`depth_NNN.f32`, `conf_NNN.u8`); `--check DIR` compares the output with such a dump and
//! reports the number of differing pixels and the largest depth difference, so an
//! optimisation can be checked to leave the output bit-identical.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{ensure, Context};
use clap::Parser;
use dear_capture::CaptureDir;
use dear_pipeline::filter::domain_transform::{domain_transform_masked, DomainTransformScratch};
use dear_pipeline::filter::fill::fill_holes;
use dear_pipeline::filter::flying::remove_flying_pixels;
use dear_pipeline::filter::outlier::reject_outliers;
use dear_pipeline::filter::snap::snap_to_surface;
use dear_pipeline::filter::{ClassicalParams, ClassicalRefiner};
use ndarray::Array2;

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

const NAMES: [&str; 7] = [
    "flying",
    "snap (flying)",
    "outlier",
    "fill",
    "domain transform",
    "snap (surface)",
    "refine_into (all)",
];

/// Time per stage of the classical refiner on the first frames of a capture.
#[derive(Debug, Parser)]
#[command(version)]
struct Cli {
    /// Capture directory (its first --frames frames are profiled).
    capture: PathBuf,
    /// Frames profiled, from the capture's first.
    #[arg(long, default_value_t = 4)]
    frames: usize,
    /// Timed repetitions per frame (after one untimed warm-up; at least one is run).
    #[arg(long, default_value_t = 10)]
    iters: usize,
    /// Write the refiner's output for each frame to this directory (depth_NNN.f32, conf_NNN.u8).
    #[arg(long)]
    dump: Option<PathBuf>,
    /// Compare the refiner's output with a --dump written earlier to this directory.
    #[arg(long)]
    check: Option<PathBuf>,
}

fn median_min(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[0])
}

fn timed(f: impl FnOnce()) -> f64 {
    let t = Instant::now();
    f();
    t.elapsed().as_secs_f64() * 1e3
}

fn dump_paths(dir: &Path, i: usize) -> (PathBuf, PathBuf) {
    (
        dir.join(format!("depth_{i:03}.f32")),
        dir.join(format!("conf_{i:03}.u8")),
    )
}

/// Reads one file of a `--check` dump.
fn read_dump(path: &Path) -> anyhow::Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("cannot read the dump file {}", path.display()))
}

fn main() -> anyhow::Result<()> {
    let Cli {
        capture,
        frames,
        iters,
        dump,
        check,
    } = Cli::parse();
    let cap = CaptureDir::open(&capture)
        .with_context(|| format!("cannot open the capture {}", capture.display()))?;
    ensure!(frames >= 1, "--frames must be at least 1");
    ensure!(
        frames <= cap.len(),
        "--frames {frames}: the capture {} has only {} frames",
        capture.display(),
        cap.len()
    );
    let p = ClassicalParams::default();
    let mut refiner = ClassicalRefiner::new(p);
    let mut times: Vec<Vec<f64>> = vec![Vec::new(); NAMES.len()];
    let (mut differing, mut max_diff) = (0usize, 0.0f32);
    if let Some(dir) = &dump {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the dump directory {}", dir.display()))?;
    }
    for i in 0..frames {
        let f = cap.read_frame(i).with_context(|| {
            format!("cannot read frame {i} of the capture {}", capture.display())
        })?;
        let (depth, rgb) = (f.depth.view(), f.rgb.view());
        let (h, w) = depth.dim();
        let z = || Array2::<f32>::zeros((h, w));
        let b = || Array2::from_elem((h, w), false);
        let (mut cleaned, mut snapped_in, mut outlier_free) = (z(), z(), z());
        let (mut filled, mut smoothed, mut surfaced) = (z(), z(), z());
        let (mut flying_snapped, mut replaced, mut surface_snapped) = (b(), b(), b());
        let mut fill_conf = Array2::<u8>::zeros((h, w));
        let mut dts = DomainTransformScratch::new(h, w);
        let (mut out, mut conf) = (z(), Array2::<u8>::zeros((h, w)));
        for it in 0..=iters.max(1) {
            let t = [
                timed(|| {
                    remove_flying_pixels(depth, p.flying_rel, p.flying_abs_m, cleaned.view_mut())
                }),
                timed(|| {
                    snap_to_surface(
                        depth,
                        cleaned.view(),
                        p.flying_snap_radius,
                        snapped_in.view_mut(),
                        flying_snapped.view_mut(),
                    )
                }),
                timed(|| {
                    reject_outliers(
                        snapped_in.view(),
                        outlier_free.view_mut(),
                        replaced.view_mut(),
                    )
                }),
                timed(|| {
                    fill_holes(
                        outlier_free.view(),
                        rgb,
                        &p.fill,
                        filled.view_mut(),
                        fill_conf.view_mut(),
                    )
                }),
                timed(|| {
                    domain_transform_masked(
                        rgb,
                        filled.view(),
                        &p.smoothing,
                        &mut dts,
                        smoothed.view_mut(),
                    )
                }),
                timed(|| {
                    snap_to_surface(
                        smoothed.view(),
                        filled.view(),
                        p.surface_radius,
                        surfaced.view_mut(),
                        surface_snapped.view_mut(),
                    )
                }),
                timed(|| refiner.refine_into(depth, rgb, out.view_mut(), conf.view_mut())),
            ];
            // The first repetition warms caches and the thread pool.
            if it > 0 {
                for (v, t) in times.iter_mut().zip(t) {
                    v.push(t);
                }
            }
        }
        let depth_bytes: Vec<u8> = out.iter().flat_map(|v| v.to_le_bytes()).collect();
        let conf_bytes: Vec<u8> = conf.iter().copied().collect();
        if let Some(dir) = &dump {
            let (dp, cp) = dump_paths(dir, i);
            std::fs::write(&dp, &depth_bytes)
                .with_context(|| format!("cannot write {}", dp.display()))?;
            std::fs::write(&cp, &conf_bytes)
                .with_context(|| format!("cannot write {}", cp.display()))?;
        }
        if let Some(dir) = &check {
            let (dp, cp) = dump_paths(dir, i);
            let ref_depth = read_dump(&dp)?;
            let ref_conf = read_dump(&cp)?;
            for (path, found, expected) in [
                (&dp, ref_depth.len(), depth_bytes.len()),
                (&cp, ref_conf.len(), conf_bytes.len()),
            ] {
                ensure!(
                    found == expected,
                    "frame {i}: size differs: {} has {found} bytes, the output {expected}",
                    path.display()
                );
            }
            for (k, (a, b)) in ref_depth
                .chunks_exact(4)
                .zip(depth_bytes.chunks_exact(4))
                .enumerate()
            {
                let (a, b) = (
                    f32::from_le_bytes(a.try_into().unwrap()),
                    f32::from_le_bytes(b.try_into().unwrap()),
                );
                if a.to_bits() != b.to_bits() || ref_conf[k] != conf_bytes[k] {
                    differing += 1;
                    max_diff = max_diff.max((a - b).abs());
                }
            }
        }
    }
    println!(
        "{} frames x {iters} repetitions, {} threads",
        frames,
        rayon::current_num_threads()
    );
    for (name, v) in NAMES.iter().zip(&mut times) {
        let (med, min) = median_min(v);
        println!("{name:>20}: median {med:7.2} ms  min {min:7.2} ms");
    }
    if check.is_some() {
        println!(
            "check: {differing} pixels differ from the dump (depth or confidence), \
             largest depth difference {max_diff:e} m"
        );
    }
    Ok(())
}
