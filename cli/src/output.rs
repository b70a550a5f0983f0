//! The files `holo reference` and `holo render` both write: SLM patterns, midpoint hologram, focal previews,
//! the scene itself and a report.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use ndarray::{Array3, ArrayView3, Axis};
use num_complex::Complex32;
use serde_json::json;
use tensorholo::io::{
    ensure_not_input, resolve, save_amplitude_png, save_u8_png, write_complex_npy,
};
use tensorholo::metrics::{psnr, ssim_multichannel};
use tensorholo::optics::OpticalSetup;
use tensorholo::reference::channel_means;
use tensorholo::scene::RgbdFrame;

/// Files written into `--out`.
pub const OUTPUTS: [&str; 11] = [
    "phase_r.png",
    "phase_g.png",
    "phase_b.png",
    "midpoint.npy",
    "focus_near.png",
    "focus_mid.png",
    "focus_far.png",
    "target.png",
    "depth.png",
    "report.json",
    "cnn_input.npy",
];

/// Names of the three focal previews, near to far.
pub const FOCUS: [&str; 3] = ["focus_near.png", "focus_mid.png", "focus_far.png"];

/// The output-file section of `--help`.
pub const OUTPUTS_HELP: &str = "\
Outputs in --out:
  phase_r.png phase_g.png phase_b.png  8-bit SLM patterns, one per laser (linear LUT: code c = 2*pi*c/256 rad;
                                       with --calibration, its look-up tables)
  midpoint.npy                         complex64 [3, H, W] midpoint hologram (numpy.load reads it)
  focus_near.png focus_mid.png focus_far.png
                                       simulated reconstructions of the SLM patterns (Fourier filter +
                                       propagation) focused at the 5th/50th/95th depth percentiles
  target.png depth.png                 the scene amplitude and normalised depth (white = far)
  report.json                          inputs, parameters, timings per stage, image statistics, how the
                                       CNN plans were made (cnn_plan: the plan table, --tuning or --tune)
  tuning.json                          (--tune) the CNN plans the timing chose; --tuning FILE repeats them
  cnn_input.npy                        (holo render --save-cnn-input) float32 [4*L, H, W] hologram CNN input";

/// The command line for reports, each argument as text (a name that is not UTF-8 is written lossily, with
/// U+FFFD where its bytes are not text; the files themselves keep their exact names).
pub fn command_line() -> Vec<String> {
    std::env::args_os()
        .map(|a| a.to_string_lossy().into_owned())
        .collect()
}

/// A path as report text: lossy where it is not UTF-8 (U+FFFD where its bytes are not text), never a panic
/// (`serde_json::json!` on a `Path` panics on such a name).
pub fn path_text(path: &Path) -> String {
    path.to_string_lossy().into_owned()
}

/// The output guard's refusal: `--out` is, lies inside or holds an input. A usage error, like the argument
/// parser's: `main` exits with code 2 on it ([`EXIT_USAGE`]).
#[derive(Debug)]
pub struct OutputGuard(pub String);

impl std::fmt::Display for OutputGuard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for OutputGuard {}

/// Exit code of a usage error: the argument parser's, and the output guard's ([`OutputGuard`]).
pub const EXIT_USAGE: i32 = 2;

/// A usage error other than the output guard's (e.g. a bad profile given to `holo display check`): `main`
/// exits with code 2 on it ([`EXIT_USAGE`]).
#[derive(Debug)]
pub struct UsageError(pub String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// What an input path is to the output guard ([`guard`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    /// A file (image, depth map, `.npy`, model, calibration, CSV, capture).
    File,
    /// A folder whose files are inputs (`--rgb-dir`, `--photos`, calibration captures): the output may be
    /// neither it, nor inside it, nor a folder holding it.
    Folder,
    /// A folder that the output may lie inside but not be or hold (`baselines`' dataset folder, whose default
    /// output is `DATASET/baselines`; its files are given to the guard as [`InputKind::File`]s).
    FolderMayHoldOut,
}

/// One input path of a command, with the flag that named it.
#[derive(Debug, Clone, Copy)]
pub struct Input<'a> {
    /// The flag (`--rgb`, `--rgb-dir`, `FILE`), for the message.
    pub flag: &'a str,
    /// The path as given.
    pub path: &'a Path,
    /// File or folder.
    pub kind: InputKind,
}

