//! End-to-end tests of `holo dataset`: shards, manifest, previews, refusing an existing dataset.

mod common;

use common::{holo, png_size, stderr};

use std::path::Path;
use std::process::Output;

use ndarray::{Array1, Array4, Ix4, OwnedRepr};
use ndarray_npy::NpzReader;
use num_complex::Complex32;

const TINY: [&str; 14] = [
    "dataset",
    "--train",
    "2",
    "--val",
    "1",
    "--test",
    "1",
    "--size",
    "32",
    "--levels",
    "16",
    "--shard-size",
    "2",
    "--threads=2",
];

fn run_tiny(out: &Path, extra: &[&str]) -> Output {
    let mut args: Vec<&str> = TINY.to_vec();
    args.extend_from_slice(&["--out", out.to_str().unwrap()]);
    args.extend_from_slice(extra);
    holo(&args)
}

#[test]
fn dataset_writes_shards_manifest_and_previews() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ds");
    let o = run_tiny(&out, &["--seed", "3", "--previews", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));

    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["format_version"], 1);
    assert_eq!(m["seed"], 3);
    assert_eq!(m["resolution"], serde_json::json!([32, 32]));
    assert_eq!(m["ldi_layers"], 5);
    assert_eq!(m["synthesis"]["levels"], 16);
    assert_eq!(m["optics"]["pixel_pitch_m"], 8e-6);
    assert_eq!(m["compressed"], true);
    assert_eq!(m["generator"]["command"][1], "dataset");
    assert!(m["generator"]["git_commit"].as_str().unwrap().len() >= 7);
    let splits = m["splits"].as_array().unwrap();
    let summary: Vec<(String, u64, usize)> = splits
        .iter()
        .map(|s| {
            (
                s["name"].as_str().unwrap().to_string(),
                s["samples"].as_u64().unwrap(),
                s["shards"].as_array().unwrap().len(),
            )
        })
        .collect();
    assert_eq!(
        summary,
        [
            ("train".to_string(), 2, 1),
            ("val".to_string(), 1, 1),
            ("test".to_string(), 1, 1)
        ]
    );
    assert_eq!(m["statistics"]["samples"], 4);

    for (file, n) in [
        ("train-00000.npz", 2),
        ("val-00000.npz", 1),
        ("test-00000.npz", 1),
    ] {
        let mut npz = NpzReader::new(std::fs::File::open(out.join(file)).unwrap()).unwrap();
        let ldi: Array4<f32> = npz.by_name("ldi").unwrap();
        let valid: Array4<u8> = npz.by_name("ldi_valid").unwrap();
        let mid: Array4<Complex32> = npz.by_name("midpoint").unwrap();
        let index: Array1<u64> = npz.by_name("index").unwrap();
        assert_eq!(ldi.dim(), (n, 20, 32, 32), "{file}");
        assert_eq!(valid.dim(), (n, 5, 32, 32), "{file}");
        assert_eq!(mid.dim(), (n, 3, 32, 32), "{file}");
        assert_eq!(index.to_vec(), (0..n as u64).collect::<Vec<_>>());
        assert!(valid
            .index_axis(ndarray::Axis(1), 0)
            .iter()
            .all(|&v| v == 1));
        assert!(ldi.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(mid.iter().all(|v| v.is_finite()) && mid.iter().any(|v| v.norm() > 0.05));
        // The LDI is stored as f32, not f64.
        assert!(npz.by_name::<OwnedRepr<f64>, Ix4>("ldi").is_err());
    }
    for i in 0..2 {
        let p = |s: &str| out.join(format!("previews/train_{i:05}_{s}.png"));
        assert_eq!(png_size(&p("rgb")), (32, 32));
        assert_eq!(png_size(&p("depth")), (32, 32));
        assert_eq!(png_size(&p("layers")), (5 * 32, 64));
    }
    assert!(!out.join("previews/train_00002_rgb.png").exists());

    // The same seed regenerates identical shards (uncompressed and compressed hold the same arrays).
    let again = dir.path().join("again");
    let o = run_tiny(
        &again,
        &["--seed", "3", "--previews", "0", "--uncompressed"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let read = |d: &Path| {
        let mut npz =
            NpzReader::new(std::fs::File::open(d.join("val-00000.npz")).unwrap()).unwrap();
        let ldi: Array4<f32> = npz.by_name("ldi").unwrap();
        let mid: Array4<Complex32> = npz.by_name("midpoint").unwrap();
        (ldi, mid)
    };
    assert_eq!(read(&out), read(&again));
    assert!(!again.join("previews").exists());
    let compressed = std::fs::metadata(out.join("val-00000.npz")).unwrap().len();
    let plain = std::fs::metadata(again.join("val-00000.npz"))
        .unwrap()
        .len();
    assert!(compressed < plain, "{compressed} >= {plain}");
}

#[test]
fn dataset_refuses_an_existing_dataset_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ds");
    assert!(run_tiny(&out, &["--previews", "0"]).status.success());
    let before = std::fs::read(out.join("manifest.json")).unwrap();
    let o = run_tiny(&out, &["--previews", "0", "--seed", "9"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("already holds a dataset") && stderr(&o).contains("--force"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(out.join("manifest.json")).unwrap(), before);
    let o = run_tiny(&out, &["--previews", "0", "--seed", "9", "--force"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["seed"], 9);
}

#[test]
fn dataset_arguments_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ds");
    let out = out.to_str().unwrap();
    let cases: [(&[&str], &str); 5] = [
        (
            &["dataset", "--out", out, "--shapes", "10-5"],
            "MIN must not exceed MAX",
        ),
        (
            &["dataset", "--out", out, "--size", "0"],
            "positive integer",
        ),
        (&["dataset", "--out", out, "--layers", "0"], "layers"),
        (
            &["dataset", "--out", out, "--shard-size", "0"],
            "shard_size",
        ),
        (
            &[
                "dataset",
                "--out",
                out,
                "--size",
                "16",
                "--photos",
                "/no/such/folder",
            ],
            "/no/such/folder",
        ),
    ];
    for (args, needle) in cases {
        let o = holo(args);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(stderr(&o).contains(needle), "{args:?}: {}", stderr(&o));
    }
    assert!(!Path::new(out).join("manifest.json").exists());
}

#[test]
fn dataset_never_writes_over_a_photo() {
    // Photos in the output folder: a preview name that collides with a photo is refused.
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("previews");
    std::fs::create_dir_all(&photos).unwrap();
    let photo = photos.join("train_00000_rgb.png");
    image::RgbImage::from_fn(16, 16, |x, y| {
        image::Rgb([(x * 16) as u8, (y * 16) as u8, 90])
    })
    .save(&photo)
    .unwrap();
    let before = std::fs::read(&photo).unwrap();
    let o = run_tiny(dir.path(), &["--photos", photos.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("refusing to overwrite input"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(&photo).unwrap(), before);
}
