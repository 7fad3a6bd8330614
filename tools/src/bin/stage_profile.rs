//! Times the per-frame stages of the daemon's steady-state (`Cached`) frame path on frame 0 of
//! a capture, repeated: preprocessing, alignment (splat + flow), the two warps, confidence and
//! the edge check, and with `--full` the classical filter and the refine graph as well.
//!
//! ```text
//! cargo build --release -p dear-tools --bin stage_profile
//! target/release/stage_profile CAPTURE BUNDLE [--full] [--iters N] [--dump DIR]
//!     [--worker N] [--tract-threads N]
//! ```
//!
//! Prints the median (and minimum) milliseconds per stage. `--worker N` also times, N times,
//! the parts of the background worker's measurement (`DearChain::measure`) on the same frame:
//! the rough-flow network, the robust least squares of its flow and the direct fit to the
//! edges, and prints the fitted calibrations' bit patterns (to check an optimisation leaves
//! them unchanged). `--tract-threads N` runs the refine graph on a pool of N threads (build with
//! `--features multithread`; without it the option has no effect). `--dump DIR` writes every geometry
//! stage's output for the frame as raw little-endian bytes (and the edge check's numbers as
//! bit patterns), so an optimisation can be checked to leave them bit-identical with `cmp`;
//! with `--full` also the classical filter's output and the refined depth.
//! The dumped confidence is computed against the aligned (splatted) depth rather than the
//! refine graph's output, so the dump depends only on the geometry code.

use std::path::{Path, PathBuf};
use std::time::Instant;

use dear_capture::frame::Flow;
use dear_capture::Calibration;
use dear_capture::CaptureDir;
use dear_pipeline::align::StaticAligner;
use dear_pipeline::chain::confidence::confidence_into;
use dear_pipeline::chain::preprocess::{normalize_amplitude_into, rgb_planes_into};
use dear_pipeline::filter::ClassicalRefiner;
use dear_pipeline::geometry::{warp_depth, warp_depth_and_bilinear};
use dear_pipeline::model::{BundleRunner, ModelBundle, RunnerOptions};
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

fn write_f32(dir: &Path, name: &str, a: &Array2<f32>) {
    let bytes: Vec<u8> = a.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(dir.join(name), bytes).unwrap();
}

fn main() {
    let mut args = std::env::args().skip(1);
    let (mut positional, mut full, mut iters, mut dump) = (Vec::new(), false, 20usize, None);
    let (mut worker, mut tract_threads) = (0usize, 1usize);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--full" => full = true,
            "--iters" => iters = args.next().unwrap().parse().unwrap(),
            "--dump" => dump = Some(PathBuf::from(args.next().unwrap())),
            "--worker" => worker = args.next().unwrap().parse().unwrap(),
            "--tract-threads" => tract_threads = args.next().unwrap().parse().unwrap(),
            _ => positional.push(a),
        }
    }
    let cap = CaptureDir::open(&positional[0]).unwrap();
    let f = cap.read_frame(0).unwrap();
    let (h, w) = f.dim();
    let bundle = (full || worker > 0).then(|| ModelBundle::load(&positional[1]).unwrap());
    let mut runner = bundle.as_ref().filter(|_| full).map(|b| {
        let options = RunnerOptions {
            threads: tract_threads,
        };
        BundleRunner::with_options(b, w, h, options).unwrap()
    });
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
                runner
                    .refine(aw.view(), dw.view(), rgb, Some(cd.view()), out.view_mut())
                    .unwrap();
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
        profile_worker(bundle, &f, worker);
    }

    if let Some(dir) = dump {
        std::fs::create_dir_all(&dir).unwrap();
        for (k, p) in rgbp.iter().enumerate() {
            write_f32(&dir, &format!("pre_rgb{k}.f32"), p);
        }
        write_f32(&dir, "pre_amp.f32", &amp);
        write_f32(&dir, "align_depth.f32", &drgb);
        write_f32(&dir, "align_flow_u.f32", &aligner.flow().u);
        write_f32(&dir, "align_flow_v.f32", &aligner.flow().v);
        write_f32(&dir, "warp_depth.f32", &dw);
        write_f32(&dir, "warp_amp.f32", &aw);
        if runner.is_some() {
            // With --full: the classical filter's output and the refiner's (graph and tail).
            write_f32(&dir, "classical_depth.f32", &cd);
            std::fs::write(dir.join("classical_conf.u8"), cc.as_slice().unwrap()).unwrap();
            write_f32(&dir, "refined_depth.f32", &out);
        }
        confidence_into(dw.view(), drgb.view(), conf.view_mut());
        std::fs::write(dir.join("confidence.u8"), conf.as_slice().unwrap()).unwrap();
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
        std::fs::write(dir.join("edge.txt"), format!("{edge:?}\n")).unwrap();
        println!("dumped to {}", dir.display());
    }
}

/// Times the parts of the worker's measurement on `f`, `n` times, and prints the fits' bits.
fn profile_worker(bundle: &ModelBundle, f: &dear_capture::RgbdFrame, n: usize) {
    let (h, w) = f.dim();
    let mut runner = BundleRunner::new(bundle, w, h).unwrap();
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
            .unwrap();
        let c0 = Instant::now();
        warp_depth(f.depth.view(), &flow, drgb.view_mut());
        let c1 = Instant::now();
        let fit =
            Measurement::from_flow(&flow, drgb.view(), RobustOptions::default(), 3.0).unwrap();
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
}
