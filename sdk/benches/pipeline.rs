//! Criterion benchmarks of the real-time path with the shipped models (results and the command in
//! `docs/BENCHMARKS.md`): the 8-layer RGB-D hologram CNN at 384×384 in both tract layouts
//! ([`CnnLayout`]), and one `HologramSession::render` of the built-in scene with AA-DPM (offset 0, or
//! `holo render --no-prefilter`) and with the 6 mm DDPM pre-filter (what `holo render` does by default).
//! tract runs on one thread (its default); `holo bench`
//! covers the other variants, sizes and thread counts.
//!
//! Run: `cargo bench -p tensorholo --bench pipeline`.
#![allow(missing_docs)] // criterion_group! generates undocumented items

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use ndarray::Array3;
use tensorholo::cnn::CnnLayout;
use tensorholo::model::{embedded, ModelConfig, Precision};
use tensorholo::pipeline::{HologramPipeline, ModelSelection, PipelineConfig, PrefilterMode};
use tensorholo::scene::procedural;

const SIZE: (usize, usize) = (384, 384);

fn cnn(c: &mut Criterion) {
    let mut group = c.benchmark_group("holo8_f32_384x384");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(8));
    let model = embedded::hologram_model(
        8,
        Precision::F32,
        &ModelConfig {
            offset_m: 0.0,
            ..ModelConfig::default()
        },
    )
    .expect("shipped model loads");
    let model = tensorholo::cnn::tract::TractModel::new(&model).expect("tract reads it");
    let (h, w) = SIZE;
    let input = Array3::<f32>::from_shape_fn((4, h, w), |(c, y, x)| {
        ((x * 7 + y * 3 + c) % 13) as f32 / 12.0
    });
    for layout in CnnLayout::ALL {
        let plan = model.plan_with_layout(h, w, layout).expect("plans");
        group.bench_function(BenchmarkId::from_parameter(layout), |b| {
            b.iter(|| plan.run_outputs(input.view()).expect("runs"))
        });
    }
    group.finish();
}

fn session(c: &mut Criterion) {
    let mut group = c.benchmark_group("session_render_holo8_384x384");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(8));
    let (h, w) = SIZE;
    let frame = procedural::default_scene(h, w).expect("built-in scene");
    for (name, offset_m, prefilter) in [
        ("aa-dpm_0mm", 0.0, PrefilterMode::Off),
        ("ddpm_6mm", 6e-3, PrefilterMode::Required),
    ] {
        let selection = ModelSelection {
            prefilter,
            ..ModelSelection::default()
        };
        let pipeline = HologramPipeline::embedded(
            &selection,
            PipelineConfig {
                offset_m,
                ..PipelineConfig::default()
            },
        )
        .expect("shipped models load");
        let mut session = pipeline.session(h, w).expect("session");
        group.bench_function(BenchmarkId::from_parameter(name), |b| {
            b.iter(|| session.render(&frame).expect("renders").timings.total_s)
        });
    }
    group.finish();
}

criterion_group!(benches, cnn, session);
criterion_main!(benches);
