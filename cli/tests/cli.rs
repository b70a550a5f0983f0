//! End-to-end tests of the `holo` binary: outputs, interoperability files and error messages.

mod common;

use common::{holo, png_size, shared, stderr};

use std::path::Path;

use ndarray::Array3;
use num_complex::Complex32;
use tensorholo::io::{read_complex_npy, write_complex_npy};

#[test]
fn reference_on_the_built_in_scene_writes_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = holo(&[
        "reference",
        "--size",
        "48x64",
        "--levels",
        "32",
        "--offset-mm",
        "6",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for name in [
        "phase_r.png",
        "phase_g.png",
        "phase_b.png",
        "focus_near.png",
        "focus_mid.png",
        "focus_far.png",
        "target.png",
        "depth.png",
    ] {
        assert_eq!(png_size(&out.join(name)), (64, 48), "{name}");
    }
    let mid = read_complex_npy(&out.join("midpoint.npy")).unwrap();
    assert_eq!(mid.dim(), (3, 48, 64));
    assert!(mid.iter().all(|v| v.is_finite()) && mid.iter().any(|v| v.norm() > 0.1));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["parameters"]["synthesis"]["levels"], 32);
    assert_eq!(report["parameters"]["offset_m"], 0.006);
    assert!(report["timings_s"]["synthesis"].as_f64().unwrap() > 0.0);
    let focus = report["statistics"]["focus"].as_array().unwrap();
    assert_eq!(focus.len(), 3);
    for f in focus {
        let p = f["encoding_psnr_db"].as_f64().unwrap();
        assert!(p > 10.0 && p < 80.0, "{p}");
    }
}

