//! The GPU backend on a real RGB-D photo (Redwood living room, Kinect-style depth) against the CPU path, as a
//! user comparing `holo render --backend gpu` with `--backend cpu` would: the SLM codes agree to float
//! rounding, and what the SLM displays (phase-only simulation, focal stack) is as close to the SM-LBM
//! ground truth on both backends, within 0.1 dB PSNR.
//! Runs on whatever adapter exists (CI: Mesa's lavapipe); skips with a message where none exists, unless
//! `TENSORHOLO_REQUIRE_GPU=1`.

use ndarray::Array3;
use tensorholo::gpu::GpuContext;
use tensorholo::metrics::psnr;
use tensorholo::optics::focal_stack;
use tensorholo::pipeline::{
    Backend, GpuPrecision, HologramPipeline, ModelSelection, PipelineConfig, PrefilterMode,
    SelfCheck,
};
use tensorholo::reference::ReferencePipeline;
use tensorholo::scene::{load_rgbd, DepthEncoding, LoadOptions, RgbdFrame};
use tensorholo::synthesis::SceneLayer;
use tensorholo_integration_tests::{displayed_focal_stack, shared_data};

/// A context on any adapter, or a skip; required where `TENSORHOLO_REQUIRE_GPU=1` (`.ci/run`).
fn context() -> Option<GpuContext> {
    tensorholo::gpu::test_context(std::env::var("TENSORHOLO_REQUIRE_GPU").as_deref() == Ok("1"))
}

/// The displayed focal stack (phase-only SLM simulation, Eq. 8–10) of one backend's frame, and its codes.
fn displayed(
    ctx: &GpuContext,
    backend: Backend,
    precision: GpuPrecision,
    frame: &RgbdFrame,
    depths: &[f64],
) -> (Vec<Array3<f32>>, Array3<u8>) {
    let config = PipelineConfig {
        offset_m: 6e-3,
        backend,
        gpu_precision: precision,
        ..PipelineConfig::default()
    };
    let selection = ModelSelection {
        prefilter: PrefilterMode::Required,
        ..ModelSelection::default()
    };
    let pipeline = HologramPipeline::embedded(&selection, config)
        .unwrap()
        .with_gpu_context(ctx.clone());
    let mut session = pipeline.session(frame.height(), frame.width()).unwrap();
    let out = session.render(frame).unwrap();
    assert_eq!(out.backend, backend);
    (
        displayed_focal_stack(out, &config, depths),
        out.codes.clone(),
    )
}

#[test]
fn gpu_and_cpu_display_the_redwood_frame_equally_well_against_sm_lbm() {
    let Some(ctx) = context() else { return };
    let (frame, _) = load_rgbd(
        &shared_data("redwood_livingroom_seq/color/00000.jpg"),
        &shared_data("redwood_livingroom_seq/depth/00000.png"),
        DepthEncoding::Millimetres16,
        &LoadOptions {
            size: Some((120, 160)),
            ..LoadOptions::default()
        },
    )
    .unwrap();
    let depths = [0.1, 0.5, 0.9];
    let reference = ReferencePipeline::default();
    let layer = SceneLayer {
        amplitude: frame.amplitude.view(),
        depth: frame.depth.view(),
        valid: None,
    };
    let hologram = reference.run(&[layer], &|_, _| {}).unwrap();
    let truth = focal_stack(
        hologram.midpoint.view(),
        &reference.synthesis.setup,
        0.0,
        &depths,
        reference.synthesis.options,
        false,
    )
    .unwrap();
    let (cpu, cpu_codes) = displayed(&ctx, Backend::Cpu, GpuPrecision::F32, &frame, &depths);
    let mut precisions = vec![(GpuPrecision::F32, 1e-3)];
    if ctx.info().shader_f16 {
        // f16 activations move some codes by a step or two; the bound is the self-check's.
        precisions.push((GpuPrecision::F16, 1e-2));
    }
    for (precision, bound) in precisions {
        let name = precision.name();
        let (gpu, gpu_codes) = displayed(&ctx, Backend::Gpu, precision, &frame, &depths);
        let check = SelfCheck::compare(&gpu_codes, &cpu_codes);
        println!(
            "GPU {name}: codes off by more than one step: {} of {} (max Δ {})",
            check.codes_off_by_more_than_one, check.codes, check.max_code_difference
        );
        assert!(check.codes_off_by_more_than_one as f64 <= bound * check.codes as f64);
        for ((g, c), (t, d)) in gpu.iter().zip(&cpu).zip(truth.iter().zip(depths)) {
            let pg = psnr(t.view(), g.view(), 1.0).unwrap();
            let pc = psnr(t.view(), c.view(), 1.0).unwrap();
            println!(
                "GPU {name}, focus d = {d}: PSNR against SM-LBM: GPU {pg:.3} dB, CPU {pc:.3} dB"
            );
            assert!(
                (pg - pc).abs() < 0.1,
                "{name} d = {d}: GPU {pg} dB vs CPU {pc} dB"
            );
        }
    }
}