impl<'a> Input<'a> {
    /// An input file.
    pub fn file(flag: &'a str, path: &'a Path) -> Self {
        Self {
            flag,
            path,
            kind: InputKind::File,
        }
    }

    /// An input folder.
    pub fn folder(flag: &'a str, path: &'a Path) -> Self {
        Self {
            flag,
            path,
            kind: InputKind::Folder,
        }
    }
}

/// Where the entry `path` itself lives: its parent resolved, then its own name. Unlike [`resolve`] this does
/// not follow a final symbolic link, so an input that is a link inside `--out` counts as inside it.
fn resolve_entry(path: &Path) -> PathBuf {
    match (path.parent(), path.file_name()) {
        (Some(parent), Some(name)) => {
            let parent = if parent.as_os_str().is_empty() {
                Path::new(".")
            } else {
                parent
            };
            resolve(parent).join(name)
        }
        _ => resolve(path),
    }
}

/// The output guard of every `holo` command: refuses an output (`--out` folder or output file, flag
/// `out_flag`) that
///
/// - is an input (file or folder),
/// - lies inside an input folder (the run would write among the inputs), or
/// - holds an input, file or folder, anywhere below it (the run writes beside the input and could replace it).
///
/// Paths are compared resolved ([`resolve`]: symbolic links, `.`/`..`, relative spellings; an output that
/// does not exist yet through its nearest existing ancestor). Call it first, before anything is created or
/// written. The refusal is an [`OutputGuard`] naming both paths (exit code 2).
pub fn guard(out_flag: &str, out: &Path, inputs: &[Input]) -> Result<()> {
    let out_resolved = resolve(out);
    let refuse = |what: String, input: &Input| -> Result<()> {
        Err(OutputGuard(format!(
            "{out_flag} `{}` {what} `{}` ({}): refusing to overwrite inputs or write among them; choose an \
             output outside every input",
            out.display(),
            input.path.display(),
            input.flag
        ))
        .into())
    };
    for input in inputs {
        let resolved = resolve(input.path);
        let entry = resolve_entry(input.path);
        let is_folder = input.kind == InputKind::Folder || resolved.is_dir();
        let noun = if is_folder || input.kind == InputKind::FolderMayHoldOut {
            "input folder"
        } else {
            "input"
        };
        if resolved == out_resolved || entry == out_resolved {
            return refuse(format!("is the {noun}"), input);
        }
        if is_folder
            && input.kind != InputKind::FolderMayHoldOut
            && out_resolved.starts_with(&resolved)
        {
            return refuse("lies inside the input folder".into(), input);
        }
        if resolved.starts_with(&out_resolved) || entry.starts_with(&out_resolved) {
            return refuse(format!("holds the {noun}"), input);
        }
    }
    Ok(())
}

/// Refuses an output folder that is, lies inside or holds an input ([`guard`]) or whose files would overwrite
/// an input; creates it and removes a previous run's `report.json` ([`start_run`]).
pub fn prepare(out: &Path, inputs: &[Input]) -> Result<()> {
    guard("--out", out, inputs)?;
    let paths: Vec<&Path> = inputs.iter().map(|i| i.path).collect();
    for name in OUTPUTS {
        ensure_not_input(&out.join(name), &paths)?;
    }
    start_run(out, &[], Some(&out.join("report.json")))
}

/// Starts a run writing into `out`: creates it and the `subfolders` inside it, then removes a previous run's
/// `report` if given (the file the run writes last), so that a folder holding a report holds a complete run and a
/// failed or interrupted re-run does not leave new files beside an old report.
///
/// A subfolder that exists as a symbolic link is refused: writing through it would put files outside `out`.
/// (`out` itself may be a link: the user named it.)
pub fn start_run(out: &Path, subfolders: &[&Path], report: Option<&Path>) -> Result<()> {
    create_dir(out)?;
    for dir in subfolders {
        let mut partial = out.to_path_buf();
        // Check every component below `out`, so that `out/a` being a link to elsewhere is caught for `out/a/b`.
        for component in dir.strip_prefix(out).unwrap_or(dir).components() {
            partial.push(component);
            if std::fs::symlink_metadata(&partial).is_ok_and(|m| m.file_type().is_symlink()) {
                bail!(
                    "`{}` is a symbolic link: refusing to write through it out of the output folder `{}` \
                     (remove the link or choose another --out)",
                    partial.display(),
                    out.display()
                );
            }
        }
        create_dir(dir)?;
    }
    report.map_or(Ok(()), remove_old_report)
}

