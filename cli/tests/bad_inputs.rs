//! The bad-input matrix of `holo` (issue 13): for each command, one case per class of bad input (unreadable,
//! truncated or corrupt files, sizes beyond the limits, probably-wrong data, bad parameters, files where folders
//! belong). Every case must:
//!
//! - exit with code 1 (a refusal) or 2 (a usage error caught by the argument parser), never 0 (silently
//!   wrong), 70 (a caught panic), 101 or a signal (abort);
//! - name what was wrong (the file or the parameter) in its message;
//! - leave every input byte-identical;
//! - leave no file in its output folder (no partial run).

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::{holo, shared, stderr};
use ndarray::{Array2, Array3};
use tensorholo::io::{save_amplitude_png, write_complex_npy, write_f32_npy};
use tensorholo::Complex32;

/// Every file under `dir` (recursively) with its bytes.
fn snapshot(paths: &[PathBuf]) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack: Vec<PathBuf> = paths.to_vec();
    while let Some(p) = stack.pop() {
        if p.is_dir() {
            for e in std::fs::read_dir(&p).unwrap() {
                stack.push(e.unwrap().path());
            }
        } else if p.is_file() {
            out.insert(p.clone(), std::fs::read(&p).unwrap());
        }
    }
    out
}

fn files_under(dir: &Path) -> Vec<PathBuf> {
    snapshot(&[dir.to_path_buf()]).into_keys().collect()
}

struct Inputs {
    dir: PathBuf,
    rgb: PathBuf,
    depth: PathBuf,
}

impl Inputs {
    fn path(&self, name: &str) -> String {
        self.dir.join(name).display().to_string()
    }
}

