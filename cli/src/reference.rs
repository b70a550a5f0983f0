//! `holo reference`: SM-LBM reference hologram → SLM patterns, midpoint hologram, previews and a report.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use ndarray::{Array3, Axis};
use serde_json::json;
use tensorholo::encoding::DoublePhaseMethod;
use tensorholo::io::{ensure_not_input, save_amplitude_png, save_u8_png, write_complex_npy};
use tensorholo::metrics::{psnr, ssim_multichannel};
use tensorholo::reference::{channel_means, preview_depths, ReferencePipeline};
use tensorholo::scene::{
    load_rgbd, procedural, DepthEncoding, DepthMapping, DepthRange, LoadOptions, RgbdFrame,
};
use tensorholo::synthesis::{ldi_layers, SceneLayer, SmLbm};

/// Phase-only encodings offered on the command line.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum Encoding {
    /// Plain double phase encoding (paper Eq. 7).
    Dpm,
    /// Anti-aliasing DPM: Gaussian pre-blur (--aa-sigma-px, --aa-kernel).
    AaDpm,
    /// Band-limiting DPM (Sui et al. 2021): diamond Fourier mask (--bl-k).
    BlDpm,
}

fn parse_encoding(s: &str) -> std::result::Result<DepthEncoding, String> {
    s.parse::<DepthEncoding>().map_err(|e| {
        let names: Vec<String> = DepthEncoding::ALL.iter().map(|e| e.to_string()).collect();
        format!("{e} (one of: {})", names.join(", "))
    })
}

fn parse_size(s: &str) -> std::result::Result<(usize, usize), String> {
    let (h, w) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected HEIGHTxWIDTH such as 384x384, got `{s}`"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<usize>()
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| format!("`{v}` is not a positive integer"))
    };
    Ok((parse(h)?, parse(w)?))
}

/// Arguments of `holo reference`.
#[derive(Debug, Args)]
#[command(after_long_help = EXAMPLES)]
pub struct ReferenceArgs {
    /// RGB image (PNG, JPEG or PPM, sRGB). Omit (with --depth) to use the built-in procedural scene.
    #[arg(long, requires_all = ["depth", "depth_encoding"])]
    rgb: Option<PathBuf>,
    /// Depth map matching the RGB image pixel for pixel.
    #[arg(long, requires = "rgb")]
    depth: Option<PathBuf>,
    /// How the depth file stores depth: mm16 (16-bit millimetres: Redwood, derived NYU/SUN), tum (16-bit,
    /// /5000 m), sun (SUN RGB-D bit-rotated mm), kinect-disparity (NYU raw PGM), iphone-disparity (8-bit
    /// normalised disparity of iPhone portraits), relative-near-bright, relative-near-dark (8-bit unitless).
    #[arg(long, value_parser = parse_encoding)]
    depth_encoding: Option<DepthEncoding>,
    /// Nearest metric depth mapped to the front of the 3D volume (metres). Default: 1st percentile of the
    /// valid depths. Ignored for relative encodings.
    #[arg(long, requires = "z_far_m")]
    z_near_m: Option<f32>,
    /// Farthest metric depth mapped to the back of the 3D volume (metres). Default: 99th percentile.
    #[arg(long, requires = "z_near_m")]
    z_far_m: Option<f32>,
    /// Mapping from metric depth to the volume: linear in diopters (1/m, how eyes focus) or in metres.
    #[arg(long, default_value = "diopters", value_parser = ["diopters", "metres"])]
    depth_mapping: String,
    /// Resize the scene to HEIGHTxWIDTH before synthesis (e.g. 384x384, the paper's training size).
    /// Default: the input's own size (384x384 for the built-in scene).
    #[arg(long, value_parser = parse_size)]
    size: Option<(usize, usize)>,
    /// Number of SM-LBM depth planes (the paper: 2048 suffices, 10000 as a showcase).
    #[arg(long, default_value_t = 2048)]
    levels: usize,
    /// Phase-only encoding.
    #[arg(long, value_enum, default_value_t = Encoding::AaDpm)]
    encoding: Encoding,
    /// AA-DPM Gaussian standard deviation (pixels).
    #[arg(long, default_value_t = 0.7)]
    aa_sigma_px: f32,
    /// AA-DPM Gaussian kernel width (pixels, odd).
    #[arg(long, default_value_t = 5)]
    aa_kernel: usize,
    /// BL-DPM cut-off k in (0, 1] (fraction of the checkerboard Nyquist cell).
    #[arg(long, default_value_t = 0.5)]
    bl_k: f32,
    /// Distance from the midpoint hologram to the SLM plane in millimetres (paper: 0, 6 or 12).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    offset_mm: f64,
    #[command(flatten)]
    optics: crate::args::OpticsArgs,
    /// Use the built-in scene as a 2-layer layered depth image (paper Fig. 1: the second layer holds what the
    /// bar and the disc hide), instead of an RGB-D image.
    #[arg(long, conflicts_with = "rgb")]
    ldi: bool,
    /// Output folder (created if missing). Files of the same names in it are replaced; inputs never are.
    #[arg(long)]
    out: PathBuf,
}

