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
use tensorholo::foveation::{FoveaRadius, FoveationOptions, Gaze};
use tensorholo::model::Precision;
use tensorholo::optics::{focal_stack, post_encoding_midpoint, PropagationOptions};
use tensorholo::pipeline::{
    Backend, HologramPipeline, HologramSession, ModelSelection, PipelineConfig,
};
use tensorholo::scene::{load_rgbd, DepthEncoding, LoadOptions, RgbdFrame};
use tensorholo::synthesis::{SceneLayer, SmLbm};
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
/// pattern's (the post-encoding midpoint, Eq. 8–10), at `depths`. The reconstructions zero-pad the field (a
/// real display's light leaves the frame at its edges): the FFT's periodic wrap would carry an edge's light
/// to the opposite edge, where a foveated frame's pre-filter runs its base filter only.
struct Stacks {
    midpoint: Vec<Array3<f32>>,
    displayed: Vec<Array3<f32>>,
    scale: f32,
}

fn stacks(session: &HologramSession, depths: &[f64]) -> Stacks {
    let setup = tensorholo::optics::OpticalSetup::default();
    let options = padded();
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

/// Propagation with the field zero-padded (no periodic wrap).
fn padded() -> PropagationOptions {
    PropagationOptions {
        pad: true,
        ..Default::default()
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
    let (h, w) = (360, 480);
    let radius = 90.0;
    let gazes = [
        Gaze {
            x: 240.0,
            y: 180.0,
            depth_m: None,
        },
        Gaze {
            x: 105.5,
            y: 270.2,
            depth_m: None,
        },
    ];
    // Per precision: the full frame, the foveated frame, and a hard switch at R (a band of one pixel: its
    // ring [R, R + 16) is the periphery's model alone).
    let mut sessions: Vec<_> = [Precision::F32, Precision::Int8Qdq]
        .into_iter()
        .map(|precision| {
            let make = |f| pipeline(precision, f).session(h, w).unwrap();
            let hard = FoveationOptions {
                band_px: 1.0,
                ..pixels(radius)
            };
            (
                precision,
                make(None),
                make(Some(pixels(radius))),
                make(Some(hard)),
            )
        })
        .collect();
    let setup = tensorholo::optics::OpticalSetup::default();
    for (name, frame) in real_frames(h, w) {
        // The SM-LBM reference (Eq. 1–4) and its focal stack, as the Table 2 protocol scores against it.
        let truth = SmLbm {
            levels: 256,
            setup,
            options: padded(),
            silhouette_masks: true,
        }
        .synthesize(&[SceneLayer::from(&frame)], &|_, _| {})
        .unwrap();
        let truth = focal_stack(truth.view(), &setup, 0.0, &DEPTHS, padded(), false).unwrap();
        for (precision, full_session, fov_session, hard_session) in &mut sessions {
            full_session.render(&frame).unwrap();
            let want = stacks(full_session, &DEPTHS);
            println!(
                "{name} {precision:?}: full normaliser {:.3} = {:.3} × max A",
                want.scale,
                want.scale / brightest(&frame)
            );
            for gaze in &gazes {
                fov_session.render_foveated(&frame, gaze).unwrap();
                let report = *fov_session.fovea_report().unwrap();
                assert!(!report.covers_frame);
                let got = stacks(fov_session, &DEPTHS);
                let fovea = ring(h, w, gaze, 0.0, radius + 0.5);
                let band = ring(h, w, gaze, radius + 0.5, radius + 16.0);
                let far = ring(h, w, gaze, radius + 48.0, f64::INFINITY);
                let plane = nearest_plane(report.gaze_depth);
                let mut line = format!(
                    "  gaze ({}, {}) d_g {:.2} (plane {plane}):",
                    gaze.x, gaze.y, report.gaze_depth
                );
                let (mut worst_m, mut worst_d, mut sm_lbm) =
                    (f64::INFINITY, f64::INFINITY, [0.0f64; 4]);
                for k in 0..DEPTHS.len() {
                    let m = psnr_ls(&want.midpoint[k], &got.midpoint[k], &fovea);
                    let d = psnr_ls(&want.displayed[k], &got.displayed[k], &fovea);
                    (worst_m, worst_d) = (worst_m.min(m), worst_d.min(d));
                    assert!(
                        m >= 40.0 && d >= 40.0,
                        "{name} {precision:?} {gaze:?} plane {k}: {m:.1} / {d:.1} dB"
                    );
                    // The fovea's scores against SM-LBM, full and foveated, midpoint and displayed.
                    for (i, s) in [
                        &want.midpoint,
                        &got.midpoint,
                        &want.displayed,
                        &got.displayed,
                    ]
                    .into_iter()
                    .enumerate()
                    {
                        sm_lbm[i] += psnr_ls(&truth[k], &s[k], &fovea) / DEPTHS.len() as f64;
                    }
                }
                line += &format!(
                    " fovea vs full ≥ {worst_m:.1} (midpoint) / {worst_d:.1} dB (displayed); vs SM-LBM \
                     {:.2} → {:.2} / {:.2} → {:.2} dB",
                    sm_lbm[0], sm_lbm[1], sm_lbm[2], sm_lbm[3]
                );
                // The CNN's hologram scores as the full frame's; what the SLM displays moves by the
                // normaliser's rule (a fixed multiple of the frame's largest amplitude instead of the field's
                // largest |H|: up to 25 % dimmer or a few clipped peaks) and the pre-filter's tile.
                assert!(
                    (sm_lbm[1] - sm_lbm[0]).abs() <= 0.1 && (sm_lbm[3] - sm_lbm[2]).abs() <= 0.2,
                    "{name} {precision:?}: SM-LBM scores {sm_lbm:?}"
                );
                let top = f64::from(want.midpoint[plane].iter().copied().fold(0.0f32, f32::max));
                let band_psnr = psnr_ls_peak(
                    &want.midpoint[plane],
                    &got.midpoint[plane],
                    &band,
                    Some(top),
                );
                let far_mid = psnr_ls(&want.midpoint[plane], &got.midpoint[plane], &far);
                let far_shown = psnr_ls(&want.displayed[plane], &got.displayed[plane], &far);
                hard_session.render_foveated(&frame, gaze).unwrap();
                let switched = stacks(hard_session, &DEPTHS);
                let hard_band = psnr_ls_peak(
                    &want.midpoint[plane],
                    &switched.midpoint[plane],
                    &band,
                    Some(top),
                );
                // The seam's brightness relative to the fovea's, against the full frame's.
                let rel = |s: &Array3<f32>| mean_in(s, &band) / mean_in(s, &fovea);
                let seam = rel(&got.midpoint[plane]) / rel(&want.midpoint[plane]);
                line += &format!(
                    " | band {band_psnr:.1} dB (hard switch {hard_band:.1}), seam {seam:.3}; periphery \
                     {far_mid:.1}/{far_shown:.1} dB"
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
    // A corner: the fovea no longer covers the frame, but a fovea that can cover it from the centre has a
    // tile as large as the frame: the full frame still.
    fov.render_foveated(
        frame,
        &Gaze {
            x: 0.0,
            y: 0.0,
            depth_m: None,
        },
    )
    .unwrap();
    assert!(fov.fovea_report().unwrap().covers_frame);
    // A tile that is the whole frame (a 10-pixel fovea, its band and the CNN's 8-pixel margin need 71 pixels
    // of a 48 × 64 frame): nothing to save, the full frame.
    let small = &real_frames(48, 64)[1].1;
    let want = pipeline(Precision::F32, None)
        .session(48, 64)
        .unwrap()
        .render(small)
        .unwrap()
        .clone();
    let mut tiny = pipeline(Precision::F32, Some(pixels(10.0)))
        .session(48, 64)
        .unwrap();
    let got = tiny
        .render_foveated(
            small,
            &Gaze {
                x: 0.0,
                y: 0.0,
                depth_m: None,
            },
        )
        .unwrap();
    assert_eq!(got.codes, want.codes);
    assert!(tiny.fovea_report().unwrap().covers_frame);
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
