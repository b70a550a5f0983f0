//! End-to-end on real RGB-D photos: `ReferencePipeline` (SM-LBM → double phase → simulated reconstruction)
//! and the real-time `HologramSession` with the shipped CNNs (hologram CNN → offset → pre-filter CNN → double
//! phase → simulated reconstruction).
//! A near-focused reconstruction must be sharper on the near object than a far-focused one, and the reverse on
//! the background, where "sharper" means a smaller gradient-domain error against the input
//! ([`detail_error`]).
//!
//! Also: phone-style camera buffers (`scene::CameraFrame`) built from a real RGB-D frame give exactly the
//! frame `load_rgbd` reads from the files.

use std::path::Path;

use ndarray::{Array2, Array3};
use tensorholo::pipeline::{HologramPipeline, ModelSelection, PipelineConfig, PrefilterMode};
use tensorholo::reference::ReferencePipeline;
use tensorholo::scene::{
    load_rgbd, CameraFrame, ColorFormat, ColorImage, DepthEncoding, DepthFormat, DepthImage, Fit,
    FrameOptions, LoadOptions, RgbdFrame, Rotation,
};
use tensorholo::synthesis::{SceneLayer, SmLbm};
use tensorholo_integration_tests::{detail_error, displayed_focal_stack, shared_data};

/// Phase-only reconstructions of a frame at normalised depths `[near, far]`.
type Reconstruct = fn(&RgbdFrame, &[f64]) -> Vec<Array3<f32>>;

fn reference(frame: &RgbdFrame, depths: &[f64]) -> Vec<Array3<f32>> {
    let pipeline = ReferencePipeline {
        synthesis: SmLbm {
            levels: 256,
            ..SmLbm::default()
        },
        ..ReferencePipeline::default()
    };
    let layer = SceneLayer {
        amplitude: frame.amplitude.view(),
        depth: frame.depth.view(),
        valid: None,
    };
    let hologram = pipeline.run(&[layer], &|_, _| {}).expect("synthesis");
    pipeline
        .reconstruct_phase_only(&hologram, depths)
        .expect("reconstruction")
}

/// The shipped 8-layer CNN with the 6 mm pre-filter (DDPM), what `holo render` runs by default.
fn shipped_cnn(frame: &RgbdFrame, depths: &[f64]) -> Vec<Array3<f32>> {
    let config = PipelineConfig {
        offset_m: 6e-3,
        ..PipelineConfig::default()
    };
    let selection = ModelSelection {
        prefilter: PrefilterMode::Required,
        ..ModelSelection::default()
    };
    let pipeline = HologramPipeline::embedded(&selection, config).expect("models");
    let mut session = pipeline
        .session(frame.height(), frame.width())
        .expect("session");
    let out = session.render(frame).expect("frame");
    displayed_focal_stack(out, &config, depths)
}

fn check_near_far_focus(
    rgb: &Path,
    depth: &Path,
    encoding: DepthEncoding,
    size: (usize, usize),
    reconstruct: Reconstruct,
) {
    let options = LoadOptions {
        size: Some(size),
        ..LoadOptions::default()
    };
    let (frame, _) = load_rgbd(rgb, depth, encoding, &options).expect("loads");
    let mut sorted: Vec<f32> = frame.depth.iter().copied().collect();
    sorted.sort_by(f32::total_cmp);
    let q = |p: f64| sorted[((sorted.len() - 1) as f64 * p) as usize];
    let (near_d, far_d) = (q(0.1), q(0.9));
    let (near_cut, far_cut) = (q(0.3), q(0.7));
    assert!(
        far_d - near_d > 0.2,
        "scene must span the volume: {near_d}..{far_d}"
    );
    let near_region: Array2<bool> = frame.depth.mapv(|d| d <= near_cut);
    let far_region: Array2<bool> = frame.depth.mapv(|d| d >= far_cut);
    let recon = reconstruct(&frame, &[near_d as f64, far_d as f64]);
    // "Sharper" = reproduces the scene's own detail there: the gradient-domain error against the input
    // amplitude. (Raw gradient energy is not usable: defocused smooth-phase content rings rather than blurs.)
    let err = |a: &Array3<f32>, r: &Array2<bool>| detail_error(a, &frame.amplitude, r);
    let near_obj = (err(&recon[0], &near_region), err(&recon[1], &near_region));
    let background = (err(&recon[0], &far_region), err(&recon[1], &far_region));
    println!(
        "{}: detail error (near focus / far focus): near object {:.3e} / {:.3e}, background {:.3e} / {:.3e}",
        rgb.display(),
        near_obj.0,
        near_obj.1,
        background.0,
        background.1
    );
    assert!(near_obj.1 > 1.25 * near_obj.0, "near object: {near_obj:?}");
    assert!(
        background.0 > 1.05 * background.1,
        "background: {background:?}"
    );
}

