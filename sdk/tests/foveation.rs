//! Foveated frames (`HologramSession::render_foveated`, docs/FOVEATION.md) against the full 3D frame of the
//! same session configuration, on real RGB-D frames from `../shared/data` with the shipped CNNs:
//!
//! - inside the fovea the focal stack (of the complex midpoint hologram, and of what the SLM codes display)
//!   agrees with the full frame's to ≥ 40 dB at every plane, each at its least-squares scale;
//! - the normaliser does not follow the gaze; the seam keeps the full frame's brightness; the periphery
//!   matches the full frame at the gaze's plane and blurs away from it;
//! - a fovea covering the frame is the full frame bit for bit; gazes at the corners, a jumping gaze, a radius
//!   of 0; bad gazes and options are refused by name and leave the session usable.
//!
//! Rerun with the figures printed: `cargo test -p tensorholo --test foveation -- --nocapture`.

use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3, Axis};
use num_complex::Complex32;
use tensorholo::foveation::{FoveaRadius, FoveationOptions, Gaze};
use tensorholo::model::Precision;
use tensorholo::optics::{focal_stack, post_encoding_midpoint};
use tensorholo::pipeline::{
    Backend, HologramPipeline, HologramSession, ModelSelection, PipelineConfig,
};
use tensorholo::scene::{load_rgbd, DepthEncoding, LoadOptions, RgbdFrame};
use tensorholo::HoloError;

const OFFSET_M: f64 = 6e-3;

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

/// Real frames at `h × w`: TUM (Kinect v1), a RealSense frame, the iPhone portrait.
fn real_frames(h: usize, w: usize) -> Vec<(&'static str, RgbdFrame)> {
    let options = LoadOptions {
        size: Some((h, w)),
        ..LoadOptions::default()
    };
    let load = |rgb: &str, depth: &str, enc| {
        load_rgbd(&data(rgb), &data(depth), enc, &options)
            .unwrap()
            .0
    };
    vec![
        (
            "tum",
            load(
                "tum/TUM_color.png",
                "tum/TUM_depth.png",
                DepthEncoding::Tum5000,
            ),
        ),
        (
            "realsense",
            load(
                "realsense_seq/rgb/000012.png",
                "realsense_seq/depth/000012.png",
                DepthEncoding::Millimetres16,
            ),
        ),
        (
            "iphone",
            load(
                "iphone_portrait_vase/derived_rgb_576x768.png",
                "iphone_portrait_vase/disparity_aux_576x768.jpg",
                DepthEncoding::IphoneDisparity,
            ),
        ),
    ]
}

fn pipeline(precision: Precision, foveation: Option<FoveationOptions>) -> HologramPipeline {
    let selection = ModelSelection {
        precision,
        ..ModelSelection::default()
    };
    let config = PipelineConfig {
        offset_m: OFFSET_M,
        backend: Backend::Cpu,
        foveation,
        ..PipelineConfig::default()
    };
    HologramPipeline::embedded(&selection, config).unwrap()
}

fn pixels(radius: f64) -> FoveationOptions {
    FoveationOptions {
        radius: FoveaRadius::Pixels { pixels: radius },
        ..FoveationOptions::default()
    }
}

/// What a frame displays and its CNN midpoint: the complex midpoint hologram's focal stack and the SLM
/// pattern's (the post-encoding midpoint, Eq. 8–10), at `depths`.
struct Stacks {
    midpoint: Vec<Array3<f32>>,
    displayed: Vec<Array3<f32>>,
    scale: f32,
}

fn stacks(session: &HologramSession, depths: &[f64]) -> Stacks {
    let setup = tensorholo::optics::OpticalSetup::default();
    let options = tensorholo::optics::PropagationOptions::default();
    let out = session.output();
    let midpoint = session.last_heads().unwrap().to_field().unwrap();
    let shown = post_encoding_midpoint(
        out.phase.view(),
        out.amplitude_scale,
        &setup,
        OFFSET_M,
        options,
    )
    .unwrap();
    Stacks {
        midpoint: focal_stack(midpoint.view(), &setup, 0.0, depths, options, false).unwrap(),
        displayed: focal_stack(shown.view(), &setup, 0.0, depths, options, false).unwrap(),
        scale: out.amplitude_scale,
    }
}

/// Pixels whose distance from `gaze` lies in `[lo, hi)`.
fn ring(h: usize, w: usize, gaze: &Gaze, lo: f64, hi: f64) -> Array2<bool> {
    Array2::from_shape_fn((h, w), |(y, x)| {
        let r = (x as f64 - gaze.x).hypot(y as f64 - gaze.y);
        r >= lo && r < hi
    })
}

