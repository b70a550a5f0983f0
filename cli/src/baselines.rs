//! `holo baselines`: the non-learned baselines of the model card, computed on the scenes of a dataset split
//! from the RGB-D input the CNN sees (the first LDI layer), for `training/tensorholo_training/evaluate.py
//! --baseline NAME=FOLDER` (`FOLDER/<index:05d>.npy`, complex64 `[3, H, W]` midpoint holograms).
//!
//! - `maimone/`: the occlusion-unaware layer-based hologram (Maimone et al. 2017 style: SM-LBM without
//!   silhouette masks), complex;
//! - `smlbm-aadpm-<s>mm/`: SM-LBM with silhouette masks → offset propagation to the SLM (Eq. 6) → AA-DPM
//!   (Eq. 7) → simulated phase-only reconstruction at the midpoint plane (Eq. 8–10), rescaled by the
//!   encoding's amplitude normaliser: the post-encoding midpoint hologram, comparable with the CNN's
//!   `--phase-only` evaluation at the same offset.
//!
//! All physics is the SDK's ([`SmLbm`], [`ReferencePipeline`]'s stages); this file reads shards, schedules
//! scenes and writes files.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use ndarray::{s, Array3, Axis};
use rayon::iter::{ParallelBridge, ParallelIterator};
use serde_json::json;
use tensorholo::dataset::{read_manifest, read_shard, Manifest, Split, MANIFEST_FILE};
use tensorholo::encoding::{double_phase_encode, DoublePhaseMethod};
use tensorholo::io::{ensure_not_input, write_complex_npy};
use tensorholo::optics::{
    post_encoding_midpoint, propagate_colour, Carrier, OpticalSetup, PropagationOptions,
};
use tensorholo::reference::ReferencePipeline;
use tensorholo::synthesis::{SceneLayer, SmLbm};

/// Folder of the occlusion-unaware layer-based baseline.
const MAIMONE_FOLDER: &str = "maimone";
/// Report written last into `--out`.
const REPORT_FILE: &str = "baselines.json";

fn parse_split(s: &str) -> std::result::Result<Split, String> {
    Split::ALL
        .into_iter()
        .find(|split| split.name() == s)
        .ok_or_else(|| format!("unknown split `{s}` (one of: train, val, test)"))
}

/// Arguments of `holo baselines`.
#[derive(Debug, Args)]
#[command(after_long_help = EXAMPLES)]
pub struct BaselinesArgs {
    /// Dataset folder written by `holo dataset` (manifest.json and .npz shards; docs/DATASET.md). Its files
    /// are only read.
    #[arg(long)]
    dataset: PathBuf,
    /// Split whose scenes to use: train, val or test.
    #[arg(long, default_value = "test", value_parser = parse_split)]
    split: Split,
    /// Output folder (created if missing; default DATASET/baselines). Baseline .npy files of earlier runs in
    /// it are replaced; it may not be the dataset folder itself.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Use only the first N scenes of the split (in the split's order).
    #[arg(long)]
    limit: Option<usize>,
    /// SLM offsets s in millimetres (distance from the midpoint hologram to the SLM; paper: 0, 6, 12), one
    /// smlbm-aadpm-{s}mm baseline each, comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        default_values_t = [0.0, 6.0, 12.0]
    )]
    offsets_mm: Vec<f64>,
    /// SM-LBM depth planes of both baselines (default: the dataset's own, manifest synthesis.levels).
    #[arg(long)]
    levels: Option<usize>,
    /// Worker threads (default: all cores, or RAYON_NUM_THREADS). Scenes run in parallel; each scene's
    /// three colours share the same pool.
    #[arg(long, value_parser = crate::args::parse_threads)]
    threads: Option<usize>,
}

const EXAMPLES: &str = "\
Examples:
  holo baselines --dataset data/quick
      every test scene; offsets 0, 6 and 12 mm; the dataset's SM-LBM planes; into data/quick/baselines
  holo baselines --dataset data/mit-cgh-4k-v2 --split val --limit 20 --offsets-mm 6 --out out/val-baselines
      the first 20 validation scenes, SLM at 6 mm only

Every baseline sees only the first LDI layer (the RGB-D image the CNN gets: ldi channels 0-3, every pixel
valid) and uses the dataset's optics and propagation options (manifest.json).

