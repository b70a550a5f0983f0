//! The same hologram on every CPU: a session renders the built-in scene with the shipped CNNs and its
//! midpoint hologram and SLM codes are compared with reference files written on x86-64
//! (`tests/fixtures/parity/`). CI runs this test natively and for aarch64 under `qemu-aarch64` (docs/GUIDE.md
//! "ARM and phones"), where tract runs its NEON kernels and rustfft its NEON butterflies instead of AVX/FMA ones.
//!
//! Where differences come from: the two CPUs sum the same products in another order (tract's matrix-product
//! tiles, rustfft's radix passes) and fuse multiply-adds differently, so f32 results differ by rounding
//! (~1e-7 relative); int8 convolutions accumulate exactly in i32, and only the float rescaling rounds
//! differently. A phase that lands within rounding of a code boundary can then move one code: a handful of
//! codes change by ±1 (cyclically), never more.
//!
//! Regenerate the references (x86-64 only; review the diff): `TENSORHOLO_WRITE_PARITY=1 cargo test -p
//! tensorholo --test platform_parity`.
//!
//! The tract cases need the feature `tract`; the native engine's case runs in every build (CI's ARM step
//! builds without tract, as the phone library can: scripts/test-aarch64.sh).
#![cfg(feature = "embedded-models")]

use std::path::PathBuf;

use ndarray::{Array3, Array4, Axis};
use ndarray_npy::{read_npy, write_npy};
use num_complex::Complex32;
#[cfg(feature = "tract")]
use tensorholo::cnn::tract::TractModel;
use tensorholo::cnn::{CnnEngine, CnnLayout, CnnOptions, ThreadCount};
use tensorholo::model::Precision;
use tensorholo::pipeline::{
    Backend, HologramPipeline, ModelSelection, PipelineConfig, PrefilterMode,
};
use tensorholo::scene::procedural::default_scene;

/// Scene size: small enough for an emulated CPU, non-square so that a transposed axis cannot pass.
const H: usize = 64;
const W: usize = 96;

struct Case {
    name: &'static str,
    /// The case whose reference files it is compared with (its own, or the tract case of its precision).
    reference: &'static str,
    precision: Precision,
    /// The session's CPU CNN engine.
    engine: CnnEngine,
    layout: CnnLayout,
    /// Largest |Δ| of the midpoint hologram over its largest |value|.
    field_tol: f32,
    /// Largest fraction of SLM codes allowed to differ (each by ±1 at most).
    code_fraction_tol: f64,
}

const CASES: [Case; 5] = [
    Case {
        name: "f32_nchw",
        reference: "f32_nchw",
        engine: CnnEngine::Tract,
        precision: Precision::F32,
        layout: CnnLayout::ChannelsFirst,
        field_tol: 1e-5,
        code_fraction_tol: 1e-3,
    },
    Case {
        name: "f32_nhwc",
        reference: "f32_nhwc",
        engine: CnnEngine::Tract,
        precision: Precision::F32,
        layout: CnnLayout::ChannelsLast,
        field_tol: 1e-5,
        code_fraction_tol: 1e-3,
    },
    // int8: exact integer accumulation, but a float rescale that rounds an activation the other way moves
    // it one quantisation step (1/127 of its range); allow a few such steps, and report the actual figure.
    Case {
        name: "int8qdq_nchw",
        reference: "int8qdq_nchw",
        engine: CnnEngine::Tract,
        precision: Precision::Int8Qdq,
        layout: CnnLayout::ChannelsFirst,
        field_tol: 2e-2,
        code_fraction_tol: 1e-2,
    },
    Case {
        name: "int8qop_nchw",
        reference: "int8qop_nchw",
        engine: CnnEngine::Tract,
        precision: Precision::Int8QOperator,
        layout: CnnLayout::ChannelsFirst,
        field_tol: 2e-2,
        code_fraction_tol: 1e-2,
    },
    // The native engine (this CPU's SIMD kernel row) against the tract reference: its own midpoint hologram
    // (the session's CNN output) and its SLM codes.
    Case {
        name: "f32_native",
        reference: "f32_nchw",
        precision: Precision::F32,
        engine: CnnEngine::Native,
        layout: CnnLayout::ChannelsFirst,
        field_tol: 1e-5,
        code_fraction_tol: 1e-3,
    },
];

fn reference(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/parity")
        .join(name)
}

/// The midpoint hologram `[3, H, W]` (complex) and the session's SLM codes `[3, H, W]`.
fn render(case: &Case) -> (Array3<Complex32>, Array3<u8>) {
    let selection = ModelSelection {
        layers: 8,
        precision: case.precision,
        prefilter: PrefilterMode::Required,
        ..ModelSelection::default()
    };
    let config = PipelineConfig {
        offset_m: 6e-3,
        // The CPU path's parity across CPUs; the GPU has its own tests (gpu_pipeline.rs).
        backend: Backend::Cpu,
        cnn: CnnOptions {
            layout: case.layout,
            engine: case.engine,
            threads: ThreadCount::Fixed(1),
            ..CnnOptions::default()
        },
        ..PipelineConfig::default()
    };
    let pipeline = HologramPipeline::embedded(&selection, config).unwrap();
    let frame = default_scene(H, W).unwrap();
    let mut session = pipeline.session(H, W).unwrap();
    let codes = session.render(&frame).unwrap().codes.clone();
    let midpoint = match case.engine {
        // The midpoint of tract's channels-first plan, as the references were written.
        #[cfg(feature = "tract")]
        CnnEngine::Tract => TractModel::new(pipeline.hologram_model())
            .unwrap()
            .run_frame(&frame)
            .unwrap(),
        // The native engine's own midpoint (the session's CNN output), against tract's reference.
        _ => session
            .into_last_frame()
            .1
            .expect("the session keeps its heads")
            .to_field()
            .unwrap(),
    };
    (midpoint, codes)
}