#[test]
fn iphone_portrait_near_focus_sharpens_the_vase_far_focus_the_background() {
    check_near_far_focus(
        &shared_data("iphone_portrait_vase/derived_rgb_576x768.png"),
        &shared_data("iphone_portrait_vase/disparity_aux_576x768.jpg"),
        DepthEncoding::IphoneDisparity,
        (256, 192),
        reference,
    );
}

#[test]
fn redwood_frame_near_focus_sharpens_the_foreground_far_focus_the_background() {
    check_near_far_focus(
        &shared_data("redwood_livingroom_seq/color/00000.jpg"),
        &shared_data("redwood_livingroom_seq/depth/00000.png"),
        DepthEncoding::Millimetres16,
        (240, 320),
        reference,
    );
}

#[test]
fn shipped_cnn_near_focus_sharpens_the_vase_far_focus_the_background() {
    check_near_far_focus(
        &shared_data("iphone_portrait_vase/derived_rgb_576x768.png"),
        &shared_data("iphone_portrait_vase/disparity_aux_576x768.jpg"),
        DepthEncoding::IphoneDisparity,
        (256, 192),
        shipped_cnn,
    );
}

#[test]
fn shipped_cnn_near_focus_sharpens_the_redwood_foreground_far_focus_the_background() {
    check_near_far_focus(
        &shared_data("redwood_livingroom_seq/color/00000.jpg"),
        &shared_data("redwood_livingroom_seq/depth/00000.png"),
        DepthEncoding::Millimetres16,
        (240, 320),
        shipped_cnn,
    );
}

/// The Redwood frame as raw camera buffers (packed RGB8 + little-endian `MillimetresU16`), stretched at
/// its native 480×640, equals `load_rgbd` with `mm16` exactly (same automatic range, same hole filling);
/// as BGRA with padded rows and a 90° rotation it equals that frame rotated clockwise.
#[test]
fn redwood_camera_buffers_equal_load_rgbd() {
    let rgb_path = shared_data("redwood_livingroom_seq/color/00000.jpg");
    let depth_path = shared_data("redwood_livingroom_seq/depth/00000.png");
    let (expected, load_report) = load_rgbd(
        &rgb_path,
        &depth_path,
        DepthEncoding::Millimetres16,
        &LoadOptions::default(),
    )
    .expect("load_rgbd");
    let rgb = image::open(&rgb_path).expect("jpeg").to_rgb8();
    let depth = match image::open(&depth_path).expect("png") {
        image::DynamicImage::ImageLuma16(d) => d,
        other => panic!("expected 16-bit grey depth, got {:?}", other.color()),
    };
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    assert_eq!((h, w), (480, 640));
    assert_eq!((depth.height() as usize, depth.width() as usize), (h, w));
    let depth_bytes: Vec<u8> = depth
        .as_raw()
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let frame = CameraFrame {
        color: ColorImage {
            data: rgb.as_raw(),
            format: ColorFormat::Rgb8,
            width: w,
            height: h,
            row_stride: 0,
        },
        depth: DepthImage {
            data: &depth_bytes,
            format: DepthFormat::MillimetresU16,
            width: w,
            height: h,
            row_stride: 0,
        },
        rotation: Rotation::Deg0,
        color_crop: None,
        confidence: None,
    };
    let options = FrameOptions {
        fit: Fit::Stretch,
        ..FrameOptions::default()
    };
    let (got, report) = frame.to_rgbd(h, w, &options).expect("camera frame");
    assert_eq!(got, expected);
    assert_eq!(report.range_used, load_report.range_used);
    assert_eq!(report.invalid_fraction, load_report.invalid_fraction);
    assert!(
        report.invalid_fraction > 0.05,
        "the frame has holes to fill"
    );

    // BGRA with 24 bytes of row padding (no padding after the last row), rotated 90° clockwise.
    let stride = 4 * w + 24;
    let mut bgra = vec![0u8; stride * (h - 1) + 4 * w];
    for (i, p) in rgb.pixels().enumerate() {
        let o = (i / w) * stride + (i % w) * 4;
        bgra[o..o + 4].copy_from_slice(&[p[2], p[1], p[0], 255]);
    }
    let rotated = CameraFrame {
        color: ColorImage {
            data: &bgra,
            format: ColorFormat::Bgra8,
            width: w,
            height: h,
            row_stride: stride,
        },
        rotation: Rotation::Deg90,
        ..frame
    };
    let (got, report) = rotated.to_rgbd(w, h, &options).expect("rotated frame");
    assert_eq!(report.range_used, load_report.range_used);
    // Clockwise: output (y, x) shows buffer pixel (h − 1 − x, y).
    let mut turned = expected.clone();
    turned.depth = Array2::from_shape_fn((w, h), |(y, x)| expected.depth[[h - 1 - x, y]]);
    turned.amplitude =
        Array3::from_shape_fn((3, w, h), |(c, y, x)| expected.amplitude[[c, h - 1 - x, y]]);
    assert_eq!(got, turned);
}

