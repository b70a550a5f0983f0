//! `holo render | video --aberration FILE` and the display profile's `aberration` key (docs/ABERRATION.md):
//! the viewer's aberrations corrected with the shipped CNNs, reported in report.json; bad aberration files
//! refused naming the field, with nothing written.

mod common;

use std::path::Path;

use common::{holo, stderr, ONE_SAMPLE_DATASET};

/// A viewer's astigmatism, the same at every distance (radians at the pupil edge).
const EYE: &str = r#"{
  "format": "tensorholo.aberration",
  "version": 1,
  "samples": [
    {"distance_m": 0.0, "coefficients": {"focus": 3.5, "astigmatism_vertical": -7.0}}
  ]
}"#;

/// Display optics whose coma changes with distance.
const VARYING: &str = r#"{
  "format": "tensorholo.aberration",
  "version": 1,
  "pixel_pitch_m": 8e-6,
  "samples": [
    {"distance_m": -0.02, "coefficients": {"coma_horizontal": 9.0}},
    {"distance_m": 0.02, "coefficients": {"coma_horizontal": -3.0}}
  ]
}"#;

fn render(extra: &[&str], out: &Path) -> std::process::Output {
    let mut args = vec!["render", "--size", "40x56", "--repeat", "0"];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", out.to_str().unwrap()]);
    holo(&args)
}

fn report(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

#[test]
fn render_corrects_from_the_flag_or_the_profile_key_and_reports_what_it_applied() {
    let dir = tempfile::tempdir().unwrap();
    let eye = dir.path().join("eye.json");
    std::fs::write(&eye, EYE).unwrap();
    let plain = dir.path().join("plain");
    assert!(render(&[], &plain).status.success());

    let flag = dir.path().join("flag");
    let o = render(&["--aberration", eye.to_str().unwrap()], &flag);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&flag);
    let applied = &r["models"]["aberration"]["applied"];
    assert_eq!(applied["exact"], true);
    assert_eq!(applied["distance_m"], -0.006);
    assert_eq!(applied["coefficients"][1]["astigmatism_vertical"], -7.0);
    // AA-DPM, not the DDPM pre-filter, and the CPU.
    assert!(r["models"]["prefilter_cnn"].is_null());
    assert!(r["models"]["prefilter_reason"]
        .as_str()
        .unwrap()
        .contains("aberration correction"));
    assert_eq!(r["backend"]["active"], "cpu");
    let png = |d: &Path| std::fs::read(d.join("phase_g.png")).unwrap();
    assert_ne!(
        png(&flag),
        png(&plain),
        "the correction changes the pattern"
    );

    // The profile's key, relative to the profile's folder: the same pattern as the flag.
    let profile = dir.path().join("display.json");
    std::fs::write(
        &profile,
        r#"{"pixel_pitch_m": 8e-6, "resolution": [40, 56], "wavelengths_m": [638e-9, 520e-9, 450e-9],
            "volume_depth_m": 6e-3, "offsets_m": [6e-3], "aberration": "eye.json"}"#,
    )
    .unwrap();
    let keyed = dir.path().join("keyed");
    let o = render(&["--display", profile.to_str().unwrap()], &keyed);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(png(&keyed), png(&flag));

    // Coefficients that change with distance: applied at the midpoint plane, the residual reported.
    let varying = dir.path().join("varying.json");
    std::fs::write(&varying, VARYING).unwrap();
    let out = dir.path().join("varying");
    let o = render(&["--aberration", varying.to_str().unwrap()], &out);
    assert!(o.status.success(), "{}", stderr(&o));
    let applied = report(&out)["models"]["aberration"]["applied"].clone();
    assert_eq!(applied["exact"], false);
    let coma = applied["coefficients"][0]["coma_horizontal"]
        .as_f64()
        .unwrap();
    assert!((coma - 4.8).abs() < 1e-9, "{coma}");
    let residual = applied["residual_rms_rad"][0].as_f64().unwrap();
    assert!(residual > 0.0 && residual < 1.0, "{residual}");
}

