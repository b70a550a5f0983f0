//! Command-line flags shared by several subcommands.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::Args;
use serde_json::json;
use tensorholo::cnn::{CnnOptions, ConvAlgorithm, Isa, SavedPlans};
use tensorholo::display::DisplayProfile;
use tensorholo::encoding::DoublePhaseMethod;
use tensorholo::model::SceneInput;
use tensorholo::optics::{OpticalSetup, PropagationOptions};
use tensorholo::scene::{
    load_ldi_dir, load_rgbd_with_confidence, procedural, DepthEncoding, DepthMapping, DepthRange,
    LayeredDepthImage, LoadOptions, RgbdFrame,
};
use tensorholo::synthesis::{ldi_layers, SceneLayer};

/// Display geometry and angular-spectrum options (`docs/CONVENTIONS.md` §3, §5.1), shared by `reference`,
/// `encode`, `dataset`, `render`, `video` and `bench`: a display profile (`--display`) and the single flags
/// that override its values.
#[derive(Debug, Args)]
pub struct OpticsArgs {
    /// Display profile (JSON, docs/DISPLAYS.md): SLM pitch and resolution, lasers, volume, offsets,
    /// calibration. --pitch-m, --wavelengths-m, --volume-depth-m (and, where a command has them, --offset-mm
    /// and --calibration) override its values.
    #[arg(long, value_name = "FILE")]
    pub display: Option<PathBuf>,
    /// Zero-pad propagations to 2H x 2W (linear convolution; 4x slower).
    #[arg(long)]
    pub pad: bool,
    /// Band-limit transfer functions (Matsushima & Shimobaba 2009).
    #[arg(long)]
    pub band_limit: bool,
    /// SLM pixel pitch in metres [default: 8e-6, or the --display profile's].
    #[arg(long)]
    pub pitch_m: Option<f64>,
    /// Laser wavelengths in metres, R,G,B [default: 6.38e-7,5.2e-7,4.5e-7, or the --display profile's].
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub wavelengths_m: Option<Vec<f64>>,
    /// Depth of the 3D volume in metres, centred on the midpoint hologram [default: 6e-3, or the --display
    /// profile's].
    #[arg(long)]
    pub volume_depth_m: Option<f64>,
}

impl OpticsArgs {
    /// Reads the `--display` profile, if given. A command reads it once, at its start, and passes it down
    /// (so that `--display /dev/stdin` or a pipe fed once serves every part of the command). Errors: the file
    /// cannot be read or is not a valid profile (the message names the key).
    pub fn profile(&self) -> Result<Option<DisplayProfile>> {
        self.display.as_deref().map(read_profile).transpose()
    }

    /// The `--display` file for the output guard ([`crate::output::guard`]), if given.
    pub fn guard_input(&self) -> Option<crate::output::Input<'_>> {
        Some(crate::output::Input::file(
            "--display",
            self.display.as_deref()?,
        ))
    }

    /// The validated optical setup: `profile`'s (the `--display` profile [`OpticsArgs::profile`] read; the
    /// paper's display without one) with the single flags in place of its values. Errors: not exactly 3
    /// wavelengths, or a non-positive value.
    pub fn setup(&self, profile: Option<&DisplayProfile>) -> Result<OpticalSetup> {
        self.setup_over(profile.map_or_else(OpticalSetup::default, DisplayProfile::optics))
    }

    /// The validated optical setup: `base` (the paper's display, or a display profile's) with the flags
    /// given on the command line in place of its values. Errors: as [`OpticsArgs::setup`].
    pub fn setup_over(&self, base: OpticalSetup) -> Result<OpticalSetup> {
        let wavelengths_m = match &self.wavelengths_m {
            None => base.wavelengths_m,
            Some(w) => {
                let [r, g, b] = w[..] else {
                    bail!(
                        "--wavelengths-m needs 3 comma-separated values (R,G,B), got {}",
                        w.len()
                    );
                };
                [r, g, b]
            }
        };
        let setup = OpticalSetup {
            wavelengths_m,
            pixel_pitch_m: self.pitch_m.unwrap_or(base.pixel_pitch_m),
            volume_depth_m: self.volume_depth_m.unwrap_or(base.volume_depth_m),
        };
        setup.validate()?;
        Ok(setup)
    }

    /// Padding and band-limit options.
    pub fn options(&self) -> PropagationOptions {
        PropagationOptions {
            pad: self.pad,
            band_limit: self.band_limit,
        }
    }
}

