//! Every available kernel row × the TensorHolo layer shapes at 384×384, one thread; the pre-filter's
//! depthwise base filter on every path; the heads as phasors (`phasors_1080p`: one 1080×1920 plane); the box
//! means of a foveated periphery's blur (`box_means_1080p`: one 1080×1920 plane).
//!
//! Throughput is reported in "elements" = operations (2 per multiply-add, `2·9·C_in·C_out·H·W` per layer),
//! so criterion's `Gelem/s` reads as GFLOP/s (f32) or GOP/s (int8). The peaks of each ISA are measured with
//! the same harness (groups `peak_f32_fma`, `peak_int8`) right before the kernels, under the same load.
//!
//! `cargo bench -p tensorholo-kernels --bench conv3x3 -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use std::hint::black_box;
use tensorholo_kernels::{
    depthwise, peak, phasor, registry, Conv3x3F32, Conv3x3U8, Conv3x3U8Spec, Inputs, Isa, QuantU8,
    RowPlanar,
};

const H: usize = 384;
const W: usize = 384;

/// (name, C_in source a, C_in source b, C_out, ReLU, residual, planar output)
const LAYERS: [(&str, usize, usize, usize, bool, bool, bool); 6] = [
    ("first_4to24", 4, 0, 24, true, false, false),
    ("mid_24to24", 24, 0, 24, true, true, false),
    ("last_24+4to6", 24, 4, 6, false, false, true),
    ("pre_6to8", 6, 0, 8, true, false, false),
    ("pre_8to8", 8, 0, 8, true, true, false),
    ("pre_last_8+6to6", 8, 6, 6, false, false, true),
];

fn data(n: usize, seed: u32) -> Vec<f32> {
    let mut s = seed.wrapping_mul(2_654_435_761) | 1;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        })
        .collect()
}

fn f32_rows(c: &mut Criterion) {
    for isa in Isa::available() {
        if let Ok(g) = peak::f32_fma_gflops(isa, 300) {
            println!("peak f32 FMA {isa}: {g:.1} GFLOP/s (1 thread)");
        }
    }
    // The peak measured with the same harness, right before the kernels (same machine load).
    let mut group = c.benchmark_group("peak_f32_fma");
    for isa in Isa::available() {
        let iters = 1 << 20;
        let flops = peak::f32_fma_loop(isa, 1).expect("available") * iters as f64;
        group.throughput(Throughput::Elements(flops as u64));
        group.bench_function(isa.name(), |bch| {
            bch.iter(|| peak::f32_fma_loop(isa, iters))
        });
    }
    group.finish();
    let mut group = c.benchmark_group("conv3x3_f32_384x384");
    for info in registry::f32_kernels() {
        if !info.is_available() {
            println!("SKIPPED {}: this CPU lacks {}", info.name, info.isa);
            continue;
        }
        for &(layer, ca, cb, cout, relu, residual, planar) in &LAYERS {
            let cin = ca + cb;
            let plan = Conv3x3F32::with_kernel(
                &data(cout * cin * 9, 1),
                &data(cout, 2),
                cin,
                cout,
                relu,
                info.name,
            )
            .expect("plan");
            let a = RowPlanar::from_planar(&data(ca * H * W, 3), ca, H, W, None).expect("a");
            let b = (cb > 0)
                .then(|| RowPlanar::from_planar(&data(cb * H * W, 4), cb, H, W, None).expect("b"));
            let r = RowPlanar::from_planar(&data(cout * H * W, 5), cout, H, W, None).expect("r");
            let mut inputs = Inputs::new(&a);
            if let Some(b) = &b {
                inputs = inputs.concat(b);
            }
            if residual {
                inputs = inputs.residual(&r);
            }
            let mut out = RowPlanar::new(cout, H, W).expect("out");
            let mut planar_out = vec![0.0f32; cout * H * W];
            group.throughput(Throughput::Elements((2 * 9 * cin * cout * H * W) as u64));
            group.bench_function(BenchmarkId::new(info.name, layer), |bch| {
                bch.iter(|| {
                    if planar {
                        plan.run_planar(inputs, &mut planar_out, 0..H).expect("run");
                    } else {
                        plan.run(inputs, &mut out, 0..H).expect("run");
                    }
                    black_box(&out);
                })
            });
        }
    }
    group.finish();
}