const EXAMPLES: &str = "\
Examples:
  holo reference --out out/default
      built-in procedural scene (384x384, occluding bar, disc and textured background)
  holo reference --ldi --out out/ldi
      the same scene as a 2-layer layered depth image (occluded content included)
  holo reference --rgb photo.png --depth depth.png --depth-encoding mm16 --size 384x512 --out out/photo
      a depth-camera frame; metric range from the 1st/99th percentiles of its depths
  holo reference --rgb derived_rgb_576x768.png --depth disparity_aux_576x768.jpg \\
      --depth-encoding iphone-disparity --offset-mm 6 --encoding bl-dpm --out out/vase

Outputs in --out:
  phase_r.png phase_g.png phase_b.png  8-bit SLM patterns, one per laser (linear LUT: code c = 2*pi*c/256 rad)
  midpoint.npy                         complex64 [3, H, W] midpoint hologram (numpy.load reads it)
  focus_near.png focus_mid.png focus_far.png
                                       simulated reconstructions of the SLM patterns (Fourier filter +
                                       propagation) focused at the 5th/50th/95th depth percentiles
  target.png depth.png                 the scene amplitude and normalised depth (white = far)
  report.json                          inputs, parameters, timings per stage, image statistics";

/// A progress bar on stderr for long SM-LBM runs.
fn progress_bar(total: u64) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} propagations (eta {eta})",
        )
        .expect("valid template"),
    );
    bar.set_message("SM-LBM");
    bar
}