/// Phase-only encodings offered on the command line (`tensorholo::encoding`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Encoding {
    /// Plain double phase encoding (paper Eq. 7), what DDPM applies after its pre-filter CNN.
    Dpm,
    /// Anti-aliasing DPM: Gaussian pre-blur (--aa-sigma-px, --aa-kernel).
    AaDpm,
    /// Band-limiting DPM (Sui et al. 2021): diamond Fourier mask (--bl-k).
    BlDpm,
}

/// Double phase encoding flags, shared by `reference`, `render`, `video` and `encode`.
#[derive(Debug, Args)]
pub struct EncodingArgs {
    /// Phase-only encoding [default: aa-dpm for reference/render/video (without a pre-filter CNN), dpm for
    /// encode]. `--method` is accepted as an alias.
    #[arg(long, alias = "method", value_enum)]
    pub encoding: Option<Encoding>,
    /// AA-DPM Gaussian standard deviation (pixels).
    #[arg(long, default_value_t = 0.7)]
    pub aa_sigma_px: f32,
    /// AA-DPM Gaussian kernel width (pixels, odd).
    #[arg(long, default_value_t = 5)]
    pub aa_kernel: usize,
    /// BL-DPM cut-off k in (0, 1] (fraction of the checkerboard Nyquist cell).
    #[arg(long, default_value_t = 0.5)]
    pub bl_k: f32,
}

impl EncodingArgs {
    /// The chosen encoding (`default` where none is given) and its SDK method.
    pub fn method(&self, default: Encoding) -> (Encoding, DoublePhaseMethod) {
        let e = self.encoding.unwrap_or(default);
        let m = match e {
            Encoding::Dpm => DoublePhaseMethod::Plain,
            Encoding::AaDpm => DoublePhaseMethod::AntiAliased {
                sigma_px: self.aa_sigma_px,
                kernel_size: self.aa_kernel,
            },
            Encoding::BlDpm => DoublePhaseMethod::BandLimited { k: self.bl_k },
        };
        (e, m)
    }
}

/// Parses a depth encoding name, listing the valid ones on error.
pub fn parse_depth_encoding(s: &str) -> std::result::Result<DepthEncoding, String> {
    s.parse::<DepthEncoding>().map_err(|e| {
        let names: Vec<String> = DepthEncoding::ALL.iter().map(|e| e.to_string()).collect();
        format!("{e} (one of: {})", names.join(", "))
    })
}

/// Parses a worker thread count: 1 to [`tensorholo::cnn::MAX_CNN_THREADS`] (256), refused before any
/// thread is started (`--threads 100000` would otherwise try to start them all).
pub fn parse_threads(s: &str) -> std::result::Result<usize, String> {
    let max = tensorholo::cnn::MAX_CNN_THREADS;
    match s.trim().parse::<usize>() {
        Ok(n) if (1..=max).contains(&n) => Ok(n),
        _ => Err(format!("`{s}` is not a thread count in 1..={max}")),
    }
}

/// Parses `HEIGHTxWIDTH` (e.g. `384x512`) or `SIZE` for a square, of at most
/// [`tensorholo::generator::MAX_HOLOGRAM_PIXELS`] (8192 × 8192) pixels: refused here, before anything of that
/// size is allocated.
pub fn parse_size(s: &str) -> std::result::Result<(usize, usize), String> {
    let (h, w) = parse_size_unbounded(s)?;
    let max = tensorholo::generator::MAX_HOLOGRAM_PIXELS;
    if h.saturating_mul(w) > max {
        return Err(format!(
            "{h}x{w} is {} pixels, above the limit of {max} (8192x8192)",
            h.saturating_mul(w)
        ));
    }
    Ok((h, w))
}

