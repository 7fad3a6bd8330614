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

fn main() {
    let mut args = std::env::args().skip(1);
    let (mut positional, mut frames, mut iters) = (Vec::new(), 4usize, 10usize);
    let (mut dump, mut check) = (None, None);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--frames" => frames = args.next().unwrap().parse().unwrap(),
            "--iters" => iters = args.next().unwrap().parse().unwrap(),
            "--dump" => dump = Some(PathBuf::from(args.next().unwrap())),
            "--check" => check = Some(PathBuf::from(args.next().unwrap())),
            _ => positional.push(a),
        }
    }
    let cap = CaptureDir::open(&positional[0]).unwrap();
    let p = ClassicalParams::default();
    let mut refiner = ClassicalRefiner::new(p);
    let mut times: Vec<Vec<f64>> = vec![Vec::new(); NAMES.len()];
    let (mut differing, mut max_diff) = (0usize, 0.0f32);
    if let Some(dir) = &dump {
        std::fs::create_dir_all(dir).unwrap();
    }
    for i in 0..frames {
        let f = cap.read_frame(i).unwrap();
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
            std::fs::write(dp, &depth_bytes).unwrap();
            std::fs::write(cp, &conf_bytes).unwrap();
        }
        if let Some(dir) = &check {
            let (dp, cp) = dump_paths(dir, i);
            let ref_depth = std::fs::read(dp).unwrap();
            let ref_conf = std::fs::read(cp).unwrap();
            assert_eq!(
                ref_depth.len(),
                depth_bytes.len(),
                "frame {i}: size differs"
            );
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
}