/// Runs `holo reference`.
pub fn run(args: &ReferenceArgs) -> Result<()> {
    let t_all = Instant::now();
    let setup = args.optics.setup()?;
    let encoding = match args.encoding {
        Encoding::Dpm => DoublePhaseMethod::Plain,
        Encoding::AaDpm => DoublePhaseMethod::AntiAliased {
            sigma_px: args.aa_sigma_px,
            kernel_size: args.aa_kernel,
        },
        Encoding::BlDpm => DoublePhaseMethod::BandLimited { k: args.bl_k },
    };
    if !args.offset_mm.is_finite() {
        bail!("--offset-mm must be a finite number of millimetres");
    }
    let pipeline = ReferencePipeline {
        synthesis: SmLbm {
            levels: args.levels,
            setup,
            options: args.optics.options(),
            silhouette_masks: true,
        },
        offset_m: args.offset_mm * 1e-3,
        encoding,
    };

    let inputs: Vec<&Path> = [args.rgb.as_deref(), args.depth.as_deref()]
        .into_iter()
        .flatten()
        .collect();
    const OUTPUTS: [&str; 10] = [
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
    ];
    for name in OUTPUTS {
        ensure_not_input(&args.out.join(name), &inputs)?;
    }

    let t = Instant::now();
    let (frame, source) = load_scene(args)?;
    let load_s = t.elapsed().as_secs_f64();
    log::info!(
        "scene {}×{} ({}), {} depth planes, {:?}",
        frame.height(),
        frame.width(),
        source["kind"].as_str().unwrap_or("?"),
        args.levels,
        args.encoding
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output folder {}", args.out.display()))?;

    let ldi = if args.ldi {
        let (h, w) = (frame.height(), frame.width());
        Some(procedural::default_scene_ldi(h, w)?)
    } else {
        None
    };
    let layers: Vec<SceneLayer> = match &ldi {
        Some(ldi) => ldi_layers(ldi),
        None => vec![SceneLayer::from(&frame)],
    };
    let total = 3 * pipeline.synthesis.propagation_count(&layers)? as u64;
    let bar = progress_bar(total);
    let hologram = pipeline.run(&layers, &|done, _| bar.set_position(done))?;
    bar.finish_and_clear();
    log::info!(
        "SM-LBM {:.2} s, offset {:.3} s, encoding {:.3} s",
        hologram.timings.synthesis_s,
        hologram.timings.offset_propagation_s,
        hologram.timings.encoding_s
    );

    let t = Instant::now();
    let depths = preview_depths(frame.depth.iter());
    let phase_only = pipeline.reconstruct_phase_only(&hologram, &depths)?;
    let complex = pipeline.reconstruct_complex(&hologram, &depths)?;
    let reconstruction_s = t.elapsed().as_secs_f64();

    let t = Instant::now();
    for (c, name) in ["phase_r.png", "phase_g.png", "phase_b.png"]
        .iter()
        .enumerate()
    {
        save_u8_png(&args.out.join(name), hologram.codes.index_axis(Axis(0), c))?;
    }
    write_complex_npy(&args.out.join("midpoint.npy"), hologram.midpoint.view())?;
    let mut focus_stats = Vec::new();
    for ((name, d), (recon, ideal)) in ["focus_near.png", "focus_mid.png", "focus_far.png"]
        .iter()
        .zip(depths)
        .zip(phase_only.iter().zip(&complex))
    {
        save_amplitude_png(&args.out.join(name), recon.view(), 1.0)?;
        focus_stats.push(json!({
            "file": name,
            "depth": d,
            "z_m": setup.depth_to_z(d),
            "mean_amplitude_rgb": channel_means(recon),
            "encoding_psnr_db": psnr(clamp01(ideal).view(), clamp01(recon).view(), 1.0)?,
            "encoding_ssim": ssim_multichannel(clamp01(ideal).view(), clamp01(recon).view(), 1.0)?,
        }));
    }
    save_amplitude_png(&args.out.join("target.png"), frame.amplitude.view(), 1.0)?;
    let depth_preview = frame.depth.mapv(f32::sqrt).insert_axis(Axis(0));
    save_amplitude_png(&args.out.join("depth.png"), depth_preview.view(), 1.0)?;
    let write_s = t.elapsed().as_secs_f64();

    let amp = hologram.midpoint.mapv(|v| v.norm());
    let report = json!({
        "tensorholo_version": env!("CARGO_PKG_VERSION"),
        "command": std::env::args().collect::<Vec<_>>(),
        "input": source,
        "size": [frame.height(), frame.width()],
        "parameters": pipeline,
        "timings_s": {
            "load": load_s,
            "synthesis": hologram.timings.synthesis_s,
            "offset_propagation": hologram.timings.offset_propagation_s,
            "encoding": hologram.timings.encoding_s,
            "lut": hologram.timings.lut_s,
            "reconstruction": reconstruction_s,
            "write": write_s,
            "total": t_all.elapsed().as_secs_f64(),
        },
        "statistics": {
            "scene_mean_amplitude_rgb": channel_means(&frame.amplitude),
            "midpoint_mean_amplitude_rgb": channel_means(&amp),
            "midpoint_max_amplitude": amp.iter().copied().fold(0.0f32, f32::max),
            "double_phase_amplitude_scale": hologram.double_phase.amplitude_scale,
            "double_phase_mean_phase_rad": hologram.double_phase.mean_phase,
            "focus": focus_stats,
        },
    });
    let report_path = args.out.join("report.json");
    std::fs::write(&report_path, serde_json::to_string_pretty(&report)? + "\n")
        .with_context(|| format!("cannot write {}", report_path.display()))?;
    log::info!(
        "wrote {} in {:.1} s",
        args.out.display(),
        t_all.elapsed().as_secs_f64()
    );
    Ok(())
}

fn clamp01(a: &Array3<f32>) -> Array3<f32> {
    a.mapv(|v| v.clamp(0.0, 1.0))
}

/// Loads the RGB-D input or builds the procedural scene; returns it with a JSON description of its source.
fn load_scene(args: &ReferenceArgs) -> Result<(RgbdFrame, serde_json::Value)> {
    match (&args.rgb, &args.depth, args.depth_encoding) {
        (Some(rgb), Some(depth), Some(encoding)) => {
            let range = match (args.z_near_m, args.z_far_m) {
                (Some(z_near_m), Some(z_far_m)) => Some(DepthRange { z_near_m, z_far_m }),
                _ => None,
            };
            let options = LoadOptions {
                range,
                mapping: args
                    .depth_mapping
                    .parse::<DepthMapping>()
                    .map_err(|e| anyhow::anyhow!("{e}"))?,
                size: args.size,
            };
            let (frame, report) = load_rgbd(rgb, depth, encoding, &options)?;
            Ok((
                frame,
                json!({"kind": "rgbd-files", "rgb": rgb, "depth": depth, "depth_report": report}),
            ))
        }
        (None, None, _) => {
            let (h, w) = args.size.unwrap_or((384, 384));
            Ok((
                procedural::default_scene(h, w)?,
                json!({"kind": if args.ldi {
                    "built-in procedural scene, 2-layer layered depth image"
                } else {
                    "built-in procedural scene"
                }}),
            ))
        }
        _ => bail!(
            "give --rgb, --depth and --depth-encoding together, or none for the built-in scene"
        ),
    }
}