fn parse_size_unbounded(s: &str) -> std::result::Result<(usize, usize), String> {
    let parse = |v: &str| {
        v.trim()
            .parse::<usize>()
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| {
                format!("`{v}` is not a positive integer (expected HEIGHTxWIDTH or SIZE)")
            })
    };
    match s.split_once(['x', 'X']) {
        Some((h, w)) => Ok((parse(h)?, parse(w)?)),
        None => {
            let n = parse(s)?;
            Ok((n, n))
        }
    }
}

/// How sensor depth becomes normalised depth, shared by every command that reads RGB-D files.
#[derive(Debug, Args)]
pub struct DepthArgs {
    /// How the depth file stores depth: mm16 (16-bit millimetres: Redwood, derived NYU/SUN), tum (16-bit,
    /// /5000 m), sun (SUN RGB-D bit-rotated mm), kinect-disparity (NYU raw PGM), iphone-disparity (8-bit
    /// normalised disparity of iPhone portraits), relative-near-bright, relative-near-dark (8-bit unitless),
    /// relative16 (16-bit unitless, 0 = no point: LDI folders), metres (float metres in OpenEXR: Record3D).
    #[arg(long, value_parser = parse_depth_encoding)]
    pub depth_encoding: Option<DepthEncoding>,
    /// Nearest metric depth mapped to the front of the 3D volume (metres). Default: 1st percentile of the
    /// valid depths (per frame; give both for a video). Ignored for relative encodings.
    #[arg(long, requires = "z_far_m")]
    pub z_near_m: Option<f32>,
    /// Farthest metric depth mapped to the back of the 3D volume (metres). Default: 99th percentile.
    #[arg(long, requires = "z_near_m")]
    pub z_far_m: Option<f32>,
    /// Mapping from metric depth to the volume: linear in diopters (1/m, how eyes focus) or in metres.
    #[arg(long, default_value = "diopters", value_parser = ["diopters", "metres"])]
    pub depth_mapping: String,
    /// Resize the scene to HEIGHTxWIDTH (e.g. 384x384, the paper's training size). Default: the input's own
    /// size (384x384 for the built-in scene).
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(usize, usize)>,
    /// Refuse a depth map with more than this fraction of invalid pixels (a wrong --depth-encoding is the
    /// usual cause); raise it for a scene that is mostly empty background.
    #[arg(long, default_value_t = 0.75, value_parser = parse_fraction)]
    pub max_invalid_depth: f32,
    /// With --z-near-m/--z-far-m: refuse when more than this fraction of the valid depths lies outside the
    /// range (they would be clamped onto its ends).
    #[arg(long, default_value_t = 0.5, value_parser = parse_fraction)]
    pub max_depth_outside_range: f32,
    /// How a depth map of lower resolution than the colour (the same field of view: a phone's LiDAR depth
    /// under its image) is brought to the colour's: joint-bilateral (guided by the colour, docs/VIDEO.md) or
    /// nearest.
    #[arg(long, value_enum, default_value_t = DepthUpsamplingArg::JointBilateral)]
    pub depth_upsampling: DepthUpsamplingArg,
    /// With depth confidence maps (--confidence, --confidence-dir, a --recording's): depth pixels of lower
    /// confidence are invalid, filled from their confident neighbours. 0 to 255: ARKit and Stray Scanner
    /// store 0 (low), 1 (medium), 2 (high); ARCore 0–255.
    #[arg(long, default_value_t = tensorholo::scene::DEFAULT_MIN_CONFIDENCE)]
    pub min_confidence: u8,
}

