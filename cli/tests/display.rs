//! `--display FILE` (docs/DISPLAYS.md) through every command that reads a display profile: `render`,
//! `reference`, `dataset` and `calibrate`. A good profile sets the optics, offsets, SLM size and lasers; every
//! bad profile is refused naming its key, before anything is written; a display no shipped model serves is
//! refused naming the colour and saying how to retrain; a widened tolerance is accepted and reported.

mod common;

use common::{holo, png_size, stderr, ONE_SAMPLE_DATASET};

/// A 4 µm SLM at the paper's lasers: the shipped 8 µm models serve it with σ = 0.25.
const GOOD: &str = r#"{
  "name": "4 um LCoS",
  "pixel_pitch_m": 4e-6,
  "resolution": [40, 56],
  "wavelengths_m": [638e-9, 520e-9, 450e-9],
  "volume_depth_m": 1.5e-3,
  "offsets_m": [1.5e-3, 3e-3]
}"#;

/// `GOOD` with `line_key`'s line replaced by `replacement` (a whole `"key": value` or nothing).
fn with(line_key: &str, replacement: &str) -> String {
    GOOD.lines()
        .map(|l| {
            if l.trim_start().starts_with(&format!("\"{line_key}\"")) {
                let comma = if l.trim_end().ends_with(',') && !replacement.is_empty() {
                    ","
                } else {
                    ""
                };
                if replacement.is_empty() {
                    String::new()
                } else {
                    format!("  {replacement}{comma}")
                }
            } else {
                l.to_string()
            }
        })
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join("\n")
}

