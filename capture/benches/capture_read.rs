//! Reading one replayed frame of `samples/demo` (320 × 240): the full read (sensor planes,
//! ground truth, mask; what evaluation uses) against the sensor read the daemon's replay uses.
//!
//! `cargo bench -p dear-capture --bench capture_read -- --warm-up-time 1 --measurement-time 5`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use dear_capture::CaptureDir;

fn bench(c: &mut Criterion) {
    let demo = CaptureDir::open(concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/demo"))
        .expect("samples/demo");
    let mut group = c.benchmark_group("capture_read_320x240");
    group.bench_function("read_sample", |b| {
        b.iter(|| black_box(demo.read_sample(black_box(0)).unwrap()))
    });
    group.bench_function("read_frame", |b| {
        b.iter(|| black_box(demo.read_frame(black_box(0)).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
