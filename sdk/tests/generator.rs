//! The app-facing API (`tensorholo::generator`) with the shipped CNNs: camera buffers in, SLM patterns out;
//! model choice by name; thread safety; streams (order, drops, errors, the locked depth range); previews.
// Some helpers and imports serve only the tests that compare with tract (cargo feature `tract`).
#![cfg_attr(not(feature = "tract"), allow(unused_imports, dead_code))]
#![cfg(feature = "embedded-models")]

use std::sync::{Arc, Mutex};

use tensorholo::cnn::{CnnLayout, CnnOptions, PlanRequest, ThreadCount};
use tensorholo::color::amplitude_to_srgb8;
use tensorholo::generator::{
    pack_rgba, GeneratorConfig, HologramGenerator, SlmPatterns, StreamListener,
};
use tensorholo::metrics::psnr;
use tensorholo::pipeline::{HologramPipeline, ModelSelection, PipelineConfig, PrefilterMode};
use tensorholo::scene::{
    procedural, CameraFrameBuf, ColorFormat, ColorImageBuf, DepthFormat, DepthImageBuf, DepthRange,
    Fit, Rotation,
};
use tensorholo::HoloError;

const H: usize = 48;
const W: usize = 64;

/// The built-in scene as phone buffers: BGRA8 colour and f32 metres, depth `d` mapped linearly in
/// diopters onto `[0.5, 2] m`.
fn camera_frame(h: usize, w: usize, shift: f32) -> CameraFrameBuf {
    let scene = procedural::default_scene(h, w).unwrap();
    let mut bgra = vec![0u8; h * w * 4];
    for y in 0..h {
        for x in 0..w {
            let px = &mut bgra[(y * w + x) * 4..][..4];
            for (c, slot) in [2usize, 1, 0].into_iter().zip(0..3) {
                px[slot] = amplitude_to_srgb8(scene.amplitude[[c, y, x]]);
            }
            px[3] = 255;
        }
    }
    let (near, far) = (0.5f32, 2.0f32);
    let mut depth = Vec::with_capacity(h * w * 4);
    for &d in scene.depth.iter() {
        let dioptre = 1.0 / near - d * (1.0 / near - 1.0 / far);
        depth.extend_from_slice(&(shift / dioptre).to_le_bytes());
    }
    CameraFrameBuf {
        color: ColorImageBuf {
            data: bgra,
            format: ColorFormat::Bgra8,
            width: w,
            height: h,
            row_stride: 0,
        },
        depth: DepthImageBuf {
            data: depth,
            format: DepthFormat::MetresF32,
            width: w,
            height: h,
            row_stride: 0,
        },
        rotation: Rotation::Deg0,
        color_crop: None,
        confidence: None,
    }
}

fn config() -> GeneratorConfig {
    let mut c = GeneratorConfig::new(W, H);
    c.fit = Fit::Stretch;
    c.cnn.threads = ThreadCount::Fixed(1);
    // The plan table's engine, named (the tests compare generators and sessions bit for bit).
    c.cnn.engine = tensorholo::cnn::CnnEngine::Native;
    c
}

fn generator() -> HologramGenerator {
    HologramGenerator::new(config()).unwrap()
}

#[test]
fn generator_is_send_and_sync_and_renders_like_its_session() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<HologramGenerator>();
    let g = generator();
    let frame = camera_frame(H, W, 1.0);
    let out = g.render(&frame.view()).unwrap();
    assert_eq!((out.width, out.height), (W, H));
    assert_eq!(out.codes.dim(), (3, H, W));
    // The same conversion through a fresh pipeline and session gives the same codes bit for bit.
    let (rgbd, _) = g.convert(&frame.view()).unwrap();
    let pipeline =
        HologramPipeline::embedded(&ModelSelection::default(), config().pipeline_config()).unwrap();
    let mut session = pipeline.session(H, W).unwrap();
    assert_eq!(session.render(&rgbd).unwrap().codes, out.codes);
    // Two threads at once: both get the single-threaded answer.
    let g = Arc::new(g);
    let handles: Vec<_> = (0..2)
        .map(|_| {
            let (g, f) = (Arc::clone(&g), frame.clone());
            std::thread::spawn(move || g.render(&f.view()).unwrap().codes)
        })
        .collect();
    for h in handles {
        assert_eq!(h.join().unwrap(), out.codes);
    }
    let info = g.info().unwrap();
    assert_eq!((info.layers, info.width, info.height), (8, W, H));
    assert!(info.prefilter_model.is_some(), "{}", info.prefilter_reason);
    assert!(info.plan.layout != CnnLayout::Auto);
}

#[test]
fn rgba_frame_carries_the_three_lasers() {
    let out = generator().render(&camera_frame(H, W, 1.0).view()).unwrap();
    let rgba = out.to_rgba();
    assert_eq!(rgba, pack_rgba(out.codes.view()));
    assert_eq!(rgba.len(), W * H * 4);
    let (y, x) = (H / 2, W / 3);
    let px = &rgba[(y * W + x) * 4..][..4];
    assert_eq!(
        px,
        [
            out.codes[[0, y, x]],
            out.codes[[1, y, x]],
            out.codes[[2, y, x]],
            255
        ]
    );
}

