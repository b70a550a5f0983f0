//! Scene loading against the real third-party RGB-D files of `shared/data` (read in place, never copied),
//! checking the documented facts of the encoding table (`docs/CONVENTIONS.md` §6), plus error paths and
//! properties.

use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3};
use proptest::prelude::*;
use tensorholo::scene::*;
use tensorholo::HoloError;

/// Path of a shared data file; fails loudly (never skips) when the shared data checkout is missing.
fn data(rel: &str) -> PathBuf {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data"));
    let p = root.join(rel);
    assert!(
        p.is_file(),
        "shared test data file missing: {} (tests read third-party RGB-D data in place from \
         `../shared/data` next to the workspace; see docs/CONVENTIONS.md §6.2 and NOTICE)",
        p.display()
    );
    p
}

fn decode(rel: &str, enc: DepthEncoding) -> DecodedDepth {
    decode_depth_file(&data(rel), enc).unwrap_or_else(|e| panic!("decoding {rel} as {enc}: {e}"))
}

/// Checks size, invalid fraction and valid min/max against the data table (`docs/CONVENTIONS.md` §6.2).
#[track_caller]
fn check(
    d: &DecodedDepth,
    size: (usize, usize),
    invalid: (f32, f32),
    min: f32,
    max: f32,
    tol: f32,
) {
    assert_eq!(d.values.dim(), size);
    let inv = d.invalid_fraction();
    assert!(
        (invalid.0..=invalid.1).contains(&inv),
        "invalid fraction {inv} not in {invalid:?}"
    );
    let (lo, hi) = d.valid_min_max().expect("some valid pixels");
    assert!((lo - min).abs() <= tol, "min {lo} vs documented {min}");
    assert!((hi - max).abs() <= tol, "max {hi} vs documented {max}");
    assert!(d.values.iter().zip(d.valid.iter()).all(|(&v, &ok)| if ok {
        v.is_finite() && v > 0.0
    } else {
        v == 0.0
    }));
}

#[test]
fn redwood_sequence_mm16_matches_data_table() {
    // docs/CONVENTIONS.md §6.2: 0.96–2.70 m, 12–13 % invalid, 640×480, 5 frames.
    for i in 0..5 {
        let d = decode(
            &format!("redwood_livingroom_seq/depth/0000{i}.png"),
            DepthEncoding::Millimetres16,
        );
        assert!(d.metric);
        let (lo, hi) = d.valid_min_max().unwrap();
        assert!((0.95..=1.06).contains(&lo), "frame {i}: min {lo}");
        assert!((2.67..=2.71).contains(&hi), "frame {i}: max {hi}");
        let inv = d.invalid_fraction();
        assert!((0.12..=0.135).contains(&inv), "frame {i}: invalid {inv}");
        assert_eq!(d.values.dim(), (480, 640));
    }
    let d0 = decode(
        "redwood_livingroom_seq/depth/00000.png",
        DepthEncoding::Millimetres16,
    );
    check(&d0, (480, 640), (0.12, 0.135), 0.96, 2.70, 0.01);
}

#[test]
fn nyu_raw_kinect_disparity_matches_data_table() {
    // docs/CONVENTIONS.md §6.2: little-endian 16-bit PGM, 351.3/(1092.5 − raw), 1.39–6.69 m, raw ≥ 1092
    // invalid, 7 %.
    let d = decode("nyu/NYU_depth.pgm", DepthEncoding::KinectDisparity);
    check(&d, (480, 640), (0.065, 0.08), 1.39, 6.69, 0.01);
}

#[test]
fn nyu_raw_and_derived_mm_agree() {
    let raw = decode("nyu/NYU_depth.pgm", DepthEncoding::KinectDisparity);
    let mm = decode(
        "nyu/derived/NYU_depth_mm_u16_UNALIGNED.png",
        DepthEncoding::Millimetres16,
    );
    assert_eq!(raw.valid, mm.valid, "validity masks differ");
    let (mut n, mut worst, mut sum) = (0usize, 0.0f32, 0.0f32);
    for ((&a, &b), &ok) in raw
        .values
        .iter()
        .zip(mm.values.iter())
        .zip(raw.valid.iter())
    {
        if ok {
            let e = (a - b).abs();
            worst = worst.max(e);
            sum += e;
            n += 1;
        }
    }
    assert!(n > 250_000);
    // mm rounding: half a millimetre, plus f32 slack.
    assert!(worst <= 0.000_6, "worst difference {worst} m");
    assert!(
        sum / (n as f32) < 0.000_3,
        "mean difference {} m",
        sum / n as f32
    );
}

#[test]
fn sun_rotated_matches_data_table_and_derived() {
    // docs/CONVENTIONS.md §6.2: bits rotated left by 3 on disk, 1.06–9.87 m, 18 % invalid.
    let raw = decode("sun/SUN_depth.png", DepthEncoding::SunRotated);
    check(&raw, (480, 640), (0.175, 0.19), 1.06, 9.87, 0.01);
    let mm = decode(
        "sun/derived/SUN_depth_mm_u16.png",
        DepthEncoding::Millimetres16,
    );
    assert_eq!(
        raw, mm,
        "SUN raw (rotated) and derived mm must decode identically"
    );
    // Reading the raw file as plain mm would be wrong: it is not the same data.
    let wrong = decode("sun/SUN_depth.png", DepthEncoding::Millimetres16);
    assert_ne!(wrong.values, mm.values);
}

#[test]
fn tum_matches_data_table() {
    // docs/CONVENTIONS.md §6.2: v/5000, 1.46–9.33 m, 19 % invalid.
    let d = decode("tum/TUM_depth.png", DepthEncoding::Tum5000);
    check(&d, (480, 640), (0.185, 0.2), 1.46, 9.33, 0.01);
}

#[test]
fn iphone_disparity_matches_data_table() {
    // docs/CONVENTIONS.md §6.2: 8-bit JPEG, 576×768 (W×H), 1/(0.650879 + v/255·1.858887), 0.40–1.54 m, none
    // invalid.
    let d = decode(
        "iphone_portrait_vase/disparity_aux_576x768.jpg",
        DepthEncoding::IphoneDisparity,
    );
    check(&d, (768, 576), (0.0, 0.0), 0.40, 1.54, 0.01);
}

#[test]
fn odak_relative_near_bright_matches_data_table() {
    // docs/CONVENTIONS.md §6.2: 1600×900, 8-bit ×3 channels, relative, larger = nearer, 0 = empty background
    // (71 %).
    let d = decode(
        "odak_dragonbunny/DragonBunny_depthmap.png",
        DepthEncoding::RelativeNearBright,
    );
    assert!(!d.metric);
    assert_eq!(d.values.dim(), (900, 1600));
    let inv = d.invalid_fraction();
    assert!((0.70..=0.72).contains(&inv), "invalid {inv}");
    let (lo, hi) = d.valid_min_max().unwrap();
    assert!(
        lo >= 0.0 && hi < 1.0 && hi - lo > 0.3,
        "relative range {lo}..{hi}"
    );
}