fn u8_rows(c: &mut Criterion) {
    let mut group = c.benchmark_group("peak_int8");
    for isa in Isa::available() {
        let iters = 1 << 20;
        let ops = peak::int8_dot_loop(isa, 1).expect("available") * iters as f64;
        group.throughput(Throughput::Elements(ops as u64));
        group.bench_function(isa.name(), |bch| {
            bch.iter(|| peak::int8_dot_loop(isa, iters))
        });
    }
    group.finish();
    let mut group = c.benchmark_group("conv3x3_u8s8_384x384");
    for info in registry::u8_kernels() {
        if !info.is_available() {
            println!("SKIPPED {}: this CPU lacks {}", info.name, info.isa);
            continue;
        }
        for &(layer, ca, cb, cout, relu, residual, planar) in &LAYERS {
            let cin = ca + cb;
            let weights: Vec<i8> = data(cout * cin * 9, 1)
                .iter()
                .map(|v| (v * 250.0) as i8)
                .collect();
            let scales = vec![0.01f32; cout];
            let bias = data(cout, 2);
            let q = QuantU8 {
                scale: 0.02,
                zero_point: 3,
            };
            let spec = Conv3x3U8Spec {
                weights: &weights,
                weight_scales: &scales,
                bias: &bias,
                c_in_a: ca,
                c_in_b: cb,
                c_out: cout,
                input_scale: 1.0 / 255.0,
                input_zero_point_a: 3,
                input_zero_point_b: 3,
                relu,
                residual: residual.then_some(q),
                output: (!planar).then_some(q),
            };
            let plan = Conv3x3U8::with_kernel(&spec, info.name).expect("plan");
            let bytes = |c: usize, seed: u32| -> Vec<u8> {
                data(c * H * W, seed)
                    .iter()
                    .map(|v| ((v + 0.5) * 255.0) as u8)
                    .collect()
            };
            let a = RowPlanar::from_planar_u8(&bytes(ca, 3), ca, H, W, 3).expect("a");
            let b =
                (cb > 0).then(|| RowPlanar::from_planar_u8(&bytes(cb, 4), cb, H, W, 3).expect("b"));
            let r = RowPlanar::from_planar_u8(&bytes(cout, 5), cout, H, W, 3).expect("r");
            let mut inputs = Inputs::new(&a);
            if let Some(b) = &b {
                inputs = inputs.concat(b);
            }
            if residual {
                inputs = inputs.residual(&r);
            }
            let mut out = RowPlanar::new_quantized(cout, H, W, 3).expect("out");
            let mut planar_out = vec![0.0f32; cout * H * W];
            group.throughput(Throughput::Elements((2 * 9 * cin * cout * H * W) as u64));
            group.bench_function(BenchmarkId::new(info.name, layer), |bch| {
                bch.iter(|| {
                    if planar {
                        plan.run_planar(inputs, &mut planar_out, 0..H).expect("run");
                    } else {
                        plan.run(inputs, &mut out, 0..H).expect("run");
                    }
                    black_box(&out);
                })
            });
        }
    }
    group.finish();
}

/// The pre-filter's 5×5 base filter of 6 channels (one thread) at 384² and on a strip of 16 rows of a 1080p
/// frame's 1920 columns (what the fused base filters per strip: `sdk/src/cnn/native/f32.rs`, `FusedBase`),
/// on every path of the kernel table that this CPU has (`registry::depthwise_paths`; throughput in FLOP, 2
/// per tap).
fn depthwise_paths(c: &mut Criterion) {
    let (ch, k) = (6, 5);
    for (h, w) in [(H, W), (16, 1920)] {
        let input = data(ch * h * w, 7);
        let kernel = data(ch * k * k, 8);
        let mut out = data(ch * h * w, 9);
        let mut group = c.benchmark_group(format!("depthwise_6ch_5x5_{h}x{w}"));
        group.throughput(Throughput::Elements((2 * k * k * ch * h * w) as u64));
        for isa in registry::depthwise_paths() {
            if !isa.is_available() {
                println!("SKIPPED depthwise.{isa}: this CPU lacks {isa}");
                continue;
            }
            group.bench_function(isa.name(), |bch| {
                bch.iter(|| {
                    depthwise(&input, ch, h, w, &kernel, k, &mut out, true, isa).expect("run");
                    black_box(&out);
                })
            });
        }
        group.finish();
    }
}