#[test]
fn prefilter_rule_is_the_sdks() {
    let pipe = |layers, prefilter, offset_m| {
        HologramPipeline::embedded(
            &ModelSelection {
                layers,
                prefilter,
                ..ModelSelection::default()
            },
            PipelineConfig {
                offset_m,
                ..PipelineConfig::default()
            },
        )
    };
    // Auto: each CNN depth embedded in this build with the pre-filter trained on its holograms.
    for &layers in tensorholo::model::embedded::LAYERS {
        for offset_m in [6e-3, 12e-3] {
            let p = pipe(layers, PrefilterMode::Auto, offset_m).unwrap();
            let pre = p.prefilter_model().expect("a pre-filter");
            assert_eq!(pre.metadata().hologram_layers, Some(layers));
            assert_eq!(pre.metadata().offset_m, offset_m);
            assert!(
                p.prefilter_reason().contains(&format!("{layers}-layer")),
                "{}",
                p.prefilter_reason()
            );
        }
    }
    assert!(pipe(8, PrefilterMode::Auto, 0.0)
        .unwrap()
        .prefilter_model()
        .is_none());
    assert!(pipe(8, PrefilterMode::Auto, 7e-3)
        .unwrap()
        .prefilter_model()
        .is_none());
    assert!(pipe(8, PrefilterMode::Off, 6e-3)
        .unwrap()
        .prefilter_model()
        .is_none());
    // Required: an error where none is shipped for the offset.
    assert!(pipe(30, PrefilterMode::Required, 6e-3)
        .unwrap()
        .prefilter_model()
        .is_some());
    for offset in [0.0, 7e-3] {
        match pipe(8, PrefilterMode::Required, offset).unwrap_err() {
            HoloError::InvalidParameter { name, .. } => assert_eq!(name, "prefilter"),
            e => panic!("unexpected {e}"),
        }
    }
    assert!(matches!(
        pipe(9, PrefilterMode::Auto, 6e-3).unwrap_err(),
        HoloError::InvalidParameter { name: "layers", .. }
    ));
}

#[test]
fn bad_frames_are_errors_and_the_generator_goes_on() {
    let g = generator();
    let good = camera_frame(H, W, 1.0);
    let reference = g.render(&good.view()).unwrap().codes;
    let mut short = good.clone();
    short.color.data.truncate(100);
    let mut all_invalid = good.clone();
    all_invalid.depth.data.iter_mut().for_each(|b| *b = 0);
    let mut nan = good.clone();
    nan.depth.data = f32::NAN
        .to_le_bytes()
        .repeat(all_invalid.depth.data.len() / 4);
    let mut narrow_stride = good.clone();
    narrow_stride.color.row_stride = 4 * W - 1;
    let mut empty = good.clone();
    empty.color.width = 0;
    let mut huge = good.clone();
    huge.color.width = usize::MAX / 2;
    for (what, bad) in [
        ("short buffer", short),
        ("all depth invalid", all_invalid),
        ("all depth NaN", nan),
        ("stride shorter than a row", narrow_stride),
        ("zero width", empty),
        ("overflowing size", huge),
    ] {
        let e = g.render(&bad.view()).unwrap_err();
        assert!(
            matches!(
                e,
                HoloError::InvalidParameter { .. } | HoloError::InvalidDepth(_)
            ),
            "{what}: {e}"
        );
        assert_eq!(g.render(&good.view()).unwrap().codes, reference, "{what}");
    }
    assert!(g.preview(&good.view(), 1.5).is_err());
    assert!(g.preview(&good.view(), f32::NAN).is_err());
}

#[test]
fn preview_is_sharpest_at_the_scene_depth() {
    // A flat textured scene at d = 0.5: the reconstruction focused there resembles the target more than one
    // focused at the front or the back of the volume.
    let (h, w) = (64, 64);
    let mut c = GeneratorConfig::new(w, h);
    c.fit = Fit::Stretch;
    c.cnn.threads = ThreadCount::Fixed(1);
    c.depth_range = Some(DepthRange::new(0.5, 2.0).unwrap());
    let g = HologramGenerator::new(c).unwrap();
    let mut frame = camera_frame(h, w, 1.0);
    let mid = 1.0 / (1.0 / 0.5 - 0.5 * (1.0 / 0.5 - 1.0 / 2.0)) as f32;
    frame.depth.data = mid.to_le_bytes().repeat(h * w);
    let (rgbd, _) = g.convert(&frame.view()).unwrap();
    assert!(rgbd.depth.iter().all(|d| (d - 0.5).abs() < 1e-4));
    let target = rgbd
        .amplitude
        .mapv(|a| amplitude_to_srgb8(a) as f32 / 255.0);
    let patterns = g.render(&frame.view()).unwrap();
    let score = |focus: f32| {
        let p = g.preview_patterns(&patterns, focus).unwrap();
        assert_eq!((p.width, p.height, p.rgba.len()), (w, h, w * h * 4));
        assert!(p.rgba.chunks_exact(4).all(|px| px[3] == 255));
        let img = ndarray::Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            p.rgba[(y * w + x) * 4 + c] as f32 / 255.0
        });
        psnr(img.view(), target.view(), 1.0).unwrap()
    };
    let (at, near, far) = (score(0.5), score(0.0), score(1.0));
    assert!(at > near + 1.0 && at > far + 1.0, "{at} vs {near}, {far}");
}

#[derive(Default)]
struct Recorder {
    patterns: Vec<(u64, SlmPatterns)>,
    errors: Vec<(u64, String)>,
}

