//! A dataset's generation split across processes and machines, resumed after an interruption, and merged.
//!
//! The plan of a dataset (every split's shards, in file order) is numbered by *ordinal*: `train-00000.npz`
//! is 0, the next shard 1, through the val and test shards. A [`ShardSelection`] `I/N` takes the shards
//! whose ordinal `j` has `j mod N = I`, so that `N` processes (a Slurm job array, a Kubernetes Indexed
//! Job) write disjoint parts of one global plan. Every sample is a pure function of the configuration
//! and (seed, split, index), and the `.npz` writer has no clock, so a shard is byte-identical whichever
//! process wrote it.
//!
//! Beside each shard lies its record, `<shard>.shard.json` ([`ShardRecord`]): the plan it belongs to
//! ([`DatasetPlan`]: the manifest less who made it, when, and the statistics), its size in bytes, and the
//! running sums of its statistics ([`ShardStatistics`]). The shard is written first and its record last,
//! both atomically, so a record names a complete shard. Generation skips a shard whose record has the
//! same plan and whose file has the recorded size (resume after `kill -9`); anything else is rewritten.
//!
//! [`merge_shards`] checks that every planned shard is there exactly once with one plan, combines the
//! statistics in ordinal order and writes `manifest.json` atomically; the one-process [`super::generate`]
//! ends with the same merge, so its manifest equals a merged one up to timings and the command line.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::config::{DatasetConfig, GenerateOptions, Split};
use super::manifest::{
    shard_file_name, DatasetPlan, DatasetStatistics, GeneratorInfo, Manifest, FORMAT_NAME,
    FORMAT_VERSION, MANIFEST_FILE,
};
use super::npz::{io_error, write_atomic, write_shard};
use super::sample::{LdiStatistics, Sample, SampleGenerator};
use crate::error::{invalid, HoloError, Result};
use crate::io::ensure_not_input;

/// Suffix of a shard's record: `train-00000.npz` → `train-00000.npz.shard.json`.
pub const SHARD_RECORD_SUFFIX: &str = ".shard.json";
/// Value of a record's `format` field.
pub const SHARD_RECORD_FORMAT: &str = "tensorholo-dataset-shard";

/// Which shards of the plan one process writes: those whose ordinal `j` has `j mod count = index`
/// (`holo dataset --shard INDEX/COUNT`; a Slurm array task or a Kubernetes completion index).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShardSelection {
    index: usize,
    count: usize,
}

impl ShardSelection {
    /// Every shard: the one-process run (`0/1`).
    pub const ALL: ShardSelection = ShardSelection { index: 0, count: 1 };

    /// Part `index` of `count` (0-based).
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`shard`) for `count = 0` or `index ≥ count`.
    pub fn new(index: usize, count: usize) -> Result<Self> {
        if count == 0 {
            return Err(invalid("shard", "the number of parts must be at least 1"));
        }
        if index >= count {
            return Err(invalid(
                "shard",
                format!(
                    "part {index} of {count}: parts are numbered 0 to {}",
                    count - 1
                ),
            ));
        }
        Ok(Self { index, count })
    }

    /// The part, 0-based.
    pub fn index(self) -> usize {
        self.index
    }

    /// The number of parts.
    pub(crate) fn count(self) -> usize {
        self.count
    }

    /// Whether this part writes the shard of plan ordinal `ordinal`.
    pub(crate) fn selects(self, ordinal: usize) -> bool {
        ordinal % self.count == self.index
    }
}

impl std::fmt::Display for ShardSelection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Running sums over samples, from which [`DatasetStatistics`] follow; one per shard in its record, added
/// in ordinal order by [`merge_shards`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ShardStatistics {
    /// Samples summed.
    pub samples: usize,
    /// Sum of non-empty SM-LBM planes.
    pub planes_sum: f64,
    /// Fewest non-empty planes (0 without samples).
    pub planes_min: usize,
    /// Most non-empty planes.
    pub planes_max: usize,
    /// Sum of valid fractions per LDI layer `[L]`.
    pub valid_sum: Vec<f64>,
    /// Sum of the fractions of pixels with at least two valid layers.
    pub multi_sum: f64,
    /// Smallest such fraction (0 without samples).
    pub multi_min: f64,
    /// Sum of mean valid layers per pixel.
    pub layers_sum: f64,
    /// Largest midpoint amplitude `|H|`.
    pub amp_max: f64,
    /// Sum of per-sample mean midpoint amplitudes.
    pub amp_sum: f64,
    /// Sum of per-sample seconds on one worker.
    pub seconds_sum: f64,
    /// Wall-clock seconds spent on this shard (its share of the batch it was computed in).
    pub wall_seconds: f64,
    /// Worker threads of the process that wrote it.
    pub threads: usize,
}

