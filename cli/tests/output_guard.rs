//! Issue 20: one output guard for every `holo` command, and reports that name non-UTF-8 files lossily.
//!
//! The guard (`cli/src/output.rs`, `guard`) refuses an output (`--out`, `propagate --output`) that is an input,
//! lies inside an input folder, or holds an input (file or folder) anywhere below it. Each guard case here
//! asserts: exit code 2 (a usage error), a message naming both the output and the input as given, every file
//! and folder under the test's root byte-identical afterwards, and nothing created (the snapshot includes
//! folders, so a created `--out` fails it). Without the guard each case would run (exit 0, or 1 for the
//! inputs that are not decodable on purpose) and write into or beside the inputs, failing the exit code and
//! the snapshot assertions.
//!
//! `holo bench` takes no input path (built-in models and procedural frames only), so it has no guard case;
//! its `--json` report is covered by the non-UTF-8 cases. `holo calibrate patterns` and `calibrate simulate`
//! take no input either.
//!
//! The non-UTF-8 cases (Unix: names are bytes there) give each command that writes a report an input whose
//! file name is `...\xff...` (not UTF-8) and assert exit code 0 and the name in the report with U+FFFD.
//! `propagate` writes no report (only its `.npy`), and the calibration reports (`black.json`, the `.holocal`
//! notes) hold no path: for `calibrate` the case asserts that such names run (exit 0) and its report is
//! written.

mod common;

use std::collections::BTreeMap;
use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};
use std::process::Output;

use common::{shared, stderr};
use ndarray::Array3;
use num_complex::Complex32;
use tensorholo::io::write_complex_npy;

/// Runs `holo` with arguments that need not be UTF-8.
fn holo<S: AsRef<OsStr>>(args: &[S]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_holo"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("holo runs")
}

/// Every folder (as `None`) and file (with its bytes) under `root`.
fn snapshot(root: &Path) -> BTreeMap<PathBuf, Option<Vec<u8>>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(p) = stack.pop() {
        let meta = std::fs::symlink_metadata(&p).unwrap();
        if meta.is_dir() {
            out.insert(p.clone(), None);
            for e in std::fs::read_dir(&p).unwrap() {
                stack.push(e.unwrap().path());
            }
        } else {
            out.insert(p.clone(), Some(std::fs::read(&p).unwrap_or_default()));
        }
    }
    out
}