struct Shared(Arc<Mutex<Recorder>>);

impl StreamListener for Shared {
    fn on_patterns(&mut self, index: u64, patterns: SlmPatterns) {
        self.0.lock().unwrap().patterns.push((index, patterns));
    }
    fn on_error(&mut self, index: u64, error: HoloError) {
        self.0
            .lock()
            .unwrap()
            .errors
            .push((index, error.to_string()));
    }
}

#[test]
fn stream_delivers_in_order_with_errors_in_place() {
    let g = generator();
    let rec = Arc::new(Mutex::new(Recorder::default()));
    let stream = g.stream(Box::new(Shared(Arc::clone(&rec))), 8).unwrap();
    let good = camera_frame(H, W, 1.0);
    let mut bad = good.clone();
    bad.depth.data.truncate(10);
    for i in 0..5u64 {
        let f = if i == 2 { bad.clone() } else { good.clone() };
        assert_eq!(stream.push(f).unwrap(), i);
    }
    stream.close();
    assert!(stream.push(good.clone()).is_err(), "push after close");
    let rec = rec.lock().unwrap();
    let indices: Vec<u64> = rec.patterns.iter().map(|(i, _)| *i).collect();
    assert_eq!(indices, vec![0, 1, 3, 4]);
    assert_eq!(rec.errors.len(), 1);
    assert_eq!(rec.errors[0].0, 2);
    assert!(rec.errors[0].1.contains("depth"), "{}", rec.errors[0].1);
    assert_eq!(stream.dropped_frames(), 0);
    // Streamed frames equal single renders bit for bit.
    let single = g.render(&good.view()).unwrap();
    for (_, p) in rec.patterns.iter() {
        assert_eq!(p.codes, single.codes);
    }
}

#[test]
fn stream_keeps_the_first_frames_depth_range() {
    let g = generator();
    let rec = Arc::new(Mutex::new(Recorder::default()));
    let stream = g.stream(Box::new(Shared(Arc::clone(&rec))), 4).unwrap();
    // The second frame is the first one 1.5× farther away: alone it would get its own range.
    let (first, second) = (camera_frame(H, W, 1.0), camera_frame(H, W, 1.5));
    let own = g.render(&second.view()).unwrap().depth_range.unwrap();
    stream.push(first.clone()).unwrap();
    stream.push(second).unwrap();
    stream.close();
    let rec = rec.lock().unwrap();
    assert_eq!(rec.patterns.len(), 2, "errors: {:?}", rec.errors);
    let r0 = rec.patterns[0].1.depth_range.unwrap();
    let r1 = rec.patterns[1].1.depth_range.unwrap();
    assert_eq!(r0, r1);
    assert!(
        (own.z_near_m / r0.z_near_m - 1.5).abs() < 0.01,
        "{own} vs {r0}"
    );
}

/// A stream's temporal state (`encoding::PhaseContinuity`): each frame after the first carries its churn from
/// the previous delivered pattern; with `align_phase` each frame's colours are shifted towards the previous
/// frame's global phase (the codes a whole-code shift of the unaligned ones, as `PhaseContinuity` shifts them,
/// the churn no higher); through a calibrated look-up table the aligning stream is refused.
#[test]
fn a_stream_counts_phase_churn_and_aligns_when_asked() {
    use tensorholo::encoding::phase_churn;
    let frames = [
        camera_frame(H, W, 1.0),
        camera_frame(H, W, 1.3),
        camera_frame(H, W, 1.0),
    ];
    let run = |align: bool| {
        let mut c = config();
        c.align_phase = align;
        let g = HologramGenerator::new(c).unwrap();
        let rec = Arc::new(Mutex::new(Recorder::default()));
        let stream = g.stream(Box::new(Shared(Arc::clone(&rec))), 4).unwrap();
        for f in &frames {
            stream.push(f.clone()).unwrap();
        }
        stream.close();
        let rec = rec.lock().unwrap();
        assert!(rec.errors.is_empty(), "{:?}", rec.errors);
        rec.patterns
            .iter()
            .map(|(_, p)| p.clone())
            .collect::<Vec<_>>()
    };
    let plain = run(false);
    assert_eq!(plain.len(), 3);
    assert!(plain[0].phase_churn.is_none());
    for i in 1..3 {
        let want = phase_churn(plain[i - 1].codes.view(), plain[i].codes.view()).unwrap();
        assert_eq!(plain[i].phase_churn, Some(want));
        assert!(want.mean_abs_rad > 0.0, "frame {i} equals the one before");
    }
    let aligned = run(true);
    assert_eq!(aligned[0].codes, plain[0].codes);
    for i in 1..3 {
        for c in 0..3 {
            let (a, p) = (
                aligned[i].codes.index_axis(ndarray::Axis(0), c),
                plain[i].codes.index_axis(ndarray::Axis(0), c),
            );
            let shift = a[[0, 0]].wrapping_sub(p[[0, 0]]);
            assert!(
                a.iter()
                    .zip(p.iter())
                    .all(|(&x, &y)| x == y.wrapping_add(shift)),
                "frame {i} colour {c}: not a whole-code shift"
            );
        }
        let (a, p) = (
            aligned[i].phase_churn.unwrap(),
            plain[i].phase_churn.unwrap(),
        );
        assert!(a.mean_abs_rad <= p.mean_abs_rad + 1e-12, "{a:?} vs {p:?}");
    }
    // The aligned stream is the plain one through an aligning `PhaseContinuity`, frame for frame.
    let mut state = tensorholo::encoding::PhaseContinuity::new(true, false).unwrap();
    for (p, a) in plain.iter().zip(&aligned) {
        let mut codes = p.codes.clone();
        let step = state.next(codes.view_mut()).unwrap();
        assert_eq!(codes, a.codes);
        assert_eq!(step.map(|s| s.churn), a.phase_churn);
    }
    // Alignment through a calibrated look-up table is refused when the stream starts, naming the setting.
    let mut c = config();
    c.align_phase = true;
    let g = HologramGenerator::new(c).unwrap();
    g.set_calibration(Some(Arc::new(panel_calibration(H, W))))
        .unwrap();
    let rec = Arc::new(Mutex::new(Recorder::default()));
    let e = g.stream(Box::new(Shared(rec)), 4).unwrap_err().to_string();
    assert!(e.contains("align_phase"), "{e}");
}

