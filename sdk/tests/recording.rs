//! Phone recordings (issue 80): an entry that exists but is not what the layout needs is named for what it is,
//! in Record3D and Stray Scanner alike (not reported as missing); Stray Scanner's odometry refuses a frame
//! listed twice, two frames at one timestamp and a span that is not finite and positive; its intrinsics are
//! finite.
#![cfg(all(feature = "research", unix))]

use std::fs;
use std::path::{Path, PathBuf};

use tensorholo::scene::{open_recording, RecordingKind};

/// A Record3D export of frames 0 and 1 (empty files: listing reads none of them).
fn record3d(root: &Path) -> PathBuf {
    let dir = root.join("r3d");
    fs::create_dir_all(dir.join("rgb")).unwrap();
    fs::create_dir_all(dir.join("depth")).unwrap();
    fs::write(dir.join("metadata.json"), r#"{"fps": 30}"#).unwrap();
    for i in 0..2 {
        fs::write(dir.join(format!("rgb/{i}.jpg")), b"").unwrap();
        fs::write(dir.join(format!("depth/{i}.exr")), b"").unwrap();
    }
    dir
}

/// A Stray Scanner folder of frames 0, 1 and 2 with `odometry` (timestamp, frame per line).
fn stray(root: &Path, odometry: &str) -> PathBuf {
    let dir = root.join("stray");
    fs::create_dir_all(dir.join("rgb")).unwrap();
    fs::create_dir_all(dir.join("depth")).unwrap();
    fs::write(
        dir.join("camera_matrix.csv"),
        "500.0,0.0,320.0\n0.0,500.0,240.0\n0.0,0.0,1.0\n",
    )
    .unwrap();
    fs::write(
        dir.join("odometry.csv"),
        format!("timestamp, frame, x, y, z, qx, qy, qz, qw\n{odometry}"),
    )
    .unwrap();
    for i in 0..3 {
        fs::write(dir.join(format!("rgb/{i:06}.png")), b"").unwrap();
        fs::write(dir.join(format!("depth/{i:06}.png")), b"").unwrap();
    }
    dir
}

const ODOMETRY: &str = "1.0, 0, 0,0,0,0,0,0,1\n1.5, 1, 0,0,0,0,0,0,1\n2.0, 2, 0,0,0,0,0,0,1\n";

fn mkfifo(path: &Path) {
    assert!(std::process::Command::new("mkfifo")
        .arg(path)
        .status()
        .unwrap()
        .success());
}

/// Replaces the entry `path` by `kind`: a folder, a FIFO, a link to /dev/zero, a looping or a dangling link.
fn replace(path: &Path, kind: &str) {
    if path.is_dir() {
        fs::remove_dir_all(path).unwrap();
    } else {
        let _ = fs::remove_file(path);
    }
    match kind {
        "folder" => fs::create_dir(path).unwrap(),
        "fifo" => mkfifo(path),
        "device" => std::os::unix::fs::symlink("/dev/zero", path).unwrap(),
        "loop" => std::os::unix::fs::symlink(path, path).unwrap(),
        "dangling" => std::os::unix::fs::symlink(path.with_extension("gone"), path).unwrap(),
        "file" => fs::write(path, b"").unwrap(),
        other => panic!("{other}"),
    }
}

/// What the message says for each kind of entry.
fn said(kind: &str) -> &'static str {
    match kind {
        "folder" => "is a folder",
        "fifo" => "is a FIFO",
        "device" => "is a symbolic link to a character device",
        "loop" => "is a looping symbolic link",
        "dangling" => "is a dangling symbolic link",
        "file" => "is a file",
        other => panic!("{other}"),
    }
}

