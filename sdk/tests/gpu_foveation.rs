//! Foveated frames on the GPU (`Backend::Gpu`, docs/FOVEATION.md "On the GPU") against the CPU's foveated
//! frames of the same configuration, on real RGB-D frames from `../shared/data` with the shipped 8-layer CNN
//! (f32), on whatever adapter exists (CI: Mesa's lavapipe): the composed midpoint hologram, the periphery's
//! phase, the normaliser, the SLM pattern and what it displays; a gaze at a corner; a fovea covering the frame
//! and a tile as large as the frame give the GPU's `render` bit for bit; a moving gaze creates no GPU object;
//! `Backend::Auto` makes its self-check on a full frame before the first foveated frame.
//! Skips with a message where no adapter exists, unless `TENSORHOLO_REQUIRE_GPU=1`.
//!
//! Rerun with the figures printed: `cargo test -p tensorholo --features gpu --test gpu_foveation -- --nocapture`.

use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3, Axis};
use num_complex::Complex32;
use tensorholo::foveation::{FoveaRadius, FoveationOptions, Gaze};
use tensorholo::gpu::GpuContext;
use tensorholo::model::Precision;
use tensorholo::optics::{focal_stack, post_encoding_midpoint, OpticalSetup, PropagationOptions};
use tensorholo::pipeline::{
    Backend, GpuPrecision, HologramPipeline, HologramSession, ModelSelection, PipelineConfig,
    PrefilterMode, SelfCheck, SlmFrame,
};
use tensorholo::scene::{load_rgbd, DepthEncoding, LoadOptions, RgbdFrame};

mod gpu_common;

const H: usize = 192;
const W: usize = 256;
const OFFSET_M: f64 = 6e-3;
const RADIUS: f64 = 40.0;

/// Path of a shared data file; fails loudly (never skips) when the shared data checkout is missing.
fn data(rel: &str) -> PathBuf {
    let p = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data")).join(rel);
    assert!(
        p.is_file(),
        "shared test data file missing: {}",
        p.display()
    );
    p
}

fn frame(name: &str) -> RgbdFrame {
    let options = LoadOptions {
        size: Some((H, W)),
        ..LoadOptions::default()
    };
    let (rgb, depth, enc) = match name {
        "tum" => (
            "tum/TUM_color.png",
            "tum/TUM_depth.png",
            DepthEncoding::Tum5000,
        ),
        _ => (
            "iphone_portrait_vase/derived_rgb_576x768.png",
            "iphone_portrait_vase/disparity_aux_576x768.jpg",
            DepthEncoding::IphoneDisparity,
        ),
    };
    load_rgbd(&data(rgb), &data(depth), enc, &options)
        .unwrap()
        .0
}

fn session(
    ctx: &GpuContext,
    backend: Backend,
    prefilter: PrefilterMode,
    radius: f64,
) -> HologramSession {
    let selection = ModelSelection {
        layers: 8,
        precision: Precision::F32,
        prefilter,
        ..ModelSelection::default()
    };
    let config = PipelineConfig {
        offset_m: OFFSET_M,
        backend,
        gpu_precision: GpuPrecision::F32,
        foveation: Some(FoveationOptions {
            radius: FoveaRadius::Pixels { pixels: radius },
            ..FoveationOptions::default()
        }),
        ..PipelineConfig::default()
    };
    let s = HologramPipeline::embedded(&selection, config)
        .unwrap()
        .with_gpu_context(ctx.clone())
        .session(H, W)
        .unwrap();
    // Auto picks the GPU only on hardware, or on the context an app hands in (this one).
    assert_eq!(
        s.backend_report().active,
        if backend == Backend::Auto {
            Backend::Gpu
        } else {
            backend
        }
    );
    s
}

/// Cyclic phase distance in radians.
fn phase_distance(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(std::f32::consts::TAU);
    d.min(std::f32::consts::TAU - d)
}

fn distance(g: &Gaze, y: usize, x: usize) -> f64 {
    (x as f64 - g.x).hypot(y as f64 - g.y)
}

/// PSNR of `test` against `reference` over `region` (all colours), `test` at its least-squares scale, the
/// peak the reference's largest value there.
fn psnr_ls(reference: &Array3<f32>, test: &Array3<f32>, region: &Array2<bool>) -> f64 {
    let (mut rt, mut tt, mut peak) = (0.0f64, 0.0f64, 0.0f64);
    for c in 0..3 {
        let (r, t) = (
            reference.index_axis(Axis(0), c),
            test.index_axis(Axis(0), c),
        );
        for ((idx, &r), &t) in r.indexed_iter().zip(t.iter()) {
            if region[idx] {
                rt += f64::from(r) * f64::from(t);
                tt += f64::from(t) * f64::from(t);
                peak = peak.max(f64::from(r));
            }
        }
    }
    let s = rt / tt.max(1e-30);
    let (mut se, mut n) = (0.0f64, 0usize);
    for c in 0..3 {
        let (r, t) = (
            reference.index_axis(Axis(0), c),
            test.index_axis(Axis(0), c),
        );
        for ((idx, &r), &t) in r.indexed_iter().zip(t.iter()) {
            if region[idx] {
                se += (f64::from(r) - s * f64::from(t)).powi(2);
                n += 1;
            }
        }
    }
    10.0 * (peak * peak * n as f64 / se.max(1e-30)).log10()
}