#[test]
fn a_full_stream_queue_drops_the_oldest_frames() {
    let g = generator();
    let rec = Arc::new(Mutex::new(Recorder::default()));
    let stream = g.stream(Box::new(Shared(Arc::clone(&rec))), 1).unwrap();
    let frame = camera_frame(H, W, 1.0);
    let n = 12u64;
    for _ in 0..n {
        stream.push(frame.clone()).unwrap();
    }
    stream.close();
    let rec = rec.lock().unwrap();
    let delivered = rec.patterns.len() as u64;
    assert!(rec.errors.is_empty(), "{:?}", rec.errors);
    assert!(
        stream.dropped_frames() > 0,
        "pushing 12 frames at once into a 1-frame queue"
    );
    assert_eq!(delivered + stream.dropped_frames(), n);
    assert!(rec.patterns.windows(2).all(|w| w[0].0 < w[1].0));
    // The newest frame is never dropped.
    assert_eq!(rec.patterns.last().unwrap().0, n - 1);
}

#[test]
#[cfg(feature = "tract")]
fn autotuned_plans_report_their_candidates_and_agree_with_the_file_layout() {
    use tensorholo::model::{embedded, ModelConfig, Precision};
    let cfg = ModelConfig {
        offset_m: 0.0,
        ..ModelConfig::default()
    };
    for precision in [Precision::F32, Precision::Int8QOperator] {
        let m = tensorholo::cnn::tract::TractModel::new(
            &embedded::hologram_model(8, precision, &cfg).unwrap(),
        )
        .unwrap();
        let request = &PlanRequest {
            source: tensorholo::cnn::PlanSource::Tune,
            cnn: CnnOptions {
                layout: CnnLayout::Auto,
                threads: ThreadCount::Auto,
                ..CnnOptions::default()
            },
        };
        let (plan, report) = m.tuned_plan(24, 40, request).unwrap();
        assert!(report.autotuned);
        let threads = tensorholo::cnn::auto_thread_candidates();
        assert_eq!(report.candidates.len(), 2 * threads.len());
        let timed: Vec<_> = report
            .candidates
            .iter()
            .filter(|c| c.seconds.is_some())
            .collect();
        let best = timed
            .iter()
            .min_by(|a, b| a.seconds.unwrap().total_cmp(&b.seconds.unwrap()))
            .unwrap();
        assert_eq!((plan.layout(), plan.threads()), (best.layout, best.threads));
        assert_eq!((report.layout, report.threads), (best.layout, best.threads));
        if precision == Precision::Int8QOperator {
            // tract cannot move QLinearConv channels-last: skipped with the reason.
            assert!(report
                .candidates
                .iter()
                .filter(|c| c.layout == CnnLayout::ChannelsLast)
                .all(|c| c.seconds.is_none() && c.skipped.is_some()));
        } else {
            assert_eq!(timed.len(), report.candidates.len());
        }
        let input = ndarray::Array3::from_shape_fn((4, 24, 40), |(c, y, x)| {
            ((c * 3 + y * 5 + x * 7) % 11) as f32 / 10.0
        });
        let (a, _) = plan.run_outputs(input.view()).unwrap();
        let (b, _) = m.plan(24, 40).unwrap().run_outputs(input.view()).unwrap();
        let err = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(err < 1e-4, "{precision}: {err}");
        // The second request comes from the cache.
        let (_, again) = m.tuned_plan(24, 40, request).unwrap();
        assert_eq!(again.tuning_s, 0.0);
        assert_eq!(again.layout, report.layout);
    }
}

/// A panel with a gamma response over 2.5π on every colour, green per pixel (tiles), and a red intensity map.
fn panel_calibration(h: usize, w: usize) -> tensorholo::slm::DisplayCalibration {
    use tensorholo::slm::{
        DisplayCalibration, LutRepresentation, PhaseCurve, PhaseLut, TiledCurves,
    };
    let mut cal = DisplayCalibration::linear(h, w).unwrap();
    let pi = std::f32::consts::PI;
    for c in [0, 2] {
        cal.colours[c].lut = PhaseLut::new(LutRepresentation::Global(
            PhaseCurve::gamma(2.5 * pi, 1.5).unwrap(),
        ));
    }
    let tiles = (h.div_ceil(16)) * (w.div_ceil(16));
    let curves = (0..tiles)
        .map(|t| PhaseCurve::gamma((2.4 + 0.02 * t as f32) * pi, 1.4).unwrap())
        .collect();
    cal.colours[1].lut = PhaseLut::new(LutRepresentation::Tiled(
        TiledCurves::new(h, w, 16, 16, curves).unwrap(),
    ));
    cal.colours[0].intensity_scale = Some(ndarray::Array2::from_elem((h, w), 0.8));
    cal
}

