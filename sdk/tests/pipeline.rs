//! The real-time pipeline (`tensorholo::pipeline`, docs/CONVENTIONS.md §8) on the random-init fixture CNNs:
//! layouts, streaming vs single frames, and bad input. The session against a naive composition of the SDK's
//! stand-alone stages, on every engine and executor, is the per-runtime suite (`sdk/src/pipeline/suite.rs`).
// Some helpers and imports serve only the tests that compare with tract (cargo feature `tract`).
#![cfg_attr(not(feature = "tract"), allow(unused_imports, dead_code))]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use ndarray::{Array2, Array3};
#[cfg(feature = "tract")]
use tensorholo::cnn::tract::TractModel;
use tensorholo::cnn::{CnnEngine, CnnLayout, CnnOptions};
use tensorholo::model::{HologramModel, ModelConfig, ModelKind};
use tensorholo::pipeline::{Backend, HologramPipeline, PipelineConfig};
use tensorholo::scene::RgbdFrame;
use tensorholo::HoloError;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/models")
        .join(name)
}

fn load(name: &str, kind: ModelKind) -> Arc<HologramModel> {
    Arc::new(HologramModel::from_path(fixture(name), kind, &ModelConfig::default()).unwrap())
}

/// The fixtures are trained for a 6 mm offset.
fn config(offset_m: f64) -> PipelineConfig {
    PipelineConfig {
        offset_m,
        // These tests pin the CPU path (bit-exact streams, stage by stage); the GPU has gpu_pipeline.rs.
        backend: Backend::Cpu,
        // and tract, which the naive composition runs (`CnnEngine::Auto` is the native engine, which agrees
        // with tract to ~1e-7, not bit for bit: src/cnn/tests.rs). A build without
        // tract runs the tests that do not compare with the naive composition on the native engine.
        cnn: CnnOptions {
            engine: if cfg!(feature = "tract") {
                CnnEngine::Tract
            } else {
                CnnEngine::Native
            },
            ..CnnOptions::default()
        },
        ..PipelineConfig::default()
    }
}

fn pipeline(prefilter: bool) -> HologramPipeline {
    let pre = prefilter.then(|| load("holo8_rgbd.prefilter.onnx", ModelKind::PreFilter));
    HologramPipeline::new(
        load("holo8_rgbd.onnx", ModelKind::Hologram),
        pre,
        config(6e-3),
    )
    .unwrap()
}

fn frame(h: usize, w: usize, seed: usize) -> RgbdFrame {
    let amp = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
        (((x * 7 + y * 13 + c * 5 + seed * 3) % 17) as f32 / 16.0).sqrt()
    });
    let depth = Array2::from_shape_fn((h, w), |(y, x)| ((x + 2 * y + seed) % 11) as f32 / 10.0);
    RgbdFrame::new(amp, depth).unwrap()
}

