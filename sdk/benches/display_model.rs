//! Criterion benchmark of the display model's fit (`slm::model_fit::fit`, docs/CALIBRATION.md "The display
//! model") against the number of captures: a simulated 48×48 display (`holo calibrate model simulate`'s hidden
//! parameters, seed 1), the 8 test patterns of one colour at 3, 6 and 9 distances (24, 48 and 72 captures,
//! 16-bit PNGs with 1 % noise, written once to a temporary folder), fitted with the defaults (3×3 kernel, at
//! most 40 Levenberg–Marquardt iterations). Each sample reads the manifest and its PNGs, as
//! `holo calibrate model fit` does. The refinement's time per iteration through each part of a model is
//! `holo bench --refine N --display-model-parts …` (docs/BENCHMARKS.md).
//!
//! Run: `cargo bench -p tensorholo --bench display_model`.
#![allow(missing_docs)] // criterion_group! generates undocumented items

use std::path::Path;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use tensorholo::optics::OpticalSetup;
use tensorholo::slm::model_captures::{
    capture_patterns, simulate_display, ManifestEntry, ManifestFile, CAPTURES_FORMAT,
    CAPTURES_VERSION,
};
use tensorholo::slm::model_fit::{fit, FitOptions};
use tensorholo::slm::simulate::write_grey_png;

/// The SLM's side in pixels.
const SIDE: usize = 48;

/// Writes the 8 patterns and their captures of a simulated display, green at `distances` (metres), and the
/// manifest into `dir`; returns the manifest's path.
fn write_set(dir: &Path, distances: &[f64]) -> std::path::PathBuf {
    let setup = OpticalSetup::default();
    let patterns = capture_patterns(SIDE, SIDE, 7);
    let plan: Vec<(usize, usize, f64)> = (0..patterns.len())
        .flat_map(|p| distances.iter().map(move |&d| (p, 1, d)))
        .collect();
    let sim = simulate_display([SIDE, SIDE], &setup, &patterns, &plan, 0.01, 1)
        .expect("a valid simulated plan");
    for (k, p) in patterns.iter().enumerate() {
        tensorholo::io::save_u8_png(&dir.join(format!("pattern_{k}.png")), p.view())
            .expect("a writable folder");
    }
    let mut captures = Vec::new();
    for (i, (&(p, _, d), img)) in plan.iter().zip(&sim.captures).enumerate() {
        let name = format!("capture_{i:02}.png");
        write_grey_png(&dir.join(&name), img.view(), 16).expect("a writable folder");
        captures.push(ManifestEntry {
            pattern: format!("pattern_{p}.png"),
            colour: "green".into(),
            distance_m: d,
            capture: Some(name),
        });
    }
    let manifest = dir.join("manifest.json");
    let file = ManifestFile {
        format: CAPTURES_FORMAT.into(),
        version: CAPTURES_VERSION,
        captures,
    };
    std::fs::write(
        &manifest,
        serde_json::to_string(&file).expect("a manifest serialises"),
    )
    .expect("a writable folder");
    manifest
}

fn model_fit(c: &mut Criterion) {
    let mut group = c.benchmark_group("model_fit_48x48");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20));
    let dir = tempfile::tempdir().expect("a temporary folder");
    for distances_mm in [
        &[-9.0, -6.0, -3.0][..],
        &[-9.0, -8.0, -7.0, -6.0, -4.5, -3.0],
        &[-9.0, -8.0, -7.0, -6.5, -6.0, -5.0, -4.0, -3.5, -3.0],
    ] {
        let distances: Vec<f64> = distances_mm.iter().map(|d| d * 1e-3).collect();
        let set = dir.path().join(format!("d{}", distances.len()));
        std::fs::create_dir_all(&set).expect("a writable folder");
        let manifest = write_set(&set, &distances);
        let captures = 8 * distances.len();
        group.bench_function(BenchmarkId::new("captures", captures), |b| {
            b.iter(|| {
                let report = fit(&manifest, &FitOptions::default()).expect("a valid set");
                assert_eq!(report.residuals.len(), captures);
                report
            })
        });
    }
    group.finish();
}

criterion_group!(benches, model_fit);
criterion_main!(benches);