#[test]
fn every_pair_loads_with_filled_depth() {
    use DepthEncoding::*;
    let pairs = [
        (
            "redwood_livingroom_seq/color/00000.jpg",
            "redwood_livingroom_seq/depth/00000.png",
            Millimetres16,
        ),
        ("nyu/NYU_color.ppm", "nyu/NYU_depth.pgm", KinectDisparity),
        ("sun/SUN_color.jpg", "sun/SUN_depth.png", SunRotated),
        ("tum/TUM_color.png", "tum/TUM_depth.png", Tum5000),
        (
            "iphone_portrait_vase/derived_rgb_576x768.png",
            "iphone_portrait_vase/disparity_aux_576x768.jpg",
            IphoneDisparity,
        ),
        (
            "odak_dragonbunny/DragonBunny_rgb.png",
            "odak_dragonbunny/DragonBunny_depthmap.png",
            RelativeNearBright,
        ),
    ];
    for (rgb, depth, enc) in pairs {
        let (frame, report) = load_rgbd(&data(rgb), &data(depth), enc, &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{rgb} + {depth}: {e}"));
        assert_eq!((frame.height(), frame.width()), report.source_size);
        assert_eq!(report.encoding, enc);
        assert!(frame.depth.iter().all(|d| (0.0..=1.0).contains(d)));
        assert!(frame.amplitude.iter().all(|a| (0.0..=1.0).contains(a)));
        if enc.is_metric() {
            // Both ends of the range are used (automatic percentiles).
            let near = frame.depth.iter().filter(|&&d| d < 0.1).count();
            let far = frame.depth.iter().filter(|&&d| d > 0.9).count();
            assert!(near > 0 && far > 0, "{depth}: near {near} far {far}");
            let r = report.range_used.expect("metric range");
            assert!(r.z_near_m >= report.metric_min_m.unwrap());
            assert!(r.z_far_m <= report.metric_max_m.unwrap());
        } else {
            assert!(report.range_used.is_none() && report.metric_min_m.is_none());
            // Relative depth passes through: the filled map stays within the decoded valid range.
            let dec = decode_depth_file(&data(depth), enc).unwrap();
            let (lo, hi) = dec.valid_min_max().unwrap();
            assert!(frame.depth.iter().all(|&d| d >= lo && d <= hi));
        }
    }
}

#[test]
fn holes_in_real_depth_take_the_farthest_neighbour() {
    // TUM: 19 % holes. In the first ring around valid data each hole must equal the largest valid d
    // among its 3×3 neighbours, i.e. the background side of the occlusion edge.
    let dec = decode("tum/TUM_depth.png", DepthEncoding::Tum5000);
    let (d, range) = normalise_depth(&dec, None, DepthMapping::LinearDiopters).unwrap();
    let r = range.unwrap();
    assert!(
        (r.z_near_m - 1.516).abs() < 0.01 && (r.z_far_m - 7.33).abs() < 0.01,
        "{r}"
    );
    let filled = fill_invalid(&d, &dec.valid).unwrap();
    let (h, w) = d.dim();
    let mut ring = 0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            if dec.valid[[y, x]] {
                assert_eq!(filled[[y, x]], d[[y, x]]);
                continue;
            }
            let mut best = f32::NEG_INFINITY;
            for yy in y - 1..=y + 1 {
                for xx in x - 1..=x + 1 {
                    if dec.valid[[yy, xx]] {
                        best = best.max(d[[yy, xx]]);
                    }
                }
            }
            if best.is_finite() {
                assert_eq!(filled[[y, x]], best, "hole at ({y}, {x})");
                ring += 1;
            }
        }
    }
    assert!(ring > 1000, "{ring}");
    assert!(filled.iter().all(|v| v.is_finite()));
}

#[test]
fn explicit_range_and_resize_are_honoured() {
    let range = DepthRange::new(1.0, 3.0).unwrap();
    let opts = LoadOptions {
        range: Some(range),
        mapping: DepthMapping::LinearMetres,
        size: Some((240, 320)),
        ..LoadOptions::default()
    };
    let (frame, report) = load_rgbd(
        &data("redwood_livingroom_seq/color/00000.jpg"),
        &data("redwood_livingroom_seq/depth/00000.png"),
        DepthEncoding::Millimetres16,
        &opts,
    )
    .unwrap();
    assert_eq!(report.range_used, Some(range));
    assert_eq!(report.source_size, (480, 640));
    assert_eq!((frame.height(), frame.width()), (240, 320));
    assert_eq!(frame.amplitude.dim(), (3, 240, 320));
    // Nearest of 0.955 m is clamped to d = 0; 2.70 m maps to (2.70 − 1)/2 = 0.85 at most.
    let max = frame.depth.iter().cloned().fold(0.0, f32::max);
    assert!((max - 0.851).abs() < 0.01, "{max}");
    let json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["encoding"], "mm16");
    assert_eq!(json["source_size"], serde_json::json!([480, 640]));
}

#[test]
fn a_wrong_encoding_or_range_is_refused_not_rendered_flat() {
    let (rgb, depth) = (
        data("redwood_livingroom_seq/color/00000.jpg"),
        data("redwood_livingroom_seq/depth/00000.png"),
    );
    let load = |encoding, opts: &LoadOptions| load_rgbd(&rgb, &depth, encoding, opts);
    // Redwood's millimetres read as TUM's 1/5000 m units: most depths fall outside a 1–3 m range.
    let range = LoadOptions {
        range: Some(DepthRange::new(1.0, 3.0).unwrap()),
        ..LoadOptions::default()
    };
    let err = load(DepthEncoding::Tum5000, &range)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("outside the range") && err.contains("00000.png"),
        "{err}"
    );
    // The same range on the right encoding holds (a few depths beyond 2.7 m at most).
    load(DepthEncoding::Millimetres16, &range).unwrap();
    // A scene that is mostly invalid under the chosen encoding is refused; the limit can be raised.
    let strict = LoadOptions {
        max_invalid_fraction: 0.05,
        ..LoadOptions::default()
    };
    let err = load(DepthEncoding::Millimetres16, &strict)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("invalid") && err.contains("--depth-encoding"),
        "{err}"
    );
    load(DepthEncoding::Millimetres16, &LoadOptions::default()).unwrap();
}