/// PSNR of `test` against `reference` over `region` (all colours), `test` at its least-squares scale, the
/// peak the reference's largest value there.
fn psnr_ls(reference: &Array3<f32>, test: &Array3<f32>, region: &Array2<bool>) -> f64 {
    psnr_ls_peak(reference, test, region, None)
}

/// [`psnr_ls`] with the peak given (the plane's largest value, to compare regions), or the region's.
fn psnr_ls_peak(
    reference: &Array3<f32>,
    test: &Array3<f32>,
    region: &Array2<bool>,
    peak_of_plane: Option<f64>,
) -> f64 {
    let (mut rt, mut tt, mut peak) = (0.0f64, 0.0f64, 0.0f64);
    let each = |f: &mut dyn FnMut(f64, f64)| {
        for c in 0..3 {
            let r = reference.index_axis(Axis(0), c);
            let t = test.index_axis(Axis(0), c);
            for ((idx, &r), &t) in r.indexed_iter().zip(t.iter()) {
                if region[idx] {
                    f(f64::from(r), f64::from(t));
                }
            }
        }
    };
    each(&mut |r, t| {
        rt += r * t;
        tt += t * t;
        peak = peak.max(r);
    });
    let peak = peak_of_plane.unwrap_or(peak);
    let s = if tt > 0.0 { rt / tt } else { 0.0 };
    let (mut se, mut n) = (0.0f64, 0usize);
    each(&mut |r, t| {
        se += (r - s * t).powi(2);
        n += 1;
    });
    10.0 * (peak * peak * n as f64 / se.max(1e-30)).log10()
}

/// Mean amplitude over `region`, all colours.
fn mean_in(a: &Array3<f32>, region: &Array2<bool>) -> f64 {
    let (mut s, mut n) = (0.0f64, 0usize);
    for c in 0..3 {
        for ((idx, &v), _) in a.index_axis(Axis(0), c).indexed_iter().zip(0..) {
            if region[idx] {
                s += f64::from(v);
                n += 1;
            }
        }
    }
    s / n as f64
}

fn brightest(frame: &RgbdFrame) -> f32 {
    frame.amplitude.iter().copied().fold(0.0, f32::max)
}

const DEPTHS: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];

/// The focal plane of `DEPTHS` nearest the gaze's depth.
fn nearest_plane(d_g: f64) -> usize {
    (0..DEPTHS.len())
        .min_by(|&a, &b| (DEPTHS[a] - d_g).abs().total_cmp(&(DEPTHS[b] - d_g).abs()))
        .unwrap()
}

