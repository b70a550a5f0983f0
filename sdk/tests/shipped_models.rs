//! Every shipped model file (`models/`, embedded with the default feature `embedded-models`) loads, carries the
//! metadata its name promises, and reproduces PyTorch's output of the checkpoint it was exported from
//! (`models/fixtures/`, written by `training/make_shipped_fixtures.py`) on every CPU engine of the build that
//! runs it (tract with the feature `tract`; the native engine: f32 and int8 QDQ): f32 within 1e-4, int8 within
//! the quantisation tolerance of `training/tests/test_export.py` (mean |error| < 0.01, max < 0.1). Without
//! `tract` (the phone library's build, the ARM step of CI) the native engine runs alone and the int8 QOperator
//! files, which only tract runs, are not embedded.
#![cfg(feature = "embedded-models")]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use ndarray::Array3;
use tensorholo::cnn::{cnn_plan, CnnEngine, CnnOptions, PlanRequest, ThreadCount};
use tensorholo::model::{embedded, HologramModel, ModelConfig, ModelKind, Precision, SceneInput};

/// The precisions whose files this build embeds: the int8 QOperator forms only with tract.
fn precisions() -> impl Iterator<Item = Precision> {
    Precision::ALL
        .into_iter()
        .filter(|&p| cfg!(feature = "tract") || p != Precision::Int8QOperator)
}

/// The CPU engines of this build that run `precision`'s files (QOperator int8: tract's alone).
fn engines(precision: Precision) -> Vec<CnnEngine> {
    let mut engines = Vec::new();
    if cfg!(feature = "tract") {
        engines.push(CnnEngine::Tract);
    }
    if precision != Precision::Int8QOperator {
        engines.push(CnnEngine::Native);
    }
    engines
}

