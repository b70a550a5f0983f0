//! Criterion benchmark of bringing a phone's lower-resolution depth to its colour's resolution
//! (`scene::upsample_depth`, docs/VIDEO.md): a 1080 × 1920 frame with depth at 1/4 (270 × 480), nearest
//! neighbour against the colour-guided joint bilateral upsampling, on the machine's rayon threads.
//!
//! Run: `cargo bench -p tensorholo --bench scene`.
#![allow(missing_docs)] // criterion_group! generates undocumented items

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use ndarray::{Array2, Array3};
use tensorholo::scene::{upsample_depth, DecodedDepth, DepthUpsampling};

fn upsampling(c: &mut Criterion) {
    let mut group = c.benchmark_group("depth_upsampling_1080x1920_from_270x480");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(5));
    let (h, w) = (1080, 1920);
    // A textured colour and a depth with edges and ~5 % holes.
    let guide = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
        (((x / 37 + y / 23 + c) % 7) as f32 / 6.0) * 0.8 + 0.1
    });
    let low = DecodedDepth {
        values: Array2::from_shape_fn((h / 4, w / 4), |(y, x)| 0.5 + ((x / 9 + y / 13) % 5) as f32),
        valid: Array2::from_shape_fn((h / 4, w / 4), |(y, x)| (x * 31 + y * 17) % 20 != 0),
        metric: true,
    };
    for method in [DepthUpsampling::Nearest, DepthUpsampling::JointBilateral] {
        group.bench_function(BenchmarkId::from_parameter(method.name()), |b| {
            b.iter(|| upsample_depth(low.clone(), guide.view(), method))
        });
    }
    group.finish();
}

criterion_group!(benches, upsampling);
criterion_main!(benches);
