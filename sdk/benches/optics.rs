//! Criterion benchmarks of the optics hot paths (results and the command in `docs/BENCHMARKS.md`):
//! ASM per colour at 384×384 and 1920×1080 (with and without 2× padding), SM-LBM at 384×384 for 256 and 2048
//! depth planes on the built-in scene, double phase encoding at 1080p (three colours, and the real-time
//! pipeline's per-colour passes one thread per pixel: `encode_rows_1080p`), the calibrated look-up tables at
//! 1080p.
//!
//! Run: `cargo bench -p tensorholo --bench optics`.
#![allow(missing_docs)] // criterion_group! generates undocumented items

use criterion::BatchSize;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use ndarray::{Array2, Array3};
use num_complex::Complex32;
use std::time::Duration;
use tensorholo::cnn::Isa;
use tensorholo::encoding::{
    double_phase_encode, normaliser, wrap_phase, ChannelEncoder, DoublePhaseMethod, LinearLut,
};
use tensorholo::optics::{Carrier, PropagationOptions, Propagator};
use tensorholo::scene::procedural;
use tensorholo::synthesis::{SceneLayer, SmLbm};

fn test_field(h: usize, w: usize) -> Vec<Complex32> {
    (0..h * w)
        .map(|i| Complex32::from_polar(((i % 97) as f32 / 97.0).sqrt(), (i % 13) as f32 * 0.4))
        .collect()
}

fn asm(c: &mut Criterion) {
    let mut group = c.benchmark_group("asm_per_colour");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(4));
    for (h, w) in [(384, 384), (1080, 1920)] {
        for pad in [false, true] {
            let prop = Propagator::new(
                h,
                w,
                8e-6,
                520e-9,
                PropagationOptions {
                    pad,
                    band_limit: false,
                },
            )
            .expect("valid parameters");
            let tf = prop
                .transfer_function(3e-3, Carrier::Keep)
                .expect("finite distance");
            let mut scratch = prop.plan().scratch();
            let mut field = test_field(h, w);
            let id = format!("{h}x{w}{}", if pad { "_padded" } else { "" });
            group.bench_function(BenchmarkId::from_parameter(id), |b| {
                b.iter(|| {
                    prop.propagate(&mut field, &tf, &mut scratch)
                        .expect("sizes match")
                })
            });
        }
    }
    group.finish();
}

fn sm_lbm(c: &mut Criterion) {
    let mut group = c.benchmark_group("sm_lbm_384x384");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10));
    let frame = procedural::default_scene(384, 384).expect("built-in scene");
    // Worst case: a plane tilted through the whole volume (767 distinct depths, so most planes are non-empty).
    let ramp = Array2::from_shape_fn((384, 384), |(y, x)| (x + y) as f32 / 766.0);
    for (scene, depth) in [
        ("default_scene", frame.depth.view()),
        ("full_ramp", ramp.view()),
    ] {
        let layer = SceneLayer {
            amplitude: frame.amplitude.view(),
            depth,
            valid: None,
        };
        for levels in [256, 2048] {
            let cfg = SmLbm {
                levels,
                ..SmLbm::default()
            };
            let planes = cfg.propagation_count(&[layer]).expect("valid scene");
            let id = format!("{scene}_{levels}_levels_{planes}_planes");
            group.bench_function(BenchmarkId::from_parameter(id), |b| {
                b.iter(|| cfg.synthesize(&[layer], &|_, _| {}).expect("valid scene"))
            });
        }
    }
    group.finish();
}

fn double_phase(c: &mut Criterion) {
    let mut group = c.benchmark_group("double_phase_1080p");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(5));
    let (h, w) = (1080, 1920);
    let field = Array3::from_shape_fn((3, h, w), |(ch, y, x)| {
        Complex32::from_polar(
            0.2 + 0.8 * ((x * 7 + y * 3 + ch) % 101) as f32 / 101.0,
            (x as f32) * 0.01,
        )
    });
    for (name, method) in [
        ("dpm", DoublePhaseMethod::Plain),
        ("aa_dpm", DoublePhaseMethod::default()),
        ("bl_dpm", DoublePhaseMethod::BandLimited { k: 0.5 }),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| double_phase_encode(field.view(), &method).expect("valid field"))
        });
    }
    group.finish();
}

