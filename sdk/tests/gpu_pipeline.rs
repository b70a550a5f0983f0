//! The whole frame on the GPU (`Backend::Gpu`) against the CPU path (`Backend::Cpu`) with the shipped CNNs,
//! on whatever adapter exists (CI: Mesa's lavapipe); the backend choice of `Backend::Auto` (self-check), the
//! CPU fallback when the device is lost mid-stream, and that frames create no GPU objects.
//! Skips with a message where no adapter exists, unless `TENSORHOLO_REQUIRE_GPU=1`.

use ndarray::Array3;
use tensorholo::gpu::GpuContext;
use tensorholo::pipeline::{
    Backend, GpuPrecision, HologramPipeline, ModelSelection, PipelineConfig, PrefilterMode,
    SelfCheck, SlmFrame,
};
use tensorholo::scene::procedural::default_scene;
use tensorholo::scene::RgbdFrame;

mod gpu_common;

/// Non-square, not a power of two (radix 2·3 and 2·5 FFTs), small enough for a software GPU.
const H: usize = 48;
const W: usize = 60;

fn pipeline(
    ctx: &GpuContext,
    backend: Backend,
    offset_m: f64,
    prefilter: PrefilterMode,
) -> HologramPipeline {
    pipeline_in(ctx, backend, offset_m, prefilter, GpuPrecision::F32)
}

fn pipeline_in(
    ctx: &GpuContext,
    backend: Backend,
    offset_m: f64,
    prefilter: PrefilterMode,
    gpu_precision: GpuPrecision,
) -> HologramPipeline {
    let selection = ModelSelection {
        layers: 8,
        prefilter,
        ..ModelSelection::default()
    };
    let config = PipelineConfig {
        offset_m,
        backend,
        gpu_precision,
        ..PipelineConfig::default()
    };
    HologramPipeline::embedded(&selection, config)
        .unwrap()
        .with_gpu_context(ctx.clone())
}

/// Cyclic phase distance in radians.
fn phase_distance(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(std::f32::consts::TAU);
    d.min(std::f32::consts::TAU - d)
}

fn max_relative(a: &Array3<f32>, b: &Array3<f32>) -> f32 {
    let scale = b.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b.iter())
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// Compares a GPU frame with the CPU's and prints the figures.
/// `f16`: the GPU CNNs ran with f16 activations (looser bounds: 1 % of the codes, 2e-3 on the normaliser and
/// the mean phase, instead of 0.1 % and 1e-4).
fn assert_close(what: &str, gpu: &SlmFrame, cpu: &SlmFrame, f16: bool) {
    let (max_off_fraction, tol) = if f16 { (1e-2, 2e-3) } else { (1e-3, 1e-4) };
    assert_eq!(gpu.backend, Backend::Gpu, "{what}");
    assert_eq!(cpu.backend, Backend::Cpu, "{what}");
    let check = SelfCheck::compare(&gpu.codes, &cpu.codes);
    let max_phase = gpu
        .phase
        .iter()
        .zip(cpu.phase.iter())
        .fold(0.0f32, |m, (&a, &b)| m.max(phase_distance(a, b)));
    let scale_rel = (gpu.amplitude_scale - cpu.amplitude_scale).abs() / cpu.amplitude_scale;
    let mean = (0..3)
        .map(|c| phase_distance(gpu.mean_phase[c], cpu.mean_phase[c]))
        .fold(0.0f32, f32::max);
    println!(
        "{what}: codes off by >1 step {} of {}, max code Δ {}, max phase Δ {max_phase:.2e} rad, \
         normaliser rel Δ {scale_rel:.1e}, mean phase Δ {mean:.1e} rad",
        check.codes_off_by_more_than_one, check.codes, check.max_code_difference
    );
    assert!(scale_rel < tol, "{what}: normaliser {scale_rel}");
    assert!(mean < tol, "{what}: mean phase {mean}");
    assert!(
        check.codes_off_by_more_than_one as f64 <= max_off_fraction * check.codes as f64,
        "{what}: {check:?}"
    );
}

fn frame() -> RgbdFrame {
    default_scene(H, W).unwrap()
}