/// What the SLM pattern displays focused at normalised depth `d` (the field zero-padded).
fn displayed(out: &SlmFrame, d: f64) -> Array3<f32> {
    let setup = OpticalSetup::default();
    let options = PropagationOptions {
        pad: true,
        ..Default::default()
    };
    let shown = post_encoding_midpoint(
        out.phase.view(),
        out.amplitude_scale,
        &setup,
        OFFSET_M,
        options,
    )
    .unwrap();
    focal_stack(shown.view(), &setup, 0.0, &[d], options, false)
        .unwrap()
        .remove(0)
}

/// The GPU's foveated frame against the CPU's: the composed heads everywhere (complex), the periphery's
/// phase, the normaliser (bit for bit: the same rule on the same frame), the pattern (over the whole frame
/// with AA-DPM; with the DDPM pre-filter, which the GPU runs over the whole frame and the CPU on its tile,
/// within `R + B + 40` of the gaze, relative to each frame's mean phase), and the displayed image at the
/// gaze's plane inside the fovea.
#[test]
fn gpu_foveated_frames_match_the_cpu() {
    let Some(ctx) = gpu_common::context() else {
        return;
    };
    let cases = [
        ("tum", PrefilterMode::Required, "DDPM pre-filter"),
        ("iphone", PrefilterMode::Off, "AA-DPM"),
    ];
    for (name, prefilter, what) in cases {
        let frame = frame(name);
        let mut gpu = session(&ctx, Backend::Gpu, prefilter, RADIUS);
        let mut cpu = session(&ctx, Backend::Cpu, prefilter, RADIUS);
        // Inside the frame (the tile away from the edges), and at a corner (the tile clipped).
        for gaze in [(131.4, 90.7), (0.0, 191.0)] {
            let gaze = Gaze {
                x: gaze.0,
                y: gaze.1,
                depth_m: None,
            };
            let what = format!("{name}, {what}, gaze ({}, {})", gaze.x, gaze.y);
            let g = gpu.render_foveated(&frame, &gaze).unwrap().clone();
            let gr = *gpu.fovea_report().unwrap();
            let c = cpu.render_foveated(&frame, &gaze).unwrap().clone();
            let cr = *cpu.fovea_report().unwrap();
            assert_eq!(g.backend, Backend::Gpu, "{what}");
            assert_eq!(c.backend, Backend::Cpu, "{what}");
            assert!(!gr.covers_frame && gr.cnn_share < 0.5, "{what}: {gr:?}");
            assert_eq!(
                (gr.tile, gr.gaze_depth, gr.cnn_share, gr.radius_px),
                (cr.tile, cr.gaze_depth, cr.cnn_share, cr.radius_px),
                "{what}"
            );
            if gaze.x == 0.0 {
                assert_eq!((gr.tile[0], gr.tile[1]), (H - gr.tile[2], 0), "{what}");
            }
            let theta = (0..3)
                .map(|k| phase_distance(gr.periphery_phase_rad[k], cr.periphery_phase_rad[k]))
                .fold(0.0f32, f32::max);
            assert_eq!(
                g.amplitude_scale, c.amplitude_scale,
                "{what}: the normaliser"
            );
            assert!(g.timings.gpu_s > 0.0 && g.timings.total_s >= g.timings.gpu_s);
            // The composed midpoint hologram.
            let (gf, cf) = (
                gpu.last_heads().unwrap().to_field().unwrap(),
                cpu.last_heads().unwrap().to_field().unwrap(),
            );
            let peak = cf.iter().fold(0.0f32, |m, v| m.max(v.norm()));
            let heads = gf
                .iter()
                .zip(cf.iter())
                .fold(0.0f32, |m, (a, b): (&Complex32, &Complex32)| {
                    m.max((a - b).norm())
                })
                / peak;
            // The pattern: in the region where both frames ran the same stages.
            let near = RADIUS + 16.0 + 40.0;
            let (mut compared, mut off, mut max_d, mut sum_d) = (0usize, 0usize, 0.0f32, 0.0f64);
            for ch in 0..3 {
                for y in 0..H {
                    for x in 0..W {
                        if prefilter == PrefilterMode::Required && distance(&gaze, y, x) >= near {
                            continue;
                        }
                        let d = phase_distance(
                            g.phase[[ch, y, x]] + g.mean_phase[ch],
                            c.phase[[ch, y, x]] + c.mean_phase[ch],
                        );
                        compared += 1;
                        max_d = max_d.max(d);
                        sum_d += f64::from(d);
                        // Two LUT steps.
                        if d > 2.0 * std::f32::consts::TAU / 256.0 {
                            off += 1;
                        }
                    }
                }
            }
            let check = SelfCheck::compare(&g.codes, &c.codes);
            // What the pattern displays at the gaze's plane, inside the fovea.
            let fovea = Array2::from_shape_fn((H, W), |(y, x)| distance(&gaze, y, x) < RADIUS);
            let psnr = psnr_ls(
                &displayed(&c, gr.gaze_depth),
                &displayed(&g, gr.gaze_depth),
                &fovea,
            );
            println!(
                "{what}: heads max |ΔU|/peak {heads:.1e}, periphery phase Δ {theta:.1e} rad, pattern Δ \
                 (mean-free) max {max_d:.1e} / mean {:.1e} rad, {off} of {compared} beyond two steps; codes \
                 off by >1 step {} of {}; displayed at the gaze's plane, fovea: {psnr:.1} dB",
                sum_d / compared as f64,
                check.codes_off_by_more_than_one,
                check.codes
            );
            assert!(heads < 1e-4, "{what}: heads {heads}");
            assert!(theta < 1e-3, "{what}: periphery phase {theta}");
            assert!(
                off as f64 <= 1e-3 * compared as f64,
                "{what}: pattern {off}"
            );
            if prefilter == PrefilterMode::Off {
                assert!(
                    check.codes_off_by_more_than_one as f64 <= 1e-3 * check.codes as f64,
                    "{what}: {check:?}"
                );
            }
            // With AA-DPM both frames run the same stages after the heads: the GPU tests' 40 dB. With the DDPM
            // pre-filter the CPU's frame has the base filter alone beyond its pre-filter's zone, whose light
            // still reaches a small fovea (a quarter disc of 40 pixels at a corner: 38.8 dB measured), where
            // the GPU's, like the full frame's, has the whole pre-filter.
            let bound = if prefilter == PrefilterMode::Off {
                40.0
            } else {
                35.0
            };
            assert!(psnr >= bound, "{what}: displayed {psnr} dB");
        }
    }
}