/// A step that may refuse the run before anything is written (a display no model serves): on its error an
/// earlier run's `report.json` in `out`, if there is one, is removed so that it is not taken for this run's,
/// and nothing else is created or touched.
pub fn before_writing<T>(out: &Path, step: Result<T>) -> Result<T> {
    if step.is_err() && out.is_dir() {
        remove_old_report(&out.join("report.json"))?;
    }
    step
}

/// Removes a previous run's report at `report`, if there is one (the run writes its own last). A device, a
/// FIFO or a socket there, a link to one, or a standard stream (`--json /dev/stdout`, `/dev/fd/1`) is not a
/// report: it is left as it is (`tensorholo::io::remove_output`; docs/INPUTS.md, "Outputs").
pub fn remove_old_report(report: &Path) -> Result<()> {
    tensorholo::io::remove_output(report)
        .with_context(|| format!("cannot remove the old {}", report.display()))
}

/// `create_dir_all`, which fails on an existing file of that name, with the folder named.
fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create output folder {}", dir.display()))
}

/// What [`write_images`] writes besides the scene.
pub struct Images<'a> {
    /// SLM codes `[3, H, W]`.
    pub codes: ArrayView3<'a, u8>,
    /// Complex midpoint hologram `[3, H, W]`.
    pub midpoint: ArrayView3<'a, Complex32>,
    /// The three focal previews (phase-only reconstructions at `depths`), near to far.
    pub focus: &'a [Array3<f32>],
    /// The complex hologram's reconstructions at the same depths, if the encoding loss should be reported.
    pub ideal: Option<&'a [Array3<f32>]>,
    /// Normalised depths of the previews.
    pub depths: &'a [f64],
}

/// Writes the SLM codes, the midpoint hologram, the focal previews, the scene and its depth. Returns
/// per-preview statistics (PSNR/SSIM against `ideal` when given).
pub fn write_images(
    out: &Path,
    images: &Images,
    setup: &OpticalSetup,
    frame: &RgbdFrame,
) -> Result<Vec<serde_json::Value>> {
    let Images {
        codes,
        midpoint,
        focus,
        ideal,
        depths,
    } = *images;
    for (c, name) in ["phase_r.png", "phase_g.png", "phase_b.png"]
        .iter()
        .enumerate()
    {
        save_u8_png(&out.join(name), codes.index_axis(Axis(0), c))?;
    }
    write_complex_npy(&out.join("midpoint.npy"), midpoint)?;
    let mut stats = Vec::new();
    for (i, ((name, &d), recon)) in FOCUS.iter().zip(depths).zip(focus).enumerate() {
        save_amplitude_png(&out.join(name), recon.view(), 1.0)?;
        let mut s = json!({
            "file": name,
            "depth": d,
            "z_m": setup.depth_to_z(d),
            "mean_amplitude_rgb": channel_means(recon),
        });
        if let Some(ideal) = ideal {
            let (a, b) = (clamp01(&ideal[i]), clamp01(recon));
            s["encoding_psnr_db"] = json!(psnr(a.view(), b.view(), 1.0)?);
            s["encoding_ssim"] = json!(ssim_multichannel(a.view(), b.view(), 1.0)?);
        }
        stats.push(s);
    }
    save_amplitude_png(&out.join("target.png"), frame.amplitude.view(), 1.0)?;
    let depth_preview = frame.depth.mapv(f32::sqrt).insert_axis(Axis(0));
    save_amplitude_png(&out.join("depth.png"), depth_preview.view(), 1.0)?;
    Ok(stats)
}

fn clamp01(a: &Array3<f32>) -> Array3<f32> {
    a.mapv(|v| v.clamp(0.0, 1.0))
}
