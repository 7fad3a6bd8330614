//! The DEAR chain at VGA (640 × 480) with the shipped edge bundle (`models/edge`; set
//! `DEAR_BENCH_BUNDLE` to time another): each network alone, and one frame in `Full` mode (the
//! paper: the rough-flow network every frame), `Cached` with fusion skipped (the online
//! steady state) and `Cached` with fusion run.
//!
//! `cargo bench -p dear-pipeline --bench dear_chain -- --warm-up-time 2 --measurement-time 10`
//! With `--features multithread`, every case also runs with tract on 2 threads (`…/mt2`).
//! The onnxruntime peer figure for the same files: `.venv/bin/dear-bench-onnx --bundle
//! models/edge`.

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use dear_capture::{Calibration, Flow};
use dear_pipeline::chain::{
    CachedFusion, ChainInput, ChainMode, ChainOptions, ChainOutput, DearChain,
};
use dear_pipeline::model::kernel_apply::{apply_gated, GatedKernel, GATED_CHANNELS};
use dear_pipeline::model::manifest::JumpOn;
use dear_pipeline::model::{ClassicalEstimate, ModelBundle, RunnerOptions};
use ndarray::{Array2, Array3};

// The daemon's allocator (see deard's main.rs: with glibc's malloc, tract's large intermediate
// tensors come back as fresh page faults on every run).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

const H: usize = 480;
const W: usize = 640;