Outputs in --out (<i> = position of the scene in the split, 5 digits):
  maimone/<i>.npy              complex64 [3, H, W]  occlusion-unaware layer-based midpoint hologram
                                                    (SM-LBM without silhouette masks, Maimone et al. 2017)
  smlbm-aadpm-<s>mm/<i>.npy    complex64 [3, H, W]  SM-LBM (silhouette masks) -> offset propagation to the SLM
                                                    at s mm -> AA-DPM -> Fourier filter and back-propagation to
                                                    the midpoint, times the encoding's amplitude normaliser:
                                                    the post-encoding midpoint hologram (compare with the CNN's
                                                    --phase-only evaluation at the same offset)
  baselines.json               dataset, split, count, levels, offsets, optics, folders, seconds per scene,
                               command line

Scoring (paper Table 2 protocol):
  python -m tensorholo_training.evaluate --onnx model.onnx --dataset data/quick --split test \\
      --baseline maimone=data/quick/baselines/maimone \\
      --baseline smlbm-aadpm-0mm=data/quick/baselines/smlbm-aadpm-0mm";

/// Folder name of the AA-DPM baseline at `offset_mm` (`smlbm-aadpm-6mm`, `smlbm-aadpm-1.5mm`).
fn aadpm_folder(offset_mm: f64) -> String {
    // `+ 0.0` turns -0 into 0, so that `-0` does not name a folder of its own.
    format!("smlbm-aadpm-{}mm", offset_mm + 0.0)
}

/// What every scene needs: the two SM-LBM configurations and one pipeline per offset.
struct Plan {
    /// Occlusion-unaware layer-based method (no silhouette masks).
    maimone: SmLbm,
    /// One pipeline per offset (all share `synthesis`, silhouette masks on), with its output folder.
    pipelines: Vec<(ReferencePipeline, PathBuf)>,
    /// Output folder of the Maimone baseline.
    maimone_dir: PathBuf,
    /// Dataset files that must never be written over.
    inputs: Vec<PathBuf>,
}

/// Seconds one scene spent in each stage, on its worker.
#[derive(Debug, Clone, Default)]
struct SceneSeconds {
    maimone: f64,
    smlbm: f64,
    /// Offset propagation + encoding + simulated reconstruction, per offset.
    encode: Vec<f64>,
    total: f64,
}

impl Plan {
    /// Writes `field` to `dir/<index:05d>.npy` unless that would replace a dataset file.
    fn write(&self, dir: &Path, index: usize, field: &Array3<tensorholo::Complex32>) -> Result<()> {
        let path = dir.join(format!("{index:05}.npy"));
        let inputs: Vec<&Path> = self.inputs.iter().map(PathBuf::as_path).collect();
        ensure_not_input(&path, &inputs)?;
        write_complex_npy(&path, field.view())
            .with_context(|| format!("cannot write {}", path.display()))
    }

    /// Computes and writes every baseline of scene `index` from its first LDI layer `rgbd` `[4, H, W]`
    /// (R, G, B amplitude, normalised depth).
    fn scene(&self, index: usize, rgbd: &Array3<f32>) -> Result<SceneSeconds> {
        let t_scene = Instant::now();
        let layer = [SceneLayer {
            amplitude: rgbd.slice(s![0..3, .., ..]),
            depth: rgbd.index_axis(Axis(0), 3),
            valid: None,
        }];
        let mut seconds = SceneSeconds::default();

        let t = Instant::now();
        let maimone = self.maimone.synthesize(&layer, &|_, _| {})?;
        seconds.maimone = t.elapsed().as_secs_f64();
        self.write(&self.maimone_dir, index, &maimone)?;
        drop(maimone);

        // SM-LBM once per scene: every pipeline shares the same synthesis configuration.
        let Some((first, _)) = self.pipelines.first() else {
            seconds.total = t_scene.elapsed().as_secs_f64();
            return Ok(seconds);
        };
        let t = Instant::now();
        let midpoint = first.synthesis.synthesize(&layer, &|_, _| {})?;
        seconds.smlbm = t.elapsed().as_secs_f64();

        for (pipeline, dir) in &self.pipelines {
            let t = Instant::now();
            let post = phase_only_baseline(pipeline, &midpoint)?;
            seconds.encode.push(t.elapsed().as_secs_f64());
            self.write(dir, index, &post)?;
        }
        seconds.total = t_scene.elapsed().as_secs_f64();
        Ok(seconds)
    }
}