#[test]
fn a_calibrated_generator_shows_on_its_panel_what_an_ideal_one_shows() {
    let (h, w) = (64, 64);
    let mut c = GeneratorConfig::new(w, h);
    c.fit = Fit::Stretch;
    c.cnn.threads = ThreadCount::Fixed(1);
    let frame = camera_frame(h, w, 1.0);
    let ideal = HologramGenerator::new(c.clone()).unwrap();
    let ideal_patterns = ideal.render(&frame.view()).unwrap();
    let ideal_view = ideal.preview_patterns(&ideal_patterns, 0.5).unwrap();

    let g = HologramGenerator::new(c).unwrap();
    let mut cal = panel_calibration(h, w);
    // No intensity map here: the two generators must aim at the same target.
    cal.colours[0].intensity_scale = None;
    g.set_calibration(Some(Arc::new(cal))).unwrap();
    let info = g.info().unwrap();
    assert_eq!(
        info.calibration.as_deref(),
        Some("64×64 SLM: red global, green tiled (16×16 px), blue global; intensity map: none")
    );
    let patterns = g.render(&frame.view()).unwrap();
    assert_ne!(patterns.codes, ideal_patterns.codes);
    let image = |p: &tensorholo::generator::Preview| {
        ndarray::Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            p.rgba[(y * w + x) * 4 + c] as f32 / 255.0
        })
    };
    // The calibrated codes on the calibrated panel ≈ the ideal codes on an ideal panel; the uncalibrated
    // codes on this panel are far off.
    let calibrated = psnr(
        image(&g.preview_patterns(&patterns, 0.5).unwrap()).view(),
        image(&ideal_view).view(),
        1.0,
    )
    .unwrap();
    let uncalibrated = psnr(
        image(&g.preview_patterns(&ideal_patterns, 0.5).unwrap()).view(),
        image(&ideal_view).view(),
        1.0,
    )
    .unwrap();
    println!("preview vs the ideal display's: calibrated {calibrated:.1} dB, uncalibrated {uncalibrated:.1} dB");
    assert!(calibrated > 35.0, "{calibrated}");
    assert!(
        calibrated > uncalibrated + 10.0,
        "{calibrated} vs {uncalibrated}"
    );

    // A calibration of another size is refused and the generator keeps its own.
    let other = Arc::new(panel_calibration(h, w + 16));
    assert!(matches!(
        g.set_calibration(Some(other)),
        Err(HoloError::ShapeMismatch { .. })
    ));
    assert_eq!(g.render(&frame.view()).unwrap().codes, patterns.codes);
    // Streams start with the generator's calibration.
    let rec = Arc::new(Mutex::new(Recorder::default()));
    let stream = g.stream(Box::new(Shared(rec.clone())), 2).unwrap();
    stream.push(frame.clone()).unwrap();
    stream.close();
    assert_eq!(rec.lock().unwrap().patterns[0].1.codes, patterns.codes);
    g.set_calibration(None).unwrap();
    assert_eq!(g.render(&frame.view()).unwrap().codes, ideal_patterns.codes);
    assert!(g.info().unwrap().calibration.is_none());
}

/// A layer behind the built-in scene: a uniform green wall at 3 m in the left half of the frame (no point in
/// the right half).
fn wall_layer(h: usize, w: usize) -> CameraFrameBuf {
    let mut layer = camera_frame(h, w, 1.0);
    layer.color.data = (0..h * w).flat_map(|_| [40u8, 220, 40, 255]).collect();
    layer.depth.data = (0..h * w)
        .flat_map(|i| (if i % w < w / 2 { 3.0f32 } else { 0.0 }).to_le_bytes())
        .collect();
    layer
}

