//! The per-runtime suite, in the manner of tract's `test-rt`: one list of frame cases ([`cases`]), run
//! against every runtime this machine has ([`runtimes`]: the CPU frame with tract, the CPU frame with the
//! native engine on each kernel ISA row the CPU runs, the GPU frame on any adapter, lavapipe in CI), each
//! compared with one independent reference ([`reference`]: tract run stand-alone and the stand-alone optics
//! and encoding functions, allocating freely) instead of runtime against runtime.
//!
//! Adding an engine or an executor is one arm in [`Runtime`]; adding a case is one entry in [`cases`].

use ndarray::{Array2, Array3, Axis};
use tensorholo_kernels::Isa;

use super::config::{Backend, GpuPrecision, PipelineConfig};
use super::models::HologramPipeline;
use super::selection::{ModelSelection, PrefilterMode};
use crate::cnn::tract::TractModel;
use crate::cnn::{CnnEngine, CnnLayout, CnnOptions, ThreadCount};
use crate::encoding::{double_phase_encode, phase_to_codes};
use crate::model::{contract, heads_to_field, Precision, SceneInput};
use crate::optics::{propagate_colour, Carrier};
use crate::scene::RgbdFrame;

/// One frame case: the shipped models by name, the SLM offset, and the frame size.
struct Case {
    name: &'static str,
    precision: Precision,
    offset_m: f64,
    height: usize,
    width: usize,
}

fn cases() -> Vec<Case> {
    vec![
        Case {
            name: "holo8 f32, 0 mm",
            precision: Precision::F32,
            offset_m: 0.0,
            height: 24,
            width: 40,
        },
        Case {
            name: "holo8 f32, 6 mm + pre-filter",
            precision: Precision::F32,
            offset_m: 6e-3,
            height: 20,
            width: 36,
        },
        Case {
            name: "holo8 int8 QDQ, 6 mm + pre-filter",
            precision: Precision::Int8Qdq,
            offset_m: 6e-3,
            height: 18,
            width: 32,
        },
    ]
}

/// What runs a case's frame.
#[derive(Debug, Clone, Copy)]
enum Runtime {
    /// The CPU frame, CNNs on tract.
    CpuTract,
    /// The CPU frame, CNNs on the native engine forced onto one kernel ISA row.
    CpuNative(Isa),
    /// The GPU frame (f32), on the test context's adapter (cargo feature `gpu`; the workspace's tests
    /// enable it).
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    Gpu,
}

fn runtimes() -> Vec<Runtime> {
    let mut v = vec![Runtime::CpuTract];
    v.extend(Isa::available().into_iter().map(Runtime::CpuNative));
    #[cfg(feature = "gpu")]
    v.push(Runtime::Gpu);
    v
}

fn frame(h: usize, w: usize) -> RgbdFrame {
    let amp = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
        (((x * 7 + y * 13 + c * 5) % 17) as f32 / 16.0).sqrt()
    });
    let depth = Array2::from_shape_fn((h, w), |(y, x)| ((x + 2 * y) % 11) as f32 / 10.0);
    RgbdFrame::new(amp, depth).unwrap()
}

fn pipeline(case: &Case, backend: Backend, engine: CnnEngine) -> HologramPipeline {
    let selection = ModelSelection {
        input: SceneInput::Rgbd,
        layers: 8,
        precision: case.precision,
        prefilter: PrefilterMode::Required,
    };
    let selection = if case.offset_m == 0.0 {
        ModelSelection {
            prefilter: PrefilterMode::Off,
            ..selection
        }
    } else {
        selection
    };
    let config = PipelineConfig {
        offset_m: case.offset_m,
        backend,
        gpu_precision: GpuPrecision::F32,
        cnn: CnnOptions {
            engine,
            // The reference runs tract channels-first; channels-last differs by float rounding.
            layout: CnnLayout::ChannelsFirst,
            threads: ThreadCount::Fixed(1),
            ..CnnOptions::default()
        },
        ..PipelineConfig::default()
    };
    HologramPipeline::embedded(&selection, config).unwrap()
}

/// What a frame gives: the heads `[6, H, W]` (amplitude, phase), the double phase pattern `[3, H, W]`
/// (radians) and the SLM codes `[3, H, W]`.
type Frame = (Array3<f32>, Array3<f32>, Array3<u8>);

/// The reference frame of `p`: its CNNs on tract, run stand-alone, and the stand-alone optics and encoding
/// functions, allocating freely.
fn reference(p: &HologramPipeline, f: &RgbdFrame) -> Frame {
    let cfg = p.config();
    let (h, w) = (f.height(), f.width());
    let mut input = Array3::zeros((4, h, w));
    contract::pack_rgbd(f, input.view_mut()).unwrap();
    let (amplitude, phase) = TractModel::new(p.hologram_model())
        .unwrap()
        .plan(h, w)
        .unwrap()
        .run_outputs(input.view())
        .unwrap();
    let mut field = heads_to_field(amplitude.view(), phase.view()).unwrap();
    let heads = ndarray::concatenate(Axis(0), &[amplitude.view(), phase.view()]).unwrap();
    // Eq. 6; at 0 m there is nothing to propagate (the session skips the stage, and an FFT round trip
    // would only add rounding).
    if cfg.offset_m != 0.0 {
        propagate_colour(
            &mut field,
            &cfg.optics,
            cfg.offset_m,
            Carrier::Remove,
            cfg.options,
        )
        .unwrap();
    }
    if let Some(pre) = p.prefilter_model() {
        let planes = ndarray::concatenate(
            Axis(0),
            &[field.mapv(|v| v.re).view(), field.mapv(|v| v.im).view()],
        )
        .unwrap();
        field = TractModel::new(pre).unwrap().run(planes.view()).unwrap();
    }
    let dp = double_phase_encode(field.view(), &p.encoding()).unwrap();
    let codes = phase_to_codes(dp.phase.view());
    (heads, dp.phase, codes)
}