/// The stages of [`ReferencePipeline::run`] after SM-LBM, then the simulated reconstruction at the midpoint
/// plane that [`ReferencePipeline::reconstruct_phase_only`] performs before its focal stack: offset
/// propagation to the SLM (Eq. 6, carrier removed), double phase encoding (Eq. 7), Fourier filter and
/// back-propagation (Eq. 8–10), rescaled by the encoding's amplitude normaliser
/// ([`post_encoding_midpoint`]).
fn phase_only_baseline(
    pipeline: &ReferencePipeline,
    midpoint: &Array3<tensorholo::Complex32>,
) -> Result<Array3<tensorholo::Complex32>> {
    let setup = &pipeline.synthesis.setup;
    let options = pipeline.synthesis.options;
    let mut slm_field = midpoint.clone();
    if pipeline.offset_m != 0.0 {
        propagate_colour(
            &mut slm_field,
            setup,
            pipeline.offset_m,
            Carrier::Remove,
            options,
        )?;
    }
    let encoded = double_phase_encode(slm_field.view(), &pipeline.encoding)?;
    drop(slm_field);
    Ok(post_encoding_midpoint(
        encoded.phase.view(),
        encoded.amplitude_scale,
        setup,
        pipeline.offset_m,
        options,
    )?)
}

fn progress_bar(total: u64) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} scenes ({per_sec}, eta {eta})",
        )
        .expect("valid template"),
    );
    bar.set_message("baselines");
    bar
}