/// `--depth-upsampling` ([`tensorholo::scene::DepthUpsampling`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DepthUpsamplingArg {
    /// The colour-guided joint bilateral upsampling (Kopf et al. 2007).
    JointBilateral,
    /// Nearest neighbour: the depth map's own blocky edges.
    Nearest,
}

impl From<DepthUpsamplingArg> for tensorholo::scene::DepthUpsampling {
    fn from(a: DepthUpsamplingArg) -> Self {
        match a {
            DepthUpsamplingArg::JointBilateral => Self::JointBilateral,
            DepthUpsamplingArg::Nearest => Self::Nearest,
        }
    }
}

/// A fraction in [0, 1].
fn parse_fraction(s: &str) -> std::result::Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(f) if (0.0..=1.0).contains(&f) => Ok(f),
        _ => Err(format!("expected a fraction between 0 and 1, got `{s}`")),
    }
}

impl DepthArgs {
    /// Loader options from the flags.
    pub fn load_options(&self) -> Result<LoadOptions> {
        let range = match (self.z_near_m, self.z_far_m) {
            (Some(z_near_m), Some(z_far_m)) => Some(DepthRange { z_near_m, z_far_m }),
            _ => None,
        };
        Ok(LoadOptions {
            range,
            mapping: self
                .depth_mapping
                .parse::<DepthMapping>()
                .map_err(|e| anyhow::anyhow!("{e}"))?,
            size: self.size,
            max_invalid_fraction: self.max_invalid_depth,
            max_outside_range_fraction: self.max_depth_outside_range,
            depth_upsampling: self.depth_upsampling.into(),
            min_confidence: self.min_confidence,
        })
    }
}

/// One scene input, shared by `reference` and `render`: an RGB-D pair of files, an LDI folder, or the
/// built-in scene (as an RGB-D image or a 2-layer LDI).
#[derive(Debug, Args)]
pub struct SceneArgs {
    /// RGB image (PNG, JPEG or PPM, sRGB). Omit (with --depth) to use the built-in procedural scene.
    #[arg(long, requires_all = ["depth", "depth_encoding"], conflicts_with = "ldi")]
    pub rgb: Option<PathBuf>,
    /// Depth map of the RGB image: its size, or a lower resolution of the same field of view (a phone's).
    #[arg(long, requires = "rgb")]
    pub depth: Option<PathBuf>,
    /// The depth map's confidence map (8-bit, at the depth map's resolution: ARKit's confidenceMap, Stray
    /// Scanner's confidence/N.png, ARCore's raw depth confidence): pixels below --min-confidence are invalid.
    #[arg(long, requires = "depth")]
    pub confidence: Option<PathBuf>,
    /// A layered depth image: a folder of rgb_0.png depth_0.png rgb_1.png depth_1.png …, front layer first
    /// (what a depth-peeling pass writes; docs/CONVENTIONS.md §6.3), its depths in --depth-encoding; in the
    /// layers behind the first a stored depth of 0 means "no point here". Without a folder: the built-in
    /// scene as a 2-layer LDI (the second layer holds what the bar and the disc hide).
    #[arg(long, value_name = "DIR", num_args = 0..=1)]
    pub ldi: Option<Option<PathBuf>>,
    #[command(flatten)]
    pub depth_args: DepthArgs,
}

/// A loaded scene: an RGB-D frame, or a layered depth image.
#[derive(Debug)]
pub enum Scene {
    /// An RGB-D frame.
    Frame(RgbdFrame),
    /// A layered depth image (its front layer is the RGB-D frame a camera would see).
    Ldi(LayeredDepthImage),
}