#[test]
fn an_ldi_generator_pads_missing_layers_and_refuses_extra_ones() {
    let mut c = config();
    c.models.input = tensorholo::model::SceneInput::Ldi;
    // Pinned so that frame and LDI renders compare bit for bit.
    c.depth_range = Some(DepthRange::new(0.5, 3.0).unwrap());
    let g = HologramGenerator::new(c.clone()).unwrap();
    assert!(g.info().unwrap().hologram_model.contains("holo8_ldi"));
    let front = camera_frame(H, W, 1.0);
    // An RGB-D frame is a one-layer LDI: the CNN sees it padded with four empty layers either way.
    let as_frame = g.render(&front.view()).unwrap();
    let as_ldi = g.render_ldi(&[front.view()]).unwrap();
    assert_eq!(as_frame.codes, as_ldi.codes);
    // A second layer (the wall hidden behind the left half) changes the hologram.
    let wall = wall_layer(H, W);
    let two = g.render_ldi(&[front.view(), wall.view()]).unwrap();
    assert_ne!(two.codes, as_ldi.codes);
    // Six layers: more than the CNN's five.
    let six = vec![front.view(); 6];
    match g.render_ldi(&six) {
        Err(HoloError::InvalidParameter { name, reason }) => {
            assert_eq!(name, "ldi");
            assert!(reason.contains("takes 5"), "{reason}");
        }
        other => panic!("{:?}", other.map(|p| p.width)),
    }
    // The generator stays usable.
    assert_eq!(g.render_ldi(&[front.view()]).unwrap().codes, as_ldi.codes);

    // An RGB-D generator takes a one-layer LDI (= the frame) and refuses two layers, naming the LDI CNN.
    let rgbd = HologramGenerator::new(config()).unwrap();
    let mut pinned = config();
    pinned.depth_range = c.depth_range;
    let rgbd_pinned = HologramGenerator::new(pinned).unwrap();
    assert_eq!(
        rgbd_pinned.render_ldi(&[front.view()]).unwrap().codes,
        rgbd_pinned.render(&front.view()).unwrap().codes
    );
    let e = rgbd
        .render_ldi(&[front.view(), wall.view()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("holo8_ldi"), "{e}");
}

/// The paper's Fig. 1 argument, on a hand-made two-layer LDI: a dark bar near the viewer over a textured wall
/// at the back; layer 1 holds the wall behind the bar. Focused on the wall, the light of the hidden wall
/// points passes around the thin bar (its blur at the wall's distance is wider than the bar), so the wall
/// shows through behind the bar in the LDI's hologram (SM-LBM of both layers, what the LDI CNN is trained
/// towards). The RGB-D CNN sees only layer 0: no wall points exist behind the bar, and its hologram shows a
/// dark strip there. Returns the wall amplitude (green) behind the bar's centre over that beside the bar, for
/// the LDI CNN (given both layers, and the front one alone), the RGB-D CNN, and SM-LBM of the LDI and of its
/// front layer.
fn wall_behind_bar_ratios() -> WallBehindBar {
    use ndarray::{s, Array2, Array3};
    use tensorholo::model::SceneInput;
    use tensorholo::scene::{LayeredDepthImage, LdiLayer, RgbdFrame};
    use tensorholo::synthesis::{ldi_layers, SceneLayer, SmLbm};
    let (h, w) = (64usize, 96usize);
    let (bar, wall_d, bar_d) = (44..52usize, 0.9f32, 0.1f32);
    // A finely textured green wall (per-pixel noise): its points send light at every angle the pixel pitch
    // allows, as the dataset's textures do (a uniform wall would send a plane wave straight into the bar).
    let wall = |c: usize, y: usize, x: usize| {
        let n = ((y * 131 + x * 71 + 17) as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40;
        let v = 0.3 + 0.7 * (n as f32 / (1u64 << 24) as f32);
        [0.3 * v, v, 0.3 * v][c]
    };
    let front_amplitude = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
        if bar.contains(&x) {
            0.05
        } else {
            wall(c, y, x)
        }
    });
    let front_depth = Array2::from_shape_fn(
        (h, w),
        |(_, x)| if bar.contains(&x) { bar_d } else { wall_d },
    );
    let front = RgbdFrame::new(front_amplitude.clone(), front_depth.clone()).unwrap();
    let back = LdiLayer {
        amplitude: Array3::from_shape_fn((3, h, w), |(c, y, x)| wall(c, y, x)),
        depth: Array2::from_elem((h, w), wall_d),
        valid: Array2::from_shape_fn((h, w), |(_, x)| bar.contains(&x)),
    };
    let ldi = LayeredDepthImage::new(vec![
        LdiLayer {
            amplitude: front_amplitude,
            depth: front_depth,
            valid: Array2::from_elem((h, w), true),
        },
        back,
    ])
    .unwrap();
    let cfg = PipelineConfig {
        offset_m: 0.0,
        ..config().pipeline_config()
    };
    // Amplitude behind the bar's centre over the wall's 20 px away (outside the bar's blur), green, focused
    // on the wall.
    let ratio = |field: &ndarray::Array3<num_complex::Complex32>| {
        let stack = tensorholo::optics::focal_stack(
            field.view(),
            &cfg.optics,
            0.0,
            &[wall_d as f64],
            cfg.options,
            false,
        )
        .unwrap();
        let green = stack[0].index_axis(ndarray::Axis(0), 1).to_owned();
        let mean = |cols: std::ops::Range<usize>| green.slice(s![16..48, cols]).mean().unwrap();
        mean(46..50) / mean(12..24)
    };
    // `layers`: whether the CNN is given the LDI (both layers) or the front frame alone.
    let cnn = |input: SceneInput, layers: bool| {
        let selection = ModelSelection {
            input,
            prefilter: PrefilterMode::Off,
            ..ModelSelection::default()
        };
        let pipeline = HologramPipeline::embedded(&selection, cfg).unwrap();
        let mut session = pipeline.session(h, w).unwrap();
        match layers {
            false => session.render(&front).unwrap(),
            true => session.render_ldi(&ldi).unwrap(),
        };
        ratio(&session.last_heads().unwrap().to_field().unwrap())
    };
    // The ground truth the CNNs learned: SM-LBM (silhouette masks) of both layers, and of the front alone.
    let smlbm = SmLbm {
        levels: 2048,
        setup: cfg.optics,
        options: cfg.options,
        silhouette_masks: true,
    };
    let truth = |layers: &[SceneLayer]| ratio(&smlbm.synthesize(layers, &|_, _| {}).unwrap());
    let truth_ldi = truth(&ldi_layers(&ldi));
    let truth_rgbd = truth(&[SceneLayer::from(&front)]);
    WallBehindBar {
        ldi_cnn: cnn(SceneInput::Ldi, true),
        ldi_cnn_front_only: cnn(SceneInput::Ldi, false),
        rgbd_cnn: cnn(SceneInput::Rgbd, false),
        truth_ldi,
        truth_front: truth_rgbd,
    }
}

