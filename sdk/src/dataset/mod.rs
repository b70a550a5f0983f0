//! The training dataset: random layered depth images paired with their SM-LBM midpoint holograms, as
//! in the paper's MIT-CGH-4K-V2 (section "MIT-CGH-4K-V2": 3800/100/100 samples of 384×384, 5-layer
//! LDIs, SM-LBM with 2048 planes or more).
//!
//! One *sample* is a random scene ([`crate::scene::random`]) rendered as an `L`-layer LDI and the
//! midpoint hologram that [`SmLbm`](crate::synthesis::SmLbm) computes from the **full** LDI (the ground truth the hologram CNN
//! learns, paper Fig. 3). Samples are written in `.npz` *shards* (NumPy zip archives, one per
//! `shard_size` consecutive samples of a split) next to a `manifest.json` that records everything
//! needed to read, check and regenerate them. The format is specified in `docs/DATASET.md`:
//!
//! | array | dtype | shape | content |
//! |---|---|---|---|
//! | `ldi` | float32 | `[N, 4·L, H, W]` | per layer `k` (front to back) channels `4k..4k+3` = R, G, B amplitude in `[0, 1]`, depth `d ∈ [0, 1]` (0 = near); invalid pixels: amplitude 0, depth 1 |
//! | `ldi_valid` | uint8 | `[N, L, H, W]` | 1 where layer `k` holds a point |
//! | `midpoint` | complex64 | `[N, 3, H, W]` | R, G, B midpoint hologram (complex field at `z = 0`) |
//! | `seed` | uint64 | `[N]` | scene seed ([`sample_seed`]) |
//! | `index` | uint64 | `[N]` | sample index within its split |
//!
//! Every sample is a pure function of (base seed, split, index) and the configuration, so generation
//! runs in parallel over samples (rayon; [`SmLbm`](crate::synthesis::SmLbm) parallelises colours inside a sample on the same
//! pool) and any sample can be regenerated alone ([`SampleGenerator::sample`]).
//!
//! One file a concept: what to generate (`config.rs`: [`DatasetConfig`], [`Split`], [`sample_seed`],
//! [`GenerateOptions`]), a sample and its tensor layout (`sample.rs`), the `.npz` shard files (`npz.rs`),
//! the manifest and its records (`manifest.rs`), generation in shards across processes and their merge
//! (`shards.rs`), and here the one-process [`generate`] and the LDI previews.

use std::path::{Path, PathBuf};

use ndarray::{Array3, Axis};

use crate::error::Result;
use crate::io::save_amplitude_png;
use crate::scene::LayeredDepthImage;

mod config;
mod manifest;
mod npz;
mod sample;
mod shards;

use npz::io_error;

pub use config::{sample_seed, DatasetConfig, DisplayInfo, GenerateOptions, Split};
pub use manifest::{
    read_manifest, shard_file_name, AberrationInfo, ArrayInfo, DatasetPlan, DatasetStatistics,
    GeneratorInfo, Manifest, OpticsInfo, ShardInfo, SplitInfo, SynthesisInfo, FORMAT_NAME,
    FORMAT_VERSION, MANIFEST_FILE,
};
pub use npz::{read_shard, write_shard, Shard};
pub use sample::{ldi_from_tensor, ldi_tensor, LdiStatistics, Sample, SampleGenerator};
pub use shards::{
    generate_shards, merge_shards, ShardRecord, ShardRun, ShardSelection, ShardStatistics,
    SHARD_RECORD_FORMAT, SHARD_RECORD_SUFFIX,
};