/// `[2, 3, H, W]`: real and imaginary parts.
fn split(field: &Array3<Complex32>) -> Array4<f32> {
    ndarray::stack(
        Axis(0),
        &[field.mapv(|c| c.re).view(), field.mapv(|c| c.im).view()],
    )
    .unwrap()
}

// One test per case, so that the harness runs them side by side (under qemu-aarch64 in CI, each takes a minute,
// most of it loading and planning the two CNNs).

#[test]
#[cfg(feature = "tract")]
fn builtin_scene_renders_the_x86_reference_on_this_cpu_f32_nchw() {
    check_case("f32_nchw");
}

#[test]
#[cfg(feature = "tract")]
fn builtin_scene_renders_the_x86_reference_on_this_cpu_f32_nhwc() {
    check_case("f32_nhwc");
}

#[test]
#[cfg(feature = "tract")]
fn builtin_scene_renders_the_x86_reference_on_this_cpu_int8qdq_nchw() {
    check_case("int8qdq_nchw");
}

#[test]
#[cfg(feature = "tract")]
fn builtin_scene_renders_the_x86_reference_on_this_cpu_int8qop_nchw() {
    check_case("int8qop_nchw");
}

#[test]
fn builtin_scene_renders_the_x86_reference_on_this_cpu_f32_native() {
    check_case("f32_native");
}

#[test]
fn every_case_has_a_test() {
    let tested = [
        "f32_nchw",
        "f32_nhwc",
        "int8qdq_nchw",
        "int8qop_nchw",
        "f32_native",
    ];
    let names: Vec<&str> = CASES.iter().map(|c| c.name).collect();
    assert_eq!(names, tested);
}

/// Renders the case named `name` and compares it with its reference files (or writes them, with
/// `TENSORHOLO_WRITE_PARITY=1`).
fn check_case(name: &str) {
    let case = CASES.iter().find(|c| c.name == name).unwrap();
    let write = std::env::var_os("TENSORHOLO_WRITE_PARITY").is_some();
    if write {
        if std::env::consts::ARCH != "x86_64" {
            panic!("the references are x86-64 results; write them on an x86-64 machine");
        }
        std::fs::create_dir_all(reference("")).unwrap();
    }
    {
        let (midpoint, codes) = render(case);
        let field_file = reference(&format!("builtin_{}_midpoint.npy", case.reference));
        let codes_file = reference(&format!("builtin_{}_codes.npy", case.reference));
        if write {
            if case.reference == case.name {
                write_npy(&field_file, &split(&midpoint)).unwrap();
                write_npy(&codes_file, &codes).unwrap();
            }
            return;
        }
        let want_field: Array4<f32> =
            read_npy(&field_file).unwrap_or_else(|e| panic!("{}: {e}", field_file.display()));
        let want_codes: Array3<u8> =
            read_npy(&codes_file).unwrap_or_else(|e| panic!("{}: {e}", codes_file.display()));
        let got_field = split(&midpoint);
        assert_eq!(got_field.dim(), want_field.dim(), "{}", case.name);
        assert_eq!(codes.dim(), want_codes.dim(), "{}", case.name);

        let scale = want_field.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(
            scale > 0.1,
            "{}: the reference hologram is empty",
            case.name
        );
        let field_err = got_field
            .iter()
            .zip(want_field.iter())
            .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()))
            / scale;
        // Codes are phases modulo 2π: 255 and 0 are neighbours.
        let steps: Vec<u8> = codes
            .iter()
            .zip(want_codes.iter())
            .map(|(a, b)| a.wrapping_sub(*b).min(b.wrapping_sub(*a)))
            .collect();
        let max_step = steps.iter().copied().max().unwrap();
        let changed = steps.iter().filter(|&&s| s != 0).count();
        let fraction = changed as f64 / steps.len() as f64;
        println!(
            "platform parity on {} ({H}×{W} built-in scene, holo8 + DDPM pre-filter, 6 mm): \
             {:<13} midpoint hologram max |Δ|/max|h| {field_err:.1e} (tolerance {:.0e}); \
             SLM codes: {changed} of {} differ ({:.3} %), by at most {max_step}",
            std::env::consts::ARCH,
            case.name,
            case.field_tol,
            steps.len(),
            100.0 * fraction
        );
        assert!(
            field_err <= case.field_tol,
            "{}: midpoint hologram differs from the x86-64 reference by {field_err:e} (relative)",
            case.name
        );
        assert!(
            max_step <= 1,
            "{}: an SLM code moved by {max_step} (rounding moves one code by at most 1)",
            case.name
        );
        assert!(
            fraction <= case.code_fraction_tol,
            "{}: {changed} SLM codes differ from the x86-64 reference",
            case.name
        );
    }
}