impl ShardStatistics {
    fn add(&mut self, s: &Sample) {
        let st = LdiStatistics::of(&s.ldi);
        let mut one = ShardStatistics {
            samples: 1,
            planes_sum: s.nonempty_planes as f64,
            planes_min: s.nonempty_planes,
            planes_max: s.nonempty_planes,
            valid_sum: st.valid_fraction.clone(),
            multi_sum: st.multi_layer_fraction,
            multi_min: st.multi_layer_fraction,
            layers_sum: st.mean_valid_layers,
            seconds_sum: s.seconds,
            ..Default::default()
        };
        let (mut mx, mut sum) = (0.0f64, 0.0f64);
        for v in &s.midpoint {
            let a = f64::from(v.norm());
            mx = mx.max(a);
            sum += a;
        }
        one.amp_max = mx;
        one.amp_sum = sum / s.midpoint.len() as f64;
        self.merge(&one);
    }

    /// Adds `other`'s sums to these.
    fn merge(&mut self, other: &ShardStatistics) {
        self.wall_seconds += other.wall_seconds;
        self.threads = self.threads.max(other.threads);
        if other.samples == 0 {
            return;
        }
        if self.samples == 0 {
            let (wall, threads) = (self.wall_seconds, self.threads);
            *self = other.clone();
            self.wall_seconds = wall;
            self.threads = threads;
            return;
        }
        self.samples += other.samples;
        self.planes_sum += other.planes_sum;
        self.planes_min = self.planes_min.min(other.planes_min);
        self.planes_max = self.planes_max.max(other.planes_max);
        for (a, v) in self.valid_sum.iter_mut().zip(&other.valid_sum) {
            *a += v;
        }
        self.multi_sum += other.multi_sum;
        self.multi_min = self.multi_min.min(other.multi_min);
        self.layers_sum += other.layers_sum;
        self.amp_max = self.amp_max.max(other.amp_max);
        self.amp_sum += other.amp_sum;
        self.seconds_sum += other.seconds_sum;
    }

    fn finish(&self) -> DatasetStatistics {
        let n = self.samples.max(1) as f64;
        DatasetStatistics {
            samples: self.samples,
            mean_nonempty_planes: self.planes_sum / n,
            min_nonempty_planes: self.planes_min,
            max_nonempty_planes: self.planes_max,
            mean_valid_fraction: self.valid_sum.iter().map(|v| v / n).collect(),
            mean_multi_layer_fraction: self.multi_sum / n,
            min_multi_layer_fraction: self.multi_min,
            mean_valid_layers: self.layers_sum / n,
            max_midpoint_amplitude: self.amp_max,
            mean_midpoint_amplitude: self.amp_sum / n,
            mean_sample_seconds: self.seconds_sum / n,
            wall_seconds: self.wall_seconds,
            threads: self.threads,
        }
    }
}

/// The record beside a finished shard (`<shard>.shard.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardRecord {
    /// [`SHARD_RECORD_FORMAT`].
    pub format: String,
    /// The shard's file name.
    pub file: String,
    /// Its position in the plan (train shards first, then val, then test).
    pub ordinal: usize,
    /// Its size in bytes: a file of another size is not this shard.
    pub bytes: u64,
    /// The part that wrote it, `[index, count]`.
    pub selection: ShardSelection,
    /// Who wrote it (version, commit, command line).
    pub generator: GeneratorInfo,
    /// Sums over its samples.
    pub statistics: ShardStatistics,
    /// The plan it belongs to, with the format and crate versions: `{"format", "format_version",
    /// "version", "plan"}`.
    pub plan: serde_json::Value,
}

fn record_path(out_dir: &Path, file: &str) -> PathBuf {
    out_dir.join(format!("{file}{SHARD_RECORD_SUFFIX}"))
}

fn read_record(path: &Path) -> Option<ShardRecord> {
    ShardRecord::from_json_str(&crate::io::read_text(path).ok()?)
}

impl ShardRecord {
    /// A shard record from its JSON text, `None` for text that is not a record of
    /// [`SHARD_RECORD_FORMAT`] (a merge reports such a record as unreadable).
    pub fn from_json_str(text: &str) -> Option<Self> {
        let r: ShardRecord = serde_json::from_str(text).ok()?;
        (r.format == SHARD_RECORD_FORMAT).then_some(r)
    }
}