/// Runs `holo baselines`.
pub fn run(args: &BaselinesArgs) -> Result<()> {
    if args.limit == Some(0) {
        bail!("--limit must be at least 1 (omit it to use every scene of the split)");
    }
    if let Some(bad) = args.offsets_mm.iter().find(|s| !s.is_finite()) {
        bail!("--offsets-mm: every offset must be a finite number of millimetres, got {bad}");
    }
    let mut folders: Vec<String> = Vec::new();
    for &s in &args.offsets_mm {
        let folder = aadpm_folder(s);
        if folders.contains(&folder) {
            bail!("--offsets-mm: offset {s} mm is given twice");
        }
        folders.push(folder);
    }
    if args.levels == Some(0) {
        bail!("--levels must be at least 1");
    }
    if args.threads == Some(0) {
        bail!("--threads must be at least 1");
    }

    let manifest_path = args.dataset.join(MANIFEST_FILE);
    if !manifest_path.exists() {
        bail!(
            "`{}` is not a dataset: it has no {MANIFEST_FILE} (generate one with `holo dataset --out {}`)",
            args.dataset.display(),
            args.dataset.display()
        );
    }
    let manifest = read_manifest(&args.dataset)
        .with_context(|| format!("cannot read the dataset in `{}`", args.dataset.display()))?;
    let split = manifest.split(args.split).with_context(|| {
        format!(
            "the dataset in `{}` has no {} split",
            args.dataset.display(),
            args.split.name()
        )
    })?;
    if split.samples == 0 {
        bail!(
            "the {} split of `{}` holds no scene",
            args.split.name(),
            args.dataset.display()
        );
    }
    let count = args.limit.map_or(split.samples, |l| l.min(split.samples));

    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.dataset.join("baselines"));

    let setup = OpticalSetup {
        wavelengths_m: manifest.plan.optics.wavelengths_m,
        pixel_pitch_m: manifest.plan.optics.pixel_pitch_m,
        volume_depth_m: manifest.plan.optics.volume_depth_m,
    };
    setup
        .validate()
        .with_context(|| format!("bad optics in `{}`", manifest_path.display()))?;
    let options = PropagationOptions {
        pad: manifest.plan.synthesis.pad,
        band_limit: manifest.plan.synthesis.band_limit,
    };
    let levels = args.levels.unwrap_or(manifest.plan.synthesis.levels);
    let smlbm = SmLbm {
        levels,
        setup,
        options,
        silhouette_masks: true,
    };
    let mut inputs = vec![manifest_path.clone()];
    inputs.extend(split_files(&manifest, &args.dataset));
    let plan = Plan {
        maimone: SmLbm {
            silhouette_masks: false,
            ..smlbm
        },
        pipelines: args
            .offsets_mm
            .iter()
            .zip(&folders)
            .map(|(&s, folder)| {
                (
                    ReferencePipeline {
                        synthesis: smlbm,
                        offset_m: s * 1e-3,
                        encoding: DoublePhaseMethod::default(),
                    },
                    out.join(folder),
                )
            })
            .collect(),
        maimone_dir: out.join(MAIMONE_FOLDER),
        inputs,
    };
    // The output may lie inside the dataset folder (the default, DATASET/baselines) but be neither the
    // folder nor hold it or any of its files.
    let mut guarded = vec![crate::output::Input {
        flag: "--dataset",
        path: &args.dataset,
        kind: crate::output::InputKind::FolderMayHoldOut,
    }];
    guarded.extend(
        plan.inputs
            .iter()
            .map(|p| crate::output::Input::file("--dataset", p)),
    );
    crate::output::guard("--out", &out, &guarded)?;
    let report_path = out.join(REPORT_FILE);
    {
        let inputs: Vec<&Path> = plan.inputs.iter().map(PathBuf::as_path).collect();
        ensure_not_input(&report_path, &inputs)?;
    }
    let subfolders: Vec<&Path> = std::iter::once(&plan.maimone_dir)
        .chain(plan.pipelines.iter().map(|(_, d)| d))
        .map(PathBuf::as_path)
        .collect();
    crate::output::start_run(&out, &subfolders, Some(&report_path))?;

    let pool = {
        let mut b = rayon::ThreadPoolBuilder::new();
        if let Some(n) = args.threads {
            b = b.num_threads(n);
        }
        b.build().context("cannot start the worker threads")?
    };
    let threads = pool.current_num_threads();
    log::info!(
        "{count} {} scenes of {} ({}x{}): maimone + SM-LBM/AA-DPM at {:?} mm, {levels} planes, {threads} threads",
        args.split.name(),
        args.dataset.display(),
        manifest.plan.resolution[0],
        manifest.plan.resolution[1],
        args.offsets_mm,
    );

    let t_all = Instant::now();
    let bar = progress_bar(count as u64);
    let seconds = pool.install(|| {
        compute_all(
            &plan,
            &manifest,
            &args.dataset,
            args.split,
            count,
            threads,
            &bar,
        )
    })?;
    bar.finish_and_clear();
    let wall_seconds = t_all.elapsed().as_secs_f64();

    let n = seconds.len().max(1) as f64;
    let mean = |f: &dyn Fn(&SceneSeconds) -> f64| seconds.iter().map(f).sum::<f64>() / n;
    let maimone_s = mean(&|s| s.maimone);
    let smlbm_s = mean(&|s| s.smlbm);
    let encode_s: Vec<f64> = (0..plan.pipelines.len())
        .map(|k| mean(&|s| s.encode[k]))
        .collect();
    let total_s = mean(&|s| s.total);

    let mut baselines = vec![json!({
        "name": MAIMONE_FOLDER,
        "folder": MAIMONE_FOLDER,
        "description": "occlusion-unaware layer-based midpoint hologram of the RGB-D input (SM-LBM \
                        without silhouette masks, Maimone et al. 2017), complex",
        "synthesis": plan.maimone,
        "phase_only": false,
        "seconds_per_scene": maimone_s,
    })];
    for (((pipeline, _), folder), (&offset_mm, &enc_s)) in plan
        .pipelines
        .iter()
        .zip(&folders)
        .zip(args.offsets_mm.iter().zip(&encode_s))
    {
        baselines.push(json!({
            "name": folder,
            "folder": folder,
            "description": "post-encoding midpoint hologram: SM-LBM (silhouette masks) of the RGB-D input \
                            -> offset propagation to the SLM (carrier removed) -> AA-DPM -> Fourier filter \
                            and back-propagation to the midpoint plane, times the amplitude normaliser; \
                            compare with the CNN's --phase-only evaluation at the same offset",
            "offset_mm": offset_mm,
            "pipeline": pipeline,
            "phase_only": true,
            "seconds_per_scene": smlbm_s + enc_s,
        }));
    }
    let report = json!({
        "format": "tensorholo-baselines",
        "format_version": 1,
        "tensorholo_version": env!("CARGO_PKG_VERSION"),
        "command": crate::output::command_line(),
        "dataset": crate::output::path_text(&args.dataset),
        "dataset_git_commit": manifest.generator.git_commit,
        "split": args.split,
        "count": count,
        "split_samples": split.samples,
        "file_pattern": "<folder>/<index:05d>.npy, complex64 [3, H, W] (R, G, B) midpoint hologram, \
                         index = position of the scene in the split",
        "input": "first LDI layer only (ldi channels 0-3: R, G, B amplitude, depth; every pixel valid), \
                  the RGB-D input of the CNN",
        "resolution": manifest.plan.resolution,
        "levels": levels,
        "dataset_levels": manifest.plan.synthesis.levels,
        "offsets_mm": args.offsets_mm,
        "optics": manifest.plan.optics,
        "propagation": options,
        "encoding": DoublePhaseMethod::default(),
        "baselines": baselines,
        "seconds_per_scene": {
            "maimone": maimone_s,
            "smlbm": smlbm_s,
            "offset_encode_reconstruct": encode_s,
            "total": total_s,
            "note": "mean per scene on one worker; scenes run in parallel, so this exceeds core-seconds",
        },
        "wall_seconds": wall_seconds,
        "threads": threads,
    });
    crate::args::write_json(&report_path, &report)?;
    log::info!(
        "wrote {} baselines x {count} scenes to {} in {wall_seconds:.1} s: per scene on one worker \
         maimone {maimone_s:.2} s, SM-LBM {smlbm_s:.2} s, AA-DPM chain {} s",
        1 + plan.pipelines.len(),
        out.display(),
        encode_s
            .iter()
            .map(|s| format!("{s:.2}"))
            .collect::<Vec<_>>()
            .join("/"),
    );
    Ok(())
}