fn phasor_paths(c: &mut Criterion) {
    let n = 1080 * 1920;
    let amplitude = data(n, 11);
    let phase = data(n, 12);
    let mut buf = vec![0.0f32; 2 * n];
    let mut group = c.benchmark_group("phasors_1080p");
    group.throughput(Throughput::Elements(n as u64));
    for isa in registry::phasor_paths() {
        if !isa.is_available() {
            println!("SKIPPED phasors.{isa}: this CPU lacks {isa}");
            continue;
        }
        group.bench_function(isa.name(), |bch| {
            bch.iter(|| {
                buf[..n].copy_from_slice(&amplitude);
                phasor::phasors_in_place(&mut buf, &phase, isa).expect("run");
                black_box(&buf);
            })
        });
    }
    // The per-pixel libm form it replaces (`Complex32::from_polar(a, (p − 0.5)·2π)`).
    group.bench_function("libm_sin_cos", |bch| {
        bch.iter(|| {
            for ((o, &a), &p) in buf.chunks_exact_mut(2).zip(&amplitude).zip(&phase) {
                let (s, c) = ((p - 0.5) * std::f32::consts::TAU).sin_cos();
                o[0] = a * c;
                o[1] = a * s;
            }
            black_box(&buf);
        })
    });
    group.finish();
}

/// The box means over one 1080×1920 plane (a foveated periphery's blur, red at 8 µm: half-widths up to 6),
/// its rows' unclipped columns as the SDK runs them, on every path.
fn box_means_paths(c: &mut Criterion) {
    use tensorholo_kernels::box_blur::{box_means, Defocus, SatRow};
    let (h, w, reach) = (1080usize, 1920usize, 7usize);
    let stride = w + 1;
    let image = data(h * w, 13);
    let mut table = vec![0.0f64; (h + 1) * stride];
    for y in 0..h {
        let mut acc = 0.0f64;
        for x in 0..w {
            acc += f64::from(image[y * w + x].abs());
            table[(y + 1) * stride + x + 1] = table[y * stride + x + 1] + acc;
        }
    }
    // A depth that varies slowly along a row and down the frame, as a scene's.
    let depth: Vec<f32> = (0..h * w)
        .map(|i| (i % w) as f32 / w as f32 * 0.7 + (i / w) as f32 / h as f32 * 0.3)
        .collect();
    let defocus = Defocus {
        gaze_depth: 0.4,
        scale: 6.6,
        max_half: (reach - 1) as f64,
    };
    let mut out = vec![0.0f32; w];
    let mut group = c.benchmark_group("box_means_1080p");
    group.throughput(Throughput::Elements(
        ((h - 2 * reach) * (w - 2 * reach)) as u64,
    ));
    for isa in registry::box_means_paths() {
        if !isa.is_available() {
            println!("SKIPPED box_means.{isa}: this CPU lacks {isa}");
            continue;
        }
        group.bench_function(isa.name(), |bch| {
            bch.iter(|| {
                for y in reach..h - reach {
                    let sat = SatRow {
                        table: &table,
                        stride,
                        row: y,
                        x0: reach,
                    };
                    let cols = reach..w - reach;
                    let row_depth = &depth[y * w + cols.start..y * w + cols.end];
                    box_means(sat, row_depth, defocus, &mut out[cols.clone()], isa).expect("run");
                }
                black_box(&out);
            })
        });
    }
    group.finish();
}

// criterion_group! generates an undocumented function.
#[allow(missing_docs)]
mod group {
    use super::*;
    criterion_group!(
        benches,
        f32_rows,
        u8_rows,
        depthwise_paths,
        phasor_paths,
        box_means_paths
    );
}
use group::benches;
criterion_main!(benches);