/// Deterministic values in `[0, 1)`.
fn hash01(i: usize) -> f32 {
    let mut x = (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((x ^ (x >> 31)) >> 40) as f32 / (1u64 << 24) as f32
}

/// A slanted wall with two boxes in front, noise, dropouts, and RGB/amplitude textures that
/// follow the geometry.
fn frame() -> (Array3<u8>, Array2<f32>, Array2<f32>) {
    let depth = Array2::from_shape_fn((H, W), |(y, x)| {
        let i = y * W + x;
        if hash01(3 * i) < 0.02 {
            return 0.0;
        }
        let z = if (100..300).contains(&y) && (120..320).contains(&x) {
            1.2
        } else if (250..420).contains(&y) && (380..560).contains(&x) {
            1.8
        } else {
            2.5 + 0.001 * x as f32
        };
        z * (1.0 + 0.005 * (hash01(3 * i + 1) - 0.5))
    });
    let tex =
        |y: usize, x: usize| (((x / 9) + (y / 13)) % 2) as f32 * 0.5 + 0.3 * hash01(y * W + x);
    let rgb = Array3::from_shape_fn((H, W, 3), |(y, x, c)| {
        ((tex(y, x) * (0.6 + 0.2 * c as f32)) * 255.0) as u8
    });
    let amp = Array2::from_shape_fn((H, W), |(y, x)| {
        let z = depth[[y, x]].max(0.5);
        4000.0 * (0.3 + tex(y, x)) / (z * z)
    });
    (rgb, amp, depth)
}

fn bench(c: &mut Criterion) {
    let path = std::env::var_os("DEAR_BENCH_BUNDLE")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/edge"));
    let bundle =
        ModelBundle::load(&path).unwrap_or_else(|e| panic!("bundle {}: {e}", path.display()));
    let (rgb, amp, depth) = frame();
    let calib = Calibration {
        tx: 6.0,
        ty: -2.0,
        cx: 3.0,
        cy: 1.0,
    };
    let mut thread_counts = vec![1];
    if cfg!(feature = "multithread") {
        thread_counts.push(2);
    }
    let mut group = c.benchmark_group("dear_chain_vga");
    group.sample_size(10);
    for threads in thread_counts {
        let suffix = if threads == 1 {
            String::new()
        } else {
            format!("/mt{threads}")
        };
        let options = ChainOptions {
            runner: RunnerOptions { threads },
            ..ChainOptions::default()
        };
        let mut chain = DearChain::with_options(&bundle, W, H, options).expect("runner at VGA");
        let mut out_depth = Array2::zeros((H, W));
        let mut out_conf = Array2::zeros((H, W));
        let mut process = |chain: &mut DearChain, mode| {
            chain
                .process(
                    ChainInput {
                        rgb: rgb.view(),
                        amplitude: amp.view(),
                        depth: depth.view(),
                    },
                    mode,
                    ChainOutput {
                        depth: out_depth.view_mut(),
                        confidence: out_conf.view_mut(),
                    },
                )
                .expect("frame")
        };
        // One full frame fills the intermediates the single-network cases reuse.
        let report = process(&mut chain, ChainMode::Full);
        println!("full frame stages{suffix}: {:?}", report.timings);
        let planes = chain.rgb_planes().clone();
        let amp_n = chain.amplitude().clone();
        let (rough, convt) = (chain.flow_rough().clone(), chain.flow_convt().clone());
        let (amp_w, depth_w) = (
            chain.amplitude_warped().clone(),
            chain.depth_warped().clone(),
        );
        let mut flow_out = Flow::zeros(H, W);
        let mut depth_out = Array2::zeros((H, W));
        // A hybrid refiner also takes the classical filter's output (computed once here: the
        // refine_net row times the graph and its tail; the frame rows include the filter).
        let classical = chain.runner_mut().refine_uses_classical().then(|| {
            dear_pipeline::filter::ClassicalRefiner::default().refine(depth_w.view(), rgb.view())
        });
        group.bench_function(format!("flow_net{suffix}"), |b| {
            b.iter(|| {
                chain
                    .runner_mut()
                    .flow(
                        [planes[0].view(), planes[1].view(), planes[2].view()],
                        amp_n.view(),
                        &mut flow_out,
                    )
                    .unwrap();
                black_box(&flow_out);
            })
        });
        group.bench_function(format!("fuse_net{suffix}"), |b| {
            b.iter(|| {
                chain
                    .runner_mut()
                    .fuse(&rough, &convt, &mut flow_out)
                    .unwrap();
                black_box(&flow_out);
            })
        });
        group.bench_function(format!("refine_net{suffix}"), |b| {
            b.iter(|| {
                chain
                    .runner_mut()
                    .refine(
                        amp_w.view(),
                        depth_w.view(),
                        Some([planes[0].view(), planes[1].view(), planes[2].view()]),
                        classical
                            .as_ref()
                            .map(|(depth, confidence)| ClassicalEstimate {
                                depth: depth.view(),
                                confidence: confidence.view(),
                            }),
                        depth_out.view_mut(),
                    )
                    .unwrap();
                black_box(&depth_out);
            })
        });
        group.bench_function(format!("frame_full{suffix}"), |b| {
            b.iter(|| black_box(process(&mut chain, ChainMode::Full)))
        });
        chain.set_cached_fusion(CachedFusion::Skip);
        let report = process(&mut chain, ChainMode::Cached(calib));
        println!("cached-skip frame stages{suffix}: {:?}", report.timings);
        group.bench_function(format!("frame_cached_skip{suffix}"), |b| {
            b.iter(|| black_box(process(&mut chain, ChainMode::Cached(calib))))
        });
        chain.set_cached_fusion(CachedFusion::Run);
        group.bench_function(format!("frame_cached_run{suffix}"), |b| {
            b.iter(|| black_box(process(&mut chain, ChainMode::Cached(calib))))
        });
    }
    group.finish();
}

/// The format-2 refiner's tail alone (`model::kernel_apply`): twelve 1/4-resolution maps
/// upsampled and applied to a 640×480 depth map, on the rayon pool (both cores).
fn bench_gated_tail(c: &mut Criterion) {
    let (_, _, depth) = frame();
    let (h4, w4) = (H / 4, W / 4);
    let maps: Vec<Array2<f32>> = (0..GATED_CHANNELS)
        .map(|ch| {
            Array2::from_shape_fn((h4, w4), |(y, x)| {
                0.3 * ((ch * 7 + y * 3 + x) % 11) as f32 / 11.0 - 0.1
            })
        })
        .collect();
    let kernel = GatedKernel {
        stride: 4,
        max_bias: 0.05,
        range_scale: 100.0,
        max_depth_m: 10.0,
        jump_scale: None,
        jump_on: JumpOn::EveryPixel,
        errors: None,
    };
    let mut out = Array2::zeros((H, W));
    let mut group = c.benchmark_group("dear_chain_vga");
    group.sample_size(20);
    group.bench_function("gated_tail", |b| {
        b.iter(|| {
            apply_gated(&maps, depth.view(), out.view_mut(), &kernel);
            black_box(&out);
        })
    });
    group.finish();
}

criterion_group!(benches, bench, bench_gated_tail);
criterion_main!(benches);