fn fixture(name: &str) -> Array3<f32> {
    let path: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models/fixtures")
        .join(name);
    ndarray_npy::read_npy(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn check(
    name: &str,
    bytes: &[u8],
    kind: ModelKind,
    config: &ModelConfig,
    layers: usize,
    precision: Precision,
) {
    let model =
        HologramModel::from_bytes(bytes, kind, config).unwrap_or_else(|e| panic!("{name}: {e}"));
    let md = model.metadata();
    assert_eq!(md.layers, layers, "{name}");
    let want_precision = match precision {
        Precision::F32 => "f32",
        Precision::Int8QOperator => "int8-qoperator-conv",
        Precision::Int8Qdq => "int8-qdq-conv",
    };
    assert_eq!(md.precision, want_precision, "{name}");
    assert_ne!(md.training_commit, "fixture", "{name}");
    let stem = name.split('.').next().unwrap();
    let input = fixture(&format!("{stem}_input.npy"));
    let [first, second] = kind.output_names();
    let (ra, rp) = (
        fixture(&format!("{stem}_{first}.npy")),
        fixture(&format!("{stem}_{second}.npy")),
    );
    let model = Arc::new(model);
    for engine in engines(precision) {
        let request = PlanRequest {
            cnn: CnnOptions {
                engine,
                threads: ThreadCount::Fixed(1),
                ..CnnOptions::default()
            },
            ..PlanRequest::default()
        };
        let (mut plan, _) = cnn_plan(&model, input.dim().1, input.dim().2, &request)
            .unwrap_or_else(|e| panic!("{name} on {engine:?}: {e}"));
        let (a, p) = plan.run_outputs(input.view()).unwrap();
        let diffs: Vec<f32> = a
            .iter()
            .zip(ra.iter())
            .chain(p.iter().zip(rp.iter()))
            .map(|(x, y)| (x - y).abs())
            .collect();
        let max = diffs.iter().copied().fold(0.0f32, f32::max);
        let mean = diffs.iter().sum::<f32>() / diffs.len() as f32;
        println!("{name} on {engine:?}: max |cnn − torch| {max:.2e}, mean {mean:.2e}");
        if precision == Precision::F32 {
            assert!(max < 1e-4, "{name} on {engine:?}: {max}");
        } else {
            assert!(
                mean < 0.01 && max < 0.1,
                "{name} on {engine:?}: mean {mean}, max {max}"
            );
        }
    }
}

// One test per group, so that the test harness runs them side by side (under qemu-aarch64 in CI, the load and
// plan of each file dominate: scripts/test-aarch64.sh).

#[test]
fn shipped_hologram_cnns_match_pytorch_8_layers() {
    hologram_cnns(8);
}

#[test]
#[cfg(feature = "models-15")]
fn shipped_hologram_cnns_match_pytorch_15_layers() {
    hologram_cnns(15);
}

#[test]
#[cfg(feature = "models-30")]
fn shipped_hologram_cnns_match_pytorch_30_layers() {
    hologram_cnns(30);
}

/// Every precision of the `layers`-layer hologram CNN against PyTorch. Hologram CNNs predict the midpoint
/// hologram (offset 0 in their metadata) and serve every offset: the file loads for each (its metadata checked
/// by `check` at offset 0 and again here), and its output does not depend on the offset, so it runs once.
fn hologram_cnns(layers: usize) {
    assert!(embedded::LAYERS.contains(&layers), "{layers}");
    let base = ModelConfig::default();
    for precision in precisions() {
        let name = embedded::hologram_file(layers, precision);
        let bytes = embedded::hologram_cnn(layers, precision).unwrap();
        check(&name, bytes, ModelKind::Hologram, &base, layers, precision);
        for offset_m in [6e-3, 12e-3] {
            let config = ModelConfig { offset_m, ..base };
            let model = HologramModel::from_bytes(bytes, ModelKind::Hologram, &config)
                .unwrap_or_else(|e| panic!("{name} at {offset_m} m: {e}"));
            assert_eq!(model.metadata().layers, layers, "{name}");
        }
    }
}

#[test]
fn shipped_prefilters_match_pytorch() {
    let base = ModelConfig::default();
    for mm in embedded::PREFILTER_OFFSETS_MM {
        let config = ModelConfig {
            offset_m: mm as f64 * 1e-3,
            ..base
        };
        for precision in precisions() {
            let name = embedded::prefilter_file(mm, precision);
            let bytes = embedded::prefilter_cnn(mm, precision).unwrap();
            check(&name, bytes, ModelKind::PreFilter, &config, 8, precision);
            // A pre-filter belongs to its offset only.
            let other = ModelConfig {
                offset_m: if mm == 6 { 12e-3 } else { 6e-3 },
                ..base
            };
            assert!(HologramModel::from_bytes(bytes, ModelKind::PreFilter, &other).is_err());
        }
    }
    assert!(embedded::prefilter_cnn(0, Precision::F32).is_err());
}

/// The pre-filters trained with the 15- and 30-layer CNNs (features models-15 / models-30).
#[test]
fn shipped_paired_prefilters_match_pytorch() {
    let base = ModelConfig::default();
    for &layers in embedded::LAYERS.iter().filter(|&&l| l != 8) {
        for mm in embedded::PREFILTER_OFFSETS_MM {
            let config = ModelConfig {
                offset_m: mm as f64 * 1e-3,
                ..base
            };
            for precision in precisions() {
                let name = embedded::paired_prefilter_file(mm, layers, precision);
                let bytes = embedded::paired_prefilter_cnn(mm, layers, precision).unwrap();
                check(&name, bytes, ModelKind::PreFilter, &config, 8, precision);
                let model =
                    HologramModel::from_bytes(bytes, ModelKind::PreFilter, &config).unwrap();
                assert_eq!(model.metadata().hologram_layers, Some(layers), "{name}");
            }
        }
    }
    assert!(embedded::paired_prefilter_cnn(6, 9, Precision::F32).is_err());
}

/// The LDI CNN: 5 layers of RGB-D in, the midpoint hologram out, for every offset.
#[test]
fn shipped_ldi_cnns_match_pytorch() {
    let base = ModelConfig::default();
    for precision in precisions() {
        let name = embedded::scene_hologram_file(SceneInput::Ldi, 8, precision);
        let config = ModelConfig {
            input_layers: 5,
            ..base
        };
        let bytes = embedded::scene_hologram_cnn(SceneInput::Ldi, 8, precision).unwrap();
        check(&name, bytes, ModelKind::Hologram, &config, 8, precision);
        // Not an RGB-D CNN.
        assert!(HologramModel::from_bytes(bytes, ModelKind::Hologram, &base).is_err());
    }
    assert!(embedded::scene_hologram_cnn(SceneInput::Ldi, 30, Precision::F32).is_err());
    assert!(embedded::hologram_cnn(12, Precision::F32).is_err());
}
