//! `holo reference`: SM-LBM reference hologram → SLM patterns, midpoint hologram, previews and a report.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use tensorholo::reference::{channel_means, preview_depths, ReferencePipeline};
use tensorholo::synthesis::SmLbm;

/// Arguments of `holo reference`.
#[derive(Debug, Args)]
#[command(after_long_help = format!("{EXAMPLES}\n\n{}", crate::output::OUTPUTS_HELP))]
pub struct ReferenceArgs {
    #[command(flatten)]
    scene: crate::args::SceneArgs,
    /// Number of SM-LBM depth planes (the paper: 2048 suffices, 10000 as a showcase). With --aberration the
    /// cost grows as G(G+1)/2 propagations per colour for G non-empty planes
    /// (e.g. 131,328 for 512 planes): lower it.
    #[arg(long, default_value_t = 2048)]
    levels: usize,
    /// Aberration profile (JSON, docs/ABERRATION.md): synthesise with the aberration-corrected SM-LBM of
    /// Eq. 5, each depth plane corrected with the Zernike coefficients at its distance from the SLM plane
    /// (--offset-mm). Costs G(G+1)/2 propagations per colour instead of G: lower --levels; runs above
    /// 5,000,000 per colour are refused.
    #[arg(long, value_name = "FILE")]
    aberration: Option<PathBuf>,
    #[command(flatten)]
    encoding: crate::args::EncodingArgs,
    /// Distance from the midpoint hologram to the SLM plane in millimetres (paper: 0, 6 or 12) [default: 0,
    /// or the first offset of the --display profile].
    #[arg(long, allow_hyphen_values = true)]
    offset_mm: Option<f64>,
    #[command(flatten)]
    optics: crate::args::OpticsArgs,
    /// --refine N: refine the SM-LBM + double phase pattern against SM-LBM's own focal stack (docs/REFINE.md).
    #[command(flatten)]
    refine: crate::refine::RefineCoreArgs,
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
  holo reference --ldi out/ldi_test0 --depth-encoding relative16 --out out/ldi_ref
      an LDI folder (rgb_K.png, depth_K.png front first; e.g. from holo dataset --export-ldi)
  holo reference --rgb photo.png --depth depth.png --depth-encoding mm16 --size 384x512 --out out/photo
      a depth-camera frame; metric range from the 1st/99th percentiles of its depths
  holo reference --rgb derived_rgb_576x768.png --depth disparity_aux_576x768.jpg \\
      --depth-encoding iphone-disparity --offset-mm 6 --encoding bl-dpm --out out/vase
  holo reference --aberration calibration.json --levels 256 --offset-mm 6 --out out/corrected
      aberration-corrected SM-LBM (Eq. 5): each plane corrected at its distance from the SLM";

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
    // A bad display profile stops the command before anything is written.
    let profile = args.optics.profile()?;
    let setup = args.optics.setup(profile.as_ref())?;
    let (encoding_name, encoding) = args.encoding.method(crate::args::Encoding::AaDpm);
    let offset_mm = args
        .offset_mm
        .or_else(|| profile.as_ref().map(|p| p.default_offset_m() * 1e3))
        .unwrap_or(0.0);
    crate::args::check_offset_mm(offset_mm)?;
    let refine = args.refine.options()?;
    args.refine.check_display_model_use(false)?;
    if refine.is_some() && args.aberration.is_some() {
        bail!(
            "holo reference --refine with --aberration: the aberration-corrected SM-LBM's midpoint hologram is \
             the corrected one, not a target the viewer should see; refine a corrected display with `holo render \
             --refine N --aberration FILE` (its model sees through the aberration)"
        );
    }
    if refine.is_some() && args.optics.options().pad {
        bail!("--refine runs on the unpadded grid of the real-time pipeline: leave out --pad");
    }
    let pipeline = ReferencePipeline {
        synthesis: SmLbm {
            levels: args.levels,
            setup,
            options: args.optics.options(),
            silhouette_masks: true,
        },
        offset_m: offset_mm * 1e-3,
        encoding,
    };

    let mut inputs = args.scene.guard_inputs();
    inputs.extend(args.optics.guard_input());
    inputs.extend(
        args.aberration
            .as_deref()
            .map(|p| crate::output::Input::file("--aberration", p)),
    );
    crate::output::guard("--out", &args.out, &inputs)?;
    let aberration = match &args.aberration {
        Some(path) => Some((path, crate::aberration::load("--aberration", path)?)),
        None => None,
    };
    // The scene first, as render does: a refused input leaves no output folder (an old report goes).
    let t = Instant::now();
    let (scene, source) = crate::output::before_writing(&args.out, args.scene.load())?;
    let load_s = t.elapsed().as_secs_f64();
    crate::output::prepare(&args.out, &inputs)?;
    let frame = scene.front();
    log::info!(
        "scene {}×{} ({}), {} depth planes, {:?}",
        frame.height(),
        frame.width(),
        source["kind"].as_str().unwrap_or("?"),
        args.levels,
        encoding_name
    );