/// The hologram CNN run channels-last gives the same hologram as channels-first up to float rounding, so the
/// SLM phase agrees to well under one 8-bit code (2π/256 = 0.025 rad), circularly.
#[test]
#[cfg(feature = "tract")]
fn channels_last_session_agrees_with_channels_first() {
    let f = frame(24, 32, 1);
    let render = |layout| {
        let p = HologramPipeline::new(
            load("holo8_rgbd.onnx", ModelKind::Hologram),
            Some(load("holo8_rgbd.prefilter.onnx", ModelKind::PreFilter)),
            PipelineConfig {
                cnn: CnnOptions {
                    layout,
                    ..CnnOptions::default()
                },
                ..config(6e-3)
            },
        )
        .unwrap();
        let mut s = p.session(24, 32).unwrap();
        let out = s.render(&f).unwrap().clone();
        (out, s.last_heads().unwrap().amplitude.clone())
    };
    let (first, amp_first) = render(CnnLayout::ChannelsFirst);
    let (last, amp_last) = render(CnnLayout::ChannelsLast);
    let amp = amp_first
        .iter()
        .zip(amp_last.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    let tau = std::f32::consts::TAU;
    let phase = first
        .phase
        .iter()
        .zip(last.phase.iter())
        .map(|(a, b)| {
            let d = (a - b).abs() % tau;
            d.min(tau - d)
        })
        .fold(0.0f32, f32::max);
    println!("channels-last vs first: max |Δamplitude head| {amp:.2e}, max circular |Δphase| {phase:.2e} rad");
    assert!(amp < 1e-5, "{amp}");
    assert!(phase < 1e-3, "{phase}");
}

#[test]
fn zero_offset_refuses_an_offset_trained_cnn_and_any_prefilter() {
    let p = HologramPipeline::new(
        load("holo8_rgbd.onnx", ModelKind::Hologram),
        None,
        config(0.0),
    );
    // The fixture CNN was exported for 6 mm (jointly trained with its pre-filter), so 0 mm is refused ...
    assert!(matches!(p, Err(HoloError::DisplayNotServed(_))));
    // ... and a pre-filter never runs at 0 mm.
    let e = HologramPipeline::new(
        load("holo8_rgbd.onnx", ModelKind::Hologram),
        Some(load("holo8_rgbd.prefilter.onnx", ModelKind::PreFilter)),
        PipelineConfig {
            offset_m: 0.0,
            ..PipelineConfig::default()
        },
    )
    .unwrap_err();
    assert!(matches!(
        e,
        HoloError::DisplayNotServed(_) | HoloError::InvalidParameter { .. }
    ));
}

#[test]
fn stream_equals_single_frames_bit_for_bit() {
    let p = pipeline(true);
    let frames: Vec<RgbdFrame> = (0..4).map(|i| frame(16, 20, i)).collect();
    let mut single = p.session(16, 20).unwrap();
    let expected: Vec<Array3<u8>> = frames
        .iter()
        .map(|f| single.render(f).unwrap().codes.clone())
        .collect();
    let mut session = p.session(16, 20).unwrap();
    let mut got = Vec::new();
    let n = session
        .render_stream(frames.clone().into_iter().map(Ok), |i, out| {
            assert_eq!(i, got.len());
            assert!(out.timings.total_s > 0.0);
            got.push(out.codes.clone());
            Ok(())
        })
        .unwrap();
    assert_eq!(n, 4);
    assert_eq!(got, expected);
    // Frames differ, so the comparison means something.
    assert_ne!(expected[0], expected[1]);
}

#[test]
fn bad_input_is_refused_and_the_session_stays_usable() {
    let p = pipeline(true);
    let mut session = p.session(16, 20).unwrap();
    let good = frame(16, 20, 1);
    let first = session.render(&good).unwrap().codes.clone();

    let e = session.render(&frame(20, 16, 1)).unwrap_err();
    assert!(matches!(e, HoloError::ShapeMismatch { .. }), "{e}");

    // A black frame: the CNN's output would be its bias (not zero), shown at full brightness. Refused on the
    // RGB-D path (the LDI path packs through the same check); a frame at sRGB code 2 renders.
    let mut black = good.clone();
    black.amplitude.fill(0.0);
    let e = session.render(&black).unwrap_err();
    assert!(
        matches!(&e, HoloError::InvalidData(m) if m.contains("black")),
        "{e}"
    );
    black
        .amplitude
        .fill(tensorholo::color::srgb8_to_amplitude(1));
    assert!(session.render(&black).is_err());
    black
        .amplitude
        .fill(tensorholo::color::srgb8_to_amplitude(2));
    session.render(&black).unwrap();

    assert_eq!(session.render(&good).unwrap().codes, first);
    let mut stream = p.session(16, 20).unwrap();
    let frames = vec![Ok(good.clone()), Ok(frame(8, 8, 0)), Ok(good.clone())];
    let mut delivered = 0;
    let e = stream
        .render_stream(frames, |_, _| {
            delivered += 1;
            Ok(())
        })
        .unwrap_err();
    assert!(matches!(e, HoloError::ShapeMismatch { .. }), "{e}");
    assert_eq!(delivered, 1);
    assert_eq!(stream.render(&good).unwrap().codes, first);
}

#[test]
fn pipeline_refuses_mismatched_models() {
    let holo = load("holo8_rgbd.onnx", ModelKind::Hologram);
    let pre = load("holo8_rgbd.prefilter.onnx", ModelKind::PreFilter);
    let e = HologramPipeline::new(holo.clone(), Some(pre), config(12e-3)).unwrap_err();
    assert!(
        matches!(&e, HoloError::DisplayNotServed(r) if r.key.ends_with("offset_m")),
        "{e}"
    );
    let mut cfg = config(6e-3);
    cfg.optics.pixel_pitch_m = 6.4e-6;
    assert!(matches!(
        HologramPipeline::new(holo, None, cfg),
        Err(HoloError::DisplayNotServed(_))
    ));
}

#[test]
#[cfg(feature = "tract")]
fn the_shipped_cnn_does_not_output_darkness_for_a_black_frame() {
    // Why black frames are refused (`pipeline::check_not_black`): the shipped 8-layer CNN's midpoint hologram
    // of a black 32×32 frame is its bias, far from 0, and Eq. 7's normalisation would show it at full
    // brightness. The figure printed here is the one docs/INPUTS.md quotes.
    let model = tensorholo::model::embedded::hologram_model(
        8,
        tensorholo::model::Precision::F32,
        &tensorholo::model::ModelConfig::default(),
    )
    .unwrap();
    let depth = Array2::from_shape_fn((32, 32), |(_, x)| x as f32 / 31.0);
    let black = RgbdFrame::new(Array3::zeros((3, 32, 32)), depth).unwrap();
    let field = TractModel::new(&model).unwrap().run_frame(&black).unwrap();
    let peak = field.iter().fold(0.0f32, |m, z| m.max(z.norm()));
    println!("peak midpoint amplitude of a black 32x32 frame: {peak:.3}");
    assert!(peak > 0.05, "{peak}");
    assert!(matches!(
        tensorholo::pipeline::check_not_black(0.0),
        Err(HoloError::InvalidData(_))
    ));
}

#[test]
fn sessions_without_full_outputs_keep_no_heads_and_the_same_codes() {
    // What an app's generator runs (`set_full_outputs(false)`): the heads are freed once the colour workers
    // hold them, so `last_heads` stays `None`, and the SLM codes are those of a full-output session; a
    // session that is ended keeps its last frame (`into_last_frame`).
    let (h, w) = (24, 40);
    for prefilter in [true, false] {
        let p = pipeline(prefilter);
        let (mut full, mut lean) = (p.session(h, w).unwrap(), p.session(h, w).unwrap());
        lean.set_full_outputs(false);
        for seed in 0..2 {
            let f = frame(h, w, seed);
            let a = full.render(&f).unwrap().codes.clone();
            let b = lean.render(&f).unwrap().codes.clone();
            assert_eq!(a, b, "pre-filter {prefilter}, frame {seed}");
            assert!(lean.last_heads().is_none());
            // The kept heads are this frame's (the session reuses the last frame's arrays for them): those of
            // a new session's first frame.
            let mut fresh = p.session(h, w).unwrap();
            fresh.render(&f).unwrap();
            assert_eq!(full.last_heads(), fresh.last_heads(), "frame {seed}");
        }
        let codes = full.output().codes.clone();
        let (out, heads) = full.into_last_frame();
        assert_eq!(out.codes, codes);
        assert_eq!(heads.unwrap().amplitude.dim(), (3, h, w));
        let (_, none) = lean.into_last_frame();
        assert!(none.is_none());
    }
}

/// Two sessions in one process with different plan settings (the f32 convolution algorithm, the native
/// engine's strip height and slab count, all fields of the pipeline configuration and so of the plan request;
/// the library reads no environment) each run their own plan, named in their reports, and give the same heads
/// within the Winograd forms' rounding.
#[test]
fn two_sessions_with_different_plan_settings_run_their_own_plans_side_by_side() {
    use tensorholo::cnn::ConvAlgorithm;
    let model = Arc::new(
        HologramModel::from_bytes(
            tensorholo::model::embedded::hologram_cnn(8, tensorholo::model::Precision::F32)
                .unwrap(),
            ModelKind::Hologram,
            &ModelConfig::default(),
        )
        .unwrap(),
    );
    let make = |conv, strip_rows, slabs| {
        let config = PipelineConfig {
            offset_m: 6e-3,
            backend: Backend::Cpu,
            cnn: CnnOptions {
                engine: CnnEngine::Native,
                algorithm: conv,
                strip_rows,
                slabs,
                ..CnnOptions::default()
            },
            ..PipelineConfig::default()
        };
        HologramPipeline::new(model.clone(), None, config)
    };
    let (h, w) = (40, 72);
    let f = frame(h, w, 3);
    let mut a = make(ConvAlgorithm::Direct, Some(4), Some(2))
        .unwrap()
        .session(h, w)
        .unwrap();
    let mut b = make(ConvAlgorithm::Winograd4x4, None, None)
        .unwrap()
        .session(h, w)
        .unwrap();
    // Interleaved frames: neither session's plan leaks into the other's.
    for _ in 0..2 {
        a.render(&f).unwrap();
        b.render(&f).unwrap();
    }
    let (ra, rb) = (a.plan_report(), b.plan_report());
    assert_eq!(
        (ra.request.cnn.strip_rows, ra.request.cnn.slabs),
        (Some(4), Some(2))
    );
    assert_eq!(
        (rb.request.cnn.strip_rows, rb.request.cnn.slabs),
        (None, None)
    );
    let (ka, kb) = (ra.kernel.clone().unwrap(), rb.kernel.clone().unwrap());
    assert!(!ka.contains("wino"), "{ka}");
    assert!(kb.contains("wino4x4"), "{kb}");
    let (ha, hb) = (a.last_heads().unwrap(), b.last_heads().unwrap());
    let diff = |x: &Array3<f32>, y: &Array3<f32>| {
        x.iter()
            .zip(y)
            .fold(0.0f32, |m, (p, q)| m.max((p - q).abs()))
    };
    let (da, dp) = (
        diff(&ha.amplitude, &hb.amplitude),
        diff(&ha.phase, &hb.phase),
    );
    println!("direct, 4-row strips, 2 slabs vs F(4×4, 3×3), the rules: |Δ amplitude| {da:.1e}, |Δ phase| {dp:.1e}");
    assert!(da < 1e-3 && dp < 1e-3, "{da} {dp}");
    assert!(
        da > 0.0 || dp > 0.0,
        "the two plans computed the very same bits: one setting was ignored"
    );

    // A zero is refused when the pipeline is made, naming the field.
    let e = make(ConvAlgorithm::Auto, Some(0), None).unwrap_err();
    assert!(e.to_string().contains("strip_rows"), "{e}");
    let e = make(ConvAlgorithm::Auto, None, Some(0)).unwrap_err();
    assert!(e.to_string().contains("slabs"), "{e}");
}