#[test]
fn load_rgb_is_linear_amplitude_in_rgb_order() {
    let p = data("tum/TUM_color.png");
    let amp = load_rgb(&p).unwrap();
    assert_eq!(amp.dim(), (3, 480, 640));
    let img = image::open(&p).unwrap().to_rgb8();
    for (x, y) in [(0u32, 0u32), (100, 200), (639, 479), (320, 240)] {
        let px = img.get_pixel(x, y);
        for c in 0..3 {
            assert_eq!(
                amp[[c, y as usize, x as usize]],
                tensorholo::color::srgb8_to_amplitude(px[c])
            );
        }
    }
    // Grey JPEG (the iPhone disparity) expands to three equal channels.
    let g = load_rgb(&data("iphone_portrait_vase/disparity_aux_576x768.jpg")).unwrap();
    assert_eq!(g.dim(), (3, 768, 576));
    assert_eq!(
        g.index_axis(ndarray::Axis(0), 0),
        g.index_axis(ndarray::Axis(0), 2)
    );
}

/// A depth map at a quarter of the colour's resolution (a phone's LiDAR depth under its image; the same field
/// of view) loads: with `DepthUpsampling::Nearest`, the frame is the one of a full-resolution depth file holding
/// the nearest samples, bit for bit; the report gives both sizes. The joint bilateral default differs from it
/// (the upsampling's closeness to full-resolution depth is measured in `tests/real_inputs.rs`).
#[test]
fn a_depth_map_of_lower_resolution_is_brought_to_the_colour_by_nearest_neighbour() {
    let rgb = data("redwood_livingroom_seq/color/00000.jpg"); // 640×480
    let full = image::open(data("redwood_livingroom_seq/depth/00000.png"))
        .unwrap()
        .to_luma16();
    let (w, h) = full.dimensions();
    let (ws, hs) = (w / 4, h / 4);
    let small = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(ws, hs, |x, y| {
        *full.get_pixel(4 * x + 2, 4 * y + 2)
    });
    // The nearest rule of the camera path: output pixel o reads input ⌊(o + ½)·n_in/n_out⌋.
    let near = |o: u32, n_in: u32, n_out: u32| {
        (((o as f64 + 0.5) * n_in as f64 / n_out as f64).floor() as u32).min(n_in - 1)
    };
    let up = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(w, h, |x, y| {
        *small.get_pixel(near(x, ws, w), near(y, hs, h))
    });
    let dir = tempfile::tempdir().unwrap();
    let (small_path, up_path) = (dir.path().join("small.png"), dir.path().join("up.png"));
    small.save(&small_path).unwrap();
    up.save(&up_path).unwrap();
    let options = LoadOptions {
        depth_upsampling: DepthUpsampling::Nearest,
        ..LoadOptions::default()
    };
    let (a, ra) =
        load_rgbd(&rgb, &small_path, DepthEncoding::Millimetres16, &options).expect("loads");
    let (b, rb) = load_rgbd(&rgb, &up_path, DepthEncoding::Millimetres16, &options).unwrap();
    assert_eq!(ra.depth_size, (hs as usize, ws as usize));
    assert_eq!((ra.source_size, rb.depth_size), ((480, 640), (480, 640)));
    assert_eq!(a, b);
    let (guided, _) = load_rgbd(
        &rgb,
        &small_path,
        DepthEncoding::Millimetres16,
        &LoadOptions::default(),
    )
    .unwrap();
    assert_ne!(guided.depth, a.depth);
    assert!(guided.depth.iter().all(|d| (0.0..=1.0).contains(d)));
    // Another aspect ratio (a crop of the depth) is refused, not stretched.
    let cropped = image::imageops::crop_imm(&small, 0, 0, ws, hs - 20).to_image();
    cropped.save(&small_path).unwrap();
    let e = load_rgbd(&rgb, &small_path, DepthEncoding::Millimetres16, &options).unwrap_err();
    assert!(matches!(e, HoloError::ShapeMismatch { .. }), "{e}");
    assert!(e.to_string().contains("aspect ratio"), "{e}");
}

#[test]
fn mismatched_rgb_and_depth_sizes_are_an_error_naming_both_files() {
    let rgb = data("sun/SUN_color.jpg"); // 640×480
    let depth = data("iphone_portrait_vase/disparity_aux_576x768.jpg"); // 576×768
    let err = load_rgbd(
        &rgb,
        &depth,
        DepthEncoding::IphoneDisparity,
        &LoadOptions {
            size: Some((100, 100)), // must not hide the mismatch
            ..LoadOptions::default()
        },
    )
    .unwrap_err();
    match err {
        HoloError::ShapeMismatch {
            what,
            expected,
            got,
        } => {
            assert!(
                what.contains("SUN_color.jpg") && what.contains("disparity_aux_576x768.jpg"),
                "{what}"
            );
            assert_eq!(expected, vec![480, 640]);
            assert_eq!(got, vec![768, 576]);
        }
        e => panic!("expected ShapeMismatch, got {e}"),
    }
}

#[test]
fn wrong_bit_depth_is_a_clear_error() {
    // 8-bit file as mm16.
    let p = data("iphone_portrait_vase/disparity_aux_576x768.jpg");
    match decode_depth_file(&p, DepthEncoding::Millimetres16).unwrap_err() {
        HoloError::InvalidDepth(msg) => {
            assert!(msg.contains("disparity_aux_576x768.jpg"), "{msg}");
            assert!(
                msg.contains("mm16") && msg.contains("8-bit") && msg.contains("16-bit"),
                "{msg}"
            );
        }
        e => panic!("expected InvalidDepth, got {e}"),
    }
    // 16-bit file as an 8-bit encoding.
    let p = data("tum/TUM_depth.png");
    match decode_depth_file(&p, DepthEncoding::RelativeNearDark).unwrap_err() {
        HoloError::InvalidDepth(msg) => {
            assert!(
                msg.contains("TUM_depth.png") && msg.contains("relative-near-dark"),
                "{msg}"
            )
        }
        e => panic!("expected InvalidDepth, got {e}"),
    }
    // An 8-bit RGB colour image through kinect-disparity (not a PGM): also refused.
    assert!(matches!(
        decode_depth_file(&data("tum/TUM_color.png"), DepthEncoding::KinectDisparity),
        Err(HoloError::InvalidDepth(_))
    ));
}

