//! The per-frame work of the daemon's static path at VGA (640 × 480): warp the ToF depth and
//! the RGB with a calibration flow, then run the classical refinement.
//!
//! `cargo bench -p dear-pipeline --bench static_pipeline -- --warm-up-time 1 --measurement-time 5`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use dear_capture::Calibration;
use dear_pipeline::filter::ClassicalRefiner;
use dear_pipeline::geometry::{flow_from_depth, warp_depth, warp_rgb};
use ndarray::{Array2, Array3};

const H: usize = 480;
const W: usize = 640;

/// Deterministic values in `[0, 1)`.
fn hash01(i: usize) -> f32 {
    let mut x = (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((x ^ (x >> 31)) >> 40) as f32 / (1u64 << 24) as f32
}

/// A slanted wall at 2–3 m with two boxes in front, ~0.5 % noise, 3 % dropouts, a strip of
/// flying pixels, and a colour image whose regions follow the geometry.
fn scene() -> (Array2<f32>, Array3<u8>) {
    let region = |y: usize, x: usize| {
        if (100..300).contains(&y) && (120..320).contains(&x) {
            1
        } else if (250..420).contains(&y) && (380..560).contains(&x) {
            2
        } else {
            0
        }
    };
    let depth = Array2::from_shape_fn((H, W), |(y, x)| {
        let i = y * W + x;
        if hash01(3 * i) < 0.03 {
            return 0.0;
        }
        let z = match region(y, x) {
            1 => 1.0 + 0.0005 * x as f32,
            2 => 1.6,
            _ => 2.0 + 0.0015 * x as f32 + 0.0005 * y as f32,
        };
        let flying = x == 320 && (100..300).contains(&y);
        let z = if flying { 0.5 * (z + 2.5) } else { z };
        z * (1.0 + 0.005 * (hash01(3 * i + 1) - 0.5) * 3.46)
    });
    let rgb = Array3::from_shape_fn((H, W, 3), |(y, x, c)| {
        let base = [[90u8, 110, 140], [200, 60, 50], [40, 170, 80]][region(y, x)][c];
        base.saturating_add((8.0 * hash01(5 * (y * W + x) + c)) as u8)
    });
    (depth, rgb)
}

fn bench(c: &mut Criterion) {
    let (depth, rgb) = scene();
    let calib = Calibration {
        tx: 12.0,
        ty: -3.0,
        cx: 4.5,
        cy: -2.0,
    };
    let (flow, _) = flow_from_depth(depth.view(), &calib);
    let mut warped_depth = Array2::zeros((H, W));
    let mut warped_rgb = Array3::zeros((H, W, 3));
    let mut refined = Array2::zeros((H, W));
    let mut confidence = Array2::zeros((H, W));
    let mut refiner = ClassicalRefiner::default();

    c.bench_function("warp_depth 640x480", |b| {
        b.iter(|| warp_depth(black_box(depth.view()), &flow, warped_depth.view_mut()))
    });
    c.bench_function("warp_rgb 640x480", |b| {
        b.iter(|| warp_rgb(black_box(rgb.view()), &flow, warped_rgb.view_mut(), None))
    });
    warp_depth(depth.view(), &flow, warped_depth.view_mut());
    warp_rgb(rgb.view(), &flow, warped_rgb.view_mut(), None);
    c.bench_function("classical refine 640x480", |b| {
        b.iter(|| {
            refiner.refine_into(
                black_box(warped_depth.view()),
                warped_rgb.view(),
                refined.view_mut(),
                confidence.view_mut(),
            )
        })
    });
    c.bench_function("static frame (warp depth + rgb + refine) 640x480", |b| {
        b.iter(|| {
            warp_depth(black_box(depth.view()), &flow, warped_depth.view_mut());
            warp_rgb(rgb.view(), &flow, warped_rgb.view_mut(), None);
            refiner.refine_into(
                warped_depth.view(),
                warped_rgb.view(),
                refined.view_mut(),
                confidence.view_mut(),
            );
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
