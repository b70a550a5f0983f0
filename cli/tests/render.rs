//! End-to-end tests of `holo render`, `holo video` and `holo bench` with the shipped (embedded) models.

mod common;

use common::{holo, shared, stderr};

fn report(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

#[test]
fn render_runs_the_shipped_model_on_the_built_in_scene_and_evaluates_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r");
    let o = holo(&[
        "render",
        "--size",
        "48x64",
        "--repeat",
        "1",
        "--evaluate",
        "--levels",
        "128",
        "--prefilter",
        "--save-cnn-input",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "cnn_input.npy",
        "phase_r.png",
        "phase_g.png",
        "phase_b.png",
        "midpoint.npy",
        "focus_near.png",
        "focus_mid.png",
        "focus_far.png",
        "target.png",
        "depth.png",
        "report.json",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let r = report(&out);
    assert_eq!(r["models"]["hologram_cnn"]["layers"], 8);
    assert_eq!(r["models"]["prefilter_cnn"]["offset_m"], 0.006);
    // The CNN's input: R, G, B amplitude (the report's scene means) then depth in [0, 1].
    let x: ndarray::Array3<f32> = ndarray_npy::read_npy(out.join("cnn_input.npy")).unwrap();
    assert_eq!(x.shape(), &[4, 48, 64]);
    let means = r["statistics"]["scene_mean_amplitude_rgb"]
        .as_array()
        .unwrap();
    assert_eq!(means.len(), 3);
    for (c, want) in means.iter().enumerate() {
        let m = x.index_axis(ndarray::Axis(0), c).mean().unwrap() as f64;
        assert!(
            (m - want.as_f64().unwrap()).abs() < 1e-5,
            "channel {c}: {m}"
        );
    }
    let d = x.index_axis(ndarray::Axis(0), 3);
    assert!(d.iter().all(|v| (0.0..=1.0).contains(v)));
    assert!(d.iter().fold(0f32, |a, &v| a.max(v)) - d.iter().fold(1f32, |a, &v| a.min(v)) > 0.5);
    assert!(r["timings_s"]["median"]["cnn_s"].as_f64().unwrap() > 0.0);
    assert!(r["timings_s"]["median"]["prefilter_s"].as_f64().unwrap() > 0.0);
    let ev = &r["evaluation"];
    assert_eq!(ev["focal_depths"].as_array().unwrap().len(), 20);
    for key in ["cnn_midpoint", "displayed"] {
        let p = ev[key]["psnr_fs"].as_f64().unwrap();
        let s = ev[key]["ssim_fs"].as_f64().unwrap();
        assert!(
            (10.0..60.0).contains(&p) && (0.0..=1.0).contains(&s),
            "{key}: {p} dB, {s}"
        );
    }

    // Without the pre-filter, at 0 mm: AA-DPM, no pre-filter time.
    let out0 = dir.path().join("r0");
    let o = holo(&[
        "render",
        "--size",
        "32x32",
        "--repeat",
        "1",
        "--offset-mm",
        "0",
        "--layers",
        "15",
        "--int8",
        "--out",
        out0.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&out0);
    assert_eq!(r["models"]["hologram_cnn"]["layers"], 15);
    assert!(r["models"]["prefilter_cnn"].is_null());
    assert_eq!(r["timings_s"]["median"]["prefilter_s"], 0.0);
    assert_eq!(r["pipeline"]["encoding"]["method"], "anti-aliased");

    // At 6 mm each CNN runs by default with the shipped pre-filter trained on its own holograms; --no-prefilter
    // or an explicit --encoding selects a non-learned encoding.
    for (k, (extra, prefilter, method)) in [
        (&[][..], true, "plain"),
        (&["--no-prefilter"][..], false, "anti-aliased"),
        (&["--encoding", "bl-dpm"][..], false, "band-limited"),
        (&["--layers", "30"][..], true, "plain"),
        (&["--layers", "15", "--prefilter"][..], true, "plain"),
    ]
    .into_iter()
    .enumerate()
    {
        let o6 = dir.path().join(format!("r6_{k}"));
        let mut cmd = vec![
            "render",
            "--size",
            "32x32",
            "--repeat",
            "1",
            "--out",
            o6.to_str().unwrap(),
        ];
        cmd.extend_from_slice(extra);
        let o = holo(&cmd);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        let r = report(&o6);
        assert_eq!(
            !r["models"]["prefilter_cnn"].is_null(),
            prefilter,
            "{extra:?}"
        );
        assert_eq!(r["models"]["encoding"]["method"], method, "{extra:?}");
        if prefilter {
            // Trained with the CNN it runs with.
            let layers = r["models"]["hologram_cnn"]["layers"].clone();
            assert_eq!(
                r["models"]["prefilter_cnn"]["hologram_layers"], layers,
                "{extra:?}"
            );
        }
    }
}

#[test]
fn render_refuses_bad_models_and_options_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x");
    let corrupt = dir.path().join("corrupt.onnx");
    std::fs::write(&corrupt, b"definitely not a protobuf").unwrap();
    let o = holo(&[
        "render",
        "--model",
        corrupt.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("cannot load model"), "{}", stderr(&o));

    // Each refused clearly: an unshipped depth; --prefilter where no pre-filter is shipped; --prefilter
    // (DDPM) together with --encoding (a non-learned encoding).
    let refusals: [(&[&str], &str); 3] = [
        (&["--layers", "12"], "8, 15 or 30"),
        (&["--offset-mm", "3", "--prefilter"], "pre-filter"),
        (
            &["--prefilter", "--encoding", "aa-dpm"],
            "cannot be used with",
        ),
    ];
    for (args, message) in refusals {
        let mut cmd = vec!["render", "--out", out.to_str().unwrap()];
        cmd.extend_from_slice(args);
        let o = holo(&cmd);
        assert!(!o.status.success(), "{args:?}");
        assert!(stderr(&o).contains(message), "{args:?}: {}", stderr(&o));
    }
}

/// `holo video` of the mm16 frames in `rgb` and `depth` at `size` into `out`, with `extra` flags.
fn video(
    rgb: &std::path::Path,
    depth: &std::path::Path,
    size: &str,
    extra: &[&str],
    out: &std::path::Path,
) -> std::process::Output {
    let mut args = vec![
        "video",
        "--rgb-dir",
        rgb.to_str().unwrap(),
        "--depth-dir",
        depth.to_str().unwrap(),
        "--depth-encoding",
        "mm16",
        "--size",
        size,
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", out.to_str().unwrap()]);
    holo(&args)
}

#[test]
fn video_streams_the_redwood_sequence_and_matches_single_frames() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("v");
    let rgb = shared("redwood_livingroom_seq/color");
    let depth = shared("redwood_livingroom_seq/depth");
    let o = video(&rgb, &depth, "48x64", &["--save-frames"], &out);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&out);
    assert_eq!(r["frames"], 5);
    assert_eq!(r["stream_equals_single_frame"], true);
    assert!(r["fps_overall"].as_f64().unwrap() > 0.0);
    // One metric range for the whole sequence, from the first frame.
    let range = r["depth_range_m"].as_array().unwrap();
    assert!(range[0].as_f64().unwrap() < range[1].as_f64().unwrap());
    assert!(out.join("frames/00004_phase_b.png").exists());
    // Consecutive frames of a moving camera differ.
    let a = std::fs::read(out.join("frames/00000_phase_g.png")).unwrap();
    let b = std::fs::read(out.join("frames/00004_phase_g.png")).unwrap();
    assert_ne!(a, b);
    // The temporal numbers: a churn per transition, none for the first frame.
    let t = &r["temporal"];
    assert_eq!(t["transitions"], 4, "{t}");
    let churn = t["mean_churn_rad"].as_f64().unwrap();
    assert!(churn > 0.0 && churn < std::f64::consts::PI, "{t}");
    assert!(r["per_frame"][0]["temporal"].is_null());
    assert!(r["per_frame"][1]["temporal"]["churn_rad"].as_f64().unwrap() > 0.0);

    // --align-phase: each colour's codes are the unaligned ones shifted by the reported whole number of codes
    // (a global phase: the same displayed intensity), and the churn does not rise (the double phase encoding
    // already subtracts each frame's mean phase: on this sequence every shift is 0, docs/VIDEO.md).
    let aligned = dir.path().join("aligned");
    let o = video(
        &rgb,
        &depth,
        "48x64",
        &["--save-frames", "--align-phase"],
        &aligned,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let ra = report(&aligned);
    let aligned_churn = ra["temporal"]["mean_churn_rad"].as_f64().unwrap();
    assert!(aligned_churn <= churn, "aligned {aligned_churn} vs {churn}");
    let codes =
        |d: &std::path::Path, f: &str| image::open(d.join("frames").join(f)).unwrap().to_luma8();
    let mut total: [u8; 3] = [0; 3];
    for i in 1..5 {
        let shifts = &ra["per_frame"][i]["temporal"]["aligned_shift_codes"];
        for (c, ch) in ["r", "g", "b"].iter().enumerate() {
            total[c] = total[c].wrapping_add(shifts[c].as_u64().unwrap() as u8);
            let f = format!("{i:05}_phase_{ch}.png");
            let (plain, moved) = (codes(&out, &f), codes(&aligned, &f));
            assert!(
                plain
                    .iter()
                    .zip(moved.iter())
                    .all(|(&p, &m)| p.wrapping_add(total[c]) == m),
                "frame {i} {ch}: not a shift by {}",
                total[c]
            );
        }
    }

    // A still scene (one frame three times): no churn at all.
    let (still_rgb, still_depth) = (dir.path().join("rgb"), dir.path().join("depth"));
    std::fs::create_dir_all(&still_rgb).unwrap();
    std::fs::create_dir_all(&still_depth).unwrap();
    for k in 0..3 {
        std::fs::copy(rgb.join("00000.jpg"), still_rgb.join(format!("{k:02}.jpg"))).unwrap();
        std::fs::copy(
            depth.join("00000.png"),
            still_depth.join(format!("{k:02}.png")),
        )
        .unwrap();
    }
    let still = dir.path().join("still");
    let o = video(&still_rgb, &still_depth, "48x64", &[], &still);
    assert!(o.status.success(), "{}", stderr(&o));
    let rs = report(&still);
    assert_eq!(rs["temporal"]["max_churn_rad"], 0.0, "{}", rs["temporal"]);
    assert_eq!(rs["temporal"]["max_above_half_pi"], 0.0);
}

/// `holo bench --refine N`: one row per size × backend × threads with the target's and the iterations' time, and
/// a positive gain at the held-out planes (the refinement improves the CNN's codes where the loss never looked,
/// docs/REFINE.md); the JSON holds the same figures.
#[test]
fn bench_refine_times_the_refinement_and_reports_its_held_out_gain() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("bench.json");
    let o = holo(&[
        "bench",
        "--skip-cnn",
        "--skip-pipeline",
        "--refine",
        "3",
        "--sizes",
        "48x64",
        "--threads",
        "1",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        table
            .lines()
            .filter(|l| l.starts_with("| 48x64 | cpu | 1 |"))
            .count(),
        1,
        "{table}"
    );
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let rows: Vec<&serde_json::Value> = r["results"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|x| x["kind"] == "refine")
        .collect();
    assert_eq!(rows.len(), 1, "{r}");
    let row = rows[0];
    assert_eq!(row["iterations"], 3, "{row}");
    assert!(row["target_s"].as_f64().unwrap() > 0.0, "{row}");
    assert!(row["iterations_s"].as_f64().unwrap() > 0.0, "{row}");
    assert!(row["gain_db"].as_f64().unwrap() > 0.0, "{row}");
    // Without --refine there is no such table.
    let o = holo(&["bench", "--skip-cnn", "--skip-pipeline"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!String::from_utf8_lossy(&o.stdout).contains("Refinement"));
}

#[test]
fn bench_prints_a_row_per_case() {
    let o = holo(&[
        "bench",
        "--sizes",
        "24x32",
        "--layers",
        "8",
        "--precision",
        "f32,int8-qop",
        "--threads",
        "1",
        "--repeat",
        "1",
        "--layout",
        "nchw,nhwc",
        "--profile",
        "--peak",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8_lossy(&o.stdout);
    // Timing rows (CNN and pipeline tables) have a number after the thread count; profile rows an operator.
    let rows = |prefix: &str| {
        table
            .lines()
            .filter(|l| l.starts_with(prefix))
            .filter(|l| {
                l.split('|')
                    .nth(6)
                    .is_some_and(|f| f.trim().parse::<f64>().is_ok())
            })
            .count()
    };
    // CNN table: the native engine (f32 only) and tract in both layouts for f32, channels-first only for
    // int8-qop (tract cannot move QLinearConv). Pipeline table: the first --engine (native) for f32, tract
    // for int8. The profile table has one row per tract operator kind of each tract CNN case.
    assert_eq!(rows("| holo8 | f32 | native | conv3x3.f32."), 1, "{table}");
    assert_eq!(
        rows("| holo8 | f32 | tract | nchw | 24x32 | 1 | "),
        1,
        "{table}"
    );
    assert_eq!(
        rows("| holo8 | f32 | tract | nhwc | 24x32 | 1 | "),
        1,
        "{table}"
    );
    assert_eq!(
        rows("| holo8 | int8-qop | tract | nchw | 24x32 | 1 | "),
        1,
        "{table}"
    );
    assert_eq!(rows("| holo8 | int8-qop | native"), 0, "{table}");
    assert_eq!(rows("| holo8 | int8-qop | tract | nhwc |"), 0, "{table}");
    assert_eq!(rows("| holo8 | f32 | native conv3x3.f32."), 1, "{table}");
    assert_eq!(
        rows("| holo8 | int8-qop | tract nchw | 24x32 | 1 | "),
        1,
        "{table}"
    );
    assert!(table.contains("Time per tract operator"), "{table}");
    assert!(
        table.contains("| holo8 | f32 | nhwc | 24x32 | 1 | Pad | 8 |"),
        "{table}"
    );
    assert!(
        // 7 QLinearConv: the QOperator file keeps its last convolution float (export.py).
        table.contains("| holo8 | int8-qop | nchw | 24x32 | 1 | Im2col | 7 |"),
        "{table}"
    );
    assert!(table.contains("Peak resident memory"), "{table}");
    // --peak: the measured peaks, and each CNN row's share of the f32 one.
    assert!(table.contains("peak, 1 thread(s): f32 "), "{table}");
    let share = table
        .lines()
        .find(|l| l.starts_with("| holo8 | f32 | native |"))
        .and_then(|l| l.split('|').nth(10))
        .map(|f| f.trim().to_string());
    assert!(
        share.as_deref().is_some_and(|f| f.ends_with(" %")),
        "{table}"
    );
}

/// `holo compare` finds nothing between two runs of one command, and exactly the SLM code moved by hand
/// (cyclically: 255 → 0 is one step, 0 → 2 two); `--max-code-fraction` turns that into a failure.
#[test]
fn compare_reports_exactly_the_codes_that_differ() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    for dir in [&a, &b] {
        let o = holo(&[
            "render",
            "--size",
            "32x48",
            "--threads",
            "1",
            // The plan table decides everything else: two processes give the same bits.
            "--repeat",
            "0",
            "--out",
            dir.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let run = |extra: &[&str]| {
        let mut args = vec!["compare", a.to_str().unwrap(), b.to_str().unwrap()];
        args.extend_from_slice(extra);
        holo(&args)
    };
    let o = run(&["--max-code-fraction", "0"]);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{text}{}", stderr(&o));
    assert!(text.contains("max |Δ| / max |h| = 0.00e0"), "{text}");
    assert_eq!(
        text.matches("0 of 1536 differ, by at most 0").count(),
        3,
        "{text}"
    );

    // Move code (0, 0) of the green pattern by one step across the wrap, and (1, 0) by two.
    let green = b.join("phase_g.png");
    let mut img = image::open(&green).unwrap().into_luma8();
    let p = img.get_pixel(0, 0)[0];
    img.put_pixel(0, 0, image::Luma([p.wrapping_add(1)]));
    let q = img.get_pixel(1, 0)[0];
    img.put_pixel(1, 0, image::Luma([q.wrapping_sub(2)]));
    img.save(&green).unwrap();
    let o = run(&[]);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{text}");
    assert!(
        text.contains("phase_g.png: 2 of 1536 differ, by at most 2"),
        "{text}"
    );
    let o = run(&["--max-code-fraction", "0.01"]);
    assert!(!o.status.success(), "a 2-step code must fail");
    assert!(stderr(&o).contains("by more than 1 (2)"), "{}", stderr(&o));

    // A NaN in one midpoint hologram is a difference, reported as such, whatever the codes say.
    let mid = b.join("midpoint.npy");
    let mut field = tensorholo::io::read_complex_npy(&mid).unwrap();
    field[[1, 2, 3]] = num_complex::Complex32::new(f32::NAN, 0.0);
    tensorholo::io::write_complex_npy(&mid, field.view()).unwrap();
    let o = run(&[]);
    assert!(!o.status.success(), "NaN must fail the comparison");
    assert!(
        stderr(&o).contains("NaN or infinite values (0 in") && stderr(&o).contains("1 in"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn an_ldi_exported_by_holo_dataset_renders_with_the_ldi_cnn_and_is_refused_when_bad() {
    let dir = tempfile::tempdir().unwrap();
    let ldi = dir.path().join("ldi");
    let o = holo(&[
        "dataset",
        "--out",
        ldi.to_str().unwrap(),
        "--export-ldi",
        "test:1",
        "--size",
        "48x64",
        "--seed",
        "5",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(ldi.join("ldi.json")).unwrap()).unwrap();
    assert_eq!(meta["layers"], 5);
    assert_eq!(meta["depth_encoding"], "relative16");
    assert_eq!(meta["sample"]["split"], "test");
    for k in 0..5 {
        for f in [format!("rgb_{k}.png"), format!("depth_{k}.png")] {
            assert!(ldi.join(&f).exists(), "{f} missing");
        }
    }
    // An index outside the split is refused before anything is written.
    let o = holo(&[
        "dataset",
        "--out",
        dir.path().join("none").to_str().unwrap(),
        "--export-ldi",
        "val:2",
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("the val split has 2 samples"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.path().join("none").exists());
    // Nor is an LDI written into a dataset's folder (a likely slip: --out pointed at the dataset).
    let dataset = dir.path().join("dataset");
    std::fs::create_dir(&dataset).unwrap();
    std::fs::write(dataset.join("manifest.json"), "{}").unwrap();
    let o = holo(&[
        "dataset",
        "--out",
        dataset.to_str().unwrap(),
        "--export-ldi",
        "test:0",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("holds a dataset"), "{}", stderr(&o));
    assert_eq!(std::fs::read_dir(&dataset).unwrap().count(), 1);

    let out = dir.path().join("r");
    let o = holo(&[
        "render",
        "--ldi",
        ldi.to_str().unwrap(),
        "--depth-encoding",
        "relative16",
        "--repeat",
        "0",
        "--evaluate",
        "--levels",
        "128",
        "--save-cnn-input",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&out);
    assert_eq!(r["input"]["kind"], "ldi-folder");
    assert_eq!(r["input"]["ldi_report"]["valid_fraction"][0], 1.0);
    assert_eq!(r["models"]["hologram_cnn"]["input_layers"], 5);
    // The LDI CNN's input: 5 layers of R, G, B, depth; where a back layer holds no point, amplitude 0 and
    // depth 1 (docs/CONVENTIONS.md §7), as often as the report's valid fractions say.
    let x: ndarray::Array3<f32> = ndarray_npy::read_npy(out.join("cnn_input.npy")).unwrap();
    assert_eq!(x.shape(), &[20, 48, 64]);
    for k in 1..5 {
        let empty = ndarray::Zip::from(x.index_axis(ndarray::Axis(0), 4 * k))
            .and(x.index_axis(ndarray::Axis(0), 4 * k + 3))
            .fold(0usize, |n, &a, &d| n + usize::from(a == 0.0 && d == 1.0));
        let valid = r["input"]["ldi_report"]["valid_fraction"][k]
            .as_f64()
            .unwrap();
        assert!(
            (empty as f64 / (48.0 * 64.0) - (1.0 - valid)).abs() < 0.02,
            "layer {k}: {empty} empty pixels, valid fraction {valid}"
        );
    }
    let ev = &r["evaluation"];
    assert!(ev["ground_truth"]["method"]
        .as_str()
        .unwrap()
        .contains("every layer"));
    let p = ev["cnn_midpoint"]["psnr_amp"].as_f64().unwrap();
    assert!((15.0..60.0).contains(&p), "{p} dB");

    // The same folder as an SM-LBM reference.
    let o = holo(&[
        "reference",
        "--ldi",
        ldi.to_str().unwrap(),
        "--depth-encoding",
        "relative16",
        "--levels",
        "64",
        "--out",
        dir.path().join("ref").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));

    // Refused: no encoding; an LDI CNN depth that is not shipped.
    let bad_out = dir.path().join("bad");
    let bad = |extra: &[&str]| {
        let mut a = vec!["render", "--ldi", ldi.to_str().unwrap(), "--repeat", "0"];
        a.extend_from_slice(extra);
        a.extend_from_slice(&["--out", bad_out.to_str().unwrap()]);
        let o = holo(&a);
        assert!(!o.status.success());
        stderr(&o)
    };
    assert!(bad(&[]).contains("needs --depth-encoding"), "{}", bad(&[]));
    let e = bad(&["--depth-encoding", "relative16", "--layers", "30"]);
    assert!(e.contains("ldi hologram CNNs have [8] layers"), "{e}");
}

#[test]
fn render_reads_a_display_profile_and_refuses_a_bad_one_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let profile = dir.path().join("lcos.json");
    std::fs::write(
        &profile,
        r#"{"name": "4 um LCoS", "pixel_pitch_m": 4e-6, "resolution": [48, 64],
            "wavelengths_m": [638e-9, 520e-9, 450e-9], "volume_depth_m": 1.5e-3, "offsets_m": [1.5e-3]}"#,
    )
    .unwrap();
    let out = dir.path().join("r");
    let args = |out: &std::path::Path, profile: &std::path::Path| {
        holo(&[
            "render",
            "--size",
            "48x64",
            "--repeat",
            "1",
            "--display",
            profile.to_str().unwrap(),
            "--evaluate",
            "--levels",
            "64",
            "--out",
            out.to_str().unwrap(),
        ])
    };
    let o = args(&out, &profile);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&out);
    let mapping = r["models"]["display_mapping"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert!(mapping.contains("serves 4 µm with a 1.5 mm volume"), "{r}");
    // What the mapping costs: SM-LBM at 8 µm, 6 mm shown at 4 µm, 1.5 mm against SM-LBM there. Fresnel
    // equivalence makes them agree to the non-paraxial residual (0.16 % relative L2 at 384×384).
    let ceiling = &r["evaluation"]["mapping_ceiling"];
    let ceiling_db = ceiling["psnr_amp"].as_f64().unwrap_or(0.0);
    assert!(ceiling_db > 45.0, "{ceiling}");
    assert!(
        ceiling["psnr_fs"].as_f64().unwrap_or(0.0) > 45.0,
        "{ceiling}"
    );
    assert!(
        r["models"]["prefilter_reason"]
            .as_str()
            .unwrap_or_default()
            .contains("6 mm pre-filter"),
        "{r}"
    );
    // A typo in a key: refused, naming it, and nothing is written.
    let bad = dir.path().join("bad.json");
    std::fs::write(
        &bad,
        std::fs::read_to_string(&profile)
            .unwrap()
            .replace("pixel_pitch_m", "pixel_pich_m"),
    )
    .unwrap();
    let out_bad = dir.path().join("bad_out");
    let o = args(&out_bad, &bad);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("pixel_pich_m"), "{}", stderr(&o));
    assert!(!out_bad.exists());
}

/// `--tune` times the plans and writes them to OUT/tuning.json; `--tuning` repeats them in another process,
/// bit for bit and without timing; the plan table (no flag) gives the same bits in every process; a bad or
/// foreign tuning file and `--tune` with `--tuning` are refused, naming the flag.
#[test]
fn tuned_plans_are_saved_and_repeated_and_the_table_repeats_itself() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = |name: &str| tmp.path().join(name);
    let render = |out: &std::path::Path, extra: &[&str]| {
        let mut args = vec!["render", "--size", "40x56", "--repeat", "0"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", out.to_str().unwrap()]);
        holo(&args)
    };
    let bytes = |d: &std::path::Path, f: &str| std::fs::read(d.join(f)).unwrap();
    let o = render(&dir("tuned"), &["--tune"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let tuning = dir("tuned").join("tuning.json");
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&tuning).unwrap()).unwrap();
    assert_eq!(saved["format"], "tensorholo.cnn-plans");
    assert!(!saved["rows"].as_array().unwrap().is_empty(), "{saved}");
    assert_eq!(report(&dir("tuned"))["cnn_plan"]["source"], "tuned");

    let o = render(&dir("again"), &["--tuning", tuning.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&dir("again"));
    assert_eq!(r["cnn_plan"]["source"], "saved");
    assert_eq!(r["cnn_plan"]["tuning_s"], 0.0);
    assert_eq!(r["cnn_plan"]["rows"], saved["rows"]);
    assert!(!dir("again").join("tuning.json").exists());
    for f in ["midpoint.npy", "phase_r.png", "phase_g.png", "phase_b.png"] {
        assert!(
            bytes(&dir("tuned"), f) == bytes(&dir("again"), f),
            "{f} differs"
        );
    }

    for name in ["table1", "table2"] {
        let o = render(&dir(name), &[]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert_eq!(report(&dir(name))["cnn_plan"]["source"], "table");
    }
    for f in ["midpoint.npy", "phase_r.png", "phase_g.png", "phase_b.png"] {
        assert!(
            bytes(&dir("table1"), f) == bytes(&dir("table2"), f),
            "{f} differs"
        );
    }

    // Refusals: not a plans file, plans for another kernel level, both flags.
    let bad = dir("bad.json");
    std::fs::write(&bad, "{\"format\": \"tensorholo.cnn-plans\"}").unwrap();
    let o = render(&dir("x"), &["--tuning", bad.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--tuning"), "{}", stderr(&o));
    let other = if saved["isa"] == "scalar" {
        "avx2"
    } else {
        "scalar"
    };
    let mut foreign = saved.clone();
    foreign["isa"] = other.into();
    foreign["rows"] = serde_json::json!([]);
    let foreign_file = dir("foreign.json");
    std::fs::write(&foreign_file, foreign.to_string()).unwrap();
    let o = render(&dir("y"), &["--tuning", foreign_file.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("tune again"), "{}", stderr(&o));
    let o = render(&dir("z"), &["--tune", "--tuning", tuning.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    // A saved session this network cannot run (tract cannot move a QOperator int8 graph to channels-last):
    // the file and its session are blamed, not `--layout`, a flag nobody gave.
    let impossible = serde_json::json!({
        "format": "tensorholo.cnn-plans", "version": 1, "isa": saved["isa"], "origin": "edited by hand",
        "sessions": [{"network": "hologram-cnn-8-int8-qoperator-conv-in4", "resolution": [40, 56],
                      "engine": "tract", "layout": "channels-last", "threads": 1}],
        "rows": []
    });
    let impossible_file = dir("impossible.json");
    std::fs::write(&impossible_file, impossible.to_string()).unwrap();
    let o = render(
        &dir("w"),
        &[
            "--precision",
            "int8-qop",
            "--tuning",
            impossible_file.to_str().unwrap(),
        ],
    );
    let e = stderr(&o);
    assert!(!o.status.success(), "{e}");
    assert!(
        e.contains("--tuning") && e.contains("impossible.json") && e.contains("the saved plans"),
        "{e}"
    );
    assert!(!e.contains("error: invalid parameter `layout`"), "{e}");
    assert!(std::fs::read_dir(dir("w")).map_or(true, |mut d| d.next().is_none()));
}

/// The native engine's layout settings reach the plan through `holo`'s environment (the library reads none):
/// `report.json` names them in the plan request, the codes are the same bits (the layout does not change the
/// arithmetic), and a bad value is refused naming the variable, nothing written.
#[test]
fn the_layout_environment_variables_reach_the_plan_and_bad_values_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, env: &[(&str, &str)]| {
        let out = dir.path().join(name);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_holo"))
            .args([
                "render", "--size", "40x72", "--repeat", "1", "--engine", "native",
            ])
            .args(["--out", out.to_str().unwrap()])
            .envs(env.iter().copied())
            .env("RUST_LOG", "warn")
            .output()
            .unwrap();
        (o, out)
    };
    let (o, plain) = run("plain", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (o, pinned) = run(
        "pinned",
        &[("TENSORHOLO_STRIP_ROWS", "8"), ("TENSORHOLO_SLABS", "2")],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let request = &report(&pinned)["cnn_plan"]["request"];
    assert_eq!(request["strip_rows"], 8, "{request}");
    assert_eq!(request["slabs"], 2, "{request}");
    assert!(report(&plain)["cnn_plan"]["request"]["strip_rows"].is_null());
    for c in ["r", "g", "b"] {
        let f = format!("phase_{c}.png");
        assert_eq!(
            std::fs::read(plain.join(&f)).unwrap(),
            std::fs::read(pinned.join(&f)).unwrap(),
            "{f}"
        );
    }
    // Any integer is a layout: past the frame's, one strip and the whole frame, the same bits.
    let (o, huge) = run(
        "huge",
        &[
            ("TENSORHOLO_STRIP_ROWS", "18446744073709551615"),
            ("TENSORHOLO_SLABS", "18446744073709551615"),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    for c in ["r", "g", "b"] {
        let f = format!("phase_{c}.png");
        assert_eq!(
            std::fs::read(plain.join(&f)).unwrap(),
            std::fs::read(huge.join(&f)).unwrap(),
            "{f}"
        );
    }
    let (o, bad) = run("bad", &[("TENSORHOLO_SLABS", "two")]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("TENSORHOLO_SLABS=two"),
        "{}",
        stderr(&o)
    );
    assert!(!bad.exists());
}

/// `TENSORHOLO_ISA` is `holo`'s mapping onto the SDK's `CnnOptions::isa` (the library reads no environment):
/// `scalar` reaches the plan (its kernel rows are the portable ones), and a name that is no level is refused
/// naming the variable, nothing written.
#[test]
fn the_isa_variable_reaches_the_plan_and_a_bad_name_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, isa: &str| {
        let out = dir.path().join(name);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_holo"))
            .args([
                "render", "--size", "24x32", "--repeat", "0", "--engine", "native",
            ])
            .args(["--out", out.to_str().unwrap()])
            .env("TENSORHOLO_ISA", isa)
            .env("RUST_LOG", "warn")
            .output()
            .unwrap();
        (o, out)
    };
    let (o, scalar) = run("scalar", "scalar");
    assert!(o.status.success(), "{}", stderr(&o));
    let plan = &report(&scalar)["cnn_plan"];
    assert_eq!(plan["isa"], "scalar", "{plan}");
    assert_eq!(plan["request"]["isa"], "scalar", "{plan}");
    let kernel = plan["kernel"].as_str().unwrap();
    assert!(kernel.ends_with(".scalar"), "{kernel}");
    let (o, bad) = run("bad", "sse9");
    assert!(!o.status.success());
    assert!(stderr(&o).contains("TENSORHOLO_ISA=sse9"), "{}", stderr(&o));
    assert!(!bad.exists());
}

/// `--refine N` refines the frame's pattern: report.json's `refine` has the start and every iteration, the
/// loss falls, the held-out scores and both timings are there, and the codes written are the refined ones
/// (they differ from the plain render's).
#[test]
fn render_refine_reports_its_iterations_and_writes_the_refined_codes() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut args = vec!["render", "--size", "64x64", "--repeat", "0"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", out.to_str().unwrap()]);
        let o = holo(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        out
    };
    let plain = run("plain", &[]);
    let refined = run("refined", &["--refine", "3", "--refine-levels", "64"]);
    let r = report(&refined);
    let history = r["refine"]["history"].as_array().unwrap();
    assert_eq!(history.len(), 4);
    assert_eq!(r["refine"]["started_from"], "cnn", "{}", r["refine"]);
    let loss = |i: usize| history[i]["loss"].as_f64().unwrap();
    assert!(loss(3) < loss(0), "{history:?}");
    let held = &r["refine"]["held_out"];
    assert!(
        held["refined_codes_psnr_db"].as_f64().unwrap()
            > held["cnn_codes_psnr_db"].as_f64().unwrap()
    );
    assert!(r["timings_s"]["refine_target_s"].as_f64().unwrap() > 0.0);
    assert!(r["timings_s"]["refine_iterations_s"].as_f64().unwrap() > 0.0);
    assert_ne!(
        std::fs::read(plain.join("phase_g.png")).unwrap(),
        std::fs::read(refined.join("phase_g.png")).unwrap()
    );
}

/// Bad refinement settings stop `holo render` before anything is written, naming the flag.
#[test]
fn render_refuses_bad_refinement_settings_naming_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    for (extra, flag) in [
        (&["--refine", "0"][..], "--refine"),
        (&["--refine", "10001"][..], "--refine"),
        (
            &["--refine", "2", "--refine-step", "NaN"][..],
            "--refine-step",
        ),
        (
            &["--refine", "2", "--refine-step", "-0.1"][..],
            "--refine-step",
        ),
        (
            &["--refine", "2", "--refine-planes", "0"][..],
            "--refine-planes",
        ),
        (
            &["--refine", "2", "--refine-levels", "0"][..],
            "--refine-levels",
        ),
        (
            &["--refine", "2", "--refine-init", "previous"][..],
            "--refine-init previous",
        ),
    ] {
        let out = dir.path().join("bad");
        let mut args = vec!["render", "--size", "32x32", "--repeat", "0"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", out.to_str().unwrap()]);
        let o = holo(&args);
        assert!(!o.status.success(), "{extra:?} was accepted");
        let e = stderr(&o);
        assert!(e.contains(flag), "{extra:?}: {e}");
        assert!(
            !out.join("report.json").exists(),
            "{extra:?} wrote a report"
        );
    }
}

/// `--refine N --backend gpu`: the iterations run on the session's GPU (report.json's `refine.backend`: the
/// adapter the frames ran on), and the refined codes score as the CPU's do (within 0.1 dB at the held-out
/// planes). Skips without an adapter unless `TENSORHOLO_REQUIRE_GPU=1` (CI: lavapipe).
#[test]
fn render_refines_on_the_gpu_where_the_frames_run() {
    let dir = tempfile::tempdir().unwrap();
    let run = |backend: &str| {
        let out = dir.path().join(backend);
        let o = holo(&[
            "render",
            "--size",
            "40x56",
            "--repeat",
            "0",
            "--refine",
            "3",
            "--backend",
            backend,
            "--out",
            out.to_str().unwrap(),
        ]);
        (o, out)
    };
    let (o, gpu) = run("gpu");
    if !o.status.success() {
        let required = std::env::var("TENSORHOLO_REQUIRE_GPU").as_deref() == Ok("1");
        assert!(!required, "a GPU is required: {}", stderr(&o));
        eprintln!("skipping: no GPU ({})", stderr(&o));
        return;
    }
    let (o, cpu) = run("cpu");
    assert!(o.status.success(), "{}", stderr(&o));
    let (g, c) = (report(&gpu), report(&cpu));
    let name = g["refine"]["backend"].as_str().unwrap().to_string();
    assert_ne!(name, "cpu", "{}", g["refine"]);
    assert!(
        g["backend"]["adapter"].as_str().unwrap().starts_with(&name),
        "{} vs {}",
        g["backend"]["adapter"],
        name
    );
    assert_eq!(c["refine"]["backend"], "cpu");
    let score = |r: &serde_json::Value| {
        r["refine"]["held_out"]["refined_codes_psnr_db"]
            .as_f64()
            .unwrap()
    };
    assert!(
        (score(&g) - score(&c)).abs() < 0.1,
        "GPU {} vs CPU {}",
        score(&g),
        score(&c)
    );
    assert_eq!(g["refine"]["history"].as_array().unwrap().len(), 4);
    // A video: the GPU refinement made at the first frame takes each next frame's target; every frame as the
    // CPU's.
    let (rgb, depth) = (
        shared("redwood_livingroom_seq/color"),
        shared("redwood_livingroom_seq/depth"),
    );
    let runs: Vec<serde_json::Value> = ["gpu", "cpu"]
        .iter()
        .map(|backend| {
            let out = dir.path().join(format!("video_{backend}"));
            let extra = ["--limit", "3", "--refine", "2", "--backend", backend];
            let o = video(&rgb, &depth, "24x32", &extra, &out);
            assert!(o.status.success(), "{}", stderr(&o));
            report(&out)
        })
        .collect();
    for i in 0..3 {
        let at = |r: &serde_json::Value| {
            r["per_frame"][i]["refine"]["held_out"]["refined_codes_psnr_db"]
                .as_f64()
                .unwrap()
        };
        assert_ne!(runs[0]["per_frame"][i]["refine"]["backend"], "cpu");
        assert!(
            (at(&runs[0]) - at(&runs[1])).abs() < 0.1,
            "frame {i}: {} vs {}",
            at(&runs[0]),
            at(&runs[1])
        );
    }
}

/// The 40-frame RealSense sequence (real, handheld, depth not registered to colour) runs through `holo
/// video`: every frame streamed, the temporal numbers for its 39 transitions (a moving camera over a still
/// lab: some churn, few pixels swinging by more than π/2).
#[test]
fn video_runs_the_realsense_sequence_with_its_temporal_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rs");
    let o = video(
        &shared("realsense_seq/rgb"),
        &shared("realsense_seq/depth"),
        "24x32",
        &[],
        &out,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&out);
    assert_eq!(r["frames"], 40);
    let t = &r["temporal"];
    assert_eq!(t["transitions"], 39, "{t}");
    let churn = t["mean_churn_rad"].as_f64().unwrap();
    assert!(churn > 0.0 && churn < 1.0, "{t}");
    assert!(t["max_above_half_pi"].as_f64().unwrap() < 0.5, "{t}");
}

/// `--gaze`: a foveated frame (docs/FOVEATION.md), its report section, and with `--evaluate` its scores by
/// eccentricity against the full 3D frame and SM-LBM; bad gazes and radii are refused naming the flag before
/// anything is written.
#[test]
fn render_foveates_on_a_gaze_and_scores_it_by_eccentricity() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fovea");
    let o = holo(&[
        "render",
        "--size",
        "96x128",
        "--gaze",
        "40,30",
        "--fovea-px",
        "20",
        "--evaluate",
        "--levels",
        "64",
        "--repeat",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&out);
    let fovea = &r["fovea"];
    assert_eq!(fovea["radius_px"], 20.0);
    assert_eq!(fovea["covers_frame"], false);
    let share = fovea["cnn_share"].as_f64().unwrap();
    assert!(share > 0.0 && share < 1.0, "{fovea}");
    assert!(
        r["timings_s"]["first_frame"]["periphery_s"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    let bins = &r["evaluation"]["fovea_bins"];
    assert_eq!(bins["bins_px"].as_array().unwrap().len(), 4);
    // In the fovea at the midpoint plane (d = 0.5, the third), the foveated midpoint hologram is the full
    // frame's; beyond 4R it is the periphery's 2D hologram.
    let against_full = &bins["against_full"]["midpoint"][2];
    let (fovea_db, far_db) = (
        against_full[0].as_f64().unwrap(),
        against_full[3].as_f64().unwrap(),
    );
    assert!(fovea_db > 60.0 && far_db < fovea_db, "{against_full}");
    for key in [
        "foveated_midpoint",
        "foveated_displayed",
        "full_midpoint",
        "full_displayed",
    ] {
        assert_eq!(
            bins["against_sm_lbm"][key].as_array().unwrap().len(),
            5,
            "{key}"
        );
    }

    for (extra, flag) in [
        (&["--gaze", "nan,3"][..], "--gaze"),
        (&["--gaze", "3"][..], "--gaze"),
        (&["--gaze", "32,3"][..], "--gaze"),
        (&["--gaze", "3,-0.6"][..], "--gaze"),
        (&["--gaze", "3,3", "--fovea-px", "-1"][..], "--fovea-px"),
        (&["--gaze", "3,3", "--fovea-deg", "NaN"][..], "--fovea-deg"),
        (
            &["--gaze", "3,3", "--fovea-deg", "5", "--eyepiece-mm", "0"][..],
            "--eyepiece-mm",
        ),
        (
            &["--gaze", "3,3", "--fovea-band-px", "0"][..],
            "--fovea-band-px",
        ),
        (
            &["--gaze", "3,3", "--gaze-depth", "inf"][..],
            "--gaze-depth",
        ),
        (&["--gaze-depth", "0.001"][..], "--gaze"),
    ] {
        let out = dir.path().join("bad");
        let mut args = vec!["render", "--size", "32x32", "--repeat", "0"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", out.to_str().unwrap()]);
        let o = holo(&args);
        assert!(!o.status.success(), "{extra:?} was accepted");
        let e = stderr(&o);
        assert!(e.contains(flag), "{extra:?}: {e}");
        assert!(!out.exists(), "{extra:?} wrote {}", out.display());
    }
}

/// `holo video --gaze` (one gaze for every frame) and `--gaze-track FILE.csv` (a row per frame): foveated
/// frames, the stream equal to single foveated frames; a track with a missing frame, a frame listed twice, a
/// bad row or a frame beyond the sequence is refused naming the file and the line before anything is written.
#[test]
fn video_foveates_on_a_fixed_gaze_and_on_a_gaze_track() {
    let seq = shared("realsense_seq");
    let (rgb, depth) = (seq.join("rgb"), seq.join("depth"));
    let dir = tempfile::tempdir().unwrap();
    let track = dir.path().join("track.csv");
    std::fs::write(
        &track,
        "frame,x,y,depth\n0,100,80,\n2,150,100,\n1,20.5,30,0.001\n",
    )
    .unwrap();
    let track_arg = track.to_str().unwrap();
    for (extra, kind) in [
        (vec!["--gaze", "80,60", "--fovea-px", "20"], "fixed"),
        (vec!["--gaze-track", track_arg, "--fovea-px", "20"], "track"),
    ] {
        let out = dir.path().join(kind);
        let mut args = vec!["--limit", "3"];
        args.extend_from_slice(&extra);
        let o = video(&rgb, &depth, "120x160", &args, &out);
        assert!(o.status.success(), "{kind}: {}", stderr(&o));
        let r = report(&out);
        assert_eq!(r["frames"], 3);
        assert_eq!(r["fovea"]["gaze"], kind);
        assert_eq!(r["stream_equals_single_frame"], true, "{kind}");
        assert_eq!(r["fovea"]["first_frame"]["covers_frame"], false);
        for f in r["per_frame"].as_array().unwrap() {
            assert!(
                f["timings_s"]["periphery_s"].as_f64().unwrap() > 0.0,
                "{kind}: {f}"
            );
        }
    }
    for (rows, what) in [
        ("0,1,1\n1,2,2\n", "no row for frame 2"),
        (
            "0,1,1\n1,2,2\n1,3,3\n2,1,1\n",
            "line 3: frame 1 is listed twice",
        ),
        ("0,1,1\n1,abc,2\n2,1,1\n", "line 2"),
        ("0,1,1\n1,2,2\n2,1,1\n7,1,1\n", "line 4: frame 7"),
        ("0,1,1,nan\n1,2,2\n2,1,1\n", "line 1"),
    ] {
        std::fs::write(&track, rows).unwrap();
        let out = dir.path().join("bad");
        let o = video(
            &rgb,
            &depth,
            "120x160",
            &["--limit", "3", "--gaze-track", track_arg],
            &out,
        );
        assert!(!o.status.success(), "{rows:?} was accepted");
        let e = stderr(&o);
        assert!(
            e.contains("--gaze-track") && e.contains(what),
            "{rows:?}: {e}"
        );
        assert!(!out.exists(), "{rows:?} wrote {}", out.display());
    }
}
