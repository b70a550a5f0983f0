//! Helpers shared by the `holo` end-to-end tests (each test file uses a subset).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the built `holo` binary with `args` (warnings only on stderr).
pub fn holo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_holo"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("holo runs")
}

/// `holo dataset` for one 24×24 training sample of 8 depth levels and 2 LDI layers, no previews (the caller
/// adds its options and `--out`).
pub const ONE_SAMPLE_DATASET: &[&str] = &[
    "dataset",
    "--train",
    "1",
    "--val",
    "0",
    "--test",
    "0",
    "--size",
    "24",
    "--levels",
    "8",
    "--layers",
    "2",
    "--previews",
    "0",
];

/// The captured stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A file of the third-party inputs in `../shared/data` (beside the repository).
pub fn shared(relative: &str) -> PathBuf {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data")
        .join(relative);
    assert!(p.exists(), "shared test data {} is missing", p.display());
    p
}

/// Width and height from a PNG's IHDR chunk.
pub fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[1..4], b"PNG", "{} is not a PNG", path.display());
    let be = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    (be(16), be(20))
}