/// The ratios of [`wall_behind_bar_ratios`].
struct WallBehindBar {
    /// The LDI CNN given both layers.
    ldi_cnn: f32,
    /// The LDI CNN given the front layer alone (a one-layer LDI).
    ldi_cnn_front_only: f32,
    /// The RGB-D CNN (front layer).
    rgbd_cnn: f32,
    /// SM-LBM of both layers.
    truth_ldi: f32,
    /// SM-LBM of the front layer.
    truth_front: f32,
}

#[test]
fn focused_far_the_hidden_wall_shows_in_the_ldi_ground_truth_and_not_through_the_rgbd_cnn() {
    let r = wall_behind_bar_ratios();
    eprintln!(
        "wall behind the bar / wall beside it, focused on the wall: LDI CNN {:.3} (given the front layer alone \
         {:.3}), RGB-D CNN {:.3}; SM-LBM of the LDI {:.3}, of its front layer {:.3}",
        r.ldi_cnn, r.ldi_cnn_front_only, r.rgbd_cnn, r.truth_ldi, r.truth_front
    );
    // The scene does what it is for: the hidden wall shows through in the ground truth of the LDI (0.40 of the
    // wall beside the bar), not in that of its front layer (0.10: the bar's own defocused light).
    assert!(
        r.truth_ldi > 3.0 * r.truth_front,
        "{} vs {}",
        r.truth_ldi,
        r.truth_front
    );
    // The RGB-D CNN cannot show what it never saw: it stays far below the LDI's ground truth (measured 0.158
    // against 0.40; the rest of its 0.158 over the front layer's 0.10 is its blur of the bar's edges).
    assert!(
        r.rgbd_cnn < 0.5 * r.truth_ldi,
        "{} vs {}",
        r.rgbd_cnn,
        r.truth_ldi
    );
    // Neither do the LDI CNN's weights make the LDI path lose the front layer: given the front layer alone it
    // shows what the RGB-D CNN it was started from shows (measured 0.159 vs 0.158).
    assert!(
        (r.ldi_cnn_front_only - r.rgbd_cnn).abs() < 0.25 * r.rgbd_cnn,
        "{} vs {}",
        r.ldi_cnn_front_only,
        r.rgbd_cnn
    );
}

/// What the LDI CNN is for, and what the shipped one does not do yet (models/MODEL_CARD.md, "LDI input"):
/// given the hidden wall in its second layer, it should show it brighter than given the front layer alone.
/// Measured with the shipped `holo8_ldi`: 0.159 with and without the back layer (ground truth 0.40 and 0.10).
/// Run it with `cargo test -p tensorholo --test generator -- --ignored` on a retrained LDI CNN.
#[test]
#[ignore = "the shipped holo8_ldi does not use the hidden layer on this scene yet (issue 23)"]
fn the_ldi_cnn_shows_the_hidden_wall_brighter_than_without_it() {
    let r = wall_behind_bar_ratios();
    assert!(
        r.ldi_cnn > 1.25 * r.ldi_cnn_front_only,
        "LDI CNN with the back layer {} vs without {}",
        r.ldi_cnn,
        r.ldi_cnn_front_only
    );
}

/// The photo mode for a viewer with a prescription (`GeneratorConfig::prescription`): the refinement's model
/// sees through the viewer's eye (docs/REFINE.md), so 5 iterations from the corrected CNN's codes raise the
/// held-out focal-stack PSNR seen through that eye; the refined patterns differ from those refined for an
/// emmetropic viewer, and a cancelled run is an error that leaves the generator usable.
#[test]
fn the_photo_mode_refines_for_a_viewer_with_a_prescription() {
    use std::ops::ControlFlow;
    use tensorholo::display::Prescription;
    use tensorholo::refine::{FrameRefinement, RefineOptions, RefineTarget};

    let prescription = Prescription {
        sphere_d: -0.5,
        cylinder_d: -1.0,
        axis_deg: Some(30.0),
        eyepiece_focal_m: tensorholo::display::DEFAULT_EYEPIECE_FOCAL_M,
    };
    let myope = HologramGenerator::new(GeneratorConfig {
        prescription: Some(prescription),
        ..config()
    })
    .unwrap();
    let emmetrope = generator();
    let buffers = camera_frame(H, W, 1.0);
    let frame = buffers.view();
    let request = FrameRefinement {
        options: RefineOptions {
            iterations: 5,
            ..RefineOptions::default()
        },
        target: RefineTarget::SmLbm { levels: 32 },
        ..FrameRefinement::default()
    };
    let mut records = Vec::new();
    let refined = myope
        .render_refined(&frame, &request, &mut |r| {
            records.push(r.psnr_db);
            ControlFlow::Continue(())
        })
        .unwrap();
    assert_eq!(records.len(), 6, "the start and every iteration");
    assert!(records[5] > records[0], "{records:?}");
    let plain = emmetrope
        .render_refined(&frame, &request, &mut |_| ControlFlow::Continue(()))
        .unwrap();
    assert_ne!(refined.codes, plain.codes);
    let cancelled = myope.render_refined(&frame, &request, &mut |_| ControlFlow::Break(()));
    assert!(
        matches!(cancelled, Err(HoloError::Cancelled(_))),
        "{cancelled:?}"
    );
    assert!(myope.render(&frame).is_ok());
}