/// What [`generate_shards`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct ShardRun {
    /// The part it ran.
    pub selection: ShardSelection,
    /// Shard files written by this run.
    pub written: Vec<String>,
    /// Shard files kept: a complete shard of the same plan was already there.
    pub kept: Vec<String>,
    /// Samples computed by this run.
    pub samples: usize,
}

/// One shard to produce.
#[derive(Debug, Clone, Copy)]
struct ShardJob {
    ordinal: usize,
    split: Split,
    shard: usize,
    first: usize,
    samples: usize,
}

fn generator_info(options: &GenerateOptions) -> GeneratorInfo {
    GeneratorInfo {
        name: "tensorholo".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        git_commit: options
            .git_commit
            .clone()
            .unwrap_or_else(|| "unknown".into()),
        command: options.command.clone(),
    }
}

/// Refuses an `out_dir` whose `manifest.json` is a device, a FIFO or a socket (or a link to one), before any
/// work and before anything reads it (a FIFO would block the read): the manifest is written last, and a node is
/// never replaced nor removed.
pub(super) fn refuse_node_manifest(out_dir: &Path) -> Result<()> {
    let manifest_path = out_dir.join(MANIFEST_FILE);
    match crate::io::node_at(&manifest_path) {
        Some(kind) => Err(HoloError::InvalidData(format!(
            "`{}` is {kind}, not a dataset manifest: refusing to read or replace it (choose another folder)",
            manifest_path.display()
        ))),
        None => Ok(()),
    }
}