#[test]
fn unreadable_paths_are_named_in_errors() {
    let missing = Path::new("/nonexistent/dir/no_such_depth.png");
    let err = decode_depth_file(missing, DepthEncoding::Millimetres16).unwrap_err();
    assert!(matches!(err, HoloError::Io { .. }));
    assert!(err.to_string().contains("no_such_depth.png"), "{err}");
    let err = load_rgb(Path::new("/nonexistent/no_such_rgb.png")).unwrap_err();
    assert!(matches!(err, HoloError::Io { .. }) && err.to_string().contains("no_such_rgb.png"));
    // Readable but not an image: Image error naming the file.
    let notimg = data("README.md");
    let err = load_rgb(&notimg).unwrap_err();
    assert!(matches!(err, HoloError::Image { .. }), "{err}");
    assert!(err.to_string().contains("README.md"), "{err}");
    let err = load_rgbd(
        &data("tum/TUM_color.png"),
        Path::new("/nonexistent/d.png"),
        DepthEncoding::Tum5000,
        &LoadOptions::default(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("/nonexistent/d.png"), "{err}");
}

#[test]
fn nan_depth_is_rejected_by_rgbd_frame() {
    let mut depth = Array2::from_elem((4, 4), 0.5f32);
    depth[[2, 3]] = f32::NAN;
    let err = RgbdFrame::new(Array3::from_elem((3, 4, 4), 0.5), depth).unwrap_err();
    assert!(matches!(err, HoloError::InvalidDepth(_)), "{err}");
}

fn small_map() -> impl Strategy<Value = (Array2<f32>, Array2<bool>)> {
    (1usize..12, 1usize..12).prop_flat_map(|(h, w)| {
        (
            proptest::collection::vec(0.0f32..1.0, h * w),
            proptest::collection::vec(any::<bool>(), h * w),
            0..h * w,
        )
            .prop_map(move |(d, mut v, force)| {
                v[force] = true; // at least one valid pixel
                (
                    Array2::from_shape_vec((h, w), d).unwrap(),
                    Array2::from_shape_vec((h, w), v).unwrap(),
                )
            })
    })
}

proptest! {
    #[test]
    fn fill_invalid_properties((depth, valid) in small_map()) {
        let out = fill_invalid(&depth, &valid).unwrap();
        let valid_values: Vec<f32> = depth.iter().zip(valid.iter()).filter(|x| *x.1).map(|x| *x.0).collect();
        let vmax = valid_values.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
        for ((idx, &o), &ok) in out.indexed_iter().zip(valid.iter()) {
            if ok {
                prop_assert_eq!(o, depth[idx]);
            } else {
                // Filled values are copies of valid values, never invented (no "near" zeros).
                prop_assert!(valid_values.contains(&o));
            }
        }
        let omax = out.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
        prop_assert_eq!(omax, vmax);
    }

    #[test]
    fn diopter_mapping_is_monotone(near in 0.1f32..2.0, span in 0.05f32..10.0, a in 0.0f32..1.0, b in 0.0f32..1.0) {
        let r = DepthRange::new(near, near + span).unwrap();
        let (za, zb) = (near + a * span, near + b * span);
        let m = DepthMapping::LinearDiopters;
        if za <= zb {
            prop_assert!(m.apply(za, &r) <= m.apply(zb, &r));
        }
        prop_assert!(m.apply(near, &r).abs() < 1e-5);
        prop_assert!((m.apply(near + span, &r) - 1.0).abs() < 1e-5);
    }

    #[test]
    fn resize_keeps_invariants(h in 1usize..20, w in 1usize..20, oh in 1usize..30, ow in 1usize..30) {
        let f = default_scene(h, w).unwrap();
        let r = f.resize(oh, ow).unwrap();
        prop_assert_eq!(r.amplitude.dim(), (3, oh, ow));
        prop_assert!(r.amplitude.iter().all(|a| a.is_finite() && *a >= 0.0));
        let src: Vec<f32> = f.depth.iter().cloned().collect();
        prop_assert!(r.depth.iter().all(|d| src.contains(d)));
        prop_assert!(RgbdFrame::new(r.amplitude.clone(), r.depth.clone()).is_ok());
    }
}

#[test]
fn a_truncated_or_corrupt_image_is_an_error_never_completed_with_grey() {
    // `image` decodes JPEG leniently (zune-jpeg fills a missing tail with grey); we decode strictly. The full
    // file must still give exactly what the lenient decoder gives.
    for rel in [
        "sun/SUN_color.jpg",
        "redwood_livingroom_seq/color/00000.jpg",
    ] {
        let bytes = std::fs::read(data(rel)).unwrap();
        let full = decode_rgb_bytes(&bytes, Path::new(rel)).unwrap();
        let lenient = image::load_from_memory(&bytes).unwrap().to_rgb8();
        assert_eq!(
            full.dim(),
            (3, lenient.height() as usize, lenient.width() as usize)
        );
        for (x, y, px) in lenient.enumerate_pixels().step_by(997) {
            for c in 0..3 {
                assert_eq!(
                    full[[c, y as usize, x as usize]],
                    tensorholo::color::srgb8_to_amplitude(px[c]),
                    "{rel} ({x}, {y})"
                );
            }
        }
        for keep in [0.6, 0.95] {
            let cut = &bytes[..(bytes.len() as f64 * keep) as usize];
            // The lenient decoder accepts the truncated file: this is the case being guarded against.
            assert!(image::load_from_memory(cut).is_ok(), "{rel} at {keep}");
            match decode_rgb_bytes(cut, Path::new(rel)) {
                Err(HoloError::InvalidData(m)) => {
                    assert!(m.contains(rel) && m.contains("truncated"), "{m}")
                }
                other => panic!("{rel} cut at {keep}: expected InvalidData, got {other:?}"),
            }
        }
    }
    // A truncated 16-bit depth PNG: an error naming the source, for the depth decoder too.
    let bytes = std::fs::read(data("sun/SUN_depth.png")).unwrap();
    let cut = &bytes[..bytes.len() * 3 / 4];
    let err = decode_depth_bytes(cut, Path::new("cut.png"), DepthEncoding::SunRotated).unwrap_err();
    assert!(err.to_string().contains("cut.png"), "{err}");
    assert_eq!(
        decode_depth_bytes(&bytes, Path::new("x"), DepthEncoding::SunRotated)
            .unwrap()
            .values,
        decode("sun/SUN_depth.png", DepthEncoding::SunRotated).values
    );
}

#[test]
fn resizing_never_leaves_the_input_amplitude_range() {
    // A hard edge between black and full white, up- and downsampled: Catmull-Rom overshoots there (found by
    // the camera_frame fuzz target: 1.0047 after a crop), so the result is clamped to the input's range.
    let amplitude = Array3::from_shape_fn(
        (3, 4, 6),
        |(c, y, x)| {
            if (x + y + c) % 3 == 0 {
                1.0
            } else {
                0.0
            }
        },
    );
    let frame = RgbdFrame::new(amplitude, Array2::from_elem((4, 6), 0.5)).unwrap();
    for (h, w) in [(4, 7), (9, 13), (3, 5), (17, 2)] {
        let r = frame.resize(h, w).unwrap();
        let (lo, hi) = r
            .amplitude
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        assert!(lo >= 0.0 && hi <= 1.0, "{h}x{w}: [{lo}, {hi}]");
        if h >= 4 && w >= 6 {
            // Upsampled, not flattened: both extremes are still reached.
            assert!(hi > 0.9 && lo < 0.1, "{h}x{w}: [{lo}, {hi}]");
        }
    }
}

// ---------------------------------------------------------------------------------------------------------
// Layered depth image folders (`rgb_K.png` + `depth_K.png`, front first; docs/CONVENTIONS.md §6.3).

/// A fresh, empty temporary folder for one test.
fn ldi_tempdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tensorholo-ldi-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A random `layers`-layer LDI of `h × w`: layer 0 everywhere, each further layer valid only where the one in
/// front is (with probability 0.6) and never nearer than it.
fn random_ldi(seed: u64, layers: usize, h: usize, w: usize) -> LayeredDepthImage {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut out: Vec<LdiLayer> = Vec::new();
    for k in 0..layers {
        let amplitude = Array3::from_shape_fn((3, h, w), |_| rnd());
        let mut depth = Array2::zeros((h, w));
        let mut valid = Array2::from_elem((h, w), false);
        for y in 0..h {
            for x in 0..w {
                let (front_ok, front_d) = match out.last() {
                    None => (true, 0.0),
                    Some(p) => (p.valid[[y, x]], p.depth[[y, x]]),
                };
                if front_ok && (k == 0 || rnd() < 0.6) {
                    valid[[y, x]] = true;
                    depth[[y, x]] = front_d + (1.0 - front_d) * rnd();
                }
            }
        }
        out.push(LdiLayer {
            amplitude,
            depth,
            valid,
        });
    }
    LayeredDepthImage::new(out).unwrap()
}

#[test]
fn an_ldi_folder_round_trips_within_its_quantisation() {
    let dir = ldi_tempdir("roundtrip");
    let ldi = random_ldi(7, 4, 9, 13);
    let files = write_ldi_dir(&ldi, &dir).unwrap();
    assert_eq!(files.len(), 4);
    assert_eq!(ldi_files(&dir).unwrap(), files);
    let (back, report) =
        load_ldi_dir(&dir, DepthEncoding::Relative16, &LoadOptions::default()).unwrap();
    assert_eq!(back.num_layers(), 4);
    assert_eq!(report.range_used, None);
    assert_eq!(report.front_invalid_fraction, 0.0);
    for (k, (a, b)) in ldi.layers().iter().zip(back.layers()).enumerate() {
        assert_eq!(a.valid, b.valid, "layer {k} validity");
        let frac = a.valid.iter().filter(|&&v| v).count() as f32 / a.valid.len() as f32;
        assert!((report.valid_fraction[k] - frac).abs() < 1e-6, "layer {k}");
        for ((y, x), &ok) in a.valid.indexed_iter() {
            if !ok {
                continue;
            }
            // 16-bit depth: one step of 1/65534; 8-bit sRGB colour: what the code round trip gives.
            assert!((a.depth[[y, x]] - b.depth[[y, x]]).abs() <= 0.5 / 65534.0 + 1e-7);
            for c in 0..3 {
                let code = tensorholo::color::amplitude_to_srgb8(a.amplitude[[c, y, x]]);
                let want = tensorholo::color::srgb8_to_amplitude(code);
                assert_eq!(
                    b.amplitude[[c, y, x]],
                    want,
                    "layer {k} colour {c} at {y},{x}"
                );
            }
        }
    }
    // --size resizes every layer alike: order and nesting hold (LayeredDepthImage::new checks them).
    let options = LoadOptions {
        size: Some((5, 7)),
        ..LoadOptions::default()
    };
    let (small, _) = load_ldi_dir(&dir, DepthEncoding::Relative16, &options).unwrap();
    assert_eq!((small.height(), small.width()), (5, 7));
    std::fs::remove_dir_all(&dir).ok();
}

/// Writes a 16-bit greyscale PNG of `samples`.
fn write_u16(path: &Path, samples: &Array2<u16>) {
    tensorholo::io::save_u16_png(path, samples.view()).unwrap();
}

#[test]
fn a_metric_ldi_shares_one_depth_range_and_fills_only_the_front_layer() {
    let dir = ldi_tempdir("metric");
    let (h, w) = (6, 8);
    let rgb = Array3::from_elem((3, h, w), 0.5f32);
    for k in 0..2 {
        tensorholo::io::save_amplitude_png(&dir.join(format!("rgb_{k}.png")), rgb.view(), 1.0)
            .unwrap();
    }
    // Front: a wall at 1 m with one hole (0 = no reading); behind: a wall at 2 m in the left half only.
    let mut front = Array2::from_elem((h, w), 1000u16);
    front[[2, 6]] = 0;
    let back = Array2::from_shape_fn((h, w), |(_, x)| if x < 4 { 2000u16 } else { 0 });
    write_u16(&dir.join("depth_0.png"), &front);
    write_u16(&dir.join("depth_1.png"), &back);
    let (ldi, report) =
        load_ldi_dir(&dir, DepthEncoding::Millimetres16, &LoadOptions::default()).unwrap();
    // One range over both layers: 1 m (front) → d = 0, 2 m (back) → d = 1.
    let r = report.range_used.unwrap();
    assert_eq!((r.z_near_m, r.z_far_m), (1.0, 2.0));
    let [l0, l1] = ldi.layers() else {
        panic!("two layers")
    };
    assert!(
        l0.valid.iter().all(|&v| v),
        "the front layer is valid everywhere"
    );
    assert!(
        l0.depth.iter().all(|&d| d == 0.0),
        "its hole takes the wall's depth"
    );
    assert!((report.front_invalid_fraction - 1.0 / 48.0).abs() < 1e-6);
    for ((_, x), &ok) in l1.valid.indexed_iter() {
        assert_eq!(ok, x < 4, "a stored 0 in a back layer is no point");
    }
    assert!(l1
        .depth
        .iter()
        .zip(&l1.valid)
        .all(|(&d, &ok)| !ok || d == 1.0));
    assert_eq!(report.valid_fraction, vec![1.0, 0.5]);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_ldi_folders_are_refused_naming_the_files() {
    let dir = ldi_tempdir("bad");
    let err = |dir: &Path| {
        load_ldi_dir(dir, DepthEncoding::Relative16, &LoadOptions::default())
            .unwrap_err()
            .to_string()
    };
    // Empty.
    assert!(
        err(&dir).contains("rgb_0.png and depth_0.png"),
        "{}",
        err(&dir)
    );
    // A layer whose depth is nearer than the one in front of it.
    let mut ldi = random_ldi(3, 2, 5, 6).into_layers();
    ldi[1].valid.fill(true);
    ldi[0].depth.fill(0.5);
    ldi[1].depth.fill(0.6);
    let written = write_ldi_dir(&LayeredDepthImage::new(ldi.clone()).unwrap(), &dir).unwrap();
    let mut near = Array2::from_elem((5, 6), 1 + (0.6 * 65534.0f32) as u16);
    near[[3, 4]] = 1 + (0.2 * 65534.0f32) as u16;
    write_u16(&written[1].depth, &near);
    let e = err(&dir);
    assert!(
        e.contains("layer 1 (`depth_1.png`) is nearer than layer 0 (`depth_0.png`) at 1 pixels")
            && e.contains("row 3, column 4"),
        "{e}"
    );
    // A point behind a pixel where the layer in front holds none (a gap).
    write_ldi_dir(&LayeredDepthImage::new(ldi.clone()).unwrap(), &dir).unwrap();
    let mut third = Array2::from_elem((5, 6), 0u16);
    third[[1, 2]] = 65535;
    write_u16(&dir.join("depth_2.png"), &Array2::from_elem((5, 6), 0u16));
    std::fs::copy(&written[1].rgb, dir.join("rgb_2.png")).unwrap();
    std::fs::copy(&written[1].rgb, dir.join("rgb_3.png")).unwrap();
    write_u16(&dir.join("depth_3.png"), &third);
    let e = err(&dir);
    assert!(
        e.contains(
            "layer 3 (`depth_3.png`) holds a point where layer 2 (`depth_2.png`) holds none"
        ),
        "{e}"
    );
    // A layer of another size, naming the file.
    write_u16(&dir.join("depth_3.png"), &Array2::from_elem((4, 6), 0u16));
    match load_ldi_dir(&dir, DepthEncoding::Relative16, &LoadOptions::default()) {
        Err(HoloError::ShapeMismatch {
            what,
            expected,
            got,
        }) => {
            assert!(what.contains("depth_3.png"), "{what}");
            assert_eq!((expected, got), (vec![5, 6], vec![4, 6]));
        }
        other => panic!("{other:?}"),
    }
    // A layer without its depth file, a gap in the numbering, two files for one layer.
    std::fs::remove_file(dir.join("depth_3.png")).unwrap();
    assert!(err(&dir).contains("lacks depth_3"), "{}", err(&dir));
    std::fs::remove_file(dir.join("rgb_3.png")).unwrap();
    std::fs::copy(&written[1].rgb, dir.join("rgb_5.png")).unwrap();
    assert!(
        err(&dir).contains("the numbering has a gap"),
        "{}",
        err(&dir)
    );
    std::fs::remove_file(dir.join("rgb_5.png")).unwrap();
    std::fs::copy(&written[1].rgb, dir.join("rgb_1.jpg")).unwrap();
    assert!(
        err(&dir).contains("two rgb files for layer 1"),
        "{}",
        err(&dir)
    );
    std::fs::remove_file(dir.join("rgb_1.jpg")).unwrap();
    // Files of another pattern are ignored; a wrong bit depth names the file.
    std::fs::write(dir.join("README.txt"), "notes").unwrap();
    assert!(load_ldi_dir(&dir, DepthEncoding::Relative16, &LoadOptions::default()).is_ok());
    let e = load_ldi_dir(
        &dir,
        DepthEncoding::RelativeNearDark,
        &LoadOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("depth_0.png") && e.contains("16-bit"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// One packed camera layer: RGB8 colour and u16 millimetre depth of `h × w`.
fn camera_layer(
    h: usize,
    w: usize,
    rgb: [u8; 3],
    mm: impl Fn(usize, usize) -> u16,
) -> CameraFrameBuf {
    CameraFrameBuf {
        color: ColorImageBuf {
            data: (0..h * w).flat_map(|_| rgb).collect(),
            format: ColorFormat::Rgb8,
            width: w,
            height: h,
            row_stride: 0,
        },
        depth: DepthImageBuf {
            data: (0..h * w)
                .flat_map(|i| mm(i / w, i % w).to_le_bytes())
                .collect(),
            format: DepthFormat::MillimetresU16,
            width: w,
            height: h,
            row_stride: 0,
        },
        rotation: Rotation::Deg0,
        color_crop: None,
        confidence: None,
    }
}

#[test]
fn camera_layers_make_one_ldi_with_one_range_and_fit_alike() {
    let (h, w) = (8, 12);
    let front = camera_layer(h, w, [200, 40, 40], |_, _| 1000);
    let back = camera_layer(h, w, [40, 200, 40], |_, x| if x < 6 { 3000 } else { 0 });
    let views = [front.view(), back.view()];
    let options = FrameOptions {
        fit: Fit::Stretch,
        ..FrameOptions::default()
    };
    let (ldi, report) = ldi_from_camera_frames(&views, h, w, &options).unwrap();
    let r = report.range_used.unwrap();
    assert_eq!((r.z_near_m, r.z_far_m), (1.0, 3.0));
    let l1 = &ldi.layers()[1];
    assert!(l1.valid.indexed_iter().all(|((_, x), &v)| v == (x < 6)));
    // The front layer alone equals CameraFrame::to_rgbd with the same range.
    let alone = FrameOptions {
        range: Some(r),
        ..options
    };
    let (rgbd, _) = front.view().to_rgbd(h, w, &alone).unwrap();
    assert_eq!(ldi.to_rgbd(), rgbd);
    // Letterbox into a wider hologram: bars are black and far in front, with no point behind.
    let letterbox = FrameOptions {
        fit: Fit::Letterbox,
        ..options
    };
    let (boxed, _) = ldi_from_camera_frames(&views, h, 2 * w, &letterbox).unwrap();
    let [b0, b1] = boxed.layers() else {
        panic!("two layers")
    };
    assert!(b0.valid.iter().all(|&v| v));
    assert_eq!(b0.depth[[0, 0]], 1.0);
    assert_eq!(b0.amplitude[[0, 0, 0]], 0.0);
    assert!(!b1.valid[[0, 0]] && !b1.valid[[0, 2 * w - 1]]);
    // Crop to a narrower hologram: the same window in both layers.
    let crop = FrameOptions {
        fit: Fit::Crop,
        ..options
    };
    let (cropped, _) = ldi_from_camera_frames(&views, h, h, &crop).unwrap();
    let c1 = &cropped.layers()[1];
    assert!(c1.valid.indexed_iter().all(|((_, x), &v)| v == (x < 4)));
    // Layers of different sizes, a back layer nearer than the front, no layer: refused.
    let small = camera_layer(h, w / 2, [1, 2, 3], |_, _| 3000);
    assert!(matches!(
        ldi_from_camera_frames(&[front.view(), small.view()], h, w, &options),
        Err(HoloError::ShapeMismatch { .. })
    ));
    let nearer = camera_layer(h, w, [1, 2, 3], |_, _| 500);
    let e = ldi_from_camera_frames(&[front.view(), nearer.view()], h, w, &options)
        .unwrap_err()
        .to_string();
    assert!(e.contains("buffer 1") && e.contains("nearer"), "{e}");
    assert!(ldi_from_camera_frames(&[], h, w, &options).is_err());
}

/// Writes a one-channel OpenEXR file `name` of `values` `[H, W]` (f32, or f16 with `half`).
#[cfg(feature = "research")]
fn write_exr(path: &Path, name: &str, values: &Array2<f32>, half: bool) {
    use exr::prelude::*;
    let (h, w) = values.dim();
    let samples = if half {
        FlatSamples::F16(values.iter().map(|&v| f16::from_f32(v)).collect())
    } else {
        FlatSamples::F32(values.iter().copied().collect())
    };
    let channels = AnyChannels::sort(vec![AnyChannel::new(name, samples)].into());
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        channels,
    );
    Image::from_layer(layer).write().to_file(path).unwrap();
}

/// `metres` (Record3D's OpenEXR depth): f32 files decode to the very values the 16-bit millimetre PNG of the
/// same depths gives (`v/1000`), half-float files within half's precision; zero, negative, NaN and ∞ samples
/// are invalid; the two encodings refuse each other's files, naming the right one.
#[cfg(feature = "research")]
#[test]
fn openexr_depth_in_metres_decodes_as_the_millimetre_png_does() {
    let png = data("redwood_livingroom_seq/depth/00000.png");
    let mm = decode(
        "redwood_livingroom_seq/depth/00000.png",
        DepthEncoding::Millimetres16,
    );
    let raw = image::open(&png).unwrap().to_luma16();
    let metres = Array2::from_shape_fn(mm.values.dim(), |(y, x)| {
        raw.get_pixel(x as u32, y as u32).0[0] as f32 / 1000.0
    });
    let dir = tempfile::tempdir().unwrap();
    let exr = dir.path().join("0.exr");
    write_exr(&exr, "Y", &metres, false);
    let d = decode_depth_file(&exr, DepthEncoding::Metres).expect("decodes");
    assert!(d.metric);
    assert_eq!(d, mm);

    let half = dir.path().join("half.exr");
    write_exr(&half, "R", &metres, true);
    let h = decode_depth_file(&half, DepthEncoding::Metres).unwrap();
    assert_eq!(h.valid, mm.valid);
    for (a, b) in h.values.iter().zip(mm.values.iter()) {
        assert!((a - b).abs() <= b * 1e-3, "{a} vs {b}");
    }

    let odd =
        Array2::from_shape_vec((1, 5), vec![1.5, 0.0, -2.0, f32::NAN, f32::INFINITY]).unwrap();
    let path = dir.path().join("odd.exr");
    write_exr(&path, "Z", &odd, false);
    let d = decode_depth_file(&path, DepthEncoding::Metres).unwrap();
    assert_eq!(
        d.valid.iter().copied().collect::<Vec<_>>(),
        [true, false, false, false, false]
    );
    assert_eq!(d.values[[0, 0]], 1.5);

    let e = decode_depth_file(&exr, DepthEncoding::Millimetres16).unwrap_err();
    assert!(
        e.to_string().contains("`metres`") && e.to_string().contains("0.exr"),
        "{e}"
    );
    let e = decode_depth_file(&png, DepthEncoding::Metres).unwrap_err();
    assert!(e.to_string().contains("not an OpenEXR file"), "{e}");
    // Truncated: named, never completed.
    let bytes = std::fs::read(&exr).unwrap();
    let cut = dir.path().join("cut.exr");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = decode_depth_file(&cut, DepthEncoding::Metres).unwrap_err();
    assert!(
        matches!(e, HoloError::InvalidDepth(_)) && e.to_string().contains("cut.exr"),
        "{e}"
    );
}

/// Several channels: the depth one is taken by name; none named for depth is refused, listing them.
#[cfg(feature = "research")]
#[test]
fn openexr_depth_takes_the_depth_channel_by_name() {
    use exr::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let write = |names: [&str; 2]| {
        let path = dir.path().join(format!("{}{}.exr", names[0], names[1]));
        let channels = AnyChannels::sort(
            vec![
                AnyChannel::new(names[0], FlatSamples::F32(vec![2.0; 6])),
                AnyChannel::new(names[1], FlatSamples::F32(vec![3.0; 6])),
            ]
            .into(),
        );
        let layer = Layer::new(
            (3, 2),
            LayerAttributes::default(),
            Encoding::UNCOMPRESSED,
            channels,
        );
        Image::from_layer(layer).write().to_file(&path).unwrap();
        decode_depth_file(&path, DepthEncoding::Metres)
    };
    let d = write(["A", "Z"]).unwrap();
    assert!(d.values.iter().all(|&v| v == 3.0));
    let e = write(["A", "B"]).unwrap_err();
    assert!(e.to_string().contains("A, B"), "{e}");
}

/// Issue 80: what reading an OpenEXR depth map allocates (its depth channel and the largest decoded chunk of
/// all channels, and its offset table) is counted from the header against the decoders' budget (16 bytes a
/// pixel, at least 1 MiB) before any pixel is read. A header declaring 32 float channels of 2048² pixels in one
/// tile (a 512 MiB chunk) is refused naming the file and the budget; before, every channel was allocated
/// (512 MiB) from a 925-byte file.
#[cfg(feature = "research")]
#[test]
fn openexr_depth_is_counted_against_the_decoders_budget_from_its_header() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/fuzz/exr_depth");
    let tile = std::fs::read(fixtures.join("32-channels-2048x2048-one-tile-header-only")).unwrap();
    let e = decode_depth_bytes(&tile, Path::new("tiled.exr"), DepthEncoding::Metres).unwrap_err();
    let text = e.to_string();
    assert!(
        matches!(e, HoloError::InvalidData(_))
            && text.contains("tiled.exr")
            && text.contains("budget")
            && text.contains("32 channels"),
        "{text}"
    );
    // The same header in scan lines (ZIP, 16 lines a chunk) is within the budget: it fails only for want of
    // pixels, naming the file.
    let lines = std::fs::read(fixtures.join("32-channels-2048x2048-zip-header-only")).unwrap();
    let e = decode_depth_bytes(&lines, Path::new("lines.exr"), DepthEncoding::Metres).unwrap_err();
    assert!(
        matches!(e, HoloError::InvalidDepth(_)) && e.to_string().contains("lines.exr"),
        "{e}"
    );
}

/// Issue 80: a depth map whose valid depths leave no usable pixel once normalised (all positive, but 1e-40 m:
/// 1/z overflows) is refused naming the file, not passed on as NaN nor refused anonymously.
#[cfg(feature = "research")]
#[test]
fn a_depth_map_that_leaves_no_valid_pixel_is_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = dir.path().join("rgb.png");
    image::RgbImage::from_pixel(16, 12, image::Rgb([120, 90, 60]))
        .save(&rgb)
        .unwrap();
    let depth = dir.path().join("tiny.exr");
    write_exr(&depth, "Z", &Array2::from_elem((12, 16), 1e-40), false);
    let e = load_rgbd(&rgb, &depth, DepthEncoding::Metres, &LoadOptions::default()).unwrap_err();
    let text = e.to_string();
    assert!(
        matches!(e, HoloError::InvalidDepth(_))
            && text.contains("tiny.exr")
            && text.contains("no usable pixel"),
        "{text}"
    );
}

/// A confidence map invalidates its low-confidence pixels before anything reads them: a near block of low
/// confidence on a far background takes the background's depth (never read as near), the report counts it,
/// and a map of another size than the depth is refused naming it.
#[test]
fn low_confidence_depth_is_filled_from_its_confident_neighbours_never_read_as_near() {
    let (h, w) = (24, 32);
    let dir = tempfile::tempdir().unwrap();
    let rgb = dir.path().join("rgb.png");
    image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 8) as u8, (y * 10) as u8, 90]))
        .save(&rgb)
        .unwrap();
    let block = |x: u32, y: u32| (10..18).contains(&x) && (8..16).contains(&y);
    let depth = dir.path().join("depth.png");
    image::ImageBuffer::<image::Luma<u16>, _>::from_fn(w, h, |x, y| {
        image::Luma([if block(x, y) {
            300
        } else {
            2000 + 20 * x as u16
        }])
    })
    .save(&depth)
    .unwrap();
    let confidence = dir.path().join("confidence.png");
    image::GrayImage::from_fn(w, h, |x, y| image::Luma([if block(x, y) { 0 } else { 2 }]))
        .save(&confidence)
        .unwrap();
    let options = LoadOptions {
        range: Some(DepthRange {
            z_near_m: 0.25,
            z_far_m: 3.0,
        }),
        ..LoadOptions::default()
    };
    let (plain, plain_report) =
        load_rgbd(&rgb, &depth, DepthEncoding::Millimetres16, &options).unwrap();
    let (f, report) = load_rgbd_with_confidence(
        &rgb,
        &depth,
        Some(&confidence),
        DepthEncoding::Millimetres16,
        &options,
    )
    .unwrap();
    assert_eq!(plain_report.low_confidence_fraction, None);
    assert_eq!(report.low_confidence_fraction, Some(64.0 / (24.0 * 32.0)));
    let background_min = (0..h as usize)
        .flat_map(|y| (0..w as usize).map(move |x| (y, x)))
        .filter(|&(y, x)| !block(x as u32, y as u32))
        .map(|(y, x)| f.depth[[y, x]])
        .fold(f32::INFINITY, f32::min);
    for y in 8..16 {
        for x in 10..18 {
            // Without the confidence map the block is near (d ≈ 0.18); with it, as far as the background.
            assert!(plain.depth[[y, x]] < 0.2, "{}", plain.depth[[y, x]]);
            assert!(
                f.depth[[y, x]] >= background_min,
                "({y}, {x}): {}",
                f.depth[[y, x]]
            );
        }
    }
    // A medium threshold keeps confidence 1, a high one drops it.
    image::GrayImage::from_fn(w, h, |x, y| image::Luma([if block(x, y) { 1 } else { 2 }]))
        .save(&confidence)
        .unwrap();
    let load = |min| {
        let o = LoadOptions {
            min_confidence: min,
            ..options
        };
        load_rgbd_with_confidence(
            &rgb,
            &depth,
            Some(&confidence),
            DepthEncoding::Millimetres16,
            &o,
        )
        .unwrap()
    };
    assert_eq!(load(1).0, plain);
    assert_ne!(load(2).0, plain);
    let small = dir.path().join("small.png");
    image::GrayImage::from_pixel(w / 2, h / 2, image::Luma([2]))
        .save(&small)
        .unwrap();
    let e = load_rgbd_with_confidence(
        &rgb,
        &depth,
        Some(&small),
        DepthEncoding::Millimetres16,
        &options,
    )
    .unwrap_err();
    assert!(
        matches!(e, HoloError::ShapeMismatch { .. }) && e.to_string().contains("small.png"),
        "{e}"
    );
}

