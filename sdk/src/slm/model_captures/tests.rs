//! The capture manifest: a good one reads back, and each bad input is refused naming its entry.

use std::path::Path;

use ndarray::Array2;

use super::*;
use crate::slm::simulate::write_grey_png;

/// A folder with two 8×8 patterns, three captures and their manifest; `edit` changes the entries first.
fn bench(dir: &Path, edit: impl FnOnce(&mut Vec<ManifestEntry>)) -> std::path::PathBuf {
    let patterns = capture_patterns(8, 8, 1);
    for (k, p) in patterns.iter().take(2).enumerate() {
        crate::io::save_u8_png(&dir.join(format!("p{k}.png")), p.view()).unwrap();
    }
    let grey = Array2::from_shape_fn((8, 8), |(i, j)| (i * 8 + j) as f32 / 100.0);
    for k in 0..3 {
        write_grey_png(&dir.join(format!("c{k}.png")), grey.view(), 16).unwrap();
    }
    let entry = |p: usize, d: f64, c: usize| ManifestEntry {
        pattern: format!("p{p}.png"),
        colour: "green".into(),
        distance_m: d,
        capture: Some(format!("c{c}.png")),
    };
    let mut entries = vec![entry(0, -0.003, 0), entry(0, 0.003, 1), entry(1, -0.003, 2)];
    edit(&mut entries);
    let file = ManifestFile {
        format: CAPTURES_FORMAT.into(),
        version: CAPTURES_VERSION,
        captures: entries,
    };
    let path = dir.join("manifest.json");
    std::fs::write(&path, serde_json::to_string(&file).unwrap()).unwrap();
    path
}

#[test]
fn a_manifest_reads_its_patterns_and_captures() {
    let dir = tempfile::tempdir().unwrap();
    let set = CaptureSet::read(&bench(dir.path(), |_| {})).unwrap();
    assert_eq!(set.size, (8, 8));
    assert_eq!(set.patterns.len(), 2);
    assert_eq!(
        set.patterns[0],
        capture_patterns(8, 8, 1)[0]
            .iter()
            .copied()
            .collect::<Vec<_>>()
    );
    assert_eq!(set.captures.len(), 3);
    assert_eq!(set.captures[1].distance_m, 0.003);
    assert!((set.captures[2].intensity[9] - 0.09).abs() < 1e-4);
    assert!(set.captures.iter().all(|c| c.valid.iter().all(|&v| v)));
}

#[test]
fn bad_manifests_are_refused_naming_the_entry() {
    type Edit = Box<dyn FnOnce(&Path, &mut Vec<ManifestEntry>)>;
    let cases: Vec<(&str, Edit)> = vec![
        (
            "captures[1]",
            Box::new(|_, e| e[1].capture = Some("missing.png".into())),
        ),
        (
            "captures[2]",
            Box::new(|_, e| {
                e[2] = ManifestEntry {
                    distance_m: -0.003,
                    ..e[0].clone()
                }
            }),
        ),
        (
            "captures[2]",
            Box::new(|_, e| e[2].capture = e[0].capture.clone()),
        ),
        (
            "captures[1]",
            Box::new(|_, e| e[1].colour = "yellow".into()),
        ),
        (
            "captures[2]",
            Box::new(|d, e| {
                let small = Array2::<u8>::zeros((6, 8));
                crate::io::save_u8_png(&d.join("small.png"), small.view()).unwrap();
                e[2].pattern = "small.png".into();
            }),
        ),
        (
            "captures[0]",
            Box::new(|d, _| {
                let big = Array2::<f32>::zeros((8, 9));
                write_grey_png(&d.join("c0.png"), big.view(), 8).unwrap();
            }),
        ),
        (
            "captures[1]",
            Box::new(|d, _| {
                // 2 of 64 pixels at full scale: more than 1 %.
                let mut sat = Array2::<f32>::from_elem((8, 8), 0.5);
                sat[[0, 0]] = 1.0;
                sat[[3, 3]] = 1.0;
                write_grey_png(&d.join("c1.png"), sat.view(), 16).unwrap();
            }),
        ),
    ];
    for (k, (named, edit)) in cases.into_iter().enumerate() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().to_path_buf();
        let path = bench(&d, |e| edit(&d, e));
        let err = CaptureSet::read(&path).unwrap_err().to_string();
        assert!(err.contains(named), "case {k}: {err}");
    }
    // A non-finite distance cannot be written in JSON: a number out of range is refused at its key.
    let dir = tempfile::tempdir().unwrap();
    let path = bench(dir.path(), |_| {});
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("\"distance_m\":0.003", "\"distance_m\":1e999");
    std::fs::write(&path, text).unwrap();
    let err = CaptureSet::read(&path).unwrap_err().to_string();
    assert!(err.contains("captures[1].distance_m"), "{err}");
}

#[test]
fn a_few_saturated_pixels_are_left_out_of_the_fit() {
    let dir = tempfile::tempdir().unwrap();
    let path = bench(dir.path(), |_| {});
    let mut img = Array2::<f32>::from_elem((16, 16), 0.5);
    img[[2, 2]] = 1.0;
    write_grey_png(&dir.path().join("c0.png"), img.view(), 16).unwrap();
    // Another size than the patterns' now: make the patterns 16×16 too.
    let patterns = capture_patterns(16, 16, 1);
    for (k, p) in patterns.iter().take(2).enumerate() {
        crate::io::save_u8_png(&dir.path().join(format!("p{k}.png")), p.view()).unwrap();
    }
    for k in 1..3 {
        write_grey_png(
            &dir.path().join(format!("c{k}.png")),
            Array2::<f32>::zeros((16, 16)).view(),
            16,
        )
        .unwrap();
    }
    let set = CaptureSet::read(&path).unwrap();
    assert_eq!(set.captures[0].valid.iter().filter(|&&v| !v).count(), 1);
    assert!(!set.captures[0].valid[2 * 16 + 2]);
}
