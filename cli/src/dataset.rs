//! `holo dataset`: random-scene LDIs + SM-LBM midpoint holograms in `.npz` shards with a manifest
//! (the paper's MIT-CGH-4K-V2 recipe; format in `docs/DATASET.md`).

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use tensorholo::dataset::{
    generate, generate_shards, merge_shards, save_ldi_previews, DatasetConfig, DisplayInfo,
    GenerateOptions, SampleGenerator, ShardSelection, Split, MANIFEST_FILE,
};
use tensorholo::display::DisplayProfile;
use tensorholo::io::ensure_not_input;
use tensorholo::scene::{write_ldi_dir, DepthEncoding, RandomSceneConfig};
use tensorholo::synthesis::{AberrationCorrection, SmLbm};

/// `MIN-MAX` (inclusive) or a single number.
fn parse_count_range(s: &str) -> std::result::Result<[usize; 2], String> {
    let parse = |v: &str| {
        v.trim()
            .parse::<usize>()
            .map_err(|_| format!("`{v}` is not a non-negative integer"))
    };
    let (lo, hi) = match s.split_once('-') {
        Some((a, b)) => (parse(a)?, parse(b)?),
        None => {
            let n = parse(s)?;
            (n, n)
        }
    };
    if lo > hi {
        return Err(format!("range `{s}`: MIN must not exceed MAX"));
    }
    Ok([lo, hi])
}