#[test]
fn every_entry_of_either_layout_that_is_not_what_it_needs_is_named_for_what_it_is() {
    let cases: &[(&str, &str, &[&str])] = &[
        (
            "r3d",
            "metadata.json",
            &["folder", "fifo", "device", "loop", "dangling"],
        ),
        (
            "r3d",
            "depth",
            &["file", "fifo", "device", "loop", "dangling"],
        ),
        ("r3d", "rgb", &["file", "fifo", "device", "loop"]),
        (
            "r3d",
            "depth/1.exr",
            &["folder", "fifo", "device", "loop", "dangling"],
        ),
        (
            "r3d",
            "rgb/0.jpg",
            &["folder", "fifo", "device", "loop", "dangling"],
        ),
        (
            "stray",
            "odometry.csv",
            &["folder", "fifo", "device", "loop", "dangling"],
        ),
        (
            "stray",
            "camera_matrix.csv",
            &["folder", "fifo", "device", "loop", "dangling"],
        ),
        (
            "stray",
            "rgb",
            &["file", "fifo", "device", "loop", "dangling"],
        ),
        (
            "stray",
            "depth",
            &["file", "fifo", "device", "loop", "dangling"],
        ),
        (
            "stray",
            "depth/000001.png",
            &["folder", "fifo", "device", "loop", "dangling"],
        ),
        (
            "stray",
            "rgb/000002.png",
            &["folder", "fifo", "device", "loop", "dangling"],
        ),
    ];
    for &(layout, entry, kinds) in cases {
        for &kind in kinds {
            let root = tempfile::tempdir().unwrap();
            let dir = if layout == "r3d" {
                record3d(root.path())
            } else {
                stray(root.path(), ODOMETRY)
            };
            // The folder as made is a recording of its layout.
            let r = open_recording(&dir).unwrap_or_else(|e| panic!("{layout}: {e}"));
            assert_eq!(r.frames.len(), if layout == "r3d" { 2 } else { 3 });
            let path = dir.join(entry);
            replace(&path, kind);
            let e = open_recording(&dir)
                .expect_err(&format!("{layout}: {entry} as {kind} was accepted"))
                .to_string();
            assert!(
                e.contains(&path.display().to_string()) && e.contains(said(kind)),
                "{layout}: {entry} as {kind}: {e}"
            );
        }
    }
}

#[test]
fn stray_scanner_odometry_refuses_duplicates_one_timestamp_twice_and_a_span_that_overflows() {
    let refused = [
        (
            "1.0, 0, 0,0,0,0,0,0,1\n1.5, 1, 0,0,0,0,0,0,1\n2.0, 2, 0,0,0,0,0,0,1\n2.5, 1, 0,0,0,0,0,0,1\n",
            "frame 1 is listed twice (first on line 3)",
        ),
        (
            "1.0, 0, 0,0,0,0,0,0,1\n1.5, 1, 0,0,0,0,0,0,1\n1.5, 2, 0,0,0,0,0,0,1\n",
            "two frames at one timestamp",
        ),
        (
            "-1e308, 0, 0,0,0,0,0,0,1\n0, 1, 0,0,0,0,0,0,1\n1e308, 2, 0,0,0,0,0,0,1\n",
            "not a finite, positive time",
        ),
    ];
    for (odometry, what) in refused {
        let root = tempfile::tempdir().unwrap();
        let dir = stray(root.path(), odometry);
        let e = open_recording(&dir).unwrap_err().to_string();
        assert!(e.contains("odometry.csv") && e.contains(what), "{e}");
    }
    // Timestamps in any order stay valid: frames run in timestamp order.
    let root = tempfile::tempdir().unwrap();
    let dir = stray(
        root.path(),
        "2.0, 0, 0,0,0,0,0,0,1\n1.0, 1, 0,0,0,0,0,0,1\n3.0, 2, 0,0,0,0,0,0,1\n",
    );
    let r = open_recording(&dir).unwrap();
    assert_eq!(r.kind, RecordingKind::StrayScanner);
    let order: Vec<u64> = r.frames.iter().map(|f| f.number).collect();
    assert_eq!(order, [1, 0, 2]);
    assert_eq!(r.fps, Some(1.0));
}

#[test]
fn stray_scanner_intrinsics_are_finite_with_positive_focal_lengths() {
    for matrix in [
        "nan,0,320\n0,500,240\n0,0,1\n",
        "500,0,inf\n0,500,240\n0,0,1\n",
        "-500,0,320\n0,500,240\n0,0,1\n",
    ] {
        let root = tempfile::tempdir().unwrap();
        let dir = stray(root.path(), ODOMETRY);
        fs::write(dir.join("camera_matrix.csv"), matrix).unwrap();
        let e = open_recording(&dir).unwrap_err().to_string();
        assert!(
            e.contains("camera_matrix.csv") && e.contains("finite"),
            "{matrix}: {e}"
        );
    }
}