/// Good inputs (the Redwood pair, read in place) and every bad file the cases use, in a fresh folder.
fn inputs(tag: &str) -> Inputs {
    let dir = std::env::temp_dir().join(format!("holo-bad-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let rgb = shared("redwood_livingroom_seq/color/00000.jpg");
    let depth = shared("redwood_livingroom_seq/depth/00000.png");
    let jpg = std::fs::read(&rgb).unwrap();
    std::fs::write(dir.join("truncated.jpg"), &jpg[..jpg.len() * 6 / 10]).unwrap();
    let png = std::fs::read(&depth).unwrap();
    std::fs::write(dir.join("truncated.png"), &png[..png.len() / 2]).unwrap();
    std::fs::write(dir.join("garbage.png"), b"this is not an image").unwrap();
    std::fs::write(dir.join("empty.png"), b"").unwrap();
    // 12000 x 12000 RGB declared in 49 bytes (the header is read first; nothing is decoded).
    let mut huge = b"\x89PNG\r\n\x1a\n\x00\x00\x00\x0dIHDR".to_vec();
    let ihdr = [
        12000u32.to_be_bytes().as_slice(),
        12000u32.to_be_bytes().as_slice(),
        &[8, 2, 0, 0, 0],
    ]
    .concat();
    huge.extend_from_slice(&ihdr);
    huge.extend_from_slice(&crc32fast::hash(&[b"IHDR".as_slice(), &ihdr].concat()).to_be_bytes());
    // An empty IDAT and IEND: the decoder reads the size from a complete header.
    huge.extend_from_slice(
        b"\x00\x00\x00\x00IDAT\x35\xaf\x06\x1e\x00\x00\x00\x00IEND\xae\x42\x60\x82",
    );
    std::fs::write(dir.join("huge.png"), huge).unwrap();
    std::fs::write(
        dir.join("overflow.pgm"),
        b"P5\n18446744073709551615 18446744073709551615\n2047\n\x00\x00",
    )
    .unwrap();
    save_amplitude_png(
        &dir.join("black.png"),
        Array3::zeros((3, 480, 640)).view(),
        1.0,
    )
    .unwrap();
    let mut field = Array3::from_elem((3, 16, 16), Complex32::new(1.0, 0.0));
    field[[1, 3, 4]] = Complex32::new(f32::NAN, 0.0);
    write_complex_npy(&dir.join("nan.npy"), field.view()).unwrap();
    write_f32_npy(&dir.join("real.npy"), Array2::<f32>::zeros((16, 16)).view()).unwrap();
    let npy = std::fs::read(dir.join("nan.npy")).unwrap();
    std::fs::write(dir.join("short.npy"), &npy[..npy.len() - 9]).unwrap();
    std::fs::write(
        dir.join("corrupt.onnx"),
        b"\x08\x07\x12\x04junk\x1a\x00not onnx",
    )
    .unwrap();
    std::fs::write(
        dir.join("corrupt.holocal"),
        b"HOLOCAL\x00\x01\x00\x00\x00\xff\xff\xff\xff",
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("a_folder.png")).unwrap();
    // Video folders: one frame truncated, one RGB frame without its depth.
    for (sub, files) in [
        (
            "v_trunc",
            vec![
                ("rgb/00000.jpg", jpg[..jpg.len() / 2].to_vec()),
                ("depth/00000.png", png.clone()),
            ],
        ),
        (
            "v_unmatched",
            vec![
                ("rgb/00000.jpg", jpg.clone()),
                ("rgb/00001.jpg", jpg.clone()),
                ("depth/00000.png", png.clone()),
            ],
        ),
    ] {
        for (name, bytes) in files {
            let p = dir.join(sub).join(name);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, bytes).unwrap();
        }
    }
    Inputs { dir, rgb, depth }
}

/// Runs each case `(name, args without --out, needles)` with `--out` (or `--output`) set to a fresh folder,
/// and checks the four rules of the module docs. All failures are collected, then reported together.
fn run_matrix(ins: &Inputs, out_flag: &str, cases: Vec<(&str, Vec<String>, Vec<&str>)>) {
    let watched = vec![ins.dir.clone(), ins.rgb.clone(), ins.depth.clone()];
    let before = snapshot(&watched);
    let mut failures = Vec::new();
    for (i, (name, args, needles)) in cases.into_iter().enumerate() {
        let out = ins.dir.join(format!("out-{i}"));
        let mut all: Vec<String> = args;
        if !out_flag.is_empty() {
            all.push(out_flag.into());
            all.push(
                out.join(if out_flag == "--output" {
                    "field.npy"
                } else {
                    ""
                })
                .display()
                .to_string(),
            );
        }
        let o = holo(&all.iter().map(String::as_str).collect::<Vec<_>>());
        let msg = stderr(&o);
        let last = msg
            .lines()
            .rev()
            .find(|l| l.contains("error"))
            .unwrap_or("")
            .to_string();
        if !matches!(o.status.code(), Some(1 | 2)) {
            failures.push(format!(
                "{name}: exit {:?} (want 1 or 2): {last}",
                o.status.code()
            ));
            continue;
        }
        for needle in &needles {
            if !msg.contains(needle) {
                failures.push(format!("{name}: message does not name `{needle}`: {last}"));
            }
        }
        if out.exists() {
            let left = files_under(&out);
            if !left.is_empty() {
                failures.push(format!("{name}: left files in its output folder: {left:?}"));
            }
        }
        std::fs::remove_dir_all(&out).ok();
        let now = snapshot(&watched);
        if now != before {
            let changed: Vec<_> = now
                .keys()
                .filter(|k| before.get(*k) != now.get(*k))
                .collect();
            failures.push(format!("{name}: inputs changed: {changed:?}"));
        }
    }
    assert!(
        failures.is_empty(),
        "{} case(s) failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

fn s(v: &[&str]) -> Vec<String> {
    v.iter().map(|x| x.to_string()).collect()
}

#[test]
fn render_and_reference_refuse_every_bad_input_cleanly() {
    let ins = inputs("render");
    let (rgb, depth) = (
        ins.rgb.display().to_string(),
        ins.depth.display().to_string(),
    );
    let pair = |r: &str, d: &str, extra: &[&str]| {
        let mut v = s(&[
            "render",
            "--rgb",
            r,
            "--depth",
            d,
            "--depth-encoding",
            "mm16",
            "--repeat",
            "0",
        ]);
        if !extra.contains(&"--size") {
            v.extend(s(&["--size", "24x32"]));
        }
        v.extend(s(extra));
        v
    };
    let p = |n: &str| ins.path(n);
    let mut cases = vec![
        (
            "truncated JPEG",
            pair(&p("truncated.jpg"), &depth, &[]),
            vec!["truncated.jpg", "truncated"],
        ),
        (
            "truncated PNG depth",
            pair(&rgb, &p("truncated.png"), &[]),
            vec!["truncated.png"],
        ),
        (
            "not an image",
            pair(&p("garbage.png"), &depth, &[]),
            vec!["garbage.png"],
        ),
        (
            "empty file",
            pair(&p("empty.png"), &depth, &[]),
            vec!["empty.png"],
        ),
        (
            "missing file",
            pair(&p("missing.png"), &depth, &[]),
            vec!["missing.png"],
        ),
        (
            "folder for a file",
            pair(&p("a_folder.png"), &depth, &[]),
            vec!["a_folder.png"],
        ),
        (
            "image above the pixel limit",
            pair(&p("huge.png"), &depth, &[]),
            vec!["huge.png", "--max-image-pixels"],
        ),
        (
            "file above the byte limit",
            pair(&rgb, &depth, &["--max-file-bytes", "1000"]),
            vec!["--max-file-bytes"],
        ),
        (
            "Kinect PGM size overflow",
            {
                let mut v = pair(&rgb, &p("overflow.pgm"), &[]);
                v[6] = "kinect-disparity".into();
                v
            },
            vec!["overflow.pgm"],
        ),
        (
            "wrong depth encoding",
            {
                let mut v = pair(&rgb, &depth, &[]);
                v[6] = "relative-near-bright".into();
                v
            },
            vec!["depth encoding"],
        ),
        (
            "metric range excluding the data",
            pair(&rgb, &depth, &["--z-near-m", "20", "--z-far-m", "30"]),
            vec!["--z-near-m"],
        ),
        (
            "frame below the SSIM window",
            pair(&rgb, &depth, &["--size", "8x8"]),
            vec!["8×8"],
        ),
        (
            "black frame",
            pair(&p("black.png"), &depth, &[]),
            vec!["black.png", "black"],
        ),
        (
            "zero size",
            pair(&rgb, &depth, &["--size", "0x0"]),
            vec!["--size"],
        ),
        (
            "huge size",
            pair(&rgb, &depth, &["--size", "20000x20000"]),
            vec!["size"],
        ),
        (
            "absurd thread count",
            pair(&rgb, &depth, &["--threads", "100000"]),
            vec!["threads"],
        ),
        (
            "corrupt model",
            pair(&rgb, &depth, &["--model", &p("corrupt.onnx")]),
            vec!["corrupt.onnx"],
        ),
        (
            "corrupt calibration",
            pair(&rgb, &depth, &["--calibration", &p("corrupt.holocal")]),
            vec!["corrupt.holocal"],
        ),
        (
            "RGB without depth",
            s(&["render", "--rgb", &rgb, "--size", "24x32"]),
            vec!["--depth"],
        ),
    ];
    let reference = |r: &str, extra: &[&str]| {
        let mut v = s(&[
            "reference",
            "--rgb",
            r,
            "--depth",
            &depth,
            "--depth-encoding",
            "mm16",
        ]);
        for (flag, default) in [("--size", "24x32"), ("--levels", "8")] {
            if !extra.contains(&flag) {
                v.extend(s(&[flag, default]));
            }
        }
        v.extend(s(extra));
        v
    };
    cases.extend([
        (
            "reference: truncated JPEG",
            reference(&p("truncated.jpg"), &[]),
            vec!["truncated.jpg"],
        ),
        (
            "reference: black frame",
            reference(&p("black.png"), &[]),
            vec!["black.png", "black"],
        ),
        (
            "reference: frame below the SSIM window",
            reference(&rgb, &["--size", "8x8"]),
            vec!["8×8"],
        ),
        (
            "reference: zero levels",
            reference(&rgb, &["--levels", "0"]),
            vec!["levels"],
        ),
        // An offset beyond any display (1 m) is a typing or unit error, named, not a zero hologram.
        (
            "render: an offset of 1e308 mm",
            pair(&rgb, &depth, &["--offset-mm", "1e308"]),
            vec!["--offset-mm", "1e308", "1000 mm"],
        ),
        (
            "render: an offset of 5 m",
            pair(&rgb, &depth, &["--offset-mm", "5000"]),
            vec!["--offset-mm", "5000"],
        ),
        (
            "reference: an offset of -1e308 mm",
            reference(&rgb, &["--offset-mm=-1e308"]),
            vec!["--offset-mm", "1000 mm"],
        ),
    ]);
    run_matrix(&ins, "--out", cases);
    std::fs::remove_dir_all(&ins.dir).unwrap();
}

#[test]
fn field_commands_video_and_calibrate_refuse_every_bad_input_cleanly() {
    let ins = inputs("fields");
    let p = |n: &str| ins.path(n);
    let enc = |f: &str| s(&["encode", "--input", f]);
    run_matrix(
        &ins,
        "--out",
        vec![
            (
                "encode: NaN in the field",
                enc(&p("nan.npy")),
                vec!["nan.npy", "NaN"],
            ),
            (
                "encode: real dtype",
                enc(&p("real.npy")),
                vec!["real.npy", "<f4"],
            ),
            (
                "encode: truncated .npy",
                enc(&p("short.npy")),
                vec!["short.npy"],
            ),
            (
                "encode: not a .npy",
                enc(&p("garbage.png")),
                vec!["garbage.png"],
            ),
            (
                "encode: missing",
                enc(&p("missing.npy")),
                vec!["missing.npy"],
            ),
            (
                "encode: no depths",
                [enc(&p("nan.npy")), s(&["--depths", ""])].concat(),
                vec!["--depths"],
            ),
        ],
    );
    let prop = |f: &str| {
        s(&[
            "propagate",
            "--input",
            f,
            "--distance-m",
            "1e-3",
            "--wavelength-m",
            "520e-9",
            "--pitch-m",
            "8e-6",
        ])
    };
    run_matrix(
        &ins,
        "--output",
        vec![
            ("propagate: NaN", prop(&p("nan.npy")), vec!["NaN"]),
            (
                "propagate: truncated",
                prop(&p("short.npy")),
                vec!["short.npy"],
            ),
            (
                "propagate: real dtype",
                prop(&p("real.npy")),
                vec!["real.npy"],
            ),
            (
                "propagate: infinite distance",
                {
                    let mut v = prop(&p("nan.npy"));
                    v[4] = "inf".into();
                    v
                },
                vec!["distance"],
            ),
        ],
    );
    let video = |sub: &str, extra: &[&str]| {
        let mut v = s(&[
            "video",
            "--rgb-dir",
            &p(&format!("{sub}/rgb")),
            "--depth-dir",
            &p(&format!("{sub}/depth")),
            "--depth-encoding",
            "mm16",
            "--size",
            "24x32",
            "--save-frames",
        ]);
        v.extend(s(extra));
        v
    };
    run_matrix(
        &ins,
        "--out",
        vec![
            (
                "video: truncated frame",
                video("v_trunc", &[]),
                vec!["00000.jpg"],
            ),
            (
                "video: unmatched frames",
                video("v_unmatched", &[]),
                vec!["00001.jpg", "--skip-unmatched"],
            ),
            (
                "video: missing folder",
                video("v_missing", &[]),
                vec!["v_missing"],
            ),
            (
                "video: zero limit",
                video("v_trunc", &["--limit", "0"]),
                vec!["--limit"],
            ),
        ],
    );
    run_matrix(
        &ins,
        "--out",
        vec![
            (
                "calibrate black: corrupt file",
                s(&["calibrate", "black", &p("corrupt.holocal")]),
                vec!["corrupt.holocal"],
            ),
            (
                "calibrate black: missing file",
                s(&["calibrate", "black", &p("missing.holocal")]),
                vec!["missing.holocal"],
            ),
        ],
    );
    run_matrix(
        &ins,
        "",
        vec![
            (
                "bench: zero size",
                s(&["bench", "--sizes", "0x0"]),
                vec!["size"],
            ),
            (
                "bench: zero threads",
                s(&["bench", "--threads", "0"]),
                vec!["threads"],
            ),
            (
                "bench: absurd thread count",
                s(&["bench", "--threads", "100000"]),
                vec!["threads"],
            ),
            (
                "dataset: absurd thread count",
                s(&["dataset", "--out", &p("ds"), "--threads", "100000"]),
                vec!["--threads"],
            ),
            (
                "dataset: zero threads",
                s(&["dataset", "--out", &p("ds"), "--threads", "0"]),
                vec!["--threads"],
            ),
            (
                "dataset: zero size",
                s(&["dataset", "--out", &p("ds"), "--size", "0"]),
                vec!["size"],
            ),
        ],
    );
    std::fs::remove_dir_all(&ins.dir).unwrap();
}

#[cfg(unix)]
#[test]
fn ctrl_c_exits_130_and_leaves_no_report_and_no_temporary_file() {
    let dir = std::env::temp_dir().join(format!("holo-ctrl-c-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    let out = dir.join("out");
    // A previous complete run in the folder: its report must be gone after the interrupted re-run.
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
    assert!(out.join("report.json").exists());
    // A million timed repetitions of a frame: interrupted while it computes.
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_holo"))
        .args(["render", "--size", "64x64", "--repeat", "1000000", "--out"])
        .arg(&out)
        .env("RUST_LOG", "warn")
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let killed = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(stderr(&o).contains("interrupted"), "{}", stderr(&o));
    assert!(!out.join("report.json").exists());
    let temporaries: Vec<_> = files_under(&out)
        .into_iter()
        .filter(|p| p.to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(temporaries.is_empty(), "{temporaries:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Devices that never end (`/dev/zero`, `/dev/urandom`) given for any input file are refused naming the path
/// and what it is, before anything is read (issue 57: they used to grow to gigabytes).
#[cfg(unix)]
#[test]
fn devices_given_as_input_files_are_refused_naming_them() {
    let ins = inputs("devices");
    let (rgb, depth) = (
        ins.rgb.display().to_string(),
        ins.depth.display().to_string(),
    );
    let render = |extra: &[&str]| {
        let mut v = s(&["render", "--size", "40x56", "--repeat", "0"]);
        v.extend(s(extra));
        v
    };
    let cases = vec![
        (
            "render: /dev/zero as the colour image",
            s(&[
                "render",
                "--rgb",
                "/dev/zero",
                "--depth",
                &depth,
                "--depth-encoding",
                "mm16",
            ]),
            vec!["/dev/zero", "device"],
        ),
        (
            "render: /dev/urandom as the depth map",
            s(&[
                "render",
                "--rgb",
                &rgb,
                "--depth",
                "/dev/urandom",
                "--depth-encoding",
                "mm16",
            ]),
            vec!["/dev/urandom", "device"],
        ),
        (
            "render: /dev/zero as the model",
            render(&["--model", "/dev/zero"]),
            vec!["/dev/zero", "device"],
        ),
        (
            "render: /dev/zero as the calibration",
            render(&["--calibration", "/dev/zero"]),
            vec!["/dev/zero", "device"],
        ),
        (
            "render: /dev/zero as the tuning",
            render(&["--tuning", "/dev/zero"]),
            vec!["/dev/zero", "device"],
        ),
        (
            "reference: /dev/zero as the aberration file",
            s(&[
                "reference",
                "--size",
                "16x16",
                "--levels",
                "4",
                "--aberration",
                "/dev/zero",
            ]),
            vec!["/dev/zero", "device"],
        ),
        (
            "encode: /dev/zero as the field",
            s(&["encode", "--input", "/dev/zero"]),
            vec!["/dev/zero", "device"],
        ),
    ];
    run_matrix(&ins, "--out", cases);
}
