//! This machine's physical limits, measured: the denominators of the physical-limit table
//! (RESULTS.md), so that each stage's time can be read as a fraction of what the memory system
//! and the arithmetic units allow.
//!
//! - *Memory bandwidth*: bytes read plus bytes written per second by a copy of a buffer far
//!   larger than the caches (256 MiB), best of several runs, on one thread and on all.
//! - *f32 FMA peak*: fused multiply-adds per second (2 FLOP each) by a kernel of 64 independent
//!   accumulators (8 vector registers of 8 lanes, enough chains to hide the FMA latency),
//!   compiled for AVX2+FMA where the CPU has it and chosen at run time; one thread and all.

use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

/// The measured limits.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct MachineLimits {
    /// Copy bandwidth, one thread, GB/s (10⁹ bytes read + written per second).
    pub bandwidth_gbs_one: f64,
    /// Copy bandwidth, every thread, GB/s.
    pub bandwidth_gbs_all: f64,
    /// f32 FMA throughput, one thread, GFLOP/s.
    pub fma_gflops_one: f64,
    /// f32 FMA throughput, every thread, GFLOP/s.
    pub fma_gflops_all: f64,
    /// Threads used for the "all" figures.
    pub threads: usize,
}

const COPY_BYTES: usize = 256 << 20;
const RUNS: usize = 5;

/// Measures the limits (about two seconds).
pub fn measure() -> MachineLimits {
    let threads = rayon::current_num_threads();
    MachineLimits {
        bandwidth_gbs_one: bandwidth(1),
        bandwidth_gbs_all: bandwidth(threads),
        fma_gflops_one: fma_peak(1),
        fma_gflops_all: fma_peak(threads),
        threads,
    }
}

fn bandwidth(threads: usize) -> f64 {
    let n = COPY_BYTES / 4;
    let src: Vec<f32> = (0..n).map(|i| i as f32).collect();
    let mut dst = vec![0.0f32; n];
    let chunk = n.div_ceil(threads);
    let mut best = f64::INFINITY;
    for _ in 0..RUNS {
        let t = Instant::now();
        dst.par_chunks_mut(chunk)
            .zip(src.par_chunks(chunk))
            .for_each(|(d, s)| d.copy_from_slice(s));
        best = best.min(t.elapsed().as_secs_f64());
    }
    std::hint::black_box(&dst);
    (2 * COPY_BYTES) as f64 / best / 1e9
}

fn fma_peak(threads: usize) -> f64 {
    const ITERS: usize = 4_000_000;
    let mut best = f64::INFINITY;
    for _ in 0..RUNS {
        let t = Instant::now();
        let sum: f32 = (0..threads)
            .into_par_iter()
            .map(|k| {
                let mut acc = [k as f32; 64];
                fma_kernel(ITERS, &mut acc);
                acc.iter().sum::<f32>()
            })
            .sum();
        std::hint::black_box(sum);
        best = best.min(t.elapsed().as_secs_f64());
    }
    (threads * ITERS * 64 * 2) as f64 / best / 1e9
}

#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn fma_kernel(iters: usize, acc: &mut [f32; 64]) {
    for _ in 0..iters {
        for a in acc.iter_mut() {
            *a = a.mul_add(0.999_999_9, 1e-7);
        }
    }
}