/// Generates a whole dataset into `out_dir` in this process: every shard of every split
/// ([`generate_shards`] with [`ShardSelection::ALL`]: samples in parallel on the current rayon pool, each
/// shard and its record written while the next ones compute), then `manifest.json` ([`merge_shards`],
/// see [`Manifest`]). `progress(done, total)` is called after every sample (from worker threads). Returns
/// the manifest written.
///
/// Nothing is written unless the configuration is valid. A folder that already holds a
/// `manifest.json` is refused unless [`GenerateOptions::overwrite`]. Photos (inputs) are never
/// overwritten. Files appear atomically; an interrupted run leaves no manifest, so the folder is not
/// mistaken for a dataset, and a rerun keeps the shards it had finished (`shards` module docs).
///
/// Errors: as [`generate_shards`] and [`merge_shards`].
pub fn generate(
    out_dir: &Path,
    config: &DatasetConfig,
    options: &GenerateOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<Manifest> {
    shards::refuse_node_manifest(out_dir)?;
    // Shards of a replaced dataset that the new one does not have go, with their records.
    let stale: Vec<String> = if options.overwrite {
        let mut files: Vec<String> = read_manifest(out_dir)
            .map(|old| {
                old.plan
                    .splits
                    .iter()
                    .flat_map(|s| s.shards.iter().map(|f| f.file.clone()))
                    .collect()
            })
            .unwrap_or_default();
        if let Ok(entries) = std::fs::read_dir(out_dir) {
            files.extend(entries.flatten().filter_map(|e| {
                e.file_name()
                    .to_str()
                    .and_then(|n| n.strip_suffix(SHARD_RECORD_SUFFIX))
                    .map(str::to_string)
            }));
        }
        files
    } else {
        Vec::new()
    };
    let run = generate_shards(out_dir, config, options, ShardSelection::ALL, progress)?;
    let current: std::collections::HashSet<&str> = run
        .written
        .iter()
        .chain(&run.kept)
        .map(String::as_str)
        .collect();
    for file in &stale {
        let plain = Path::new(file)
            .file_name()
            .is_some_and(|n| n == file.as_str());
        if plain && file.ends_with(".npz") && !current.contains(file.as_str()) {
            let _ = crate::io::remove_output(&out_dir.join(file));
            let _ = crate::io::remove_output(&out_dir.join(format!("{file}{SHARD_RECORD_SUFFIX}")));
        }
    }
    // Generation has already refused a manifest it may not replace (without `overwrite`).
    merge_shards(out_dir, true)
}

/// Saves previews of an LDI into `dir`: `<stem>_rgb.png` (layer 0 amplitude, sRGB), `<stem>_depth.png`
/// (layer 0 depth, grey, white = far) and `<stem>_layers.png` (all layers side by side: amplitudes in
/// the top row, depths in the bottom row, invalid pixels dark red). Returns the paths written.
///
/// Errors: [`HoloError::Io`](crate::HoloError::Io) if `dir` cannot be created; as
/// [`save_amplitude_png`].
pub fn save_ldi_previews(dir: &Path, stem: &str, ldi: &LayeredDepthImage) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(io_error(dir))?;
    let (l, h, w) = (ldi.num_layers(), ldi.height(), ldi.width());
    let first = &ldi.layers()[0];
    let rgb = dir.join(format!("{stem}_rgb.png"));
    save_amplitude_png(&rgb, first.amplitude.view(), 1.0)?;
    // Grey PNG of intensity d: amplitude √d.
    let depth = dir.join(format!("{stem}_depth.png"));
    let d = first.depth.mapv(f32::sqrt).insert_axis(Axis(0));
    save_amplitude_png(&depth, d.view(), 1.0)?;
    let mut mosaic = Array3::<f32>::zeros((3, 2 * h, l * w));
    const INVALID: [f32; 3] = [0.6, 0.0, 0.0];
    for (k, layer) in ldi.layers().iter().enumerate() {
        for y in 0..h {
            for x in 0..w {
                let ok = layer.valid[[y, x]];
                let dv = layer.depth[[y, x]].sqrt();
                for c in 0..3 {
                    mosaic[[c, y, k * w + x]] = if ok {
                        layer.amplitude[[c, y, x]]
                    } else {
                        INVALID[c]
                    };
                    mosaic[[c, h + y, k * w + x]] = if ok { dv } else { INVALID[c] };
                }
            }
        }
    }
    let layers = dir.join(format!("{stem}_layers.png"));
    save_amplitude_png(&layers, mosaic.view(), 1.0)?;
    Ok(vec![rgb, depth, layers])
}