/// The native engine's int8 path on a real photo loses no more against f32 than tract's execution of the same
/// int8 QDQ file: the PSNR of each int8 engine's CNN output (amplitude and phase heads of the hologram CNN)
/// against the f32 CNN's, native within 0.1 dB of tract (or better).
#[test]
fn native_int8_is_as_close_to_f32_as_tract_int8_on_a_real_photo() {
    use tensorholo::cnn::{cnn_plan, CnnEngine, CnnOptions, PlanRequest, ThreadCount};
    use tensorholo::model::{embedded, ModelConfig, Precision};
    let options = LoadOptions {
        size: Some((256, 192)),
        ..LoadOptions::default()
    };
    let (frame, _) = load_rgbd(
        &shared_data("iphone_portrait_vase/derived_rgb_576x768.png"),
        &shared_data("iphone_portrait_vase/disparity_aux_576x768.jpg"),
        DepthEncoding::IphoneDisparity,
        &options,
    )
    .expect("loads");
    let (h, w) = (frame.height(), frame.width());
    let mut input = Array3::zeros((4, h, w));
    tensorholo::model::contract::pack_rgbd(&frame, input.view_mut()).unwrap();
    let cfg = ModelConfig::default();
    let run = |precision, engine| {
        let model = std::sync::Arc::new(embedded::hologram_model(8, precision, &cfg).unwrap());
        let request = PlanRequest {
            cnn: CnnOptions {
                engine,
                threads: ThreadCount::Fixed(2),
                ..CnnOptions::default()
            },
            ..PlanRequest::default()
        };
        let (mut plan, report) = cnn_plan(&model, h, w, &request).unwrap();
        assert_eq!(report.engine, engine);
        let (a, p) = plan.run_outputs(input.view()).unwrap();
        ndarray::concatenate![ndarray::Axis(0), a, p]
    };
    let f32_out = run(Precision::F32, CnnEngine::Native);
    let psnr = |x: &Array3<f32>| {
        let range = std::f32::consts::SQRT_2;
        tensorholo::metrics::psnr(f32_out.view(), x.view(), range).unwrap()
    };
    let native = psnr(&run(Precision::Int8Qdq, CnnEngine::Native));
    let tract = psnr(&run(Precision::Int8Qdq, CnnEngine::Tract));
    println!("int8 QDQ heads vs f32: native {native:.2} dB, tract {tract:.2} dB");
    assert!(native.is_finite() && native > 25.0, "{native}");
    assert!(
        native >= tract - 0.1,
        "native {native} dB, tract {tract} dB"
    );
}