/// Writes the shards of `selection` (all of them with [`ShardSelection::ALL`]) into `out_dir`, each with
/// its record, and no manifest: [`merge_shards`] writes it once every part has run. A shard already there
/// with a record of the same plan and its recorded size is kept (resume); a missing, partial or foreign
/// one is (re)written. With [`GenerateOptions::overwrite`] every selected shard is rewritten and an old
/// `manifest.json` is removed first. Samples run in parallel on the current rayon pool; `progress(done,
/// total)` counts the samples this run computes.
///
/// Errors: as [`SampleGenerator::new`] and [`SampleGenerator::sample`];
/// [`HoloError::InvalidParameter`] (`out_dir`) if the folder holds a dataset (`manifest.json`) and
/// `overwrite` is false; [`HoloError::InvalidData`] if its `manifest.json` is a device, a FIFO or a socket
/// (before any work); [`HoloError::WouldOverwriteInput`] if a file would replace a photo;
/// [`HoloError::Io`] / [`HoloError::Npy`] for write failures.
pub fn generate_shards(
    out_dir: &Path,
    config: &DatasetConfig,
    options: &GenerateOptions,
    selection: ShardSelection,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<ShardRun> {
    let generator = SampleGenerator::new(config)?;
    let manifest_path = out_dir.join(MANIFEST_FILE);
    refuse_node_manifest(out_dir)?;
    if manifest_path.exists() {
        if !options.overwrite {
            return Err(invalid(
                "out_dir",
                format!(
                    "`{}` already holds a dataset ({MANIFEST_FILE}); choose another folder or allow \
                     overwriting it",
                    out_dir.display()
                ),
            ));
        }
        // A folder holding a manifest holds a complete dataset: the old one goes before any shard changes.
        match std::fs::remove_file(&manifest_path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(io_error(&manifest_path)(e)),
        }
    }
    let plan = DatasetPlan::new(config, options, &generator);
    let canonical = plan.canonical();
    let jobs: Vec<ShardJob> = plan
        .splits
        .iter()
        .flat_map(|s| {
            s.shards
                .iter()
                .enumerate()
                .map(move |(shard, f)| (s.name, shard, f))
        })
        .enumerate()
        .map(|(ordinal, (split, shard, info))| ShardJob {
            ordinal,
            split,
            shard,
            first: info.first_index,
            samples: info.samples,
        })
        .filter(|j| selection.selects(j.ordinal))
        .collect();
    let photos: Vec<&Path> = plan.photos.iter().map(PathBuf::as_path).collect();
    ensure_not_input(&manifest_path, &photos)?;
    for j in &jobs {
        let file = shard_file_name(j.split, j.shard);
        ensure_not_input(&out_dir.join(&file), &photos)?;
        ensure_not_input(&record_path(out_dir, &file), &photos)?;
    }
    std::fs::create_dir_all(out_dir).map_err(io_error(out_dir))?;

    // Resume: a shard whose record has this plan and whose file has the recorded size is complete.
    let (mut kept, mut todo) = (Vec::new(), Vec::new());
    for j in jobs {
        let file = shard_file_name(j.split, j.shard);
        let complete = !options.overwrite
            && read_record(&record_path(out_dir, &file)).is_some_and(|r| {
                r.plan == canonical
                    && r.file == file
                    && r.ordinal == j.ordinal
                    && r.statistics.samples == j.samples
                    && std::fs::metadata(out_dir.join(&file)).is_ok_and(|m| m.len() == r.bytes)
            });
        if complete {
            kept.push(file);
        } else {
            todo.push(j);
        }
    }

    // Groups of shards with at least two samples per worker thread in flight; each group is written on a
    // background thread while the next one computes.
    let total: u64 = todo.iter().map(|j| j.samples as u64).sum();
    let done = AtomicU64::new(0);
    let target = 2 * rayon::current_num_threads().max(1);
    let mut groups: Vec<Vec<ShardJob>> = Vec::new();
    let mut in_group = 0;
    for job in &todo {
        if in_group >= target || groups.is_empty() {
            groups.push(Vec::new());
            in_group = 0;
        }
        in_group += job.samples;
        groups.last_mut().expect("pushed above").push(*job);
    }
    let generator_info = generator_info(options);
    let threads = rayon::current_num_threads();
    std::thread::scope(|scope| -> Result<()> {
        let mut writer: Option<std::thread::ScopedJoinHandle<'_, Result<()>>> = None;
        let join = |h: std::thread::ScopedJoinHandle<'_, Result<()>>| {
            h.join().unwrap_or_else(|_| {
                Err(HoloError::Internal(
                    "the shard writer thread panicked".into(),
                ))
            })
        };
        for group in groups {
            let t = Instant::now();
            let items: Vec<(Split, usize)> = group
                .iter()
                .flat_map(|j| (j.first..j.first + j.samples).map(move |i| (j.split, i)))
                .collect();
            let mut samples: Vec<Sample> = items
                .par_iter()
                .map(|&(split, index)| {
                    let s = generator.sample(split, index)?;
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
                    Ok(s)
                })
                .collect::<Result<_>>()?;
            let wall = t.elapsed().as_secs_f64();
            let mut records = Vec::with_capacity(group.len());
            let mut offset = 0;
            for j in &group {
                let mut st = ShardStatistics {
                    wall_seconds: wall * j.samples as f64 / items.len().max(1) as f64,
                    threads,
                    ..Default::default()
                };
                for s in &samples[offset..offset + j.samples] {
                    st.add(s);
                }
                offset += j.samples;
                records.push(ShardRecord {
                    format: SHARD_RECORD_FORMAT.into(),
                    file: shard_file_name(j.split, j.shard),
                    ordinal: j.ordinal,
                    bytes: 0,
                    selection,
                    generator: generator_info.clone(),
                    statistics: st,
                    plan: canonical.clone(),
                });
            }
            if let Some(h) = writer.take() {
                join(h)?;
            }
            let compress = config.compress;
            writer = Some(scope.spawn(move || {
                for (job, mut record) in group.iter().zip(records).rev() {
                    let rest = samples.split_off(samples.len() - job.samples);
                    let path = out_dir.join(&record.file);
                    write_shard(&path, &rest, compress)?;
                    record.bytes = std::fs::metadata(&path).map_err(io_error(&path))?.len();
                    write_record(out_dir, &record)?;
                }
                Ok(())
            }));
        }
        if let Some(h) = writer.take() {
            join(h)?;
        }
        Ok(())
    })?;
    let samples = todo.iter().map(|j| j.samples).sum();
    Ok(ShardRun {
        selection,
        written: todo
            .iter()
            .map(|j| shard_file_name(j.split, j.shard))
            .collect(),
        kept,
        samples,
    })
}

fn write_record(out_dir: &Path, record: &ShardRecord) -> Result<()> {
    let path = record_path(out_dir, &record.file);
    let json = serde_json::to_string_pretty(record)
        .map_err(|e| HoloError::InvalidData(format!("cannot serialise a shard record: {e}")))?;
    write_atomic(&path, |tmp| {
        std::fs::write(tmp, json + "\n").map_err(io_error(tmp))
    })
}