impl Scene {
    /// The RGB-D frame of the front layer (previews, focal depths).
    pub fn front(&self) -> std::borrow::Cow<'_, RgbdFrame> {
        match self {
            Scene::Frame(f) => std::borrow::Cow::Borrowed(f),
            Scene::Ldi(ldi) => std::borrow::Cow::Owned(ldi.to_rgbd()),
        }
    }

    /// The scene's points as SM-LBM layers (every LDI layer).
    pub fn layers(&self) -> Vec<SceneLayer<'_>> {
        match self {
            Scene::Frame(f) => vec![SceneLayer::from(f)],
            Scene::Ldi(ldi) => ldi_layers(ldi),
        }
    }

    /// `(height, width)`.
    pub fn size(&self) -> (usize, usize) {
        match self {
            Scene::Frame(f) => (f.height(), f.width()),
            Scene::Ldi(ldi) => (ldi.height(), ldi.width()),
        }
    }

    /// Which input the hologram CNN needs.
    pub fn input(&self) -> SceneInput {
        match self {
            Scene::Frame(_) => SceneInput::Rgbd,
            Scene::Ldi(_) => SceneInput::Ldi,
        }
    }
}

impl SceneArgs {
    /// The input files and folders (never overwritten).
    pub fn inputs(&self) -> Vec<&Path> {
        [self.rgb.as_deref(), self.depth.as_deref(), self.ldi_dir()]
            .into_iter()
            .flatten()
            .collect()
    }

    /// The LDI folder of `--ldi DIR` (`None` for `--ldi` alone, the built-in LDI).
    fn ldi_dir(&self) -> Option<&Path> {
        self.ldi.as_ref().and_then(Option::as_deref)
    }

    /// The input files for the output guard ([`crate::output::guard`]), with their flags.
    pub fn guard_inputs(&self) -> Vec<crate::output::Input<'_>> {
        let mut inputs: Vec<_> = [
            ("--rgb", &self.rgb),
            ("--depth", &self.depth),
            ("--confidence", &self.confidence),
        ]
        .into_iter()
        .filter_map(|(flag, p)| Some(crate::output::Input::file(flag, p.as_deref()?)))
        .collect();
        inputs.extend(
            self.ldi_dir()
                .map(|p| crate::output::Input::folder("--ldi", p)),
        );
        inputs
    }

    /// Loads the scene; returns it with a JSON description of its source. Refuses a scene smaller than the
    /// SSIM window or black everywhere, naming the input.
    pub fn load(&self) -> Result<(Scene, serde_json::Value)> {
        let (scene, source) = self.load_any()?;
        let (h, w) = scene.size();
        let min = tensorholo::metrics::SSIM_WINDOW;
        if h < min || w < min {
            bail!(
                "the frame is {h}×{w} pixels: holo needs at least {min}×{min} (the window of the SSIM quality \
                 scores it reports); render larger with --size"
            );
        }
        // Before any work (the reference's SM-LBM takes long), naming the input.
        let brightest = match &scene {
            Scene::Frame(f) => f.amplitude.iter().fold(0.0f32, |m, &a| m.max(a)),
            Scene::Ldi(ldi) => ldi
                .layers()
                .iter()
                .fold(0.0f32, |m, l| l.amplitude.iter().fold(m, |m, &a| m.max(a))),
        };
        tensorholo::pipeline::check_not_black(brightest).with_context(|| {
            match (self.rgb.as_deref(), self.ldi_dir()) {
                (Some(p), _) | (None, Some(p)) => format!("`{}`", p.display()),
                (None, None) => "the scene".to_string(),
            }
        })?;
        Ok((scene, source))
    }

    fn load_any(&self) -> Result<(Scene, serde_json::Value)> {
        let encoding = self.depth_args.depth_encoding;
        if let Some(dir) = self.ldi_dir() {
            let Some(encoding) = encoding else {
                bail!(
                    "--ldi {} needs --depth-encoding (the encoding of every depth_K file; relative16 for \
                     folders written by holo dataset --export-ldi)",
                    dir.display()
                );
            };
            let options = self.depth_args.load_options()?;
            let (ldi, report) = load_ldi_dir(dir, encoding, &options)?;
            return Ok((
                Scene::Ldi(ldi),
                json!({"kind": "ldi-folder", "folder": crate::output::path_text(dir), "ldi_report": report}),
            ));
        }
        match (&self.rgb, &self.depth, encoding) {
            (Some(rgb), Some(depth), Some(encoding)) => {
                let options = self.depth_args.load_options()?;
                let (frame, report) = load_rgbd_with_confidence(
                    rgb,
                    depth,
                    self.confidence.as_deref(),
                    encoding,
                    &options,
                )?;
                Ok((
                    Scene::Frame(frame),
                    json!({
                        "kind": "rgbd-files",
                        "rgb": crate::output::path_text(rgb),
                        "depth": crate::output::path_text(depth),
                        "confidence": self.confidence.as_deref().map(crate::output::path_text),
                        "depth_report": report,
                    }),
                ))
            }
            (None, None, _) => {
                let (h, w) = self.depth_args.size.unwrap_or((384, 384));
                Ok(if self.ldi.is_some() {
                    (
                        Scene::Ldi(procedural::default_scene_ldi(h, w)?),
                        json!({"kind": "built-in procedural scene, 2-layer layered depth image"}),
                    )
                } else {
                    (
                        Scene::Frame(procedural::default_scene(h, w)?),
                        json!({"kind": "built-in procedural scene"}),
                    )
                })
            }
            _ => bail!(
                "give --rgb, --depth and --depth-encoding together, --ldi DIR with --depth-encoding, or \
                 none of them for the built-in scene"
            ),
        }
    }
}

