//! `holo calibrate aberration` (docs/ABERRATION.md, "Calibration from captures"): the loop patterns →
//! simulated display and camera → fit recovers the hidden aberration; bad inputs refused naming the field or
//! file, with nothing written.

mod common;

use std::path::{Path, PathBuf};

use common::{holo, stderr};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A small plan (64×64 SLM, green, three distances, camera scale 2, 32-pixel window) and its simulated
/// captures (8-bit, noise, seed 5). Returns (patterns, captures).
fn setup(dir: &Path) -> (PathBuf, PathBuf) {
    let (patterns, captures) = (dir.join("patterns"), dir.join("captures"));
    let o = holo(&[
        "calibrate",
        "aberration",
        "patterns",
        "--size",
        "64x64",
        "--distances-mm=-4,3,6",
        "--colours",
        "green",
        "--camera-scale",
        "2",
        "--window-px",
        "32",
        "--out",
        s(&patterns),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = holo(&[
        "calibrate",
        "aberration",
        "simulate",
        "--patterns",
        s(&patterns),
        "--seed",
        "5",
        "--max-rad",
        "1.2",
        "--out",
        s(&captures),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    (patterns, captures)
}

fn fit(patterns: &Path, captures: &Path, out: &Path) -> std::process::Output {
    holo(&[
        "calibrate",
        "aberration",
        "fit",
        "--patterns",
        s(patterns),
        "--captures",
        s(captures),
        "--out",
        s(out),
    ])
}

fn coefficients(v: &serde_json::Value, i: usize, c: usize) -> Vec<f64> {
    let sample = &v["samples"][i];
    let z = if sample["per_colour"].is_null() {
        &sample["coefficients"]
    } else {
        &sample["per_colour"][c]
    };
    [
        "focus",
        "astigmatism_vertical",
        "astigmatism_oblique",
        "coma_horizontal",
        "coma_vertical",
    ]
    .iter()
    .map(|k| z[k].as_f64().unwrap_or(0.0))
    .collect()
}

#[test]
fn the_fit_recovers_the_hidden_aberration_of_the_simulated_display() {
    let dir = tempfile::tempdir().unwrap();
    let (patterns, captures) = setup(dir.path());
    assert_eq!(
        std::fs::read_dir(&captures).unwrap().count(),
        15 + 1,
        "15 captures and hidden.json"
    );
    let out = dir.path().join("aberration.json");
    let o = fit(&patterns, &captures, &out);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(
        table.contains("max_error_vs_hidden") && table.contains("red (from green)"),
        "{table}"
    );
    let got: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let hidden: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(captures.join("hidden.json")).unwrap())
            .unwrap();
    assert_eq!(got["format"], "tensorholo.aberration");
    assert_eq!(got["pixel_pitch_m"], 8e-6);
    let mut worst = [0f64; 3];
    for i in 0..3 {
        assert_eq!(
            got["samples"][i]["distance_m"],
            hidden["samples"][i]["distance_m"]
        );
        for (c, w) in worst.iter_mut().enumerate() {
            for (a, b) in coefficients(&got, i, c)
                .iter()
                .zip(coefficients(&hidden, i, c))
            {
                *w = w.max((a - b).abs());
            }
        }
    }
    eprintln!("worst |fitted − hidden| R, G, B: {worst:.4?} rad");
    assert!(worst[1] < 0.1, "green, fitted: {worst:?}\n{table}");
    // Red and blue follow green by the wavelength rule (coma × (λ/λ_g)², up to 1.5× green's error).
    assert!(worst[0] < 0.15 && worst[2] < 0.15, "derived: {worst:?}");
}

/// Asserts the command failed, its message holds every `needle`, and `out` was not written.
fn refused(o: &std::process::Output, needles: &[&str], out: &Path) {
    let e = stderr(o);
    assert!(!o.status.success(), "should fail: {e}");
    for n in needles {
        assert!(e.contains(n), "`{n}` not in: {e}");
    }
    assert!(!e.contains("panicked"), "{e}");
    assert!(!out.exists(), "{} written on error", out.display());
}

#[test]
fn bad_captures_are_refused_naming_the_file_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let (patterns, captures) = setup(dir.path());
    let out = dir.path().join("aberration.json");
    let name = "capture_green_d1_k2.png";
    let capture = captures.join(name);
    let original = std::fs::read(&capture).unwrap();

    std::fs::remove_file(&capture).unwrap();
    refused(
        &fit(&patterns, &captures, &out),
        &["missing capture", name],
        &out,
    );
    // A folder or a device at the capture's name is not "missing": it is named for what it is.
    std::fs::create_dir(&capture).unwrap();
    refused(
        &fit(&patterns, &captures, &out),
        &[name, "is a folder"],
        &out,
    );
    std::fs::remove_dir(&capture).unwrap();
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("/dev/null", &capture).unwrap();
        refused(
            &fit(&patterns, &captures, &out),
            &[name, "not a regular file"],
            &out,
        );
        std::fs::remove_file(&capture).unwrap();
    }

    image::GrayImage::from_pixel(48, 40, image::Luma([90]))
        .save(&capture)
        .unwrap();
    refused(
        &fit(&patterns, &captures, &out),
        &[name, "48×40", "capture_green_d1_k0.png"],
        &out,
    );

    std::fs::write(&capture, &original).unwrap();
    let first = captures.join("capture_green_d2_k0.png");
    let first_bytes = std::fs::read(&first).unwrap();
    image::GrayImage::from_pixel(24, 24, image::Luma([90]))
        .save(&first)
        .unwrap();
    refused(
        &fit(&patterns, &captures, &out),
        &["capture_green_d2_k0.png", "24×24", "32×32 window"],
        &out,
    );
    std::fs::write(&first, first_bytes).unwrap();

    image::GrayImage::from_pixel(48, 48, image::Luma([0]))
        .save(&capture)
        .unwrap();
    refused(&fit(&patterns, &captures, &out), &[name, "all black"], &out);

    image::GrayImage::from_pixel(48, 48, image::Luma([255]))
        .save(&capture)
        .unwrap();
    refused(&fit(&patterns, &captures, &out), &[name, "saturated"], &out);

    std::fs::write(&capture, b"not a png").unwrap();
    refused(&fit(&patterns, &captures, &out), &[name], &out);

    std::fs::write(&capture, original).unwrap();
    let o = fit(&patterns, &captures, &out);
    assert!(o.status.success(), "restored: {}", stderr(&o));
}

#[test]
fn bad_plans_parameters_and_outputs_are_refused_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let (patterns, captures) = setup(dir.path());
    let out = dir.path().join("aberration.json");
    let plan = patterns.join("plan.json");
    let text = std::fs::read_to_string(&plan).unwrap();

    std::fs::write(&plan, text.replace("\"version\": 1", "\"version\": 9")).unwrap();
    refused(
        &fit(&patterns, &captures, &out),
        &["plan.json", "version", "9"],
        &out,
    );
    std::fs::write(
        &plan,
        text.replace("\"camera_scale\": 2.0", "\"camera_scale\": -2.0"),
    )
    .unwrap();
    refused(
        &fit(&patterns, &captures, &out),
        &["plan.json", "camera_scale"],
        &out,
    );
    // A hand-made plan for an SLM of 16384² (within 16384 a side, 4 times the 8192² a profile allows), a
    // diversity of 1e308 rad, a wrong type (the key path named), a key given twice.
    for (from, to, says) in [
        (
            "\"slm_size\": [\n    64,\n    64\n  ]",
            "\"slm_size\": [16384, 16384]",
            "slm_size",
        ),
        ("\"focus\": 2.0", "\"focus\": 1e308", "diversities"),
        (
            "\"camera_scale\": 2.0",
            "\"camera_scale\": \"2\"",
            "at `camera_scale`",
        ),
        (
            "\"camera_scale\": 2.0",
            "\"camera_scale\": 2.0, \"camera_scale\": 3.0",
            "duplicate field",
        ),
    ] {
        assert!(text.contains(from), "{from} not in {text}");
        std::fs::write(&plan, text.replacen(from, to, 1)).unwrap();
        refused(&fit(&patterns, &captures, &out), &["plan.json", says], &out);
    }
    std::fs::write(&plan, &text).unwrap();

    let elsewhere = dir.path().join("other");
    let patterns_cmd = |extra: &[&str]| {
        let mut a = vec![
            "calibrate",
            "aberration",
            "patterns",
            "--size",
            "64x64",
            "--out",
            s(&elsewhere),
        ];
        a.extend_from_slice(extra);
        holo(&a)
    };
    refused(
        &patterns_cmd(&["--distances-mm", "2000"]),
        &["distances_m", "2 m"],
        &elsewhere,
    );
    refused(
        &patterns_cmd(&["--distances-mm=-3,nan"]),
        &["distances_m", "NaN"],
        &elsewhere,
    );
    refused(
        &patterns_cmd(&["--distances-mm", "0"]),
        &["distances_m", "sub-hologram"],
        &elsewhere,
    );
    // A 4 × 4 SLM cannot hold a spot's sub-hologram: named, not four meaningless patterns.
    let o = holo(&[
        "calibrate",
        "aberration",
        "patterns",
        "--size",
        "4x4",
        "--out",
        s(&elsewhere),
    ]);
    refused(&o, &["distances_m", "cut the spot"], &elsewhere);
    refused(
        &patterns_cmd(&["--camera-scale", "nan"]),
        &["camera_scale"],
        &elsewhere,
    );
    refused(
        &patterns_cmd(&["--colours", "mauve"]),
        &["--colours", "mauve"],
        &elsewhere,
    );
    let o = holo(&[
        "calibrate",
        "aberration",
        "simulate",
        "--patterns",
        s(&patterns),
        "--max-rad",
        "inf",
        "--out",
        s(&elsewhere),
    ]);
    refused(&o, &["max_rad"], &elsewhere);

    // The output may be no input, nor lie inside an input folder; nothing is written.
    let before = std::fs::read(&plan).unwrap();
    let o = fit(&patterns, &captures, &plan);
    refused(&o, &["--patterns"], &dir.path().join("never"));
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(std::fs::read(&plan).unwrap(), before, "plan.json untouched");
    let o = fit(&patterns, &captures, &captures);
    refused(&o, &["--captures"], &dir.path().join("never"));
    let o = fit(&patterns, &captures, &captures.join("hidden.json"));
    refused(&o, &["--captures"], &dir.path().join("never"));
    let o = holo(&[
        "calibrate",
        "aberration",
        "simulate",
        "--patterns",
        s(&patterns),
        "--out",
        s(&patterns),
    ]);
    refused(&o, &["--patterns"], &dir.path().join("never"));
}