#[test]
fn gpu_frames_match_the_cpu_with_and_without_offset_and_pre_filter() {
    let Some(ctx) = gpu_common::context() else {
        return;
    };
    let frame = frame();
    let mut cases = vec![
        (
            6e-3,
            PrefilterMode::Required,
            GpuPrecision::F32,
            "6 mm, DDPM pre-filter, f32",
        ),
        (
            6e-3,
            PrefilterMode::Off,
            GpuPrecision::F32,
            "6 mm, AA-DPM, f32",
        ),
        (
            0.0,
            PrefilterMode::Off,
            GpuPrecision::F32,
            "0 mm, AA-DPM, f32",
        ),
    ];
    if ctx.info().shader_f16 {
        cases.push((
            6e-3,
            PrefilterMode::Required,
            GpuPrecision::F16,
            "6 mm, DDPM pre-filter, f16",
        ));
    }
    for (offset_m, prefilter, precision, what) in cases {
        let f16 = precision == GpuPrecision::F16;
        let mut gpu = pipeline_in(&ctx, Backend::Gpu, offset_m, prefilter, precision)
            .session(H, W)
            .unwrap();
        assert_eq!(
            gpu.backend_report().gpu_precision.as_deref(),
            Some(precision.name())
        );
        let mut cpu = pipeline(&ctx, Backend::Cpu, offset_m, prefilter)
            .session(H, W)
            .unwrap();
        assert_eq!(gpu.backend_report().active, Backend::Gpu);
        assert_eq!(cpu.backend_report().active, Backend::Cpu);
        let g = gpu.render(&frame).unwrap().clone();
        let c = cpu.render(&frame).unwrap().clone();
        assert_close(what, &g, &c, f16);
        // The midpoint hologram (CNN heads) the GPU downloads on request.
        let (gh, ch) = (gpu.last_heads().unwrap(), cpu.last_heads().unwrap());
        let amp = max_relative(&gh.amplitude, &ch.amplitude);
        let phs = max_relative(&gh.phase, &ch.phase);
        println!("{what}: heads max rel Δ amplitude {amp:.1e}, phase {phs:.1e}");
        let bound = if f16 { 2e-3 } else { 1e-4 };
        assert!(amp < bound && phs < bound, "{what}: heads {amp} {phs}");
    }
}

#[test]
fn frames_create_no_gpu_objects_and_a_stream_equals_single_frames() {
    let Some(ctx) = gpu_common::context() else {
        return;
    };
    let frames: Vec<RgbdFrame> = (0..3)
        .map(|i| {
            let mut f = frame();
            f.amplitude.mapv_inplace(|v| v * (1.0 - 0.2 * i as f32));
            f
        })
        .collect();
    let p = pipeline(&ctx, Backend::Gpu, 6e-3, PrefilterMode::Required);
    let mut session = p.session(H, W).unwrap();
    session.render(&frames[0]).unwrap();
    let before = ctx.resource_counts();
    let singles: Vec<Array3<u8>> = frames
        .iter()
        .map(|f| session.render(f).unwrap().codes.clone())
        .collect();
    let mut streamed = Vec::new();
    session
        .render_stream(frames.iter().cloned().map(Ok), |_, out| {
            assert_eq!(out.backend, Backend::Gpu);
            streamed.push(out.codes.clone());
            Ok(())
        })
        .unwrap();
    assert_eq!(ctx.resource_counts(), before, "a frame created GPU objects");
    assert_eq!(streamed, singles);
    // Different frames give different codes (the comparison above could not pass on stale output).
    assert_ne!(singles[0], singles[2]);
}

#[test]
fn auto_keeps_the_gpu_after_its_self_check() {
    let Some(ctx) = gpu_common::context() else {
        return;
    };
    // Auto on a context the caller gives (software allowed: it was chosen explicitly).
    let frame = frame();
    let mut auto = pipeline(&ctx, Backend::Auto, 6e-3, PrefilterMode::Required)
        .session(H, W)
        .unwrap();
    assert_eq!(auto.backend_report().active, Backend::Gpu);
    assert!(auto.backend_report().self_check.is_none());
    let first = auto.render(&frame).unwrap().clone();
    let report = auto.backend_report().clone();
    let check = report
        .self_check
        .expect("the first frame runs the self-check");
    assert!(check.passed, "{report:?}");
    assert_eq!(report.active, Backend::Gpu, "{report:?}");
    assert!(
        report.reason.contains("self-check passed"),
        "{}",
        report.reason
    );
    assert_eq!(first.backend, Backend::Gpu);
    let second = auto.render(&frame).unwrap();
    assert_eq!(second.backend, Backend::Gpu);
    assert_eq!(second.codes, first.codes, "the GPU is deterministic");
}

#[test]
fn a_lost_device_falls_back_to_the_cpu_without_losing_the_frame() {
    // A context of its own: destroying its device must not disturb the other tests.
    let Some(ctx) = gpu_common::context() else {
        return;
    };
    let frame = frame();
    let mut gpu = pipeline(&ctx, Backend::Gpu, 6e-3, PrefilterMode::Required)
        .session(H, W)
        .unwrap();
    let mut cpu = pipeline(&ctx, Backend::Cpu, 6e-3, PrefilterMode::Required)
        .session(H, W)
        .unwrap();
    assert_eq!(gpu.render(&frame).unwrap().backend, Backend::Gpu);
    ctx.device().destroy();
    let out = gpu
        .render(&frame)
        .expect("the frame is rendered on the CPU");
    assert_eq!(out.backend, Backend::Cpu);
    let expected = cpu.render(&frame).unwrap();
    assert_eq!(out.codes, expected.codes, "the fallback frame is the CPU's");
    let report = gpu.backend_report();
    assert_eq!(report.active, Backend::Cpu);
    assert!(report.reason.contains("GPU failed"), "{}", report.reason);
    assert_eq!(gpu.render(&frame).unwrap().backend, Backend::Cpu);
}