#[test]
fn the_fovea_is_the_full_frame_and_the_periphery_follows_it() {
    let (h, w) = (240, 320);
    let radius = 60.0;
    for precision in [Precision::F32, Precision::Int8Qdq] {
        let full = pipeline(precision, None);
        let fov = pipeline(precision, Some(pixels(radius)));
        let mut full_session = full.session(h, w).unwrap();
        let mut fov_session = fov.session(h, w).unwrap();
        // A hard switch at R (a band of one pixel): its ring [R, R + 16) is the periphery's model alone.
        let hard = pipeline(
            precision,
            Some(FoveationOptions {
                band_px: 1.0,
                ..pixels(radius)
            }),
        );
        let mut hard_session = hard.session(h, w).unwrap();
        for (name, frame) in real_frames(h, w) {
            full_session.render(&frame).unwrap();
            let want = stacks(&full_session, &DEPTHS);
            println!(
                "{name} {precision:?}: full normaliser {:.3} = {:.3} × max A",
                want.scale,
                want.scale / brightest(&frame)
            );
            for gaze in [
                Gaze {
                    x: 160.0,
                    y: 120.0,
                    depth_m: None,
                },
                Gaze {
                    x: 70.5,
                    y: 180.2,
                    depth_m: None,
                },
            ] {
                fov_session.render_foveated(&frame, &gaze).unwrap();
                let report = *fov_session.fovea_report().unwrap();
                assert!(!report.covers_frame);
                let got = stacks(&fov_session, &DEPTHS);
                let fovea = ring(h, w, &gaze, 0.0, radius + 0.5);
                let band = ring(h, w, &gaze, radius + 0.5, radius + 16.0);
                let far = ring(h, w, &gaze, radius + 48.0, f64::INFINITY);
                let plane = nearest_plane(report.gaze_depth);
                let mut line = format!(
                    "  gaze ({}, {}) d_g {:.2} (plane {plane}):",
                    gaze.x, gaze.y, report.gaze_depth
                );
                for k in 0..DEPTHS.len() {
                    let m = psnr_ls(&want.midpoint[k], &got.midpoint[k], &fovea);
                    let d = psnr_ls(&want.displayed[k], &got.displayed[k], &fovea);
                    line += &format!(" fovea {m:.1}/{d:.1}");
                    assert!(
                        m >= 40.0 && d >= 40.0,
                        "{name} {precision:?} {gaze:?} plane {k}: {m:.1} / {d:.1} dB"
                    );
                }
                let top = f64::from(want.midpoint[plane].iter().copied().fold(0.0f32, f32::max));
                let band_psnr = psnr_ls_peak(
                    &want.midpoint[plane],
                    &got.midpoint[plane],
                    &band,
                    Some(top),
                );
                let far_mid =
                    psnr_ls_peak(&want.midpoint[plane], &got.midpoint[plane], &far, Some(top));
                let far_shown = psnr_ls(&want.displayed[plane], &got.displayed[plane], &far);
                let all = Array2::from_elem((h, w), true);
                hard_session.render_foveated(&frame, &gaze).unwrap();
                let switched = stacks(&hard_session, &DEPTHS);
                let hard_band = psnr_ls_peak(
                    &want.midpoint[plane],
                    &switched.midpoint[plane],
                    &band,
                    Some(top),
                );
                let whole = psnr_ls(&want.midpoint[plane], &got.midpoint[plane], &all);
                // The seam's brightness relative to the fovea's, against the full frame's.
                let rel = |s: &Array3<f32>| mean_in(s, &band) / mean_in(s, &fovea);
                let seam = rel(&got.midpoint[plane]) / rel(&want.midpoint[plane]);
                line += &format!(
                    " | band {band_psnr:.1} dB (hard switch {hard_band:.1}), seam {seam:.3}; periphery {far_mid:.1}/{far_shown:.1} dB; frame {whole:.1}"
                );
                println!("{line}");
                assert!(
                    (seam - 1.0).abs() <= 0.03,
                    "{name}: seam brightness {seam:.3}"
                );
                assert!(
                    band_psnr >= hard_band,
                    "{name}: band {band_psnr:.1} < the periphery's model there {hard_band:.1}"
                );
                assert!(
                    far_mid >= 29.0 && far_shown >= 25.0,
                    "{name}: periphery {far_mid:.1} / {far_shown:.1}"
                );
            }
        }
    }
}

#[test]
fn the_normaliser_does_not_follow_the_gaze() {
    let (h, w) = (120, 160);
    let mut session = pipeline(Precision::F32, Some(pixels(30.0)))
        .session(h, w)
        .unwrap();
    let frame = &real_frames(h, w)[0].1;
    let at = |session: &mut HologramSession, x, y| {
        session
            .render_foveated(
                frame,
                &Gaze {
                    x,
                    y,
                    depth_m: None,
                },
            )
            .unwrap()
            .amplitude_scale
    };
    let a = at(&mut session, 20.0, 20.0);
    let b = at(&mut session, 140.0, 100.0);
    assert_eq!(a.to_bits(), b.to_bits());
    assert_eq!(
        a.to_bits(),
        (tensorholo::foveation::FOVEATED_NORMALISER_GAIN * brightest(frame)).to_bits()
    );
}

#[test]
fn a_fovea_covering_the_frame_is_the_full_frame_bit_for_bit() {
    let (h, w) = (64, 80);
    let frame = &real_frames(h, w)[1].1;
    let mut full = pipeline(Precision::F32, None).session(h, w).unwrap();
    let want = full.render(frame).unwrap().clone();
    let mut fov = pipeline(Precision::F32, Some(pixels(60.0)))
        .session(h, w)
        .unwrap();
    // The centre: the corners are 50.6 pixels away.
    let got = fov
        .render_foveated(
            frame,
            &Gaze {
                x: 39.5,
                y: 31.5,
                depth_m: None,
            },
        )
        .unwrap();
    assert_eq!(got.codes, want.codes);
    assert_eq!(
        got.amplitude_scale.to_bits(),
        want.amplitude_scale.to_bits()
    );
    assert!(fov.fovea_report().unwrap().covers_frame);
    // A corner: no longer covered, foveated.
    fov.render_foveated(
        frame,
        &Gaze {
            x: 0.0,
            y: 0.0,
            depth_m: None,
        },
    )
    .unwrap();
    assert!(!fov.fovea_report().unwrap().covers_frame);
}