/// A depth map of lower resolution than the colour (a phone's LiDAR: Redwood's depth at a quarter of its
/// colour's resolution) loaded at a smaller output size is upsampled there, guided by the colour brought there
/// first: the colour is bit for bit what resizing after gives, the depth within the bound
/// `docs/CONVENTIONS.md` §6 states (mean |Δd| ≤ 0.006; at most 2 % of the pixels off by more than 0.05, all of
/// them on depth edges, where the guide's colour steps are seen at another resolution).
#[test]
fn a_low_resolution_depth_is_upsampled_at_the_output_size_within_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let depth = image::open(data("redwood_livingroom_seq/depth/00000.png"))
        .unwrap()
        .to_luma16();
    let small =
        image::ImageBuffer::from_fn(160, 120, |x, y| *depth.get_pixel(4 * x + 2, 4 * y + 2));
    let low = dir.path().join("depth_160x120.png");
    small.save(&low).unwrap();
    let rgb = data("redwood_livingroom_seq/color/00000.jpg");
    let options = LoadOptions {
        range: Some(DepthRange::new(0.9, 2.8).unwrap()),
        ..LoadOptions::default()
    };
    let (full, _) = load_rgbd(&rgb, &low, DepthEncoding::Millimetres16, &options).unwrap();
    let after = full.resize(120, 160).unwrap();
    let sized = LoadOptions {
        size: Some((120, 160)),
        ..options
    };
    let (before, _) = load_rgbd(&rgb, &low, DepthEncoding::Millimetres16, &sized).unwrap();
    assert_eq!(before.amplitude, after.amplitude);
    let diff: Vec<f32> = before
        .depth
        .iter()
        .zip(after.depth.iter())
        .map(|(a, b)| (a - b).abs())
        .collect();
    let mean = diff.iter().sum::<f32>() / diff.len() as f32;
    let off = diff.iter().filter(|&&d| d > 0.05).count() as f32 / diff.len() as f32;
    eprintln!("mean |Δd| {mean:.5}, {:.2} % off by > 0.05", 100.0 * off);
    assert!(mean <= 0.006, "mean |Δd| {mean}");
    assert!(
        off <= 0.02,
        "{:.2} % of the pixels off by > 0.05",
        100.0 * off
    );
    assert!(
        mean > 0.0,
        "the depth is upsampled at the output size, not resized after"
    );
}