/// Every shard record in `out_dir`, by file name.
fn read_records(out_dir: &Path) -> Result<BTreeMap<String, Option<ShardRecord>>> {
    let mut records = BTreeMap::new();
    for entry in std::fs::read_dir(out_dir).map_err(io_error(out_dir))? {
        let entry = entry.map_err(io_error(out_dir))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.ends_with(SHARD_RECORD_SUFFIX) && !name.starts_with('.') {
            records.insert(name, read_record(&entry.path()));
        }
    }
    Ok(records)
}

/// The command that regenerates ordinal `ordinal`, from the command line of a part run: its `--shard`
/// value replaced by the part that writes it (`None` if no part run recorded a command).
fn rerun_command(records: &[&ShardRecord], ordinal: usize) -> Option<String> {
    let r = records.iter().find(|r| !r.generator.command.is_empty())?;
    let n = r.selection.count();
    let part = format!("{}/{n}", ordinal % n);
    let mut out: Vec<String> = Vec::new();
    let mut args = r.generator.command.iter().peekable();
    let mut had_shard = false;
    while let Some(a) = args.next() {
        if a == "--shard" {
            had_shard = true;
            out.push(a.clone());
            out.push(part.clone());
            args.next();
        } else if a.starts_with("--shard=") {
            had_shard = true;
            out.push(format!("--shard={part}"));
        } else if a == "--shard-count" {
            // Kubernetes' form: the part is spelled out instead.
            args.next();
        } else {
            out.push(a.clone());
        }
    }
    if !had_shard && n > 1 {
        out.extend(["--shard".to_string(), part]);
    }
    Some(out.join(" "))
}