/// The paper's quality protocol (Table 2: amplitude and dynamic focal stack against the SM-LBM ground truth) on
/// what the SLM displays for a real photo, with both CNNs (hologram + 6 mm pre-filter) in f32 and in int8 QDQ
/// on the native engine: int8 within 0.1 dB of f32.
#[test]
fn native_int8_displayed_hologram_is_within_a_tenth_of_a_db_of_f32() {
    use tensorholo::cnn::{CnnEngine, CnnOptions};
    use tensorholo::evaluation::{focal_depths, table2};
    use tensorholo::model::Precision;
    let options = LoadOptions {
        size: Some((192, 256)),
        ..LoadOptions::default()
    };
    let (frame, _) = load_rgbd(
        &shared_data("redwood_livingroom_seq/color/00000.jpg"),
        &shared_data("redwood_livingroom_seq/depth/00000.png"),
        DepthEncoding::Millimetres16,
        &options,
    )
    .expect("loads");
    let layer = SceneLayer {
        amplitude: frame.amplitude.view(),
        depth: frame.depth.view(),
        valid: None,
    };
    let gt = ReferencePipeline::default()
        .run(&[layer], &|_, _| {})
        .expect("SM-LBM")
        .midpoint;
    let depths = focal_depths(frame.depth.view(), 200, 15, 5, 3).unwrap();
    let config = PipelineConfig {
        offset_m: 6e-3,
        backend: tensorholo::pipeline::Backend::Cpu,
        cnn: CnnOptions {
            engine: CnnEngine::Native,
            ..CnnOptions::default()
        },
        ..PipelineConfig::default()
    };
    let score = |precision| {
        let selection = ModelSelection {
            precision,
            prefilter: PrefilterMode::Required,
            ..ModelSelection::default()
        };
        let pipeline = HologramPipeline::embedded(&selection, config).expect("models");
        let mut session = pipeline
            .session(frame.height(), frame.width())
            .expect("session");
        let out = session.render(&frame).expect("frame");
        let shown = tensorholo::optics::post_encoding_midpoint(
            out.phase.view(),
            out.amplitude_scale,
            &config.optics,
            config.offset_m,
            config.options,
        )
        .unwrap();
        table2(
            shown.view(),
            gt.view(),
            &config.optics,
            config.options,
            &depths,
        )
        .unwrap()
    };
    let f32_scores = score(Precision::F32);
    let int8_scores = score(Precision::Int8Qdq);
    println!("displayed, f32: {f32_scores:?}\ndisplayed, int8 QDQ (native): {int8_scores:?}");
    assert!(f32_scores.psnr_fs > 15.0, "{f32_scores:?}");
    assert!((int8_scores.psnr_amp - f32_scores.psnr_amp).abs() <= 0.1);
    assert!((int8_scores.psnr_fs - f32_scores.psnr_fs).abs() <= 0.1);
}