    let layers = scene.layers();
    let corrected = aberration
        .as_ref()
        .map(|(_, profile)| pipeline.aberration_corrected(profile));
    let per_colour = match &corrected {
        Some(c) => {
            let n = c.propagation_count(&layers)?;
            crate::aberration::check_cost(n, args.levels, "this scene")?;
            n
        }
        None => pipeline.synthesis.propagation_count(&layers)?,
    };
    let bar = progress_bar(3 * per_colour as u64);
    let mut hologram = match &aberration {
        Some((_, profile)) => pipeline
            .run_aberration_corrected(&layers, profile, &|done, _| bar.set_position(done))?,
        None => pipeline.run(&layers, &|done, _| bar.set_position(done))?,
    };
    bar.finish_and_clear();
    log::info!(
        "SM-LBM {:.2} s, offset {:.3} s, encoding {:.3} s",
        hologram.timings.synthesis_s,
        hologram.timings.offset_propagation_s,
        hologram.timings.encoding_s
    );

    let refined = match refine {
        Some(options) => {
            let request = tensorholo::refine::FrameRefinement {
                options,
                start: tensorholo::refine::RefineStart::SmLbmDpm,
                target: tensorholo::refine::RefineTarget::SmLbm {
                    levels: args.levels,
                },
            };
            let display = tensorholo::refine::RefineDisplay {
                optics: setup,
                propagation: args.optics.options(),
                offset_m: offset_mm * 1e-3,
                encoding,
                calibration: None,
                viewer: None,
                viewer_corrected_by_cnn: false,
            };
            let mut refiner =
                args.refine
                    .display_models()?
                    .apply(tensorholo::refine::FrameRefiner::new(
                        request,
                        display,
                        tensorholo::cnn::default_threads(),
                    )?)?;
            let r = refiner.refine_against(
                hologram.midpoint.view(),
                hologram.double_phase.phase.view(),
                None,
                &mut crate::refine::log_progress(options.iterations),
            )?;
            let report = crate::refine::report(&refiner, &r, &args.refine);
            hologram.double_phase.phase = r.phase;
            hologram.double_phase.amplitude_scale = r.amplitude_scale;
            hologram.codes = r.codes;
            Some((report, r.report.iterations_s))
        }
        None => None,
    };

    let t = Instant::now();
    let depths = preview_depths(frame.depth.iter());
    let phase_only = pipeline.reconstruct_phase_only(&hologram, &depths)?;
    let complex = pipeline.reconstruct_complex(&hologram, &depths)?;
    let reconstruction_s = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let images = crate::output::Images {
        codes: hologram.codes.view(),
        midpoint: hologram.midpoint.view(),
        focus: &phase_only,
        ideal: Some(&complex),
        depths: &depths,
    };
    let focus_stats = crate::output::write_images(&args.out, &images, &setup, &frame)?;
    let write_s = t.elapsed().as_secs_f64();

    let amp = hologram.midpoint.mapv(|v| v.norm());
    let report = json!({
        "tensorholo_version": env!("CARGO_PKG_VERSION"),
        "command": crate::output::command_line(),
        "input": source,
        "size": [frame.height(), frame.width()],
        "parameters": pipeline,
        "display": args.optics.display.as_deref().map(crate::output::path_text),
        "display_name": profile.as_ref().and_then(|p| p.name.clone()),
        "aberration": match (&aberration, &corrected) {
            (Some((path, _)), Some(c)) => crate::aberration::report(path, c, per_colour),
            _ => serde_json::Value::Null,
        },
        "timings_s": {
            "load": load_s,
            "synthesis": hologram.timings.synthesis_s,
            "offset_propagation": hologram.timings.offset_propagation_s,
            "encoding": hologram.timings.encoding_s,
            "lut": hologram.timings.lut_s,
            "reconstruction": reconstruction_s,
            "write": write_s,
            "refine_target_s": refined.as_ref().map(|_| hologram.timings.synthesis_s),
            "refine_iterations_s": refined.as_ref().map(|r| r.1),
            "total": t_all.elapsed().as_secs_f64(),
        },
        "refine": refined.as_ref().map(|r| &r.0),
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
    crate::args::write_json(&report_path, &report)?;
    log::info!(
        "wrote {} in {:.1} s",
        args.out.display(),
        t_all.elapsed().as_secs_f64()
    );
    Ok(())
}