/// `holo render --size 40x56 --repeat 0 --display PROFILE EXTRA… --out OUT`.
fn render_40x56(profile: &str, extra: &[&str], out: &std::path::Path) -> std::process::Output {
    let mut args = vec![
        "render",
        "--size",
        "40x56",
        "--repeat",
        "0",
        "--display",
        profile,
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", out.to_str().unwrap()]);
    holo(&args)
}

fn report(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

/// Each bad profile, the key its error must name.
fn bad_profiles() -> Vec<(&'static str, String)> {
    let many_offsets = format!(r#""offsets_m": [{}]"#, vec!["1.5e-3"; 65].join(", "));
    // (the key the error names, whose line is replaced by the new line: "" drops it). The bounds below
    // the first block are shared with --size (no terabyte allocation) or stop values that would overflow
    // after the check (σ = ∞ from a huge pitch, NaN holograms from a subnormal one).
    let replaced: [(&'static str, &str); 16] = [
        ("pixel_pitch_m", ""),
        ("pixel_pitch_m", r#""pixel_pitch_m": -4e-6"#),
        ("pixel_pitch_m", r#""pixel_pitch_m": 0"#),
        ("pixel_pitch_m", r#""pixel_pitch_m": 1e999"#),
        ("resolution", r#""resolution": [40, 56, 3]"#),
        ("wavelengths_m", r#""wavelengths_m": [638e-9, 520e-9]"#),
        (
            "wavelengths_m",
            r#""wavelengths_m": [638e-9, 520e-9, 300e-9]"#,
        ),
        ("volume_depth_m", ""),
        ("offsets_m", r#""offsets_m": []"#),
        ("resolution", r#""resolution": [1000000, 1000000]"#),
        ("resolution", r#""resolution": [50000, 50000]"#),
        ("pixel_pitch_m", r#""pixel_pitch_m": 1e308"#),
        ("pixel_pitch_m", r#""pixel_pitch_m": 1e-310"#),
        ("volume_depth_m", r#""volume_depth_m": 1e300"#),
        ("offsets_m", &many_offsets),
        ("offsets_m", r#""offsets_m": [2.0]"#),
    ];
    let mut cases: Vec<(&'static str, String)> = replaced
        .into_iter()
        .map(|(key, line)| (key, with(key, line)))
        .collect();

    cases.extend([
        (
            "pixel_pich_m",
            with("pixel_pitch_m", r#""pixel_pich_m": 4e-6"#),
        ),
        // Strict JSON: the key given twice is named, a top-level array or trailing text is the profile's
        // fault (not `offsets_m`'s), with no internal type names.
        (
            "`resolution` is given twice",
            GOOD.replacen(
                "\"resolution\"",
                "\"resolution\": [8, 8],\n  \"resolution\"",
                1,
            ),
        ),
        ("one JSON object", format!("[{GOOD}]")),
        ("after the profile's closing brace", format!("{GOOD} {{}}")),
        (
            "ends before the profile does",
            GOOD[..GOOD.len() - 3].to_string(),
        ),
    ]);
    cases
}

#[test]
fn every_bad_profile_is_refused_by_every_command_naming_its_key_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    for (i, (key, text)) in bad_profiles().into_iter().enumerate() {
        let profile = dir.path().join(format!("bad{i}.json"));
        std::fs::write(&profile, &text).unwrap();
        let p = profile.to_str().unwrap();
        let out = dir.path().join(format!("out{i}"));
        let o = out.to_str().unwrap();
        let commands: [Vec<&str>; 5] = [
            vec![
                "render",
                "--size",
                "40x56",
                "--repeat",
                "0",
                "--display",
                p,
                "--out",
                o,
            ],
            vec![
                "reference",
                "--size",
                "40x56",
                "--levels",
                "8",
                "--display",
                p,
                "--out",
                o,
            ],
            vec![
                "dataset",
                "--train",
                "1",
                "--val",
                "0",
                "--test",
                "0",
                "--size",
                "32",
                "--levels",
                "8",
                "--display",
                p,
                "--out",
                o,
            ],
            vec!["calibrate", "patterns", "--display", p, "--out", o],
            // --size overrides the resolution, but a bad profile is still refused.
            vec![
                "calibrate",
                "patterns",
                "--size",
                "8x8",
                "--display",
                p,
                "--out",
                o,
            ],
        ];
        for args in commands {
            let r = holo(&args);
            let e = stderr(&r);
            assert!(!r.status.success(), "{args:?} accepted:\n{text}");
            assert!(
                e.contains(key),
                "{args:?}: the error does not name `{key}`:\n{e}\n{text}"
            );
            assert!(
                !e.contains("panicked") && !e.contains("struct ") && !e.contains("tensorholo::"),
                "{args:?}: {e}"
            );
            assert!(!out.exists(), "{args:?} wrote {}", out.display());
        }
    }
}

#[test]
fn reference_dataset_and_calibrate_take_the_profile_and_flags_override_it() {
    let dir = tempfile::tempdir().unwrap();
    let profile = dir.path().join("lcos.json");
    std::fs::write(&profile, GOOD).unwrap();
    let p = profile.to_str().unwrap();

    // reference: the profile's pitch, lasers, volume and first offset; --offset-mm overrides the offset.
    let out = dir.path().join("ref");
    let o = holo(&[
        "reference",
        "--size",
        "24x32",
        "--levels",
        "16",
        "--display",
        p,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&out);
    let synthesis = &r["parameters"]["synthesis"]["setup"];
    assert_eq!(synthesis["pixel_pitch_m"], 4e-6, "{r}");
    assert_eq!(synthesis["volume_depth_m"], 1.5e-3, "{r}");
    assert_eq!(r["parameters"]["offset_m"], 1.5e-3, "{r}");
    assert_eq!(r["display_name"], "4 um LCoS", "{r}");
    let out2 = dir.path().join("ref2");
    let o = holo(&[
        "reference",
        "--size",
        "24x32",
        "--levels",
        "16",
        "--display",
        p,
        "--offset-mm",
        "3",
        "--pitch-m",
        "5e-6",
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&out2);
    assert_eq!(r["parameters"]["offset_m"], 3e-3, "{r}");
    assert_eq!(
        r["parameters"]["synthesis"]["setup"]["pixel_pitch_m"], 5e-6,
        "{r}"
    );

    // dataset: the manifest records the profile beside the optics it synthesised with.
    let data = dir.path().join("data");
    let mut args = ONE_SAMPLE_DATASET.to_vec();
    args.extend_from_slice(&["--display", p, "--out", data.to_str().unwrap()]);
    let o = holo(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("manifest.json")).unwrap())
            .unwrap();
    assert_eq!(m["optics"]["pixel_pitch_m"], 4e-6, "{m}");
    assert_eq!(m["optics"]["volume_depth_m"], 1.5e-3, "{m}");
    assert_eq!(m["display"]["name"], "4 um LCoS", "{m}");
    assert_eq!(
        m["display"]["slm_resolution"],
        serde_json::json!([40, 56]),
        "{m}"
    );
    assert_eq!(
        m["display"]["offsets_m"],
        serde_json::json!([1.5e-3, 3e-3]),
        "{m}"
    );
    assert_eq!(m["display"]["file"], p, "{m}");

    // calibrate patterns: the SLM size is the profile's resolution unless --size is given.
    let pat = dir.path().join("patterns");
    let o = holo(&[
        "calibrate",
        "patterns",
        "--display",
        p,
        "--out",
        pat.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(png_size(&pat.join("pattern_007.png")), (56, 40));
    let pat2 = dir.path().join("patterns2");
    let o = holo(&[
        "calibrate",
        "patterns",
        "--display",
        p,
        "--size",
        "8x12",
        "--out",
        pat2.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(png_size(&pat2.join("pattern_007.png")), (12, 8));
    // Without --size or --display: a clear error.
    let o = holo(&[
        "calibrate",
        "patterns",
        "--out",
        dir.path().join("p3").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--size HEIGHTxWIDTH or --display"),
        "{}",
        stderr(&o)
    );
}

/// A profile of an 8 µm SLM with lasers 638/`green`/450 nm, its volume and offset at the common `σ`.
fn green_profile(dir: &std::path::Path, green_nm: f64) -> std::path::PathBuf {
    let (sg, sr): (f64, f64) = (520.0 / green_nm, 1.0);
    let sigma = (sg.min(sr) * sg.max(sr)).sqrt();
    let text = format!(
        r#"{{"pixel_pitch_m": 8e-6, "resolution": [40, 56], "wavelengths_m": [638e-9, {}e-9, 450e-9],
            "volume_depth_m": {}, "offsets_m": [{}]}}"#,
        green_nm,
        6e-3 * sigma,
        6e-3 * sigma
    );
    let profile = dir.join(format!("green{green_nm}.json"));
    std::fs::write(&profile, text).unwrap();
    profile
}

#[test]
fn lasers_are_served_by_cost_and_a_refusal_names_what_would_serve() {
    let dir = tempfile::tempdir().unwrap();
    let render = render_40x56;
    // The most common green laser, 532 nm, beside 638/450 nm: 1.15 % off, served by the rule at a cost far
    // under 0.3 dB, and the report says so.
    let g532 = green_profile(dir.path(), 532.0);
    let out = dir.path().join("r532");
    let r = render(g532.to_str().unwrap(), &[], &out);
    assert!(r.status.success(), "{}", stderr(&r));
    let mapping = report(&out)["models"]["display_mapping"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert!(mapping.contains("the rule's"), "{mapping}");
    assert!(mapping.contains("wavelength mismatch 1.1"), "{mapping}");
    assert!(mapping.contains("estimated cost 0.1"), "{mapping}");

    // A green 8 % off 520 nm costs more than the rule allows: refused, naming green and, in order, the
    // nearest profile that serves (valid JSON), the tolerance that serves it with its cost, retraining.
    let g561 = green_profile(dir.path(), 561.6);
    let p = g561.to_str().unwrap();
    let out = dir.path().join("r561");
    let r = render(p, &[], &out);
    let e = stderr(&r);
    assert!(!r.status.success());
    assert!(e.contains("green"), "{e}");
    assert!(!out.exists());
    let steps: Vec<usize> = [
        "\n1. the nearest display",
        "\n2. --wavelength-ratio-tolerance",
        "\n3. retrain for it",
    ]
    .iter()
    .map(|s| e.find(s).unwrap_or_else(|| panic!("{s:?} missing: {e}")))
    .collect();
    assert!(steps.windows(2).all(|w| w[0] < w[1]), "{e}");
    assert!(
        e.contains(&format!("training/retrain.sh --display {p} --out")),
        "{e}"
    );
    let json_start = e[steps[0]..].find('{').unwrap() + steps[0];
    let json_end = e[json_start..].find("\n}").unwrap() + json_start + 2;
    let nearest = dir.path().join("nearest.json");
    std::fs::write(&nearest, &e[json_start..json_end]).unwrap();
    let r = render(nearest.to_str().unwrap(), &[], &dir.path().join("rn"));
    assert!(r.status.success(), "the nearest profile: {}", stderr(&r));
    let tolerance = e[steps[1]..].split_whitespace().nth(2).unwrap().to_string();
    let out = dir.path().join("rw");
    let r = render(
        p,
        &[
            "--wavelength-ratio-tolerance",
            &tolerance,
            "--evaluate",
            "--levels",
            "64",
        ],
        &out,
    );
    assert!(r.status.success(), "{}", stderr(&r));
    let rep = report(&out);
    let mapping = rep["models"]["display_mapping"]
        .as_str()
        .unwrap_or_default();
    assert!(mapping.contains("widened"), "{rep}");
    // The mismatch's cost: a perfect 520 nm model shown with this green laser, well above the CNN's own
    // error and near the predicted ceiling (docs/DISPLAYS.md).
    let ceiling = rep["evaluation"]["mapping_ceiling"]["psnr_fs"]
        .as_f64()
        .unwrap_or(0.0);
    assert!((25.0..40.0).contains(&ceiling), "{rep}");

    let p = g532.to_str().unwrap();
    // calibrate global stores the profile's lasers: render accepts the file for this display, and refuses
    // one whose lasers --wavelengths-m set to the paper's (12 nm off in green).
    for (name, extra, accepted) in [
        ("g532.holocal", None, true),
        ("g520.holocal", Some("6.38e-7,5.2e-7,4.5e-7"), false),
    ] {
        let cal = dir.path().join(name);
        let mut args = vec![
            "calibrate",
            "global",
            "--display",
            p,
            "--range-rad",
            "6.2",
            "--gamma",
            "1",
            "--out",
        ];
        let cal_text = cal.to_str().unwrap().to_string();
        args.push(&cal_text);
        if let Some(w) = extra {
            args.extend(["--wavelengths-m", w]);
        }
        let c = holo(&args);
        assert!(c.status.success(), "{}", stderr(&c));
        let out_cal = dir.path().join(format!("r_{name}"));
        let r = render_40x56(p, &["--calibration", &cal_text], &out_cal);
        assert_eq!(r.status.success(), accepted, "{name}: {}", stderr(&r));
    }
}

/// The repository's `displays/*.json`, the worked examples of docs/DISPLAYS.md.
fn shipped_display(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../displays")
        .join(name)
}

#[test]
fn the_shipped_display_profiles_render_the_paper_display_codes() {
    // Every Fresnel-equivalent display of displays/ shows the paper display's SLM codes, each within one
    // step of the 8 µm run (`holo compare` fails on any code off by more; about 1 % differ by one step, from
    // rounding in the offset propagation at the other pitch).
    let dir = tempfile::tempdir().unwrap();
    let render = |name: &str| {
        let out = dir.path().join(name);
        let o = holo(&[
            "render",
            "--size",
            "96x128",
            "--repeat",
            "0",
            "--display",
            shipped_display(name).to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        (out, report(&dir.path().join(name)))
    };
    let (paper, r) = render("pluto-8um.json");
    assert!(
        r["models"]["display_mapping"]
            .as_str()
            .unwrap_or_default()
            .contains("σ = 1.000000"),
        "{r}"
    );
    for (name, pitch, volume) in [
        ("lcos-3.74um-4k.json", "3.74 µm", "1.3113375 mm volume"),
        ("slm-4um.json", "4 µm", "1.5 mm volume"),
        ("slm-6.4um.json", "6.4 µm", "3.84 mm volume"),
    ] {
        let (out, r) = render(name);
        let mapping = r["models"]["display_mapping"].as_str().unwrap_or_default();
        assert!(
            mapping.contains(&format!("serves {pitch} with a {volume}")),
            "{name}: {mapping}"
        );
        let c = holo(&[
            "compare",
            paper.to_str().unwrap(),
            out.to_str().unwrap(),
            "--max-code-fraction",
            "0.05",
        ]);
        assert!(
            c.status.success(),
            "{name}: {}{}",
            stderr(&c),
            String::from_utf8_lossy(&c.stdout)
        );
    }
}

/// The issue's three lab profiles are served (exit 0), each row saying how; a volume deeper than the models
/// serve exits 1 naming the largest served; a bad profile exits 2.
#[test]
fn display_check_serves_the_lab_profiles_and_exits_for_scripts() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, pitch: f64, green: f64, volume: f64, offset: f64| {
        let path = dir.path().join(name);
        std::fs::write(
            &path,
            format!(
                r#"{{"name": "{name}", "pixel_pitch_m": {pitch}, "resolution": [2160, 3840],
                    "wavelengths_m": [638e-9, {green}, 450e-9], "volume_depth_m": {volume},
                    "offsets_m": [{offset}, 0.0]}}"#
            ),
        )
        .unwrap();
        path
    };
    let s374 = (3.74f64 / 8.0).powi(2);
    let s532 = (520.0f64 / 532.0).sqrt() * s374;
    let lab = [
        // 3.74 µm with a 532 nm green laser (volume and the 6 mm pre-filter's offset at the common σ).
        write("g532", 3.74e-6, 532e-9, 6e-3 * s532, 6e-3 * s532),
        // The same SLM with a rounded 1.3 mm volume (σ·6 mm = 1.3113 mm) and its 6 mm pre-filter's offset.
        write("round", 3.74e-6, 520e-9, 1.3e-3, 6e-3 * s374),
        // A 12.5 µm SLM with a 12 mm volume, inside the 14.65 mm it maps.
        write("deep", 12.5e-6, 520e-9, 12e-3, 0.0),
    ];
    for p in &lab {
        let o = holo(&["display", "check", p.to_str().unwrap()]);
        let out = String::from_utf8_lossy(&o.stdout).into_owned();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{}: {out}{}",
            p.display(),
            stderr(&o)
        );
        assert!(out.contains("| holo8_rgbd.onnx | f32 | yes |"), "{out}");
    }
    // JSON for scripts: every hologram CNN served, the 532 nm row with its cost.
    let o = holo(&["display", "check", lab[0].to_str().unwrap(), "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["served"], true);
    let cost = v["checks"][0]["mapping"]["cost_db"].as_f64().unwrap();
    assert!(cost > 0.0 && cost < 0.3, "{cost}");
    // Too deep: exit 1, naming the key and the largest volume served.
    let too_deep = write("too_deep", 12.5e-6, 520e-9, 15e-3, 0.0);
    let o = holo(&["display", "check", too_deep.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains("volume_depth_m") && out.contains("up to 14.7949219 mm"),
        "{out}"
    );
    assert!(out.contains("1. the nearest display"), "{out}");
    // A bad profile: a usage error.
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"pixel_pitch_m": -1}"#).unwrap();
    let o = holo(&["display", "check", bad.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

/// The predicted mapping ceiling (report.json → display_mapping_detail) against `--evaluate`'s measured one,
/// three laser mismatches: the slope (6 dB per doubling of the spread) within 0.3 dB, and the level within
/// 4.5 dB at this size. The prediction is the 384² fit of docs/DISPLAYS.md; a smaller frame measures a lower
/// ceiling (96×128 with 256 planes: 4.0–4.1 dB lower; 192²: 1.5 dB; 384²: within 0.3 dB).
#[test]
fn the_predicted_ceiling_agrees_with_the_measured_one() {
    let dir = tempfile::tempdir().unwrap();
    let mut pairs = Vec::new();
    for green in [525.2, 530.4, 540.8] {
        let p = green_profile(dir.path(), green);
        let out = dir.path().join(format!("r{green}"));
        let o = holo(&[
            "render",
            "--size",
            "96x128",
            "--repeat",
            "0",
            "--display",
            p.to_str().unwrap(),
            "--evaluate",
            "--levels",
            "256",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let rep = report(&out);
        let measured = rep["evaluation"]["mapping_ceiling"]["psnr_fs"]
            .as_f64()
            .unwrap();
        let predicted = rep["models"]["display_mapping_detail"]["ceiling_db"]
            .as_f64()
            .unwrap();
        assert!(
            (measured - predicted).abs() <= 4.5,
            "green {green} nm: measured {measured:.2} dB, predicted {predicted:.2} dB"
        );
        pairs.push((predicted, measured));
    }
    for w in pairs.windows(2) {
        let (dp, dm) = (w[0].0 - w[1].0, w[0].1 - w[1].1);
        assert!(
            (dp - dm).abs() <= 0.3,
            "slope: predicted {dp:.2} dB, measured {dm:.2} dB"
        );
    }
}

/// The profile is read once, so `--display /dev/stdin` (a pipe) works; a device that never ends is refused
/// naming it, before anything is read; a byte-order mark is accepted.
#[cfg(unix)]
#[test]
fn a_profile_is_read_once_bounded_and_may_start_with_a_bom() {
    use std::io::Write;
    use std::process::{Command, Stdio};
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("stdin");
    let mut child = Command::new(env!("CARGO_BIN_EXE_holo"))
        .args([
            "render",
            "--size",
            "40x56",
            "--repeat",
            "0",
            "--display",
            "/dev/stdin",
        ])
        .args(["--out", out.to_str().unwrap()])
        .stdin(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(GOOD.as_bytes())
        .unwrap();
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(report(&out)["pipeline"]["optics"]["pixel_pitch_m"], 4e-6);
    assert_eq!(report(&out)["pipeline"]["offset_m"], 1.5e-3);

    for device in ["/dev/zero", "/dev/urandom"] {
        let out = dir.path().join("device");
        let t = std::time::Instant::now();
        let o = render_40x56(device, &[], &out);
        let e = stderr(&o);
        assert!(!o.status.success());
        assert!(e.contains(device) && e.contains("device"), "{e}");
        assert!(t.elapsed().as_secs() < 30, "{device}: {:?}", t.elapsed());
        assert!(!out.exists());
    }

    let bom = dir.path().join("bom.json");
    std::fs::write(&bom, format!("\u{feff}{GOOD}")).unwrap();
    let out = dir.path().join("bom");
    let o = render_40x56(bom.to_str().unwrap(), &[], &out);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// A 4 µm display at `--offset-mm 6` (the paper's offset, too far for the paraxial mapping here) is told the
/// offsets the shipped pre-filters serve on it, not only to retrain; the metres' number given to
/// `--offset-mm` is caught.
#[test]
fn an_offset_in_the_wrong_units_or_too_far_names_the_offsets_that_serve() {
    let dir = tempfile::tempdir().unwrap();
    let profile = dir.path().join("p4.json");
    std::fs::write(&profile, GOOD).unwrap();
    let p = profile.to_str().unwrap();
    let out = dir.path().join("out");
    let r = render_40x56(p, &["--offset-mm", "6"], &out);
    let e = stderr(&r);
    assert!(!r.status.success());
    assert!(
        e.contains("--offset-mm 1.5 (the 6 mm pre-filter) or --offset-mm 3 (the 12 mm pre-filter), not 6 mm"),
        "{e}"
    );
    assert!(!out.exists());
    let r = render_40x56(p, &["--offset-mm", "0.0015"], &out);
    let e = stderr(&r);
    assert!(e.contains("its 0.0015 m is --offset-mm 1.5"), "{e}");
}