/// Depth at 1/4 and 1/8 of the colour's resolution (a phone's LiDAR under its image), brought back to it by
/// nearest neighbour and by the colour-guided joint bilateral upsampling (`scene::upsample_depth`), against
/// the hologram of the full-resolution depth (taken as exact): the shipped CNN's displayed focal stack at 5
/// planes, PSNR over every plane. The edge-aware default must be the closer one at both factors, on a
/// rendered frame (Redwood) and a real one (TUM); the figures are docs/VIDEO.md's.
#[test]
fn edge_aware_depth_upsampling_is_closer_to_the_full_resolution_hologram_than_nearest() {
    use tensorholo::scene::DepthUpsampling;
    let depths = [0.1, 0.3, 0.5, 0.7, 0.9];
    let dir = std::env::temp_dir().join(format!("tensorholo-upsampling-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (name, rgb, depth, encoding) in [
        (
            "Redwood",
            "redwood_livingroom_seq/color/00000.jpg",
            "redwood_livingroom_seq/depth/00000.png",
            DepthEncoding::Millimetres16,
        ),
        (
            "DragonBunny",
            "odak_dragonbunny/DragonBunny_rgb.png",
            "odak_dragonbunny/DragonBunny_depthmap.png",
            DepthEncoding::RelativeNearBright,
        ),
        (
            "TUM",
            "tum/TUM_color.png",
            "tum/TUM_depth.png",
            DepthEncoding::Tum5000,
        ),
    ] {
        let (rgb, depth) = (shared_data(rgb), shared_data(depth));
        let size = Some((192, 256));
        let (full, report) = load_rgbd(
            &rgb,
            &depth,
            encoding,
            &LoadOptions {
                size,
                ..LoadOptions::default()
            },
        )
        .unwrap();
        let exact = shipped_cnn(&full, &depths);
        let peak = exact
            .iter()
            .flat_map(|p| p.iter())
            .fold(0f32, |m, &v| m.max(v));
        let score = |stack: &[Array3<f32>]| {
            let mse: f64 = stack
                .iter()
                .zip(&exact)
                .map(|(a, b)| {
                    a.iter()
                        .zip(b.iter())
                        .map(|(x, y)| f64::from(x - y).powi(2))
                        .sum::<f64>()
                })
                .sum::<f64>()
                / (stack.len() * exact[0].len()) as f64;
            10.0 * (f64::from(peak).powi(2) / mse).log10()
        };
        let source = image::open(&depth).unwrap();
        let (w, h) = (source.width(), source.height());
        for factor in [4u32, 8] {
            // Each block's centre sample, at the file's own bit depth (8-bit relative maps stay 8-bit).
            let at = |x: u32, y: u32| (factor * x + factor / 2, factor * y + factor / 2);
            let small: image::DynamicImage = if source.color().bytes_per_pixel() % 2 == 0 {
                let s = source.to_luma16();
                image::ImageBuffer::<image::Luma<u16>, _>::from_fn(
                    w / factor,
                    h / factor,
                    |x, y| {
                        let (sx, sy) = at(x, y);
                        *s.get_pixel(sx, sy)
                    },
                )
                .into()
            } else {
                let s = source.to_luma8();
                image::ImageBuffer::<image::Luma<u8>, _>::from_fn(w / factor, h / factor, |x, y| {
                    let (sx, sy) = at(x, y);
                    *s.get_pixel(sx, sy)
                })
                .into()
            };
            let path = dir.join(format!("{name}_{factor}.png"));
            small.save(&path).unwrap();
            let load = |method| {
                load_rgbd(
                    &rgb,
                    &path,
                    encoding,
                    &LoadOptions {
                        size,
                        range: report.range_used,
                        depth_upsampling: method,
                        ..LoadOptions::default()
                    },
                )
                .unwrap()
                .0
            };
            let nearest = score(&shipped_cnn(&load(DepthUpsampling::Nearest), &depths));
            let guided = score(&shipped_cnn(
                &load(DepthUpsampling::JointBilateral),
                &depths,
            ));
            eprintln!(
                "{name}, depth at 1/{factor}: nearest {nearest:.2} dB, joint bilateral {guided:.2} dB \
                 against the full-resolution depth's displayed focal stack"
            );
            // TUM's full-resolution depth is a real sensor's (noise, holes), not exact: reported, not held.
            if name != "TUM" {
                assert!(
                    guided > nearest,
                    "{name} 1/{factor}: joint bilateral {guided:.2} dB ≤ nearest {nearest:.2} dB"
                );
            }
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A phone depth sensor simulated on an exact 16-bit millimetre depth map: one sample per 4×4 block (its centre),
/// 1 % uniform noise on z, and where the block spans more than 10 cm (a depth edge) a "flying pixel" anywhere
/// between its near and far depth, rated confidence 0 (the rest 2, as ARKit rates). `frame` draws other noise
/// and other flying depths (a sensor's next frame of a still scene). Returns the depth, the confidence map and
/// the number of flying samples.
fn simulated_phone_sensor(
    source: &image::ImageBuffer<image::Luma<u16>, Vec<u16>>,
    frame: u64,
) -> (
    image::ImageBuffer<image::Luma<u16>, Vec<u16>>,
    image::GrayImage,
    usize,
) {
    let (w, h) = (source.width() / 4, source.height() / 4);
    // A fixed pseudo-random number in [0, 1) per sample and frame (SplitMix64 of its index).
    let unit = |i: u64, salt: u64| {
        let mut z = (i * 2 + salt).wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut sensor = image::ImageBuffer::<image::Luma<u16>, _>::new(w, h);
    let mut confidence = image::GrayImage::new(w, h);
    let mut flying = 0;
    for y in 0..h {
        for x in 0..w {
            let block: Vec<f64> = (0..16)
                .map(|k| f64::from(source.get_pixel(4 * x + k % 4, 4 * y + k / 4).0[0]))
                .filter(|&v| v > 0.0)
                .collect();
            let i = u64::from(y * w + x) + frame * u64::from(w * h);
            let (lo, hi) = block
                .iter()
                .fold((f64::INFINITY, 0f64), |(l, u), &v| (l.min(v), u.max(v)));
            let centre = f64::from(source.get_pixel(4 * x + 2, 4 * y + 2).0[0]);
            let (value, rating) = if block.len() < 16 || centre == 0.0 {
                (centre, 2) // a hole of the exact depth stays a hole
            } else if hi - lo > 100.0 {
                flying += 1;
                (lo + unit(i, 0) * (hi - lo), 0)
            } else {
                (
                    centre * (1.0 + 0.01 * (2.0 * unit(i, 1) - 1.0) * 3f64.sqrt()),
                    2,
                )
            };
            sensor.put_pixel(x, y, image::Luma([value.round() as u16]));
            confidence.put_pixel(x, y, image::Luma([rating]));
        }
    }
    (sensor, confidence, flying)
}

/// Frame `frame` of [`simulated_phone_sensor`] on `source` (the exact depth of `rgb`), loaded beside `rgb` as
/// `holo render` loads files, without and with its confidence map (the files written into `dir`); and the
/// number of its flying samples.
fn simulated_sensor_frames(
    rgb: &Path,
    source: &image::ImageBuffer<image::Luma<u16>, Vec<u16>>,
    frame: u64,
    dir: &Path,
    options: &LoadOptions,
) -> (RgbdFrame, RgbdFrame, usize) {
    use tensorholo::scene::load_rgbd_with_confidence;
    let (sensor, confidence, flying) = simulated_phone_sensor(source, frame);
    let (sensor_path, confidence_path) = (dir.join("d.png"), dir.join("c.png"));
    sensor.save(&sensor_path).unwrap();
    confidence.save(&confidence_path).unwrap();
    let load = |confidence: Option<&Path>| {
        load_rgbd_with_confidence(
            rgb,
            &sensor_path,
            confidence,
            DepthEncoding::Millimetres16,
            options,
        )
        .unwrap()
        .0
    };
    (load(None), load(Some(&confidence_path)), flying)
}

/// A still scene (Redwood frame 0, its depth exact) seen by the simulated phone sensor of
/// [`simulated_phone_sensor`] over 5 frames, each with its own noise and flying pixels, through one session of
/// the shipped CNN at 192 × 256: the SLM patterns churn (`encoding::phase_churn`, mean wrapped |Δφ| between
/// consecutive patterns) although nothing moved, and the confidence map lowers that churn (the flying pixels,
/// which change most from frame to frame, are filled from steady neighbours); the exact depth on every frame
/// churns not at all. docs/VIDEO.md gives the figures.
#[test]
fn a_still_scene_through_a_simulated_phone_sensor_churns_less_with_its_confidence_map() {
    use tensorholo::encoding::phase_churn;
    let rgb = shared_data("redwood_livingroom_seq/color/00000.jpg");
    let depth = shared_data("redwood_livingroom_seq/depth/00000.png");
    let options = LoadOptions {
        size: Some((192, 256)),
        ..LoadOptions::default()
    };
    let (exact, report) = load_rgbd(&rgb, &depth, DepthEncoding::Millimetres16, &options).unwrap();
    let options = LoadOptions {
        range: report.range_used,
        ..options
    };
    let config = PipelineConfig {
        offset_m: 6e-3,
        ..PipelineConfig::default()
    };
    let pipeline = HologramPipeline::embedded(&ModelSelection::default(), config).expect("models");
    let mut session = pipeline.session(192, 256).expect("session");
    let mut codes = |frame: &RgbdFrame| session.render(frame).expect("frame").codes.clone();
    let mean_churn = |patterns: &[Array3<u8>]| {
        patterns
            .windows(2)
            .map(|p| phase_churn(p[0].view(), p[1].view()).unwrap().mean_abs_rad)
            .sum::<f64>()
            / (patterns.len() - 1) as f64
    };
    let still = [codes(&exact), codes(&exact)];
    assert_eq!(mean_churn(&still), 0.0);

    let source = image::open(&depth).unwrap().to_luma16();
    let dir = std::env::temp_dir().join(format!("tensorholo-churn-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (mut without, mut with) = (Vec::new(), Vec::new());
    for frame in 0..5 {
        let (plain, confident, _) = simulated_sensor_frames(&rgb, &source, frame, &dir, &options);
        without.push(codes(&plain));
        with.push(codes(&confident));
    }
    std::fs::remove_dir_all(&dir).unwrap();
    let (without, with) = (mean_churn(&without), mean_churn(&with));
    eprintln!(
        "Redwood frame 0, still, 5 frames of a simulated phone sensor: SLM phase churn {without:.4} rad \
         without the confidence map, {with:.4} rad with it (0 with the exact depth)"
    );
    assert!(without > 0.0, "{without}");
    assert!(
        with < 0.9 * without,
        "with {with:.4} rad, without {without:.4} rad"
    );
}

/// A simulated phone depth sensor ([`simulated_phone_sensor`]) on a rendered frame whose depth is exact
/// (Redwood frame 0): depth at a quarter of the resolution, 1 % noise on z, and at depth edges "flying pixels" (a
/// depth anywhere between the near and the far side, what a LiDAR or time-of-flight sensor returns across an
/// edge) rated confidence 0, the rest 2, as ARKit rates its depth. With the confidence map the flying pixels
/// are invalid and filled from their confident neighbours, so the shipped CNN's displayed focal stack is closer
/// to the one of the exact full-resolution depth than without it (PSNR over 5 planes; docs/VIDEO.md gives the
/// figures).
#[test]
fn confidence_maps_bring_a_simulated_phone_sensor_closer_to_the_exact_depth() {
    let depths = [0.1, 0.3, 0.5, 0.7, 0.9];
    let rgb = shared_data("redwood_livingroom_seq/color/00000.jpg");
    let depth = shared_data("redwood_livingroom_seq/depth/00000.png");
    let size = Some((192, 256));
    let options = LoadOptions {
        size,
        ..LoadOptions::default()
    };
    let (full, report) = load_rgbd(&rgb, &depth, DepthEncoding::Millimetres16, &options).unwrap();
    let exact = shipped_cnn(&full, &depths);
    let peak = exact
        .iter()
        .flat_map(|p| p.iter())
        .fold(0f32, |m, &v| m.max(v));
    let score = |frame: &RgbdFrame| {
        let stack = shipped_cnn(frame, &depths);
        let mse: f64 = stack
            .iter()
            .zip(&exact)
            .flat_map(|(a, b)| a.iter().zip(b.iter()))
            .map(|(x, y)| f64::from(x - y).powi(2))
            .sum::<f64>()
            / (stack.len() * exact[0].len()) as f64;
        10.0 * (f64::from(peak).powi(2) / mse).log10()
    };
    // The sensor: each 4×4 block of the exact depth gives one sample.
    let source = image::open(&depth).unwrap().to_luma16();
    let samples = (source.width() / 4) * (source.height() / 4);
    let dir = std::env::temp_dir().join(format!("tensorholo-confidence-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let options = LoadOptions {
        range: report.range_used,
        ..options
    };
    let (plain, confident, flying) = simulated_sensor_frames(&rgb, &source, 0, &dir, &options);
    let (without, with) = (score(&plain), score(&confident));
    eprintln!(
        "Redwood, a simulated phone sensor (1/4 resolution, 1 % noise, {flying} of {samples} samples flying at \
         edges): without its confidence map {without:.2} dB, with it {with:.2} dB against the exact depth's \
         displayed focal stack"
    );
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(flying > 100, "{flying}");
    assert!(
        with > without + 0.3,
        "with {with:.2} dB, without {without:.2} dB"
    );
}