#[test]
fn bad_aberration_files_are_refused_naming_the_field_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, String, &str); 6] = [
        (
            "infinite",
            EYE.replace("3.5", "1e999"),
            "aberration profile",
        ),
        (
            "unsorted",
            VARYING.replace("-0.02", "0.03"),
            "sorted by strictly increasing distance_m",
        ),
        ("pitch", VARYING.replace("8e-6", "4e-6"), "pixel_pitch_m"),
        (
            "lasers",
            EYE.replace(
                "\"version\": 1,",
                "\"version\": 1, \"wavelengths_m\": [640e-9, 532e-9, 450e-9],",
            ),
            "wavelengths_m",
        ),
        ("not json", "focus 3".to_string(), "aberration profile"),
        (
            "unknown",
            EYE.replace("\"focus\"", "\"defocus\""),
            "defocus",
        ),
    ];
    for (name, text, says) in cases {
        let file = dir.path().join(format!("{}.json", name.replace(' ', "_")));
        std::fs::write(&file, &text).unwrap();
        let out = dir.path().join(format!("out_{}", name.replace(' ', "_")));
        let o = render(&["--aberration", file.to_str().unwrap()], &out);
        let e = stderr(&o);
        assert!(!o.status.success(), "{name}");
        assert!(e.contains(says), "{name}: {e}");
        assert!(e.contains("--aberration"), "{name}: {e}");
        assert!(!e.contains("panicked"), "{name}: {e}");
        assert!(!out.exists(), "{name}: wrote {}", out.display());
    }

    // The profile's aberration file is missing: named, nothing written.
    let profile = dir.path().join("display.json");
    std::fs::write(
        &profile,
        r#"{"pixel_pitch_m": 8e-6, "resolution": [40, 56], "wavelengths_m": [638e-9, 520e-9, 450e-9],
            "volume_depth_m": 6e-3, "offsets_m": [6e-3], "aberration": "absent.json"}"#,
    )
    .unwrap();
    let out = dir.path().join("out_missing");
    let o = render(&["--display", profile.to_str().unwrap()], &out);
    let e = stderr(&o);
    assert!(!o.status.success());
    assert!(e.contains("absent.json"), "{e}");
    assert!(!out.exists());

    // --prefilter asks for the pre-filter that a correction drops.
    let eye = dir.path().join("eye.json");
    std::fs::write(&eye, EYE).unwrap();
    let out = dir.path().join("out_prefilter");
    let o = render(
        &["--aberration", eye.to_str().unwrap(), "--prefilter"],
        &out,
    );
    assert!(!o.status.success());
    assert!(!out.exists());
}

#[test]
fn a_prescription_from_the_flag_or_the_profile_is_corrected_and_bad_ones_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let flag = dir.path().join("flag");
    let o = render(&["--prescription=-2.00,-0.75,30"], &flag);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&flag);
    let a = &r["models"]["aberration"];
    assert_eq!(a["prescription"]["sphere_d"], -2.0);
    assert_eq!(a["prescription"]["axis_deg"], 30.0);
    assert_eq!(a["prescription"]["eyepiece_focal_m"], 0.021);
    assert_eq!(a["applied"]["exact"], true);
    // Green, 8 µm, 21 mm: k = π·λ·f_e²/(4p²) = 2.8143 rad per dioptre; focus −k·(S + C/2)/2.
    let focus = a["applied"]["coefficients"][1]["focus"].as_f64().unwrap();
    assert!((focus - 2.8143 * 2.375 / 2.0).abs() < 1e-3, "{focus}");

    let profile = dir.path().join("display.json");
    std::fs::write(
        &profile,
        r#"{"pixel_pitch_m": 8e-6, "resolution": [40, 56], "wavelengths_m": [638e-9, 520e-9, 450e-9],
            "volume_depth_m": 6e-3, "offsets_m": [6e-3],
            "prescription": {"sphere_d": -2.0, "cylinder_d": -0.75, "axis_deg": 30}}"#,
    )
    .unwrap();
    let keyed = dir.path().join("keyed");
    let o = render(&["--display", profile.to_str().unwrap()], &keyed);
    assert!(o.status.success(), "{}", stderr(&o));
    let png = |d: &Path| std::fs::read(d.join("phase_g.png")).unwrap();
    assert_eq!(png(&keyed), png(&flag));

    for (value, says) in [
        ("--prescription=-25", "sphere_d"),
        ("--prescription=-2,-1", "3 values"),
        ("--prescription=-2,-1,200", "axis_deg"),
        ("--prescription=two", "SPHERE,CYLINDER,AXIS"),
    ] {
        let out = dir.path().join("bad");
        let o = render(&[value], &out);
        let e = stderr(&o);
        assert!(!o.status.success(), "{value}");
        assert!(e.contains(says), "{value}: {e}");
        assert!(!out.exists(), "{value}");
    }
    let out = dir.path().join("bad");
    let o = render(&["--prescription=-2", "--eyepiece-mm", "0.021"], &out);
    assert!(stderr(&o).contains("eyepiece"), "{}", stderr(&o));
    assert!(!out.exists());
}