/// A fresh folder for one test.
fn fresh(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("holo-guard-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs `args` and checks the guard's refusal: exit 2, both paths named, nothing under `root` changed or
/// created.
fn assert_refused(root: &Path, args: &[OsString], out: &Path, input: &Path) {
    let before = snapshot(root);
    let o = holo(args);
    let msg = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {msg}");
    for p in [out, input] {
        assert!(
            msg.contains(&p.display().to_string()),
            "{args:?}: the message does not name `{}`: {msg}",
            p.display()
        );
    }
    let after = snapshot(root);
    let changed: Vec<_> = after
        .keys()
        .chain(before.keys())
        .filter(|k| before.get(*k) != after.get(*k))
        .collect();
    assert!(
        changed.is_empty(),
        "{args:?}: changed or created {changed:?}"
    );
}

fn os(v: &[&dyn AsRef<OsStr>]) -> Vec<OsString> {
    v.iter().map(|a| a.as_ref().to_os_string()).collect()
}

/// The Redwood RGB-D pair copied into `dir` as `rgb.jpg` and `depth.png` (or the given names).
fn rgbd_pair(dir: &Path, rgb: &OsStr, depth: &OsStr) -> (PathBuf, PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let (r, d) = (dir.join(rgb), dir.join(depth));
    std::fs::copy(shared("redwood_livingroom_seq/color/00000.jpg"), &r).unwrap();
    std::fs::copy(shared("redwood_livingroom_seq/depth/00000.png"), &d).unwrap();
    (r, d)
}

fn plain_pair(dir: &Path) -> (PathBuf, PathBuf) {
    rgbd_pair(dir, OsStr::new("rgb.jpg"), OsStr::new("depth.png"))
}

/// A smooth complex colour field `[3, 16, 16]` in `path`.
fn field(path: &Path) {
    let f = Array3::from_shape_fn((3, 16, 16), |(c, y, x)| {
        Complex32::from_polar(0.5 + 0.1 * c as f32, 0.05 * (x * y) as f32)
    });
    write_complex_npy(path, f.view()).unwrap();
}

/// A tiny dataset (1 train, 1 test scene of 16x24, 16 planes) in `dir`.
fn tiny_dataset(dir: &Path) {
    let o = holo(&os(&[
        &"dataset",
        &"--out",
        &dir,
        &"--train",
        &"1",
        &"--val",
        &"0",
        &"--test",
        &"1",
        &"--size",
        &"16x24",
        &"--levels",
        &"16",
        &"--previews",
        &"0",
        &"--threads=2",
    ]));
    assert!(o.status.success(), "{}", stderr(&o));
}

fn report(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

// ---------------------------------------------------------------------------------------------------------
// The guard, one case (or more) per command.

#[test]
fn guard_render_refuses_an_out_holding_its_inputs() {
    let root = fresh("render");
    let (rgb, depth) = plain_pair(&root.join("in"));
    let out = root.join("in");
    let args = |out: &Path| {
        os(&[
            &"render",
            &"--rgb",
            &rgb,
            &"--depth",
            &depth,
            &"--depth-encoding",
            &"mm16",
            &"--size",
            &"24x32",
            &"--repeat",
            &"0",
            &"--out",
            &out,
        ])
    };
    // `holo render --rgb a.png --depth b.png --out .` in the inputs' folder.
    assert_refused(&root, &args(&out), &out, &rgb);
    // A model file inside --out (spelled with `..`), the scene elsewhere.
    let model = root.join("models/my.onnx");
    std::fs::create_dir_all(model.parent().unwrap()).unwrap();
    std::fs::write(&model, b"not looked at: the guard runs first").unwrap();
    let out = root.join("in/../models");
    assert_refused(
        &root,
        &os(&[&"render", &"--model", &model, &"--out", &out]),
        &out,
        &model,
    );
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn guard_reference_refuses_an_out_holding_its_inputs_or_being_one() {
    let root = fresh("reference");
    let (rgb, depth) = plain_pair(&root.join("in"));
    let base = |out: &Path| {
        os(&[
            &"reference",
            &"--rgb",
            &rgb,
            &"--depth",
            &depth,
            &"--depth-encoding",
            &"mm16",
            &"--size",
            &"24x32",
            &"--levels",
            &"8",
            &"--out",
            &out,
        ])
    };
    let out = root.clone();
    assert_refused(&root, &base(&out), &out, &rgb);
    // --out naming the depth file itself.
    assert_refused(&root, &base(&depth), &depth, &depth);
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn guard_video_refuses_an_out_inside_or_holding_a_frame_folder() {
    let root = fresh("video");
    let (rgb_dir, depth_dir) = (root.join("seq/rgb"), root.join("seq/depth"));
    for n in ["00000", "00001"] {
        rgbd_pair(
            &rgb_dir,
            OsStr::new(&format!("{n}.jpg")),
            OsStr::new("unused.png"),
        );
        rgbd_pair(
            &depth_dir,
            OsStr::new("unused.jpg"),
            OsStr::new(&format!("{n}.png")),
        );
    }
    std::fs::remove_file(rgb_dir.join("unused.png")).unwrap();
    std::fs::remove_file(depth_dir.join("unused.jpg")).unwrap();
    let args = |out: &Path| {
        os(&[
            &"video",
            &"--rgb-dir",
            &rgb_dir,
            &"--depth-dir",
            &depth_dir,
            &"--depth-encoding",
            &"mm16",
            &"--size",
            &"24x32",
            &"--save-frames",
            &"--out",
            &out,
        ])
    };
    // Inside the RGB folder (the run would add report.json and frames/ among the frames).
    let out = rgb_dir.join("out");
    assert_refused(&root, &args(&out), &out, &rgb_dir);
    // The depth folder itself.
    assert_refused(&root, &args(&depth_dir), &depth_dir, &depth_dir);
    // Holding both folders.
    let out = root.join("seq");
    assert_refused(&root, &args(&out), &out, &rgb_dir);
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn guard_dataset_refuses_an_out_inside_or_holding_the_photo_folder() {
    let root = fresh("dataset");
    let photos = root.join("photos");
    rgbd_pair(&photos, OsStr::new("a.jpg"), OsStr::new("b.png"));
    let args = |out: &Path| {
        os(&[
            &"dataset",
            &"--train",
            &"1",
            &"--val",
            &"0",
            &"--test",
            &"0",
            &"--size",
            &"16",
            &"--levels",
            &"4",
            &"--photos",
            &photos,
            &"--out",
            &out,
        ])
    };
    let out = photos.join("ds");
    assert_refused(&root, &args(&out), &out, &photos);
    let out = root.clone();
    assert_refused(&root, &args(&out), &out, &photos);
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn guard_baselines_refuses_the_dataset_folder_and_a_folder_holding_it() {
    let root = fresh("baselines");
    let ds = root.join("data/ds");
    tiny_dataset(&ds);
    let args = |out: &Path| {
        os(&[
            &"baselines",
            &"--dataset",
            &ds,
            &"--levels",
            &"4",
            &"--offsets-mm",
            &"0",
            &"--out",
            &out,
        ])
    };
    assert_refused(&root, &args(&ds), &ds, &ds);
    // A folder holding the dataset (its manifest and shards would lie inside --out).
    let out = root.join("data");
    assert_refused(&root, &args(&out), &out, &ds);
    // The default, DATASET/baselines, inside the dataset folder, stays allowed.
    let o = holo(&os(&[
        &"baselines",
        &"--dataset",
        &ds,
        &"--levels",
        &"4",
        &"--offsets-mm",
        &"0",
    ]));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(ds.join("baselines/baselines.json").exists());
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn guard_encode_refuses_an_out_holding_its_input() {
    let root = fresh("encode");
    let input = root.join("fields/mid.npy");
    std::fs::create_dir_all(input.parent().unwrap()).unwrap();
    field(&input);
    let out = root.join("fields");
    assert_refused(
        &root,
        &os(&[&"encode", &"--input", &input, &"--out", &out]),
        &out,
        &input,
    );
    // A fresh subfolder beside the input is fine.
    let ok = root.join("fields/encoded");
    let o = holo(&os(&[&"encode", &"--input", &input, &"--out", &ok]));
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn guard_propagate_refuses_its_input_as_output_whatever_the_spelling() {
    let root = fresh("propagate");
    let input = root.join("a/field.npy");
    std::fs::create_dir_all(root.join("a/b")).unwrap();
    field(&input);
    let output = root.join("a/b/../field.npy");
    assert_refused(
        &root,
        &os(&[
            &"propagate",
            &"--input",
            &input,
            &"--distance-m",
            &"1e-3",
            &"--wavelength-m",
            &"520e-9",
            &"--pitch-m",
            &"8e-6",
            &"--output",
            &output,
        ]),
        &output,
        &input,
    );
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn guard_calibrate_refuses_outputs_among_captures_and_calibration_files() {
    let root = fresh("calibrate");
    // Captures: the guard runs before any capture is read, so placeholders do.
    let green = root.join("captures/green");
    std::fs::create_dir_all(&green).unwrap();
    std::fs::write(green.join("capture_000.png"), b"placeholder").unwrap();
    let out = green.join("display.holocal");
    assert_refused(
        &root,
        &os(&[
            &"calibrate",
            &"lut",
            &"--green",
            &green,
            &"--size",
            &"16x24",
            &"--out",
            &out,
        ]),
        &out,
        &green,
    );
    // `black` into the folder holding its calibration file.
    let cal = root.join("cal/display.holocal");
    std::fs::create_dir_all(cal.parent().unwrap()).unwrap();
    std::fs::write(&cal, b"placeholder").unwrap();
    let out = root.join("cal");
    assert_refused(
        &root,
        &os(&[&"calibrate", &"black", &cal, &"--out", &out]),
        &out,
        &cal,
    );
    // `intensity` over its own --base, `global` over its CSV, `curves` over its file.
    let beam = root.join("cal/diffuser_green.png");
    std::fs::write(&beam, b"placeholder").unwrap();
    assert_refused(
        &root,
        &os(&[
            &"calibrate",
            &"intensity",
            &"--green",
            &beam,
            &"--base",
            &cal,
            &"--out",
            &cal,
        ]),
        &cal,
        &cal,
    );
    let csv = root.join("cal/red.csv");
    std::fs::write(&csv, b"0,0\n").unwrap();
    assert_refused(
        &root,
        &os(&[
            &"calibrate",
            &"global",
            &"--size",
            &"16x24",
            &"--red-csv",
            &csv,
            &"--out",
            &csv,
        ]),
        &csv,
        &csv,
    );
    assert_refused(
        &root,
        &os(&[
            &"calibrate",
            &"curves",
            &cal,
            &"--color",
            &"green",
            &"--out",
            &cal,
        ]),
        &cal,
        &cal,
    );
    std::fs::remove_dir_all(&root).unwrap();
}

// ---------------------------------------------------------------------------------------------------------
// Names that are not UTF-8 in reports.

#[cfg(unix)]
mod non_utf8 {
    use super::*;
    use std::os::unix::ffi::OsStrExt;

    fn name(bytes: &[u8]) -> &OsStr {
        OsStr::from_bytes(bytes)
    }

    fn text(v: &serde_json::Value) -> &str {
        v.as_str().unwrap_or_else(|| panic!("{v} is not a string"))
    }

    #[test]
    fn render_and_reference_reports_name_the_input_lossily() {
        let root = fresh("utf8-render");
        let (rgb, depth) = rgbd_pair(&root, name(b"frame\xff.jpg"), name(b"depth\xfe.png"));
        for (cmd, extra) in [
            ("render", ["--repeat", "0"]),
            ("reference", ["--levels", "8"]),
        ] {
            let out = root.join(format!("out-{cmd}"));
            let o = holo(&os(&[
                &cmd,
                &"--rgb",
                &rgb,
                &"--depth",
                &depth,
                &"--depth-encoding",
                &"mm16",
                &"--size",
                &"24x32",
                &extra[0],
                &extra[1],
                &"--out",
                &out,
            ]));
            assert_eq!(o.status.code(), Some(0), "{cmd}: {}", stderr(&o));
            let r = report(&out.join("report.json"));
            assert!(
                text(&r["input"]["rgb"]).ends_with("frame\u{fffd}.jpg"),
                "{cmd}: {}",
                r["input"]
            );
            assert!(
                text(&r["input"]["depth"]).ends_with("depth\u{fffd}.png"),
                "{cmd}: {}",
                r["input"]
            );
        }
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn reference_report_names_a_non_utf8_aberration_file_lossily() {
        let root = fresh("utf8-aberration");
        let profile = root.join(name(b"lens\xff.json"));
        std::fs::write(
            &profile,
            br#"{"format": "tensorholo.aberration", "version": 1,
                "samples": [{"distance_m": 0.0, "coefficients": {"focus": 0.5}}]}"#,
        )
        .unwrap();
        let out = root.join("out");
        let o = holo(&os(&[
            &"reference",
            &"--size",
            &"16x16",
            &"--levels",
            &"4",
            &"--aberration",
            &profile,
            &"--out",
            &out,
        ]));
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let r = report(&out.join("report.json"));
        assert!(
            text(&r["aberration"]["file"]).ends_with("lens\u{fffd}.json"),
            "{}",
            r["aberration"]
        );
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn video_report_names_non_utf8_frames_lossily() {
        let root = fresh("utf8-video");
        let (rgb_dir, depth_dir) = (root.join("rgb"), root.join("depth"));
        let (rgb, _) = rgbd_pair(&rgb_dir, name(b"f\xff.jpg"), name(b"x.png"));
        let (_, depth) = rgbd_pair(&depth_dir, name(b"x.jpg"), name(b"f\xff.png"));
        std::fs::remove_file(rgb_dir.join("x.png")).unwrap();
        std::fs::remove_file(depth_dir.join("x.jpg")).unwrap();
        assert!(rgb.exists() && depth.exists());
        let out = root.join("out");
        let o = holo(&os(&[
            &"video",
            &"--rgb-dir",
            &rgb_dir,
            &"--depth-dir",
            &depth_dir,
            &"--depth-encoding",
            &"mm16",
            &"--size",
            &"24x32",
            &"--out",
            &out,
        ]));
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let r = report(&out.join("report.json"));
        let frame = &r["per_frame"][0];
        assert!(text(&frame["rgb"]).ends_with("f\u{fffd}.jpg"), "{frame}");
        assert!(text(&frame["depth"]).ends_with("f\u{fffd}.png"), "{frame}");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn encode_report_names_a_non_utf8_input_lossily() {
        let root = fresh("utf8-encode");
        let input = root.join(name(b"mid\xff.npy"));
        field(&input);
        let out = root.join("out");
        let o = holo(&os(&[&"encode", &"--input", &input, &"--out", &out]));
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let r = report(&out.join("encode.json"));
        assert!(
            text(&r["input"]).ends_with("mid\u{fffd}.npy"),
            "{}",
            r["input"]
        );
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn propagate_runs_on_a_non_utf8_input() {
        // No report: only the output .npy, which keeps its exact name.
        let root = fresh("utf8-propagate");
        let input = root.join(name(b"field\xff.npy"));
        field(&input);
        let output = root.join(name(b"out\xfe.npy"));
        let o = holo(&os(&[
            &"propagate",
            &"--input",
            &input,
            &"--distance-m",
            &"1e-3",
            &"--wavelength-m",
            &"520e-9",
            &"--pitch-m",
            &"8e-6",
            &"--output",
            &output,
        ]));
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        assert!(output.exists());
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn dataset_manifest_and_baselines_report_name_non_utf8_paths_lossily() {
        let root = fresh("utf8-dataset");
        let photos = root.join(name(b"photos\xff"));
        rgbd_pair(&photos, name(b"photo\xfe.jpg"), OsStr::new("b.png"));
        std::fs::remove_file(photos.join("b.png")).unwrap();
        let ds = root.join(name(b"ds\xff"));
        let o = holo(&os(&[
            &"dataset",
            &"--out",
            &ds,
            &"--train",
            &"1",
            &"--val",
            &"0",
            &"--test",
            &"1",
            &"--size",
            &"16x24",
            &"--levels",
            &"16",
            &"--previews",
            &"1",
            &"--photos",
            &photos,
            &"--threads=2",
        ]));
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let m = report(&ds.join("manifest.json"));
        assert!(
            text(&m["photos"][0]).ends_with("photos\u{fffd}/photo\u{fffd}.jpg"),
            "{}",
            m["photos"]
        );
        assert!(
            text(&m["scene"]["photo_folder"]).ends_with("photos\u{fffd}"),
            "{}",
            m["scene"]
        );
        // The manifest still reads back (baselines reads it).
        let o = holo(&os(&[
            &"baselines",
            &"--dataset",
            &ds,
            &"--levels",
            &"4",
            &"--offsets-mm",
            &"0",
        ]));
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let r = report(&ds.join("baselines/baselines.json"));
        assert!(
            text(&r["dataset"]).ends_with("ds\u{fffd}"),
            "{}",
            r["dataset"]
        );
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn calibrate_runs_on_non_utf8_names() {
        // The calibration reports (black.json, the .holocal notes) hold no path: such names must only run.
        let root = fresh("utf8-calibrate");
        let cal = root.join(name(b"panel\xff.holocal"));
        let o = holo(&os(&[
            &"calibrate",
            &"global",
            &"--size",
            &"16x24",
            &"--range-rad",
            &"7",
            &"--gamma",
            &"1.1",
            &"--out",
            &cal,
        ]));
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let out = root.join(name(b"black\xfe"));
        let o = holo(&os(&[&"calibrate", &"black", &cal, &"--out", &out]));
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let r = report(&out.join("black.json"));
        assert!(r["green"]["black_level_calibrated"].is_number(), "{r}");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn bench_report_names_a_non_utf8_json_path_lossily() {
        let root = fresh("utf8-bench");
        let json = root.join(name(b"bench\xff.json"));
        let o = holo(&os(&[
            &"bench",
            &"--skip-pipeline",
            &"--layers",
            &"8",
            &"--precision",
            &"f32",
            &"--sizes",
            &"32x32",
            &"--threads",
            &"1",
            &"--repeat",
            &"1",
            &"--json",
            &json,
        ]));
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let r = report(&json);
        let command = r["command"].as_array().unwrap();
        assert!(
            text(command.last().unwrap()).ends_with("bench\u{fffd}.json"),
            "{command:?}"
        );
        std::fs::remove_dir_all(&root).unwrap();
    }
}

/// Issue 80: every single-file output of `holo` (`propagate --output`, `calibrate global --out`, `calibrate
/// curves --out`, `bench --json` and `--save-tuning`) looks at what is at its path first: a character device
/// or a FIFO with a reader is written straight into, a FIFO with no reader, a block device or a socket is
/// refused naming the path and what it is, never waited on; none is renamed over nor removed (`bench --json`
/// removes an old report first: not a node). Before, each was replaced by a regular file and the run exited 0.
#[cfg(target_os = "linux")]
mod output_nodes {
    use std::ffi::OsString;
    use std::io::Read;
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    use std::path::{Path, PathBuf};
    use std::time::{Duration, Instant};

    use super::{field, fresh, holo, os, stderr};

    const O_NONBLOCK: i32 = 0o4000;

    /// One command per single-file writer of `holo`, writing `out`; `cal` is a calibration file made here.
    fn commands(root: &Path, out: &Path) -> Vec<(&'static str, Vec<OsString>)> {
        let input = root.join("field.npy");
        if !input.exists() {
            field(&input);
        }
        let cal = root.join("panel.holocal");
        if !cal.exists() {
            let o = holo(&os(&[
                &"calibrate",
                &"global",
                &"--size",
                &"16x24",
                &"--range-rad",
                &"7",
                &"--gamma",
                &"1.1",
                &"--out",
                &cal,
            ]));
            assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        }
        let bench = |flag: &str| {
            os(&[
                &"bench",
                &"--skip-pipeline",
                &"--layers",
                &"8",
                &"--precision",
                &"f32",
                &"--sizes",
                &"16x16",
                &"--threads",
                &"1",
                &"--repeat",
                &"1",
                &flag,
                &out,
            ])
        };
        vec![
            (
                "propagate --output",
                os(&[
                    &"propagate",
                    &"--input",
                    &input,
                    &"--distance-m",
                    &"1e-3",
                    &"--wavelength-m",
                    &"520e-9",
                    &"--pitch-m",
                    &"8e-6",
                    &"--output",
                    &out,
                ]),
            ),
            (
                "calibrate global --out",
                os(&[
                    &"calibrate",
                    &"global",
                    &"--size",
                    &"16x24",
                    &"--range-rad",
                    &"7",
                    &"--gamma",
                    &"1.1",
                    &"--out",
                    &out,
                ]),
            ),
            (
                "calibrate curves --out",
                os(&[
                    &"calibrate",
                    &"curves",
                    &cal,
                    &"--color",
                    &"green",
                    &"--out",
                    &out,
                ]),
            ),
            ("bench --json", bench("--json")),
            ("bench --save-tuning", bench("--save-tuning")),
        ]
    }

    fn mkfifo(path: &Path) {
        let ok = std::process::Command::new("mkfifo")
            .arg(path)
            .status()
            .unwrap();
        assert!(ok.success());
    }

    /// `mknod`; false, with a message, where nodes cannot be made (not root, a `nodev` file system).
    fn mknod(path: &Path, kind: &str, major: &str, minor: &str) -> bool {
        let made = std::process::Command::new("mknod")
            .arg(path)
            .args([kind, major, minor])
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if !made {
            eprintln!(
                "skipped: cannot mknod {} here (not root, or nodev)",
                path.display()
            );
        }
        made
    }

    fn file_type(path: &Path) -> std::fs::FileType {
        std::fs::metadata(path).unwrap().file_type()
    }

    fn is_link(path: &Path) -> bool {
        std::fs::symlink_metadata(path)
            .unwrap()
            .file_type()
            .is_symlink()
    }

    /// Runs `args`, killing it (and failing) after 60 s: a run waiting on a FIFO.
    fn run_within(name: &str, args: &[OsString]) -> std::process::Output {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_holo"))
            .args(args)
            .env("RUST_LOG", "warn")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while child.try_wait().unwrap().is_none() {
            if start.elapsed() > Duration::from_secs(60) {
                let _ = child.kill();
                panic!("{name} waited on its output");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        child.wait_with_output().unwrap()
    }

    #[test]
    fn fifos_with_and_without_a_reader_itself_or_through_a_link() {
        let root = fresh("nodes-fifo");
        let fifo = root.join("out.fifo");
        mkfifo(&fifo);
        let link = root.join("link.out");
        std::os::unix::fs::symlink(&fifo, &link).unwrap();
        for path in [&fifo, &link] {
            for (name, args) in commands(&root, path) {
                // No reader: refused at once, naming the path and why.
                let o = run_within(name, &args);
                let err = stderr(&o);
                assert_ne!(o.status.code(), Some(0), "{name}: {err}");
                assert!(
                    err.contains(&path.display().to_string())
                        && err.contains("a FIFO with no reader"),
                    "{name}: {err}"
                );
                assert!(file_type(&fifo).is_fifo(), "{name} replaced the FIFO");
                assert!(is_link(&link), "{name} replaced the link");
                // A reader: written into.
                let mut reader = std::fs::OpenOptions::new()
                    .read(true)
                    .custom_flags(O_NONBLOCK)
                    .open(&fifo)
                    .unwrap();
                let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_holo"))
                    .args(&args)
                    .env("RUST_LOG", "warn")
                    .stdout(std::process::Stdio::null())
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .unwrap();
                let (mut got, mut buf, start) = (Vec::new(), vec![0u8; 1 << 16], Instant::now());
                let status = loop {
                    match reader.read(&mut buf) {
                        Ok(n) if n > 0 => got.extend_from_slice(&buf[..n]),
                        _ => {
                            if let Some(status) = child.try_wait().unwrap() {
                                let _ = reader.read_to_end(&mut got);
                                break status;
                            }
                            assert!(start.elapsed() < Duration::from_secs(60), "{name} hangs");
                            std::thread::sleep(Duration::from_millis(5));
                        }
                    }
                };
                let mut err = String::new();
                child
                    .stderr
                    .take()
                    .unwrap()
                    .read_to_string(&mut err)
                    .unwrap();
                assert!(status.success(), "{name} into a FIFO with a reader: {err}");
                assert!(!got.is_empty(), "{name} wrote nothing into the FIFO");
                assert!(file_type(&fifo).is_fifo(), "{name} replaced the FIFO");
                assert!(is_link(&link), "{name} replaced the link");
            }
        }
        std::fs::remove_dir_all(&root).unwrap();
    }

    /// `--json /dev/stdout` (and `/dev/fd/1`) writes into the process's standard output whatever it is: a
    /// pipe, or a file the shell redirected it to (appended to; the link is never renamed over nor removed, as
    /// `bench --json` removes an old report). Links of the test's own to `/proc/self/fd/1` and `/dev/fd/1`
    /// stand for `/dev/stdout`, so that a regression cannot replace the system's.
    #[test]
    fn dev_stdout_is_written_into_whether_a_pipe_or_a_redirected_file() {
        let root = fresh("nodes-stdout");
        let (proc_link, fd_link) = (root.join("stdout"), root.join("fd1"));
        std::os::unix::fs::symlink("/proc/self/fd/1", &proc_link).unwrap();
        std::os::unix::fs::symlink("/dev/fd/1", &fd_link).unwrap();
        for path in [&proc_link, &fd_link] {
            for (name, args) in commands(&root, path) {
                // A pipe (the test reads it as it comes: `output` drains stdout while the run writes).
                let o = holo(&args);
                let shown = path.display();
                assert_eq!(o.status.code(), Some(0), "{name} {shown}: {}", stderr(&o));
                assert!(!o.stdout.is_empty(), "{name} wrote nothing to {shown}");
                assert!(is_link(path), "{name} replaced {shown}");
                // A regular file.
                let file = root.join("stdout.txt");
                let _ = std::fs::remove_file(&file);
                let o = std::process::Command::new(env!("CARGO_BIN_EXE_holo"))
                    .args(&args)
                    .env("RUST_LOG", "warn")
                    .stdout(std::fs::File::create(&file).unwrap())
                    .output()
                    .unwrap();
                assert_eq!(
                    o.status.code(),
                    Some(0),
                    "{name} {shown} > file: {}",
                    stderr(&o)
                );
                assert!(std::fs::metadata(&file).unwrap().len() > 0, "{name} > file");
                assert!(is_link(path), "{name} replaced {shown}");
            }
        }
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn character_devices_are_written_into_block_devices_and_sockets_refused() {
        let root = fresh("nodes-devices");
        let null_link = root.join("null.out");
        std::os::unix::fs::symlink("/dev/null", &null_link).unwrap();
        let full_link = root.join("full.out");
        std::os::unix::fs::symlink("/dev/full", &full_link).unwrap();
        let socket = root.join("out.sock");
        let _listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
        let mut written: Vec<PathBuf> = vec![null_link.clone()];
        let mut refused = vec![(socket.clone(), "a socket")];
        let null_node = root.join("null-node");
        if mknod(&null_node, "c", "1", "3") {
            written.push(null_node.clone());
        }
        let block = root.join("block-node");
        if mknod(&block, "b", "7", "0") {
            refused.push((block.clone(), "a block device"));
        }
        for path in &written {
            for (name, args) in commands(&root, path) {
                let o = run_within(name, &args);
                assert_eq!(
                    o.status.code(),
                    Some(0),
                    "{name} into {}: {}",
                    path.display(),
                    stderr(&o)
                );
                assert!(
                    file_type(path).is_char_device(),
                    "{name} replaced {}",
                    path.display()
                );
            }
        }
        assert!(is_link(&null_link) && file_type(Path::new("/dev/null")).is_char_device());
        for (name, args) in commands(&root, &full_link) {
            // /dev/full takes no byte: a failure naming the path; the link and the device stay.
            let o = run_within(name, &args);
            assert_ne!(o.status.code(), Some(0), "{name} into /dev/full");
            assert!(stderr(&o).contains("full.out"), "{name}: {}", stderr(&o));
            assert!(is_link(&full_link) && file_type(Path::new("/dev/full")).is_char_device());
        }
        for (path, what) in &refused {
            for (name, args) in commands(&root, path) {
                let o = run_within(name, &args);
                let err = stderr(&o);
                assert_ne!(o.status.code(), Some(0), "{name} onto {what}: {err}");
                assert!(
                    err.contains(&path.display().to_string()) && err.contains(what),
                    "{name}: {err}"
                );
                let t = file_type(path);
                assert!(
                    t.is_socket() || t.is_block_device(),
                    "{name} replaced {what}"
                );
            }
        }
        std::fs::remove_dir_all(&root).unwrap();
    }
}

/// Issue 80: `holo dataset` whose `--out` holds a `manifest.json` that is a FIFO (no reader) or a link to
/// /dev/null is refused at once naming it: without --force as a folder holding a dataset, with --force (which
/// reads the old manifest: a FIFO would block the read, and removes it) as a node; the node stays.
#[cfg(target_os = "linux")]
#[test]
fn dataset_refuses_a_node_for_its_manifest_at_once() {
    let root = fresh("nodes-dataset");
    let out = root.join("ds");
    std::fs::create_dir_all(&out).unwrap();
    let manifest = out.join("manifest.json");
    for node in ["fifo", "null"] {
        let _ = std::fs::remove_file(&manifest);
        if node == "fifo" {
            assert!(std::process::Command::new("mkfifo")
                .arg(&manifest)
                .status()
                .unwrap()
                .success());
        } else {
            std::os::unix::fs::symlink("/dev/null", &manifest).unwrap();
        }
        for force in [false, true] {
            let mut args: Vec<&str> = common::ONE_SAMPLE_DATASET.to_vec();
            args.extend(["--out", out.to_str().unwrap()]);
            if force {
                args.push("--force");
            }
            let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_holo"))
                .args(&args)
                .env("RUST_LOG", "warn")
                .stderr(std::process::Stdio::piped())
                .stdout(std::process::Stdio::null())
                .spawn()
                .unwrap();
            let start = std::time::Instant::now();
            while child.try_wait().unwrap().is_none() {
                if start.elapsed() > std::time::Duration::from_secs(60) {
                    let _ = child.kill();
                    panic!("dataset {node} (force {force}) waits on manifest.json");
                }
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            let o = child.wait_with_output().unwrap();
            let e = stderr(&o);
            assert!(
                !o.status.success()
                    && e.contains("manifest.json")
                    && (!force || e.contains("not a dataset manifest")),
                "{node} (force {force}): {e}"
            );
            let meta = std::fs::symlink_metadata(&manifest).unwrap();
            assert!(
                meta.file_type().is_symlink() || !meta.is_file(),
                "{node}: manifest.json was replaced"
            );
            let shards = std::fs::read_dir(&out).unwrap().count();
            assert_eq!(
                shards, 1,
                "{node} (force {force}): the refused run wrote into --out"
            );
        }
    }
    std::fs::remove_dir_all(&root).unwrap();
}