#[test]
fn bad_frames_are_refused_before_the_gpu_and_the_session_stays_usable() {
    let Some(ctx) = gpu_common::context() else {
        return;
    };
    let mut session = pipeline(&ctx, Backend::Gpu, 6e-3, PrefilterMode::Required)
        .session(H, W)
        .unwrap();
    let wrong = default_scene(H, W + 2).unwrap();
    let err = session.render(&wrong).unwrap_err();
    assert!(err.to_string().contains("shape mismatch"), "{err}");
    let mut nan = frame();
    nan.depth[[3, 4]] = f32::NAN;
    assert!(session.render(&nan).is_err());
    assert_eq!(session.render(&frame()).unwrap().backend, Backend::Gpu);
    assert_eq!(session.backend_report().active, Backend::Gpu);
}

#[test]
fn gpu_previews_match_the_cpu_simulation_of_the_codes() {
    use tensorholo::encoding::LinearLut;
    use tensorholo::optics::{focal_stack, post_encoding_midpoint};
    let Some(ctx) = gpu_common::context() else {
        return;
    };
    let p = pipeline(&ctx, Backend::Gpu, 6e-3, PrefilterMode::Required);
    let config = *p.config();
    let mut session = p.session(H, W).unwrap();
    let out = session.render(&frame()).unwrap().clone();
    let shown = post_encoding_midpoint(
        out.codes.mapv(|c| LinearLut.phase(c)).view(),
        out.amplitude_scale,
        &config.optics,
        config.offset_m,
        config.options,
    )
    .unwrap();
    let before = ctx.resource_counts();
    for focus in [0.0, 0.35, 1.0, 0.35] {
        let cpu = focal_stack(
            shown.view(),
            &config.optics,
            0.0,
            &[focus],
            config.options,
            false,
        )
        .unwrap()
        .remove(0);
        let gpu = session
            .accelerator_preview(&out.codes, out.amplitude_scale, focus)
            .expect("the GPU runs the session")
            .unwrap();
        let e = max_relative(&gpu, &cpu);
        println!("preview at d = {focus}: max rel Δ {e:.1e}");
        assert!(e < 1e-4, "d = {focus}: {e}");
    }
    // The first preview builds its buffers and each new focus its transfer functions; a repeated focus
    // creates nothing.
    let after = ctx.resource_counts();
    session
        .accelerator_preview(&out.codes, out.amplitude_scale, 0.35)
        .unwrap()
        .unwrap();
    assert_eq!(ctx.resource_counts(), after);
    assert!(after.buffers > before.buffers);
    let err = session
        .accelerator_preview(&out.codes, out.amplitude_scale, 1.5)
        .unwrap()
        .unwrap_err();
    assert!(err.to_string().contains("focus"), "{err}");
}

#[test]
fn a_display_calibration_applies_on_the_gpu_path_as_on_the_cpu() {
    use std::sync::Arc;
    use tensorholo::slm::{
        DisplayCalibration, LutRepresentation, PhaseCurve, PhaseLut, TiledCurves,
    };
    let Some(ctx) = gpu_common::context() else {
        return;
    };
    // Red: a global gamma curve; green: per-pixel tiles and an intensity map; blue: linear.
    let mut cal = DisplayCalibration::linear(H, W).unwrap();
    cal.colours[0].lut = PhaseLut::new(LutRepresentation::Global(
        PhaseCurve::gamma(7.5, 1.3).unwrap(),
    ));
    let curves = (0..6 * 8)
        .map(|t| PhaseCurve::gamma(7.0 + 0.02 * t as f32, 0.9).unwrap())
        .collect();
    cal.colours[1].lut = PhaseLut::new(LutRepresentation::Tiled(
        TiledCurves::new(H, W, 8, 8, curves).unwrap(),
    ));
    cal.colours[1].intensity_scale = Some(ndarray::Array2::from_shape_fn((H, W), |(y, x)| {
        0.5 + 0.5 * ((x + y) % 7) as f32 / 6.0
    }));
    let cal = Arc::new(cal);
    let calibrated = |backend| {
        pipeline(&ctx, backend, 6e-3, PrefilterMode::Required)
            .with_calibration(cal.clone())
            .unwrap()
    };
    let mut gpu = calibrated(Backend::Gpu).session(H, W).unwrap();
    // Only the codes an SLM needs: the look-up tables still get the phase they need.
    gpu.set_full_outputs(false);
    let mut cpu = calibrated(Backend::Cpu).session(H, W).unwrap();
    let g = gpu.render(&frame()).unwrap().clone();
    let c = cpu.render(&frame()).unwrap().clone();
    assert_close("6 mm, DDPM, calibrated", &g, &c, false);
    let uncalibrated = pipeline(&ctx, Backend::Gpu, 6e-3, PrefilterMode::Required)
        .session(H, W)
        .unwrap()
        .render(&frame())
        .unwrap()
        .clone();
    for colour in 0..2 {
        let lane = |a: &Array3<u8>| a.index_axis(ndarray::Axis(0), colour).to_owned();
        assert_ne!(lane(&g.codes), lane(&uncalibrated.codes), "colour {colour}");
    }
}