/// `SPLIT:INDEX` with SPLIT one of train, val, test.
fn parse_sample(s: &str) -> std::result::Result<(Split, usize), String> {
    let (split, index) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}`: expected SPLIT:INDEX, e.g. test:0"))?;
    let split = match split {
        "train" => Split::Train,
        "val" => Split::Val,
        "test" => Split::Test,
        _ => return Err(format!("`{split}`: the splits are train, val and test")),
    };
    let index = index
        .parse::<usize>()
        .map_err(|_| format!("`{index}` is not a sample index (0, 1, …)"))?;
    Ok((split, index))
}

/// Arguments of `holo dataset`.
#[derive(Debug, Args)]
#[command(after_long_help = EXAMPLES)]
pub struct DatasetArgs {
    /// Output folder (created if missing). A folder that already holds a dataset (manifest.json) is
    /// refused unless --force. With --export-ldi: the LDI folder.
    #[arg(long)]
    out: PathBuf,
    /// Write one sample's layered depth image as an LDI folder into --out instead of a dataset:
    /// rgb_K.png (8-bit sRGB) and depth_K.png (16-bit, encoding relative16, 0 = no point) for each layer,
    /// front first, and ldi.json. SPLIT:INDEX (e.g. test:0) is regenerated exactly from --seed and the
    /// scene flags of the dataset it belongs to; no hologram is computed. Render it with
    /// `holo render --ldi OUT --depth-encoding relative16`.
    #[arg(long, value_name = "SPLIT:INDEX", value_parser = parse_sample)]
    export_ldi: Option<(Split, usize)>,
    /// Training samples (paper: 3800).
    #[arg(long, default_value_t = 8)]
    train: usize,
    /// Validation samples (paper: 100).
    #[arg(long, default_value_t = 2)]
    val: usize,
    /// Test samples (paper: 100).
    #[arg(long, default_value_t = 2)]
    test: usize,
    /// Sample size: SIZE (square) or HEIGHTxWIDTH (paper: 384).
    #[arg(long, default_value = "384", value_parser = crate::args::parse_size)]
    size: (usize, usize),
    /// LDI layers kept per pixel (paper: 5).
    #[arg(long, default_value_t = 5)]
    layers: usize,
    /// SM-LBM depth planes of the ground-truth hologram (paper: 2048 suffices; 10000 as a showcase). With
    /// --aberration the cost grows as G(G+1)/2 propagations per colour for G non-empty planes
    /// (e.g. 131,328 for 512 planes): lower it.
    #[arg(long, default_value_t = 2048)]
    levels: usize,
    /// Aberration profile (JSON, docs/ABERRATION.md): the ground truth is the aberration-corrected SM-LBM of
    /// Eq. 5 (each depth plane corrected at its distance from the SLM plane, --offset-mm). Costs G(G+1)/2
    /// propagations per colour instead of G: lower --levels; a --levels whose worst case exceeds 5,000,000
    /// per colour (above 3161) is refused.
    #[arg(long, value_name = "FILE")]
    aberration: Option<PathBuf>,
    /// With --aberration: distance in millimetres from the midpoint plane to the SLM plane of the display
    /// the correction is for (a plane at z is corrected with the coefficients at z - offset).
    #[arg(
        long,
        default_value_t = 0.0,
        allow_hyphen_values = true,
        requires = "aberration"
    )]
    offset_mm: f64,
    /// Base seed; sample i of a split is regenerated exactly from (seed, split, i).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Samples per .npz shard.
    #[arg(long, default_value_t = 16)]
    shard_size: usize,
    /// Folder of photos (PNG, JPEG, PPM) whose random crops may texture the shapes.
    #[arg(long)]
    photos: Option<PathBuf>,
    /// Probability that a texture is a photo crop (with --photos).
    #[arg(long, default_value_t = 0.5, requires = "photos")]
    photo_probability: f32,
    /// Number of shapes per scene, MIN-MAX (default 8-40), in front of the background plane.
    #[arg(long, value_parser = parse_count_range)]
    shapes: Option<[usize; 2]>,
    /// Probability that a shape is a thin structure (line, thin bar, ring, wavy stroke); default 0.2.
    #[arg(long)]
    thin_probability: Option<f32>,
    /// Store shard arrays uncompressed (about twice the size, faster to read) instead of deflated
    /// (numpy.load reads both).
    #[arg(long)]
    uncompressed: bool,
    /// PNG previews of the first training samples written to OUT/previews/.
    #[arg(long, default_value_t = 4)]
    previews: usize,
    /// Worker threads (default: all cores, or RAYON_NUM_THREADS). Samples run in parallel; each
    /// sample's three colours share the same pool.
    #[arg(long, value_parser = crate::args::parse_threads)]
    threads: Option<usize>,
    #[command(flatten)]
    optics: crate::args::OpticsArgs,
    /// Replace a dataset already in --out (manifest, same-named shards, shards the old manifest listed).
    /// Without it, shards a previous run finished with the same configuration are kept (resume).
    #[arg(long)]
    force: bool,
    /// Write only part I of N of the shards (0-based): those whose position j in the plan (train shards
    /// first, then val, then test) has j mod N = I, with no manifest; run every part with the same flags
    /// (on as many machines as you like), then `holo dataset --merge --out DIR`. The shards are
    /// byte-identical to a one-process run's. `auto` reads I and N from a Slurm job array
    /// (SLURM_ARRAY_TASK_ID, _MIN, _STEP, _COUNT) or from a Kubernetes Indexed Job (JOB_COMPLETION_INDEX,
    /// with --shard-count N).
    #[arg(long, value_name = "I/N|auto", conflicts_with = "export_ldi")]
    shard: Option<String>,
    /// With --shard auto in a Kubernetes Indexed Job: the number of parts (the Job's completions).
    #[arg(long, value_name = "N", requires = "shard")]
    shard_count: Option<usize>,
    /// Finish a sharded dataset: check that --out holds every planned shard once, of one configuration
    /// (read from the shards' records: no other flag is needed), and write manifest.json. A missing or
    /// foreign shard is named, with the command that writes it.
    #[arg(long, conflicts_with_all = ["shard", "export_ldi"])]
    merge: bool,
}

/// The part of `--shard` (all shards without it).
fn shard_selection(shard: Option<&str>, shard_count: Option<usize>) -> Result<ShardSelection> {
    let env = |k: &str| std::env::var(k).ok().filter(|v| !v.is_empty());
    let number = |k: &str, v: &str| -> Result<usize> {
        v.trim()
            .parse::<usize>()
            .with_context(|| format!("{k}=`{v}` is not a non-negative integer"))
    };
    let selection = match shard {
        None => return Ok(ShardSelection::ALL),
        Some("auto") => {
            if let Some(id) = env("SLURM_ARRAY_TASK_ID") {
                let id = number("SLURM_ARRAY_TASK_ID", &id)?;
                let min = env("SLURM_ARRAY_TASK_MIN")
                    .map(|v| number("SLURM_ARRAY_TASK_MIN", &v))
                    .transpose()?
                    .unwrap_or(0);
                let step = env("SLURM_ARRAY_TASK_STEP")
                    .map(|v| number("SLURM_ARRAY_TASK_STEP", &v))
                    .transpose()?
                    .unwrap_or(1);
                if step == 0 {
                    bail!("--shard auto: SLURM_ARRAY_TASK_STEP=0, but a job array's step is at least 1");
                }
                let count = match (shard_count, env("SLURM_ARRAY_TASK_COUNT")) {
                    (Some(n), _) => n,
                    (None, Some(v)) => number("SLURM_ARRAY_TASK_COUNT", &v)?,
                    (None, None) => bail!(
                        "--shard auto: SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not; pass \
                         --shard-count N"
                    ),
                };
                if id < min || (id - min) % step != 0 {
                    bail!(
                        "--shard auto: SLURM_ARRAY_TASK_ID {id} is not in the array {min}, {}, …",
                        min + step
                    );
                }
                ShardSelection::new((id - min) / step, count).with_context(|| {
                    format!(
                        "--shard auto: SLURM_ARRAY_TASK_ID={id} (part {} with SLURM_ARRAY_TASK_MIN={min}, \
                         SLURM_ARRAY_TASK_STEP={step}) of {count} parts (SLURM_ARRAY_TASK_COUNT or --shard-count)",
                        (id - min) / step
                    )
                })
            } else if let Some(index) = env("JOB_COMPLETION_INDEX") {
                let index = number("JOB_COMPLETION_INDEX", &index)?;
                let Some(count) = shard_count else {
                    bail!(
                        "--shard auto in a Kubernetes Indexed Job (JOB_COMPLETION_INDEX={index}) needs \
                         --shard-count N, the Job's completions"
                    );
                };
                ShardSelection::new(index, count).with_context(|| {
                    format!("--shard auto: JOB_COMPLETION_INDEX={index} with --shard-count {count}")
                })
            } else {
                bail!(
                    "--shard auto: neither a Slurm job array (SLURM_ARRAY_TASK_ID) nor a Kubernetes \
                     Indexed Job (JOB_COMPLETION_INDEX) is running this; give the part as --shard I/N"
                );
            }
        }
        Some(text) => {
            let (i, n) = text
                .split_once('/')
                .with_context(|| format!("--shard `{text}`: expected I/N (e.g. 0/8) or auto"))?;
            if shard_count.is_some() {
                bail!(
                    "--shard-count goes with --shard auto; --shard {text} already gives the count"
                );
            }
            ShardSelection::new(number("--shard I", i)?, number("--shard N", n)?)
                .with_context(|| format!("--shard {text}"))
        }
    };
    selection
}

const EXAMPLES: &str = "\
Examples:
  holo dataset --out data/quick
      8/2/2 samples of 384x384, 5-layer LDIs, 2048 SM-LBM planes (a few minutes on 2 cores)
  holo dataset --out data/mit-cgh-4k-v2 --train 3800 --val 100 --test 100 --size 384 --layers 5 --levels 10000
      the paper's MIT-CGH-4K-V2 configuration
  holo dataset --out data/photos --photos ~/Pictures/textures --photo-probability 0.7
      shapes textured with random crops of your photos
  holo dataset --out data/corrected --aberration calibration.json --offset-mm 6 --levels 256
      aberration-corrected ground truth (Eq. 5) for a display whose SLM is 6 mm from the midpoint
  holo dataset --out out/ldi_test0 --export-ldi test:0 --size 256 --seed 2027
      test sample 0 of that dataset as an LDI folder (rgb_K.png, depth_K.png), for holo render --ldi
  holo dataset --out data/big --train 3800 --val 100 --test 100 --shard 3/8
  holo dataset --out data/big --merge
      part 3 of 8 (on any machine sharing data/big; the same flags for every part), then the manifest
  sbatch --array=0-7 scripts/cluster/dataset.sbatch
      the same on a Slurm job array (--shard auto); scripts/cluster/ also has the Kubernetes Indexed Job

Outputs in --out:
  manifest.json            format, generator (version, git commit), seed, splits and shard files,
                           resolution, LDI layers, SM-LBM levels, optics, scene configuration, array
                           layouts, statistics (non-empty planes, occlusion, timings)
  train-00000.npz.shard.json ...
                           each shard's record: its configuration, size and statistics (resume, merge)
  train-00000.npz ...      shards: ldi float32 [N, 4L, H, W] (per layer R, G, B amplitude, depth),
  val-00000.npz ...        ldi_valid uint8 [N, L, H, W], midpoint complex64 [N, 3, H, W] (R, G, B),
  test-00000.npz ...       seed uint64 [N], index uint64 [N]; see docs/DATASET.md
  previews/train_00000_rgb.png, _depth.png, _layers.png
                           first-layer amplitude, first-layer depth (white = far), all layers";

/// The git commit of this build's source tree, `-dirty` if it has uncommitted changes to tracked
/// files; from `TENSORHOLO_GIT_COMMIT` at build time if set, else asked of git at run time (works when
/// run from a checkout), else `None`.
fn git_commit() -> Option<String> {
    if let Some(c) = option_env!("TENSORHOLO_GIT_COMMIT") {
        return Some(c.to_string());
    }
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new("git")
        .arg("-C")
        .arg(dir)
        .args(["rev-parse", "HEAD"])
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    let commit = String::from_utf8(out.stdout).ok()?.trim().to_string();
    let dirty = Command::new("git")
        .arg("-C")
        .arg(dir)
        .args(["status", "--porcelain", "--untracked-files=no"])
        .output()
        .map(|o| o.status.success() && !o.stdout.is_empty())
        .unwrap_or(false);
    Some(if dirty { commit + "-dirty" } else { commit })
}

fn progress_bar(total: u64) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} samples ({per_sec}, eta {eta})",
        )
        .expect("valid template"),
    );
    bar.set_message("dataset");
    bar
}

/// Builds the dataset configuration from the arguments and the `--display` profile the command read.
fn config(args: &DatasetArgs, profile: Option<&DisplayProfile>) -> Result<DatasetConfig> {
    let defaults = RandomSceneConfig::default();
    let scene = RandomSceneConfig {
        height: args.size.0,
        width: args.size.1,
        layers: args.layers,
        shape_count: args.shapes.unwrap_or(defaults.shape_count),
        thin_probability: args.thin_probability.unwrap_or(defaults.thin_probability),
        photo_folder: args.photos.clone(),
        photo_probability: args.photo_probability,
        ..defaults
    };
    let synthesis = SmLbm {
        levels: args.levels,
        setup: args.optics.setup(profile)?,
        options: args.optics.options(),
        silhouette_masks: true,
    };
    if let (None, Some((path, s, _))) = (&args.aberration, aberration_source(args, profile)?) {
        log::info!(
            "the --display profile's aberration {}: the ground truth is the aberration-corrected SM-LBM \
             (Eq. 5) for an SLM {} mm from the midpoint plane (the profile's first offset)",
            path.display(),
            s * 1e3
        );
    }
    let aberration = match aberration_source(args, profile)? {
        Some((path, slm_offset_m, what)) => Some(AberrationCorrection {
            profile: crate::aberration::load(what, &path)?,
            slm_offset_m,
        }),
        None => None,
    };
    let config = DatasetConfig {
        scene,
        synthesis,
        aberration,
        seed: args.seed,
        train: args.train,
        val: args.val,
        test: args.test,
        shard_size: args.shard_size,
        compress: !args.uncompressed,
    };
    config.validate()?;
    if let Some(c) = config.corrected_synthesis() {
        crate::aberration::check_cost(
            c.worst_case_propagation_count(),
            args.levels,
            "worst case of a random scene",
        )?;
    }
    Ok(config)
}

/// The aberration file the ground truth corrects and the SLM offset (metres) it is for: `--aberration` at
/// `--offset-mm`, else the `--display` profile's `aberration` at the profile's first offset (so that
/// `training/retrain.sh --display FILE` trains for it); `None` without either. A profile's `prescription` is
/// not used here: the real-time correction is exact for it, no retraining needed.
fn aberration_source(
    args: &DatasetArgs,
    profile: Option<&DisplayProfile>,
) -> Result<Option<(PathBuf, f64, &'static str)>> {
    if let Some(path) = &args.aberration {
        crate::args::check_offset_mm(args.offset_mm)?;
        return Ok(Some((path.clone(), args.offset_mm * 1e-3, "--aberration")));
    }
    let Some(profile) = profile else {
        return Ok(None);
    };
    Ok(profile.aberration.clone().map(|path| {
        (
            path,
            profile.default_offset_m(),
            "the --display profile's aberration",
        )
    }))
}

/// Runs `holo dataset`.
pub fn run(args: &DatasetArgs) -> Result<()> {
    let inputs: Vec<crate::output::Input> = [
        args.photos
            .as_deref()
            .map(|p| crate::output::Input::folder("--photos", p)),
        args.optics.guard_input(),
    ]
    .into_iter()
    .flatten()
    .collect();
    // The display profile, read once and passed down.
    let profile = args.optics.profile()?;
    let aberration = aberration_source(args, profile.as_ref())?;
    let mut inputs = inputs;
    if let Some((path, _, what)) = &aberration {
        inputs.push(crate::output::Input::file(what, path));
    }
    crate::output::guard("--out", &args.out, &inputs)?;
    if args.merge {
        return merge(args);
    }
    let selection = shard_selection(args.shard.as_deref(), args.shard_count)?;
    let config = config(args, profile.as_ref())?;
    if let Some((split, index)) = args.export_ldi {
        return export_ldi(args, &config, split, index);
    }
    if args.out.join(MANIFEST_FILE).exists() && !args.force {
        bail!(
            "`{}` already holds a dataset ({MANIFEST_FILE}); pass --force to replace it or choose \
             another --out",
            args.out.display()
        );
    }
    let pool = {
        let mut b = rayon::ThreadPoolBuilder::new();
        if let Some(n) = args.threads {
            if n == 0 {
                bail!("--threads must be at least 1");
            }
            b = b.num_threads(n);
        }
        b.build().context("cannot start the worker threads")?
    };
    pool.install(|| run_in_pool(args, &config, selection, profile.as_ref()))
}

/// `--merge`: the manifest of a sharded dataset.
fn merge(args: &DatasetArgs) -> Result<()> {
    let t = std::time::Instant::now();
    let manifest = merge_shards(&args.out, args.force)?;
    let st = &manifest.statistics;
    log::info!(
        "merged {} ({} shards, {} samples) in {:.1} s: {:.2} s per sample on one worker, {:.1} s of \
         generation in all",
        args.out.display(),
        manifest.plan.splits.iter().map(|s| s.shards.len()).sum::<usize>(),
        st.samples,
        t.elapsed().as_secs_f64(),
        st.mean_sample_seconds,
        st.wall_seconds
    );
    Ok(())
}

/// The photos the scenes may be textured with (inputs: never written over).
fn photo_paths(generator: &SampleGenerator) -> Vec<&Path> {
    generator
        .scenes()
        .photo_paths()
        .iter()
        .map(PathBuf::as_path)
        .collect()
}

/// `--export-ldi SPLIT:INDEX`: the sample's LDI as an LDI folder in `--out`, with `ldi.json` (written last).
fn export_ldi(
    args: &DatasetArgs,
    config: &DatasetConfig,
    split: Split,
    index: usize,
) -> Result<()> {
    let count = match split {
        Split::Train => config.train,
        Split::Val => config.val,
        Split::Test => config.test,
    };
    if args.out.join(MANIFEST_FILE).exists() {
        bail!(
            "--export-ldi writes an LDI folder, and `{}` holds a dataset ({MANIFEST_FILE}): choose another --out \
             (the sample is regenerated from --seed and the scene flags, which the dataset's {MANIFEST_FILE} \
             lists under generator.command)",
            args.out.display()
        );
    }
    if index >= count {
        bail!(
            "--export-ldi {}:{index}: the {} split has {count} samples (--{}); sample indices start at 0",
            split.name(),
            split.name(),
            split.name()
        );
    }
    let generator = SampleGenerator::new(config)?;
    let photos = photo_paths(&generator);
    let ldi = generator.ldi(split, index)?;
    crate::output::start_run(&args.out, &[], None)?;
    for k in 0..ldi.num_layers() {
        for stem in ["rgb", "depth"] {
            ensure_not_input(&args.out.join(format!("{stem}_{k}.png")), &photos)?;
        }
    }
    let files = write_ldi_dir(&ldi, &args.out)?;
    let valid: Vec<f64> = ldi
        .layers()
        .iter()
        .map(|l| l.valid.iter().filter(|&&v| v).count() as f64 / l.valid.len() as f64)
        .collect();
    let report = serde_json::json!({
        "tensorholo_version": env!("CARGO_PKG_VERSION"),
        "command": crate::output::command_line(),
        "sample": {"split": split.name(), "index": index, "seed": config.seed},
        "size": [ldi.height(), ldi.width()],
        "layers": ldi.num_layers(),
        "depth_encoding": DepthEncoding::Relative16,
        "valid_fraction": valid,
        "files": files,
        "render": format!(
            "holo render --ldi {} --depth-encoding relative16 --out OUT",
            crate::output::path_text(&args.out)
        ),
    });
    crate::args::write_json(&args.out.join("ldi.json"), &report)?;
    log::info!(
        "wrote {} sample {index} as an LDI folder: {} layers of {}x{} in {}",
        split.name(),
        ldi.num_layers(),
        ldi.height(),
        ldi.width(),
        args.out.display()
    );
    Ok(())
}

fn run_in_pool(
    args: &DatasetArgs,
    config: &DatasetConfig,
    selection: ShardSelection,
    profile: Option<&DisplayProfile>,
) -> Result<()> {
    let generator = SampleGenerator::new(config)?;
    let photos = photo_paths(&generator);
    let total = (config.train + config.val + config.test) as u64;
    log::info!(
        "{} samples ({}/{}/{}) of {}x{}, {} LDI layers, {} SM-LBM planes, {} threads{}",
        total,
        config.train,
        config.val,
        config.test,
        config.scene.height,
        config.scene.width,
        config.scene.layers,
        config.synthesis.levels,
        rayon::current_num_threads(),
        if photos.is_empty() {
            String::new()
        } else {
            format!(", {} photos", photos.len())
        }
    );

    // Previews first (cheap: scenes only), so that a long run can be checked early.
    let preview_dir = args.out.join("previews");
    // The manifest is the dataset's report: `generate` replaces it last (and reads the old one under --force).
    // The first part (or the only one) writes them.
    let previews = if selection.index() == 0 {
        args.previews.min(config.train)
    } else {
        0
    };
    let subfolders: &[&Path] = if previews > 0 { &[&preview_dir] } else { &[] };
    crate::output::start_run(&args.out, subfolders, None)?;
    for i in 0..previews {
        let stem = format!("train_{i:05}");
        for suffix in ["rgb", "depth", "layers"] {
            ensure_not_input(&preview_dir.join(format!("{stem}_{suffix}.png")), &photos)?;
        }
        let ldi = generator.ldi(Split::Train, i)?;
        save_ldi_previews(&preview_dir, &stem, &ldi)?;
    }

    let bar = progress_bar(total);
    let options = GenerateOptions {
        overwrite: args.force,
        git_commit: git_commit(),
        command: crate::output::command_line(),
        aberration_file: aberration_source(args, profile)?.map(|(path, _, _)| path),
        display: profile.map(|p| DisplayInfo::new(p, args.optics.display.as_deref())),
    };
    if selection != ShardSelection::ALL {
        let run = generate_shards(&args.out, config, &options, selection, &|done, total| {
            bar.set_length(total);
            bar.set_position(done)
        })?;
        bar.finish_and_clear();
        log::info!(
            "part {selection}: wrote {} shards ({} samples){}; when every part is done: holo dataset \
             --merge --out {}",
            run.written.len(),
            run.samples,
            if run.kept.is_empty() {
                String::new()
            } else {
                format!(", kept {} finished earlier", run.kept.len())
            },
            crate::output::path_text(&args.out)
        );
        return Ok(());
    }
    let manifest = generate(&args.out, config, &options, &|done, total| {
        bar.set_length(total);
        bar.set_position(done)
    })?;
    bar.finish_and_clear();
    let st = &manifest.statistics;
    log::info!(
        "wrote {} ({} shards) in {:.1} s: {:.2} s per sample on one worker, {:.0} non-empty SM-LBM \
         planes per sample (min {}, max {}), valid pixels per layer {:?}, {:.0}% of pixels with >= 2 layers",
        args.out.display(),
        manifest.plan.splits.iter().map(|s| s.shards.len()).sum::<usize>(),
        st.wall_seconds,
        st.mean_sample_seconds,
        st.mean_nonempty_planes,
        st.min_nonempty_planes,
        st.max_nonempty_planes,
        st.mean_valid_fraction
            .iter()
            .map(|v| format!("{:.0}%", 100.0 * v))
            .collect::<Vec<_>>(),
        100.0 * st.mean_multi_layer_fraction
    );
    Ok(())
}