/// A fovea covering the frame, and a tile as large as the frame, render the GPU's full frame bit for bit; a
/// moving gaze (jumping across the frame) creates no GPU object; one gaze twice gives the same bits.
#[test]
fn full_frames_bit_for_bit_and_a_moving_gaze_without_new_gpu_objects() {
    let Some(ctx) = gpu_common::context() else {
        return;
    };
    let frame = frame("iphone");
    let centre = Gaze {
        x: 127.5,
        y: 95.5,
        depth_m: None,
    };
    let corner = Gaze {
        x: 255.0,
        y: 0.0,
        depth_m: None,
    };
    // 160 pixels covers the frame from its centre (its corners 159.3 pixels away), and makes the tile
    // (2·⌈R + B⌉ + 3 + 2·8 = 371) the whole frame from any gaze, the corner's included.
    let mut s = session(&ctx, Backend::Gpu, PrefilterMode::Required, 160.0);
    let full = s.render(&frame).unwrap().clone();
    for gaze in [centre, corner] {
        let fov = s.render_foveated(&frame, &gaze).unwrap().clone();
        let report = *s.fovea_report().unwrap();
        // The report says a full frame was rendered (as the CPU's).
        assert!(report.covers_frame && report.cnn_share == 1.0, "{report:?}");
        assert_eq!(fov.backend, Backend::Gpu);
        assert_eq!(fov.codes, full.codes, "gaze {gaze:?}");
        assert_eq!(
            fov.phase.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            full.phase.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(
            fov.amplitude_scale.to_bits(),
            full.amplitude_scale.to_bits()
        );
    }
    // Backend::Auto: the first foveated frame makes the self-check on a full frame, then runs on the GPU.
    let mut s = session(&ctx, Backend::Auto, PrefilterMode::Required, RADIUS);
    assert!(s.backend_report().self_check.is_none());
    let out = s.render_foveated(&frame, &centre).unwrap();
    assert_eq!(out.backend, Backend::Gpu);
    let check = s.backend_report().self_check.unwrap();
    assert!(check.passed, "{check:?}");
    assert!(!s.fovea_report().unwrap().covers_frame);
    s.set_full_outputs(false);
    let gazes = [
        Gaze {
            x: 30.0,
            y: 20.0,
            depth_m: None,
        },
        Gaze {
            x: 250.2,
            y: 185.9,
            depth_m: Some(1e-3),
        },
    ];
    let first = s.render_foveated(&frame, &gazes[0]).unwrap().codes.clone();
    let before = ctx.resource_counts();
    let second = s.render_foveated(&frame, &gazes[1]).unwrap().codes.clone();
    let report = *s.fovea_report().unwrap();
    let again = s.render_foveated(&frame, &gazes[0]).unwrap().clone();
    assert_eq!(
        ctx.resource_counts(),
        before,
        "a foveated frame created GPU objects"
    );
    assert_eq!(again.backend, Backend::Gpu);
    assert_eq!(again.codes, first, "one gaze, other bits");
    assert_ne!(second, first, "two gazes, the same bits");
    assert_eq!(report.tile[..2], [H - report.tile[2], W - report.tile[3]]);
    // The normaliser does not follow the gaze.
    let a = again.amplitude_scale;
    s.render_foveated(&frame, &gazes[1]).unwrap();
    assert_eq!(s.output().amplitude_scale.to_bits(), a.to_bits());
}