/// `case` on `runtime`, or `None` (with the reason printed) where this machine or this case has no such
/// runtime.
fn run(case: &Case, runtime: Runtime, f: &RgbdFrame) -> Option<Frame> {
    let (h, w) = (case.height, case.width);
    let mut session = match runtime {
        Runtime::CpuTract => pipeline(case, Backend::Cpu, CnnEngine::Tract)
            .session(h, w)
            .unwrap(),
        Runtime::CpuNative(isa) => {
            let p = pipeline(case, Backend::Cpu, CnnEngine::Native);
            let mut s = p.session(h, w).unwrap();
            // The same session with every CNN forced onto this ISA's kernel rows.
            s.cnn.plan = crate::cnn::native_plan_on(p.hologram_model(), h, w, isa).unwrap();
            if let Some(pre) = p.prefilter_model() {
                s.prefilter = Some(crate::cnn::native_plan_on(pre, h, w, isa).unwrap());
            }
            s
        }
        Runtime::Gpu => {
            #[cfg(feature = "gpu")]
            {
                if case.precision != Precision::F32 {
                    println!("  {runtime:?}: skipped (the GPU runs the f32 files)");
                    return None;
                }
                let ctx = crate::gpu::test_support::context()?;
                pipeline(case, Backend::Gpu, CnnEngine::Auto)
                    .with_gpu_context(ctx)
                    .session(h, w)
                    .unwrap()
            }
            #[cfg(not(feature = "gpu"))]
            return None;
        }
    };
    let out = session.render(f).unwrap();
    assert!(out.timings.total_s > 0.0);
    let (phase, codes) = (out.phase.clone(), out.codes.clone());
    let heads = session.last_heads().expect("full outputs keep the heads");
    let heads =
        ndarray::concatenate(Axis(0), &[heads.amplitude.view(), heads.phase.view()]).unwrap();
    Some((heads, phase, codes))
}

/// Codes whose cyclic difference is more than one step (one LUT step is a rounding tie).
fn codes_off(a: &Array3<u8>, b: &Array3<u8>) -> usize {
    a.iter()
        .zip(b)
        .filter(|(&x, &y)| x.wrapping_sub(y).min(y.wrapping_sub(x)) > 1)
        .count()
}

// One test per case, so that the harness runs them side by side (under qemu-aarch64 in CI, tract's load and plan
// of each case's CNNs take most of a minute).

#[test]
fn every_runtime_renders_case_0_as_the_reference() {
    every_runtime_renders_as_the_reference(0);
}

#[test]
fn every_runtime_renders_case_1_as_the_reference() {
    every_runtime_renders_as_the_reference(1);
}

#[test]
fn every_runtime_renders_case_2_as_the_reference() {
    every_runtime_renders_as_the_reference(2);
}

#[test]
fn every_case_has_a_test() {
    assert_eq!(cases().len(), 3, "add a test per new case above");
}

/// The case `index` of [`cases`] on every runtime, against the stand-alone reference.
fn every_runtime_renders_as_the_reference(index: usize) {
    {
        let case = cases().swap_remove(index);
        let f = frame(case.height, case.width);
        let (ref_heads, ref_phase, ref_codes) =
            reference(&pipeline(&case, Backend::Cpu, CnnEngine::Tract), &f);
        println!("{}:", case.name);
        for runtime in runtimes() {
            let Some((heads, phase, codes)) = run(&case, runtime, &f) else {
                continue;
            };
            let heads_err = heads
                .iter()
                .zip(&ref_heads)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            let off = codes_off(&codes, &ref_codes);
            println!(
                "  {runtime:?}: heads max |Δ| {heads_err:.1e}, {off} of {} codes off by > 1 step",
                codes.len()
            );
            // tract in the session is the reference's own CNN, and the session's optics run the same kernels
            // in the same order per colour as the stand-alone functions: bit for bit.
            if let Runtime::CpuTract = runtime {
                assert_eq!(phase, ref_phase, "{}: the double phase pattern", case.name);
            }
            // tract in the session: bit for bit (above). The native kernels sum in
            // another order (f32: float rounding; int8: the same integer sums, rounding at the requantised
            // grid points); the GPU in f32 as the self-check of `Backend::Auto` allows.
            let (max_heads, max_off) = match (runtime, case.precision) {
                (Runtime::CpuTract, _) => (0.0, 0),
                (Runtime::CpuNative(_), Precision::F32) => (1e-4, codes.len() / 1000),
                (Runtime::CpuNative(_), _) => (2e-2, codes.len() / 100),
                (Runtime::Gpu, _) => (1e-3, codes.len() / 100),
            };
            assert!(
                heads_err <= max_heads,
                "{} on {runtime:?}: heads differ by {heads_err}",
                case.name
            );
            assert!(
                off <= max_off,
                "{} on {runtime:?}: {off} codes off by more than one step",
                case.name
            );
        }
    }
}