/// Checks that `out_dir` holds every shard of one plan exactly once, with its record (written by
/// [`generate_shards`], in one process or many), combines their statistics in ordinal order and writes
/// `manifest.json` atomically. A manifest already there is replaced only where it is this merge's own (a
/// rerun: equal but for `created_unix_s` and `generator`) or with `force`. Returns the manifest.
///
/// Errors: [`HoloError::InvalidData`] naming the shards of another plan (with the key that differs),
/// unreadable records, the missing shards with the command that writes them, a manifest that is not this
/// merge's (without `force`), or a `manifest.json` that is a device, a FIFO or a socket (never read nor
/// replaced); nothing is written then.
/// [`HoloError::Io`] if the folder cannot be read or the manifest written.
pub fn merge_shards(out_dir: &Path, force: bool) -> Result<Manifest> {
    refuse_node_manifest(out_dir)?;
    let all = read_records(out_dir)?;
    let unreadable: Vec<&String> = all
        .iter()
        .filter(|(_, r)| r.is_none())
        .map(|(n, _)| n)
        .collect();
    if !unreadable.is_empty() {
        return Err(HoloError::InvalidData(format!(
            "`{}`: unreadable shard records {unreadable:?}; delete them and rerun the parts that wrote them",
            out_dir.display()
        )));
    }
    let records: Vec<&ShardRecord> = all.values().flatten().collect();
    if records.is_empty() {
        return Err(HoloError::InvalidData(format!(
            "`{}` holds no shard records (*{SHARD_RECORD_SUFFIX}): generate the shards first \
             (holo dataset --shard I/N)",
            out_dir.display()
        )));
    }
    // The plan most records share is the dataset's; the others are foreign.
    let mut counts: Vec<(&serde_json::Value, usize)> = Vec::new();
    for r in &records {
        match counts.iter_mut().find(|(p, _)| *p == &r.plan) {
            Some((_, n)) => *n += 1,
            None => counts.push((&r.plan, 1)),
        }
    }
    let (plan_value, _) = counts
        .iter()
        .copied()
        .max_by_key(|&(_, n)| n)
        .expect("records is not empty");
    let foreign: Vec<String> = records
        .iter()
        .filter(|r| &r.plan != plan_value)
        .map(|r| format!("{} ({})", r.file, plan_difference(plan_value, &r.plan)))
        .collect();
    if !foreign.is_empty() {
        return Err(HoloError::InvalidData(format!(
            "`{}` mixes datasets: {} of another configuration than the other {} shards: {}; move them \
             out (or generate each configuration into its own folder) and merge again",
            out_dir.display(),
            if foreign.len() == 1 {
                "a shard".to_string()
            } else {
                format!("{} shards", foreign.len())
            },
            records.len() - foreign.len(),
            foreign.join(", ")
        )));
    }
    let plan: DatasetPlan = serde_json::from_value(plan_value["plan"].clone())
        .map_err(|e| HoloError::InvalidData(format!("a shard record's plan is unreadable: {e}")))?;
    let by_file: BTreeMap<&str, &ShardRecord> =
        records.iter().map(|r| (r.file.as_str(), *r)).collect();
    let mut missing = Vec::new();
    let mut stats = ShardStatistics::default();
    for (ordinal, (_, info)) in plan.shards().enumerate() {
        let complete = by_file.get(info.file.as_str()).filter(|r| {
            r.ordinal == ordinal
                && std::fs::metadata(out_dir.join(&info.file)).is_ok_and(|m| m.len() == r.bytes)
        });
        match complete {
            Some(r) => stats.merge(&r.statistics),
            None => missing.push(ordinal),
        }
    }
    if !missing.is_empty() {
        let files: Vec<&str> = plan
            .shards()
            .enumerate()
            .filter(|(o, _)| missing.contains(o))
            .map(|(_, (_, f))| f.file.as_str())
            .collect();
        let mut reruns: Vec<String> = missing
            .iter()
            .filter_map(|&o| rerun_command(&records, o))
            .collect();
        reruns.sort();
        reruns.dedup();
        return Err(HoloError::InvalidData(format!(
            "`{}` misses {} of {} shards: {}; rerun {}, then merge again (complete shards are kept)",
            out_dir.display(),
            files.len(),
            plan.shards().count(),
            files.join(", "),
            if reruns.is_empty() {
                "the parts that write them".to_string()
            } else {
                reruns
                    .iter()
                    .map(|c| format!("`{c}`"))
                    .collect::<Vec<_>>()
                    .join(" and ")
            }
        )));
    }
    // Who made the dataset: the writer of its first shard.
    let first = plan
        .shards()
        .next()
        .and_then(|(_, f)| by_file.get(f.file.as_str()).copied())
        .unwrap_or(records[0]);
    let manifest = Manifest {
        format: FORMAT_NAME.into(),
        format_version: FORMAT_VERSION,
        generator: first.generator.clone(),
        created_unix_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0),
        plan,
        statistics: stats.finish(),
    };
    let json = serde_json::to_string_pretty(&manifest)
        .map_err(|e| HoloError::InvalidData(format!("cannot serialise the manifest: {e}")))?;
    // A manifest already there is replaced only where it is this merge's own (a rerun) or with `force`: a
    // hand-edited one, or another dataset's, is the user's.
    let path = out_dir.join(MANIFEST_FILE);
    if path.exists() && !force {
        // Equal but for when and by which command line it was written: any other edit is the user's.
        let content = |v: serde_json::Value| match v {
            serde_json::Value::Object(mut m) => {
                m.remove("created_unix_s");
                m.remove("generator");
                Some(m)
            }
            _ => None,
        };
        // Both sides parsed from text: serde_json's float parsing need not round-trip a value exactly.
        let new = serde_json::from_str::<serde_json::Value>(&json)
            .ok()
            .and_then(content);
        let same = crate::io::read_text(&path)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(content)
            .is_some_and(|old| Some(old) == new);
        if !same {
            return Err(HoloError::InvalidData(format!(
                "`{}` exists and is not the manifest this merge writes (hand-edited, or of another \
                 dataset): move it away, or merge with --force to replace it",
                path.display()
            )));
        }
    }
    write_atomic(&out_dir.join(MANIFEST_FILE), |tmp| {
        std::fs::write(tmp, json + "\n").map_err(io_error(tmp))
    })?;
    Ok(manifest)
}

/// The first key where two plans differ (the plan's own keys, then the versions), with both values (short),
/// e.g. "seed: 9 here, 1 in the others".
fn plan_difference(ours: &serde_json::Value, theirs: &serde_json::Value) -> String {
    let short = |v: Option<&serde_json::Value>| {
        let s = v.map_or("absent".to_string(), |v| v.to_string());
        match s.char_indices().nth(60) {
            Some((i, _)) => format!("{}…", &s[..i]),
            None => s,
        }
    };
    let levels = [
        (ours.get("plan"), theirs.get("plan")),
        (Some(ours), Some(theirs)),
    ];
    for (a, b) in levels {
        let (Some(a), Some(b)) = (a.and_then(|v| v.as_object()), b.and_then(|v| v.as_object()))
        else {
            continue;
        };
        for (k, v) in b {
            if k != "plan" && a.get(k) != Some(v) {
                return format!(
                    "{k}: {} here, {} in the others",
                    short(Some(v)),
                    short(a.get(k))
                );
            }
        }
        if let Some(k) = a.keys().find(|k| !b.contains_key(*k)) {
            return format!("{k}: absent here");
        }
    }
    "another plan".into()
}