/// `holo dataset --display` with a profile's aberration file: the ground truth is the aberration-corrected
/// SM-LBM at the profile's first offset, recorded in the manifest, so that `training/retrain.sh --display FILE`
/// trains for it; the same as `--aberration FILE --offset-mm` given by hand.
#[test]
fn a_dataset_for_a_profile_with_an_aberration_file_is_corrected_for_it() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("optics.json"), VARYING).unwrap();
    let profile = dir.path().join("display.json");
    std::fs::write(
        &profile,
        r#"{"pixel_pitch_m": 8e-6, "resolution": [24, 24], "wavelengths_m": [638e-9, 520e-9, 450e-9],
            "volume_depth_m": 6e-3, "offsets_m": [6e-3], "aberration": "optics.json"}"#,
    )
    .unwrap();
    let dataset = |extra: &[&str], out: &Path| {
        let mut args = ONE_SAMPLE_DATASET.to_vec();
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", out.to_str().unwrap()]);
        holo(&args)
    };
    let keyed = dir.path().join("keyed");
    let o = dataset(&["--display", profile.to_str().unwrap()], &keyed);
    assert!(o.status.success(), "{}", stderr(&o));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(keyed.join("manifest.json")).unwrap())
            .unwrap();
    let recorded = &manifest["synthesis"]["aberration"];
    assert_eq!(recorded["slm_offset_m"], 0.006, "{recorded}");
    assert!(
        recorded["file"].as_str().unwrap().ends_with("optics.json"),
        "{recorded}"
    );

    let by_hand = dir.path().join("by_hand");
    let optics = dir.path().join("optics.json");
    let o = dataset(
        &["--aberration", optics.to_str().unwrap(), "--offset-mm", "6"],
        &by_hand,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let shard = |d: &Path| std::fs::read(d.join("train-00000.npz")).unwrap();
    assert_eq!(shard(&keyed), shard(&by_hand), "the same ground truth");
}

/// `holo render --refine N --aberration FILE`: the refinement's model sees through the viewer's eye, so the
/// refined codes stay corrected (docs/REFINE.md "A viewer's aberration"): the held-out scores (through the same
/// eye) rise from the corrected CNN's, and the refined pattern is not the one refined for an unaberrated viewer.
/// `holo reference --refine` with `--aberration` is refused naming both, nothing written.
#[test]
fn render_refines_for_the_viewer_and_reference_refuses_refine_with_aberration() {
    let dir = tempfile::tempdir().unwrap();
    let eye = dir.path().join("eye.json");
    std::fs::write(&eye, EYE).unwrap();
    let refine = ["--refine", "3", "--refine-levels", "32"];
    let corrected = dir.path().join("corrected");
    let mut args = vec!["--aberration", eye.to_str().unwrap()];
    args.extend_from_slice(&refine);
    let o = render(&args, &corrected);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&corrected);
    assert_eq!(r["models"]["aberration"]["applied"]["exact"], true);
    let held = &r["refine"]["held_out"];
    let (cnn, refined) = (
        held["cnn_codes_psnr_db"].as_f64().unwrap(),
        held["refined_codes_psnr_db"].as_f64().unwrap(),
    );
    assert!(
        refined > cnn,
        "held-out through the eye: CNN {cnn} dB, refined {refined} dB"
    );
    let unaberrated = dir.path().join("unaberrated");
    assert!(render(&refine, &unaberrated).status.success());
    assert_ne!(
        std::fs::read(corrected.join("phase_g.png")).unwrap(),
        std::fs::read(unaberrated.join("phase_g.png")).unwrap()
    );

    let out = dir.path().join("reference");
    let o = holo(&[
        "reference",
        "--size",
        "40x56",
        "--levels",
        "16",
        "--aberration",
        eye.to_str().unwrap(),
        "--refine",
        "2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("--refine") && e.contains("--aberration"), "{e}");
    assert!(!out.exists(), "nothing written");
}