/// A foveating generator: single frames and a stream's frames on a gaze are the session's foveated frames,
/// bit for bit, unlike the full frame far from the gaze; frames pushed without a gaze are full frames; a
/// gaze outside the hologram, or one for a generator made without foveation, is refused by name.
#[test]
fn a_foveating_generator_renders_gazes_in_frames_and_streams() {
    use tensorholo::foveation::{FoveaRadius, FoveationOptions, Gaze};
    let mut cfg = config();
    cfg.foveation = Some(FoveationOptions {
        radius: FoveaRadius::Pixels { pixels: 6.0 },
        ..FoveationOptions::default()
    });
    let g = HologramGenerator::new(cfg.clone()).unwrap();
    let frame = camera_frame(H, W, 1.0);
    let gaze = Gaze {
        x: 12.0,
        y: 10.0,
        depth_m: None,
    };
    let full = g.render(&frame.view()).unwrap();
    let fov = g.render_foveated(&frame.view(), &gaze).unwrap();
    // The session's own foveated frame of the converted frame.
    let (rgbd, _) = g.convert(&frame.view()).unwrap();
    let pipeline =
        HologramPipeline::embedded(&ModelSelection::default(), cfg.pipeline_config()).unwrap();
    let mut session = pipeline.session(H, W).unwrap();
    assert_eq!(
        fov.codes,
        session.render_foveated(&rgbd, &gaze).unwrap().codes
    );
    let far = |p: &tensorholo::generator::SlmPatterns| {
        p.codes.slice(ndarray::s![.., 30.., 40..]).to_owned()
    };
    let differ = far(&fov)
        .iter()
        .zip(far(&full).iter())
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        differ * 2 > far(&full).len(),
        "{differ} of {}",
        far(&full).len()
    );

    let rec = Arc::new(Mutex::new(Recorder::default()));
    let stream = g.stream(Box::new(Shared(Arc::clone(&rec))), 8).unwrap();
    stream.push_foveated(frame.clone(), gaze).unwrap();
    stream.push(frame.clone()).unwrap();
    let outside = Gaze { x: 99.0, ..gaze };
    let e = stream.push_foveated(frame.clone(), outside).unwrap_err();
    assert!(e.to_string().contains("gaze"), "{e}");
    stream.close();
    let rec = rec.lock().unwrap();
    assert!(rec.errors.is_empty(), "{:?}", rec.errors);
    assert_eq!(rec.patterns.len(), 2);
    assert_eq!(rec.patterns[0].1.codes, fov.codes);
    assert_eq!(rec.patterns[1].1.codes, full.codes);

    let plain = generator();
    let e = plain.render_foveated(&frame.view(), &gaze).unwrap_err();
    assert!(e.to_string().contains("foveation"), "{e}");
    let stream = plain
        .stream(Box::new(Shared(Arc::new(Mutex::default()))), 2)
        .unwrap();
    let e = stream.push_foveated(frame, gaze).unwrap_err();
    assert!(e.to_string().contains("foveation"), "{e}");
}

/// The photo mode refines through a generator's display model: other codes than through the ideal display; a
/// model of another SLM size is refused when the generator is made, naming `display_model`.
#[test]
fn the_photo_mode_refines_through_the_generators_display_model() {
    use std::ops::ControlFlow;
    use tensorholo::refine::FrameRefinement;
    use tensorholo::slm::model::DisplayModel;
    let model = |h: usize, w: usize| {
        let json = format!(
            r#"{{"format": "tensorholo.display-model", "version": 1, "slm_size": [{h}, {w}],
                "green": {{"crosstalk": {{"size": [3, 3], "weights": [0, 0.05, 0, 0.05, 0.8, 0.05, 0, 0.05, 0]}},
                          "zero_order": [0.05, 0.0]}}}}"#
        );
        Arc::new(DisplayModel::from_json_str(&json, "test").unwrap())
    };
    let frame = camera_frame(H, W, 1.0);
    let mut refinement = FrameRefinement::default();
    refinement.options.iterations = 3;
    let ideal = generator()
        .render_refined(&frame.view(), &refinement, &mut |_| {
            ControlFlow::Continue(())
        })
        .unwrap();
    let mut cfg = config();
    cfg.display_model = Some(model(H, W));
    let through = HologramGenerator::new(cfg)
        .unwrap()
        .render_refined(&frame.view(), &refinement, &mut |_| {
            ControlFlow::Continue(())
        })
        .unwrap();
    let green =
        |p: &tensorholo::generator::SlmPatterns| p.codes.index_axis(ndarray::Axis(0), 1).to_owned();
    let differ = green(&ideal)
        .iter()
        .zip(green(&through).iter())
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        differ * 10 > H * W,
        "{differ} of {} green codes differ",
        H * W
    );
    let mut wrong = config();
    wrong.display_model = Some(model(H + 2, W));
    let e = HologramGenerator::new(wrong).unwrap_err();
    assert!(
        e.to_string().contains("model") || e.to_string().contains("size"),
        "{e}"
    );
}