#[test]
fn reference_accepts_the_built_in_scene_as_a_layered_depth_image() {
    let dir = tempfile::tempdir().unwrap();
    let o = holo(&[
        "reference",
        "--ldi",
        "--size",
        "32x32",
        "--levels",
        "16",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report = std::fs::read_to_string(dir.path().join("report.json")).unwrap();
    assert!(report.contains("2-layer layered depth image"));
}

#[test]
fn mismatched_rgb_and_depth_sizes_name_both_files() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = shared("tum/TUM_color.png");
    let depth = shared("iphone_portrait_vase/disparity_aux_576x768.jpg");
    let o = holo(&[
        "reference",
        "--rgb",
        rgb.to_str().unwrap(),
        "--depth",
        depth.to_str().unwrap(),
        "--depth-encoding",
        "iphone-disparity",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("shape mismatch") && e.contains("TUM_color.png") && e.contains("disparity_aux"),
        "{e}"
    );
}

#[test]
fn bad_parameters_and_files_are_named_in_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let cases: [(&[&str], &str); 7] = [
        (
            &["reference", "--pitch-m", "0", "--out", out],
            "pixel_pitch_m",
        ),
        (
            &[
                "reference",
                "--levels",
                "0",
                "--size",
                "16x16",
                "--out",
                out,
            ],
            "levels",
        ),
        (
            &[
                "reference",
                "--wavelengths-m",
                "638e-9,-520e-9,450e-9",
                "--out",
                out,
            ],
            "wavelength_m",
        ),
        (
            &["reference", "--size", "0x16", "--out", out],
            "positive integer",
        ),
        (
            &["reference", "--size", "8x40", "--out", out],
            "at least 11×11",
        ),
        (
            &[
                "reference",
                "--rgb",
                "/no/such/rgb.png",
                "--depth",
                "/no/such/d.png",
                "--depth-encoding",
                "mm16",
                "--out",
                out,
            ],
            "/no/such/",
        ),
        (
            &[
                "reference",
                "--rgb",
                "a.png",
                "--depth",
                "b.png",
                "--depth-encoding",
                "feet",
                "--out",
                out,
            ],
            "mm16",
        ),
    ];
    for (args, needle) in cases {
        let o = holo(args);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(stderr(&o).contains(needle), "{args:?}: {}", stderr(&o));
    }
}

#[test]
fn inputs_are_never_overwritten() {
    let dir = tempfile::tempdir().unwrap();
    // An input that sits where an output would be written.
    let rgb = dir.path().join("target.png");
    let depth = dir.path().join("d.jpg");
    std::fs::copy(shared("iphone_portrait_vase/derived_rgb_576x768.png"), &rgb).unwrap();
    std::fs::copy(
        shared("iphone_portrait_vase/disparity_aux_576x768.jpg"),
        &depth,
    )
    .unwrap();
    let before = std::fs::read(&rgb).unwrap();
    let o = holo(&[
        "reference",
        "--rgb",
        rgb.to_str().unwrap(),
        "--depth",
        depth.to_str().unwrap(),
        "--depth-encoding",
        "iphone-disparity",
        "--out",
        dir.path().join(".").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("refusing to overwrite input"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(&rgb).unwrap(), before);
}

#[test]
fn propagate_round_trips_a_field_and_checks_wavelength_count() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("field.npy");
    let there = dir.path().join("there.npy");
    let back = dir.path().join("back.npy");
    let field = Array3::from_shape_fn((3, 24, 32), |(c, y, x)| {
        Complex32::from_polar(0.5 + 0.1 * c as f32, 0.05 * (x * y) as f32)
    });
    write_complex_npy(&input, field.view()).unwrap();
    let run = |from: &Path, to: &Path, d: &str| {
        holo(&[
            "propagate",
            "--input",
            from.to_str().unwrap(),
            "--distance-m",
            d,
            "--wavelength-m",
            "638e-9,520e-9,450e-9",
            "--pitch-m",
            "8e-6",
            "--output",
            to.to_str().unwrap(),
        ])
    };
    assert!(run(&input, &there, "2e-3").status.success());
    assert!(run(&there, &back, "-2e-3").status.success());
    let moved = read_complex_npy(&there).unwrap();
    let result = read_complex_npy(&back).unwrap();
    let diff = |a: &Array3<Complex32>| {
        a.iter()
            .zip(field.iter())
            .map(|(x, y)| (x - y).norm())
            .fold(0.0f32, f32::max)
    };
    assert!(diff(&moved) > 0.05, "2 mm must change the field");
    assert!(diff(&result) < 1e-4, "round trip error {}", diff(&result));
    let o = holo(&[
        "propagate",
        "--input",
        input.to_str().unwrap(),
        "--distance-m",
        "1e-3",
        "--wavelength-m",
        "638e-9,520e-9",
        "--pitch-m",
        "8e-6",
        "--output",
        there.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("3 channels"),
        "{}",
        stderr(&o)
    );
    let o = holo(&[
        "propagate",
        "--input",
        input.to_str().unwrap(),
        "--distance-m",
        "1e-3",
        "--wavelength-m",
        "520e-9",
        "--pitch-m",
        "8e-6",
        "--output",
        input.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("refusing to overwrite"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn encode_writes_every_output_and_reproduces_a_smooth_field() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("mid.npy");
    let (h, w) = (24usize, 32usize);
    let field = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
        let a = 0.6 + 0.3 * ((x as f32) * 0.2).cos() * ((y as f32) * 0.15 + c as f32).cos();
        Complex32::from_polar(a, 0.3 * ((x + y) as f32 * 0.1).sin())
    });
    write_complex_npy(&input, field.view()).unwrap();
    for offset in ["6", "0"] {
        let out = dir.path().join(format!("enc{offset}"));
        let o = holo(&[
            "encode",
            "--input",
            input.to_str().unwrap(),
            "--offset-mm",
            offset,
            "--method",
            "dpm",
            "--pad",
            "--depths",
            "0.2,0.7",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        for name in [
            "slm_field.npy",
            "phase.npy",
            "post_midpoint.npy",
            "focal_stack.npy",
            "target_focal_stack.npy",
            "encode.json",
        ] {
            assert!(out.join(name).exists(), "{name} missing");
        }
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("encode.json")).unwrap())
                .unwrap();
        let offset_m: f64 = offset.parse::<f64>().unwrap() * 1e-3;
        assert!((report["offset_m"].as_f64().unwrap() - offset_m).abs() < 1e-12);
        if offset == "0" {
            // DPM + Fourier filter gives back the smooth field's amplitude (÷ a) at the SLM plane. (At 6 mm
            // this small grid loses light over its edges, so only the 0 mm case is compared.)
            let scale = report["amplitude_scale"].as_f64().unwrap() as f32;
            let post = read_complex_npy(&out.join("post_midpoint.npy")).unwrap();
            let worst = post
                .iter()
                .zip(field.iter())
                .map(|(p, f)| (p.norm() * scale - f.norm()).abs())
                .fold(0.0f32, f32::max);
            assert!(worst < 0.15, "post-encoding amplitude error {worst}");
        }
    }
    // a 2-channel field is refused with a message naming the problem
    let two = dir.path().join("two.npy");
    write_complex_npy(&two, field.slice(ndarray::s![0..2, .., ..])).unwrap();
    let o = holo(&[
        "encode",
        "--input",
        two.to_str().unwrap(),
        "--out",
        dir.path().join("x").to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("2 channels"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn calibrate_simulate_lut_curves_end_to_end() {
    let dir = std::env::temp_dir().join(format!("holo-calibrate-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    let d = |p: &str| dir.join(p).to_string_lossy().into_owned();
    let o = holo(&[
        "calibrate",
        "simulate",
        "--size",
        "16x24",
        "--out",
        &d("sim"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = holo(&[
        "calibrate",
        "lut",
        "--green",
        &d("sim/green"),
        "--size",
        "16x24",
        "--out",
        &d("d.holocal"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let cal = tensorholo::slm::DisplayCalibration::read(&dir.join("d.holocal")).unwrap();
    assert_eq!(cal.colours[0].lut.representation().name(), "linear");
    assert_eq!(cal.colours[1].lut.representation().name(), "tiled");
    let o = holo(&[
        "calibrate",
        "curves",
        &d("d.holocal"),
        "--color",
        "green",
        "--out",
        &d("g.npy"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Header (128 bytes) + [16, 24, 256] float32.
    assert_eq!(
        std::fs::metadata(dir.join("g.npy")).unwrap().len(),
        128 + 16 * 24 * 256 * 4
    );
    // The intensity map from the diffuser capture, added to a copy; --base is never the output.
    let o = holo(&[
        "calibrate",
        "intensity",
        "--green",
        &d("sim/diffuser_green.png"),
        "--base",
        &d("d.holocal"),
        "--out",
        &d("d.holocal"),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("overwrite"),
        "{}",
        stderr(&o)
    );
    let o = holo(&[
        "calibrate",
        "intensity",
        "--green",
        &d("sim/diffuser_green.png"),
        "--base",
        &d("d.holocal"),
        "--out",
        &d("e.holocal"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = tensorholo::slm::DisplayCalibration::read(&dir.join("e.holocal")).unwrap();
    let map = e.colours[1].intensity_scale.as_ref().unwrap();
    assert!(e.colours[0].intensity_scale.is_none());
    assert_eq!(e.colours[1].lut.representation().name(), "tiled");
    // The Gaussian beam is brightest near the centre: dimmed most there, not at all at its floor.
    let centre = map[[8, 12]];
    let lo = map.iter().cloned().fold(f32::INFINITY, f32::min);
    let hi = map.iter().cloned().fold(0.0f32, f32::max);
    assert!(
        centre < 0.9 && (lo - centre).abs() < 0.15 && hi == 1.0,
        "{centre} {lo} {hi}"
    );
    // The deep-black test: the calibrated pattern is predicted darker than the linear LUT's.
    let o = holo(&["calibrate", "black", &d("e.holocal"), "--out", &d("black")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("black/black.json")).unwrap())
            .unwrap();
    let g = &report["green"];
    assert!(
        g["black_level_calibrated"].as_f64().unwrap()
            < 0.5 * g["black_level_linear_lut"].as_f64().unwrap(),
        "{g}"
    );
    assert!(dir.join("black/black_g.png").exists());
    // A render through the calibration: at its size only.
    let o = holo(&[
        "render",
        "--size",
        "16x24",
        "--calibration",
        &d("e.holocal"),
        "--out",
        &d("r"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("r/report.json")).unwrap()).unwrap();
    assert!(
        report["models"]["calibration"]["summary"]
            .as_str()
            .unwrap()
            .contains("green tiled"),
        "{report}"
    );
    let o = holo(&[
        "render",
        "--size",
        "32x24",
        "--lut",
        &d("e.holocal"),
        "--out",
        &d("r2"),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("16×24"),
        "{}",
        stderr(&o)
    );
    // A maker's global table: CSV for red, the gamma model for the others; a bad CSV names its line.
    let csv: String = (0..256)
        .map(|k| format!("{k},{}\n", 7.0 * k as f32 / 255.0))
        .collect();
    std::fs::write(dir.join("red.csv"), csv).unwrap();
    let o = holo(&[
        "calibrate",
        "global",
        "--size",
        "16x24",
        "--red-csv",
        &d("red.csv"),
        "--range-rad",
        "7.2",
        "--gamma",
        "1.2",
        "--out",
        &d("g.holocal"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let g = tensorholo::slm::DisplayCalibration::read(&dir.join("g.holocal")).unwrap();
    let phase_255 = |c: usize| g.colours[c].lut.displayed_phase(0, 0, 255).unwrap();
    assert!((phase_255(0) - 7.0).abs() < 1e-3 && (phase_255(1) - 7.2).abs() < 1e-3);
    std::fs::write(dir.join("bad.csv"), "0,0\n1,oops\n").unwrap();
    let o = holo(&[
        "calibrate",
        "global",
        "--size",
        "16x24",
        "--red-csv",
        &d("bad.csv"),
        "--out",
        &d("b.holocal"),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("bad.csv"),
        "{}",
        stderr(&o)
    );
    // Another resolution's captures, a missing folder, and a wrong colour are refused by name.
    let o = holo(&[
        "calibrate",
        "lut",
        "--red",
        &d("sim/nope"),
        "--size",
        "16x24",
        "--out",
        &d("x.holocal"),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("sim/nope"),
        "{}",
        stderr(&o)
    );
    let o = holo(&[
        "calibrate",
        "lut",
        "--red",
        &d("sim/red"),
        "--size",
        "64x64",
        "--out",
        &d("x.holocal"),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("smaller than the 64×64 SLM"),
        "{}",
        stderr(&o)
    );
    let o = holo(&[
        "calibrate",
        "curves",
        &d("d.holocal"),
        "--color",
        "purple",
        "--out",
        &d("p.npy"),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("purple"),
        "{}",
        stderr(&o)
    );
    // A truncated calibration file is refused.
    let bytes = std::fs::read(dir.join("d.holocal")).unwrap();
    std::fs::write(dir.join("t.holocal"), &bytes[..bytes.len() - 9]).unwrap();
    let o = holo(&[
        "calibrate",
        "curves",
        &d("t.holocal"),
        "--color",
        "green",
        "--out",
        &d("t.npy"),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("truncated"),
        "{}",
        stderr(&o)
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[cfg(unix)]
#[test]
fn paths_that_are_not_utf8_work_and_reports_name_them_lossily() {
    use std::os::unix::ffi::OsStrExt;
    let dir = std::env::temp_dir().join(format!("holo-non-utf8-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    // "caf\xe9": Latin-1 é, not UTF-8.
    let out = dir.join(std::ffi::OsStr::from_bytes(b"caf\xe9"));
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_holo"))
        .args(["render", "--size", "16x16", "--repeat", "0", "--out"])
        .arg(&out)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let command: Vec<&str> = report["command"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(
        command.last().unwrap().ends_with("caf\u{fffd}"),
        "{command:?}"
    );
    assert!(out.join("phase_g.png").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn images_above_the_pixel_limit_are_refused_from_their_header() {
    let dir = std::env::temp_dir().join(format!("holo-image-limit-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let rgb = dir.join("rgb.png");
    let depth = dir.join("depth.png");
    image::RgbImage::from_pixel(400, 300, image::Rgb([128, 90, 60]))
        .save(&rgb)
        .unwrap();
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(400, 300, image::Luma([1000]))
        .save(&depth)
        .unwrap();
    let before = (std::fs::read(&rgb).unwrap(), std::fs::read(&depth).unwrap());
    let out = dir.join("out");
    let args = |limit: &str| {
        vec![
            "render".to_string(),
            "--rgb".into(),
            rgb.display().to_string(),
            "--depth".into(),
            depth.display().to_string(),
            "--depth-encoding".into(),
            "mm16".into(),
            "--size".into(),
            "16x16".into(),
            "--repeat".into(),
            "0".into(),
            "--max-image-pixels".into(),
            limit.into(),
            "--out".into(),
            out.display().to_string(),
        ]
    };
    let refused = holo(
        &args("100000")
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    let msg = stderr(&refused);
    assert_eq!(refused.status.code(), Some(1), "{msg}");
    assert!(
        msg.contains("rgb.png") && msg.contains("400×300") && msg.contains("100000"),
        "{msg}"
    );
    assert!(!out.join("report.json").exists());
    // Raised, the same input renders; the inputs are untouched either way.
    let o = holo(
        &args("120000")
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        (std::fs::read(&rgb).unwrap(), std::fs::read(&depth).unwrap()),
        before
    );
    let o = holo(&[
        "render",
        "--max-image-pixels",
        "0",
        "--out",
        &out.display().to_string(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("limits"),
        "{}",
        stderr(&o)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn video_refuses_unmatched_frames_and_never_saves_over_its_inputs() {
    let data = common::shared("redwood_livingroom_seq");
    let dir = std::env::temp_dir().join(format!("holo-video-bad-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    let (rgb, depth) = (dir.join("rgb"), dir.join("depth"));
    std::fs::create_dir_all(&rgb).unwrap();
    std::fs::create_dir_all(&depth).unwrap();
    for n in ["00000", "00001"] {
        std::fs::copy(
            data.join(format!("color/{n}.jpg")),
            rgb.join(format!("{n}.jpg")),
        )
        .unwrap();
    }
    std::fs::copy(data.join("depth/00000.png"), depth.join("00000.png")).unwrap();
    std::fs::write(rgb.join(".DS_Store"), b"junk").unwrap(); // hidden files are not frames
    let video = |rgb: &std::path::Path, depth: &std::path::Path, extra: &[&str], out: &str| {
        let mut args = vec![
            "video".to_string(),
            "--rgb-dir".into(),
            rgb.display().to_string(),
            "--depth-dir".into(),
            depth.display().to_string(),
            "--depth-encoding".into(),
            "mm16".into(),
            "--size".into(),
            "24x32".into(),
            "--out".into(),
            dir.join(out).display().to_string(),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        holo(&args.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let o = video(&rgb, &depth, &[], "v1");
    assert!(
        !o.status.success()
            && stderr(&o).contains("00001.jpg")
            && stderr(&o).contains("--skip-unmatched"),
        "{}",
        stderr(&o)
    );
    let o = video(&rgb, &depth, &["--skip-unmatched"], "v2");
    assert!(o.status.success(), "{}", stderr(&o));
    // Input frames inside the folder --save-frames writes to, under the names it would write: refused
    // before anything is written, inputs unchanged.
    let frames = dir.join("v3/frames");
    let depth3 = dir.join("depth3");
    std::fs::create_dir_all(&frames).unwrap();
    std::fs::create_dir_all(&depth3).unwrap();
    std::fs::copy(
        data.join("color/00000.jpg"),
        frames.join("00000_phase_r.png"),
    )
    .unwrap();
    std::fs::copy(
        data.join("depth/00000.png"),
        depth3.join("00000_phase_r.png"),
    )
    .unwrap();
    let before = std::fs::read(frames.join("00000_phase_r.png")).unwrap();
    let o = video(&frames, &depth3, &["--save-frames"], "v3");
    assert!(
        !o.status.success() && stderr(&o).contains("overwrite"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read(frames.join("00000_phase_r.png")).unwrap(),
        before
    );
    assert!(!frames.join("00000_phase_g.png").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn propagate_refuses_a_field_with_nan_instead_of_spreading_it() {
    let dir = std::env::temp_dir().join(format!("holo-propagate-nan-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let mut field = Array3::from_elem((1, 8, 8), Complex32::new(1.0, 0.0));
    field[[0, 2, 3]] = Complex32::new(f32::NAN, 0.0);
    field[[0, 5, 5]] = Complex32::new(0.0, f32::INFINITY);
    let input = dir.join("nan.npy");
    write_complex_npy(&input, field.view()).unwrap();
    let output = dir.join("out.npy");
    let o = holo(&[
        "propagate",
        "--input",
        input.to_str().unwrap(),
        "--distance-m",
        "1e-3",
        "--wavelength-m",
        "520e-9",
        "--pitch-m",
        "8e-6",
        "--output",
        output.to_str().unwrap(),
    ]);
    let msg = stderr(&o);
    assert!(
        !o.status.success() && msg.contains("2 NaN or infinite") && msg.contains("row 2, column 3"),
        "{msg}"
    );
    assert!(!output.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[cfg(unix)]
#[test]
fn outputs_replace_planted_symlinks_and_a_failed_rerun_leaves_no_old_report() {
    let dir = std::env::temp_dir().join(format!("holo-atomic-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    // A file outside --out, and a symlink to it planted where holo writes a pattern.
    let victim = dir.join("victim.txt");
    std::fs::write(&victim, b"keep me").unwrap();
    std::os::unix::fs::symlink(&victim, out.join("phase_r.png")).unwrap();
    let o = holo(&[
        "render",
        "--size",
        "16x16",
        "--repeat",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read(&victim).unwrap(), b"keep me");
    let meta = std::fs::symlink_metadata(out.join("phase_r.png")).unwrap();
    assert!(
        meta.file_type().is_file(),
        "the symlink must be replaced, not followed"
    );
    assert!(out.join("report.json").exists());
    // No temporary files are left behind.
    let leftovers: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // A re-run that fails (a missing model file) leaves no report.json of the earlier run beside it.
    let o = holo(&[
        "render",
        "--size",
        "16x16",
        "--model",
        dir.join("missing.onnx").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(!out.join("report.json").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