/// The two passes of the double phase encoding on one colour of a 1080p frame, one thread, no pre-filter
/// (what a colour worker of the real-time pipeline runs): pass 1 (`analyse`: `arg H`, max `|H|²`, `Σ arg H`)
/// and pass 2 (`encode`: `φ − mean ± acos(|H|/a)`, wrap, linear LUT codes). The field is speckle-like
/// (pseudo-random amplitude and phase per pixel), as a propagated hologram is. Divide by 1080·1920 =
/// 2 073 600 for ns per pixel. Each pass runs on this CPU's best row kernels and on the portable ones
/// (`analyse/avx512` beside `analyse/scalar`); `*_libm` are the passes as they were before the row kernels.
fn encode_rows(c: &mut Criterion) {
    let (h, w) = (1080, 1920);
    let mut group = c.benchmark_group("encode_rows_1080p");
    group
        .sample_size(20)
        .measurement_time(Duration::from_secs(4));
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut field: Vec<Complex32> = (0..h * w)
        .map(|_| {
            let a = next();
            Complex32::from_polar(a, (next() - 0.5) * std::f32::consts::TAU)
        })
        .collect();
    let mut phase = vec![0.0f32; h * w];
    let mut codes = vec![0u8; h * w];
    // This CPU's best rows and the portable ones, side by side in one run (`analyse/avx512`, `analyse/scalar`, …).
    let mut isas = vec![Isa::detect(), Isa::Scalar];
    isas.dedup();
    for isa in isas {
        let mut enc = ChannelEncoder::new(h, w, DoublePhaseMethod::Plain)
            .and_then(|e| e.with_isa(isa))
            .expect("valid size and level");
        group.bench_function(BenchmarkId::new("analyse", isa.name()), |b| {
            b.iter(|| enc.analyse(&mut field, &mut phase).expect("sizes match"))
        });
        let stats = enc.analyse(&mut field, &mut phase).expect("sizes match");
        let (a, mean) = normaliser(&[stats; 3], h * w).expect("non-zero field");
        group.bench_function(BenchmarkId::new("encode", isa.name()), |b| {
            b.iter_batched_ref(
                || phase.clone(),
                |p| {
                    enc.encode(&field, p, &mut codes, mean[0], a)
                        .expect("sizes match")
                },
                BatchSize::LargeInput,
            )
        });
    }
    let stats = ChannelEncoder::new(h, w, DoublePhaseMethod::Plain)
        .expect("valid size")
        .analyse(&mut field, &mut phase)
        .expect("sizes match");
    let (a, mean) = normaliser(&[stats; 3], h * w).expect("non-zero field");
    // The same two passes as the SDK ran them before the row kernels of `tensorholo-kernels`: libm
    // `atan2f`/`acosf` per pixel, the scalar wrap, `LinearLut::code` (the "before" of docs/BENCHMARKS.md).
    group.bench_function("analyse_libm", |b| {
        b.iter(|| {
            let (mut max, mut sum) = (0.0f32, 0.0f64);
            for (p, v) in phase.iter_mut().zip(&field) {
                *p = v.im.atan2(v.re);
                max = max.max(v.norm_sqr());
                sum += *p as f64;
            }
            (max, sum)
        })
    });
    let inv_a = 1.0 / a;
    group.bench_function("encode_libm", |b| {
        b.iter_batched_ref(
            || phase.clone(),
            |p| {
                for (y, (row, out)) in field.chunks_exact(w).zip(p.chunks_exact_mut(w)).enumerate()
                {
                    for (x, (p, v)) in out.iter_mut().zip(row).enumerate() {
                        let theta = (v.norm_sqr().sqrt() * inv_a).min(1.0).acos();
                        let sign = if (x + y) % 2 == 1 { -1.0 } else { 1.0 };
                        *p = wrap_phase(*p - mean[0] + sign * theta);
                    }
                }
                for (c, p) in codes.iter_mut().zip(p.iter()) {
                    *c = LinearLut.code(*p);
                }
            },
            BatchSize::LargeInput,
        )
    });
    group.finish();
}

/// The display calibration's phase → code look-up table on one colour of a 1080p frame (the pipeline runs
/// the three colours on three threads): linear, global (one curve) and per-pixel tiles of 4, 8 and 16 px.
fn look_up_table(c: &mut Criterion) {
    use tensorholo::slm::{LutRepresentation, PhaseCurve, PhaseLut, TiledCurves};
    let (h, w) = (1080, 1920);
    let mut group = c.benchmark_group("lut_1080p_one_colour");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(3));
    let phase: Vec<f32> = (0..h * w)
        .map(|i| (i % 1009) as f32 * std::f32::consts::TAU / 1009.0)
        .collect();
    let mut codes = vec![0u8; h * w];
    let mut luts = vec![
        ("linear".to_string(), PhaseLut::linear()),
        (
            "global".to_string(),
            PhaseLut::new(LutRepresentation::Global(
                PhaseCurve::gamma(7.5, 1.3).expect("valid model"),
            )),
        ),
    ];
    for tile in [4, 8, 16] {
        let n = h.div_ceil(tile) * w.div_ceil(tile);
        let curves = (0..n)
            .map(|t| PhaseCurve::gamma(7.0 + (t % 50) as f32 * 0.01, 1.2).expect("valid model"))
            .collect();
        let tiles = TiledCurves::new(h, w, tile, tile, curves).expect("valid tiles");
        luts.push((
            format!("tiled_{tile}px"),
            PhaseLut::new(LutRepresentation::Tiled(tiles)),
        ));
    }
    for (name, lut) in &luts {
        group.bench_function(name.as_str(), |b| {
            b.iter(|| lut.apply(h, w, &phase, &mut codes).expect("sizes match"))
        });
    }
    group.finish();
}

criterion_group!(
    benches,
    asm,
    sm_lbm,
    double_phase,
    encode_rows,
    look_up_table
);
criterion_main!(benches);