#[test]
fn corners_jumps_a_zero_radius_and_a_given_depth() {
    let (h, w) = (96, 128);
    let frame = &real_frames(h, w)[0].1;
    let mut session = pipeline(Precision::F32, Some(pixels(20.0)))
        .session(h, w)
        .unwrap();
    let corners = [
        (-0.5, -0.5),
        (127.5, -0.5),
        (-0.5, 95.5),
        (127.5, 95.5),
        (64.0, 48.0),
    ];
    let mut first = Vec::new();
    for &(x, y) in &corners {
        let codes = session
            .render_foveated(
                frame,
                &Gaze {
                    x,
                    y,
                    depth_m: None,
                },
            )
            .unwrap()
            .codes
            .clone();
        let r = *session.fovea_report().unwrap();
        let [ty, tx, th, tw] = r.tile;
        assert!(ty + th <= h && tx + tw <= w, "{r:?}");
        first.push(codes);
    }
    // The gaze jumps back and forth: the same gaze gives the same bits.
    for (i, &(x, y)) in corners.iter().enumerate().rev() {
        let codes = &session
            .render_foveated(
                frame,
                &Gaze {
                    x,
                    y,
                    depth_m: None,
                },
            )
            .unwrap()
            .codes;
        assert_eq!(codes, &first[i], "gaze {i}");
    }
    assert_ne!(first[0], first[3]);
    // A radius of 0: the band alone holds the CNN's field.
    let mut zero = pipeline(Precision::F32, Some(pixels(0.0)))
        .session(h, w)
        .unwrap();
    zero.render_foveated(
        frame,
        &Gaze {
            x: 64.0,
            y: 48.0,
            depth_m: None,
        },
    )
    .unwrap();
    // A given depth: the near end of the volume is normalised depth 0; beyond it, clamped.
    for (z, d) in [(3e-3, 0.0), (1.0, 0.0), (0.0, 0.5), (-3e-3, 1.0)] {
        session
            .render_foveated(
                frame,
                &Gaze {
                    x: 64.0,
                    y: 48.0,
                    depth_m: Some(z),
                },
            )
            .unwrap();
        let r = session.fovea_report().unwrap();
        assert_eq!(r.gaze_depth, d, "{z} m");
    }
}

/// The periphery is sharp at the gaze's depth and blurred away from it: beyond the band, the composed
/// midpoint's amplitude keeps the frame's detail (squared differences of horizontal neighbours) where the
/// scene lies at the gaze's depth, and loses more of it the further the scene lies from that depth.
#[test]
fn the_periphery_blurs_with_the_depth_difference() {
    let (h, w) = (120, 160);
    for (name, frame) in real_frames(h, w) {
        let mut session = pipeline(Precision::F32, Some(pixels(10.0)))
            .session(h, w)
            .unwrap();
        let gaze = Gaze {
            x: 10.0,
            y: 10.0,
            depth_m: Some(0.0),
        };
        session.render_foveated(&frame, &gaze).unwrap();
        let d_g = session.fovea_report().unwrap().gaze_depth as f32;
        let far = ring(h, w, &gaze, 40.0, f64::INFINITY);
        let a = &session.last_heads().unwrap().amplitude;
        // Detail kept per band of depth difference: [0, 0.05), [0.05, 0.2), [0.2, 1].
        let bins = [0.0f32, 0.05, 0.2, 1.01];
        let (mut kept, mut had) = ([0.0f64; 3], [0.0f64; 3]);
        for c in 0..3 {
            for y in 0..h {
                for x in 1..w {
                    if !(far[[y, x]] && far[[y, x - 1]]) {
                        continue;
                    }
                    let dd = (frame.depth[[y, x]] - d_g)
                        .abs()
                        .max((frame.depth[[y, x - 1]] - d_g).abs());
                    let Some(b) = (0..3).find(|&b| dd >= bins[b] && dd < bins[b + 1]) else {
                        continue;
                    };
                    kept[b] += f64::from(a[[c, y, x]] - a[[c, y, x - 1]]).powi(2);
                    had[b] +=
                        f64::from(frame.amplitude[[c, y, x]] - frame.amplitude[[c, y, x - 1]])
                            .powi(2);
                }
            }
        }
        let ratio: Vec<f64> = kept
            .iter()
            .zip(&had)
            .map(|(k, h)| k / h.max(1e-12))
            .collect();
        println!("{name}: detail kept by depth difference <0.05, <0.2, ≥0.2: {ratio:.2?}");
        assert!(ratio[0] > 0.95, "{name}: {ratio:?}");
        assert!(
            ratio[2] < 0.5 * ratio[0] && ratio[2] < ratio[1],
            "{name}: {ratio:?}"
        );
    }
}