/// Writes `value` as pretty JSON with a trailing newline, atomically (temporary file, then renamed): a
/// folder's `report.json`, written last, says its run completed.
pub fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value)? + "\n";
    tensorholo::io::write_atomic(path, text.as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Where the CNN plans of `holo render`, `video` and `bench` come from: the plan table (the default: the same
/// bits on every run), a timing now (`--tune`), or a tuning saved earlier (`--tuning FILE`).
#[derive(Debug, Args, Clone, Default)]
pub struct PlanArgs {
    /// Time the CNN candidates when the session is created (the engines, each layer's kernel row, 1, half and
    /// all cores) and keep the fastest, instead of the plan table's choices. Two tuned runs can differ in
    /// their last bits where candidates are close: render and video write the result to OUT/tuning.json, and
    /// --tuning repeats it.
    #[arg(long, conflicts_with = "tuning")]
    pub tune: bool,
    /// Repeat the CNN plans of an earlier --tune (its OUT/tuning.json, a tensorholo.cnn-plans file): nothing
    /// is timed and every run gives the same bits; refused if made for another CPU's kernels.
    #[arg(long, value_name = "FILE")]
    pub tuning: Option<PathBuf>,
}

impl PlanArgs {
    /// The `--tuning` file, read and checked. Errors: an unreadable or bad file, naming it.
    pub fn saved(&self) -> Result<Option<Arc<SavedPlans>>> {
        let Some(path) = &self.tuning else {
            return Ok(None);
        };
        let plans =
            SavedPlans::read(path).with_context(|| format!("--tuning {}", path.display()))?;
        Ok(Some(Arc::new(plans)))
    }

    /// With `--tune`, writes the session's CNN plans to `OUT/tuning.json` (a `tensorholo.cnn-plans` file that
    /// `--tuning` reads back) and says so; nothing otherwise.
    pub fn write_tuning(&self, out: &Path, report: &tensorholo::cnn::PlanReport) -> Result<()> {
        if !self.tune {
            return Ok(());
        }
        let path = out.join("tuning.json");
        tensorholo::io::write_atomic(&path, report.saved().to_json().as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        log::info!(
            "CNN plans tuned in {:.2} s written to {} (repeat them with --tuning {})",
            report.tuning_s,
            path.display(),
            path.display()
        );
        Ok(())
    }

    /// `e` with the `--tuning` file named where the SDK blames the saved plans (`tuning`: a saved session
    /// this network cannot run), so that the message points at the file, not at a flag.
    pub fn blame(&self, e: tensorholo::HoloError) -> anyhow::Error {
        match (&self.tuning, &e) {
            (Some(path), tensorholo::HoloError::InvalidParameter { name: "tuning", .. }) => {
                anyhow::Error::new(e).context(format!("--tuning {}", path.display()))
            }
            _ => e.into(),
        }
    }

    /// The `--tuning` file for the output guard ([`crate::output::guard`]), if given.
    pub fn guard_input(&self) -> Option<crate::output::Input<'_>> {
        Some(crate::output::Input::file(
            "--tuning",
            self.tuning.as_deref()?,
        ))
    }
}

/// The CNN options the environment sets, every other field at its default ([`CnnOptions::default`]): the one
/// place `holo` reads them, so the SDK reads no environment.
///
/// - `TENSORHOLO_ISA` → [`CnnOptions::isa`]: lowers the kernels' instruction set (`scalar`, `avx2`,
///   `avxvnni`, `avx512`, `avx512vnni`, `neon`, `neondot`, `neoni8mm`; a level this CPU lacks is refused);
/// - `TENSORHOLO_CONV` → [`CnnOptions::algorithm`]: pins the f32 convolution algorithm (`direct`,
///   `winograd2x2` or `winograd`, `winograd4x4`; `auto`: each layer's row from the plan);
/// - `TENSORHOLO_STRIP_ROWS`, `TENSORHOLO_SLABS` → [`CnnOptions::strip_rows`], [`CnnOptions::slabs`]: the
///   native engine's layout (positive integers).
///
/// Unset or empty: the default. Errors: another value, naming the variable.
pub fn cnn_options_from_env() -> Result<CnnOptions> {
    let var = |name: &str| std::env::var(name).ok().filter(|v| !v.trim().is_empty());
    let count = |name: &str| -> Result<Option<usize>> {
        match var(name) {
            Some(v) => match v.trim().parse::<usize>() {
                Ok(n) if n > 0 => Ok(Some(n)),
                _ => {
                    bail!("environment variable {name}={v}: expected a positive integer (or unset)")
                }
            },
            None => Ok(None),
        }
    };
    let isa = match var("TENSORHOLO_ISA") {
        Some(v) => Some(Isa::from_name(&v).with_context(|| {
            format!(
                "environment variable TENSORHOLO_ISA={v} (this CPU has: {})",
                Isa::available()
                    .iter()
                    .map(|i| i.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })?),
        None => None,
    };
    let algorithm = match var("TENSORHOLO_CONV") {
        Some(v) => ConvAlgorithm::parse(&v).context("environment variable TENSORHOLO_CONV")?,
        None => ConvAlgorithm::Auto,
    };
    Ok(CnnOptions {
        algorithm,
        strip_rows: count("TENSORHOLO_STRIP_ROWS")?,
        slabs: count("TENSORHOLO_SLABS")?,
        isa,
        ..CnnOptions::default()
    })
}

/// Checks `--offset-mm` (millimetres): finite and within the SDK's ±[`tensorholo::optics::MAX_OFFSET_M`].
/// Errors: the flag, the value and the bound.
pub fn check_offset_mm(offset_mm: f64) -> Result<()> {
    tensorholo::optics::check_offset("offset_m", offset_mm * 1e-3).with_context(|| {
        let given = if offset_mm.abs() < 1e6 {
            offset_mm.to_string()
        } else {
            format!("{offset_mm:e}")
        };
        format!(
            "--offset-mm {given}: the SLM's offset must be a finite number of millimetres within ±{} mm",
            tensorholo::optics::MAX_OFFSET_M * 1e3
        )
    })
}

/// Reads the display profile at `path` (`--display`). Commands read it once and pass it down (no cache: what
/// a command uses is what it read). Errors: the file cannot be read or is not a valid profile (the message
/// names the key and the file).
pub fn read_profile(path: &Path) -> Result<DisplayProfile> {
    DisplayProfile::from_path(path).with_context(|| format!("--display {}", path.display()))
}