/// Paths of every file of the dataset folder that this command must not write over: all shards of all
/// splits.
fn split_files(manifest: &Manifest, dataset: &Path) -> Vec<PathBuf> {
    manifest
        .plan
        .splits
        .iter()
        .flat_map(|s| s.shards.iter().map(|f| dataset.join(&f.file)))
        .collect()
}

/// One scene sent from the shard reader to the workers: its position in the split and its first LDI layer
/// `[4, H, W]`.
type SceneInput = Result<(usize, Array3<f32>)>;

/// Computes the baselines of the first `count` scenes of `split` on the current rayon pool. One thread
/// reads the shards in order (each once) and hands the scenes' first layers to the workers through a
/// bounded queue, so memory stays at one shard plus a few scenes whatever the split's size. Returns the
/// per-scene timings in the split's order.
fn compute_all(
    plan: &Plan,
    manifest: &Manifest,
    dataset: &Path,
    split: Split,
    count: usize,
    threads: usize,
    bar: &ProgressBar,
) -> Result<Vec<SceneSeconds>> {
    let info = manifest
        .split(split)
        .context("split vanished from the manifest")?;
    let (tx, rx) = mpsc::sync_channel::<SceneInput>(2 * threads.max(1));
    let results: Mutex<Vec<Option<SceneSeconds>>> = Mutex::new(vec![None; count]);
    std::thread::scope(|scope| -> Result<()> {
        let reader = scope.spawn(move || {
            let mut position = 0usize;
            for shard_info in &info.shards {
                if position >= count {
                    break;
                }
                let path = dataset.join(&shard_info.file);
                let shard = match read_shard(&path)
                    .with_context(|| format!("cannot read shard {}", path.display()))
                {
                    Ok(shard) => shard,
                    Err(e) => {
                        let _ = tx.send(Err(e));
                        return;
                    }
                };
                if shard.len() != shard_info.samples {
                    let _ = tx.send(Err(anyhow::anyhow!(
                        "shard {} holds {} samples, the manifest says {}",
                        path.display(),
                        shard.len(),
                        shard_info.samples
                    )));
                    return;
                }
                for j in 0..shard.len() {
                    if position >= count {
                        break;
                    }
                    let invalid = shard
                        .ldi_valid
                        .slice(s![j, 0, .., ..])
                        .iter()
                        .filter(|&&v| v == 0)
                        .count();
                    if invalid > 0 {
                        log::warn!(
                            "scene {position}: {invalid} pixels of the first LDI layer are marked \
                             invalid; used as the CNN sees them (amplitude 0, depth 1)"
                        );
                    }
                    let rgbd = shard.ldi.slice(s![j, 0..4, .., ..]).to_owned();
                    if tx.send(Ok((position, rgbd))).is_err() {
                        return; // the workers stopped on an error
                    }
                    position += 1;
                }
            }
            if position < count {
                let _ = tx.send(Err(anyhow::anyhow!(
                    "the shards of the {} split hold {position} scenes, the manifest says {}",
                    split.name(),
                    info.samples
                )));
            }
        });
        let outcome = rx.into_iter().par_bridge().try_for_each(|item| {
            let (index, rgbd) = item?;
            let seconds = plan
                .scene(index, &rgbd)
                .with_context(|| format!("scene {index} of the {} split", split.name()))?;
            results.lock().expect("no worker panicked")[index] = Some(seconds);
            bar.inc(1);
            Ok(())
        });
        // The receiver is gone now, so the reader stops at its next send.
        reader.join().expect("shard reader does not panic");
        outcome
    })?;
    results
        .into_inner()
        .expect("no worker panicked")
        .into_iter()
        .enumerate()
        .map(|(i, s)| s.with_context(|| format!("scene {i} was not computed")))
        .collect()
}