#[test]
fn bad_gazes_and_options_are_refused_by_name_and_the_session_stays_usable() {
    let (h, w) = (48, 64);
    let frame = &real_frames(h, w)[0].1;
    let mut session = pipeline(Precision::F32, Some(pixels(10.0)))
        .session(h, w)
        .unwrap();
    let good = session
        .render_foveated(
            frame,
            &Gaze {
                x: 30.0,
                y: 20.0,
                depth_m: None,
            },
        )
        .unwrap()
        .codes
        .clone();
    let name = |e: HoloError| match e {
        HoloError::InvalidParameter { name, .. } => name,
        e => panic!("{e}"),
    };
    for (gaze, want) in [
        (
            Gaze {
                x: f64::NAN,
                y: 1.0,
                depth_m: None,
            },
            "gaze",
        ),
        (
            Gaze {
                x: 1.0,
                y: f64::INFINITY,
                depth_m: None,
            },
            "gaze",
        ),
        (
            Gaze {
                x: 64.0,
                y: 1.0,
                depth_m: None,
            },
            "gaze",
        ),
        (
            Gaze {
                x: 1.0,
                y: -0.6,
                depth_m: None,
            },
            "gaze",
        ),
        (
            Gaze {
                x: 1.0,
                y: 1.0,
                depth_m: Some(f64::NAN),
            },
            "gaze_depth_m",
        ),
    ] {
        let e = session.render_foveated(frame, &gaze).unwrap_err();
        assert_eq!(name(e), want, "{gaze:?}");
        assert!(session.fovea_report().is_none());
    }
    let again = session
        .render_foveated(
            frame,
            &Gaze {
                x: 30.0,
                y: 20.0,
                depth_m: None,
            },
        )
        .unwrap();
    assert_eq!(again.codes, good);
    // A session made without foveation options refuses foveated frames.
    let mut plain = pipeline(Precision::F32, None).session(h, w).unwrap();
    let e = plain
        .render_foveated(
            frame,
            &Gaze {
                x: 1.0,
                y: 1.0,
                depth_m: None,
            },
        )
        .unwrap_err();
    assert_eq!(name(e), "foveation");
    // Options: a negative or non-finite radius, a bad eyepiece, a band under a pixel.
    for (options, want) in [
        (pixels(-1.0), "fovea_radius"),
        (pixels(f64::NAN), "fovea_radius"),
        (
            FoveationOptions {
                radius: FoveaRadius::Degrees {
                    degrees: 90.0,
                    eyepiece_focal_m: 0.021,
                },
                ..FoveationOptions::default()
            },
            "fovea_radius",
        ),
        (
            FoveationOptions {
                radius: FoveaRadius::Degrees {
                    degrees: 5.0,
                    eyepiece_focal_m: 0.0,
                },
                ..FoveationOptions::default()
            },
            "eyepiece_focal_m",
        ),
        (
            FoveationOptions {
                band_px: 0.5,
                ..pixels(5.0)
            },
            "band_px",
        ),
        (
            FoveationOptions {
                blur_scale: -1.0,
                ..pixels(5.0)
            },
            "blur_scale",
        ),
    ] {
        assert_eq!(name(options.check().unwrap_err()), want, "{options:?}");
        let e = pipeline(Precision::F32, Some(options))
            .session(h, w)
            .unwrap_err();
        assert_eq!(name(e), want);
    }
    // 5° behind the 21 mm eyepiece on the 8 µm SLM: 229.6 pixels.
    let mut deg = pipeline(Precision::F32, Some(FoveationOptions::default()))
        .session(h, w)
        .unwrap();
    deg.render_foveated(
        frame,
        &Gaze {
            x: 0.0,
            y: 0.0,
            depth_m: None,
        },
    )
    .unwrap();
    let r = deg.fovea_report().unwrap();
    assert!((r.radius_px - 0.021 * 5f64.to_radians().tan() / 8e-6).abs() < 1e-9);
    assert!(r.covers_frame);
}

#[allow(dead_code)]
fn _uses(_: Complex32) {}
