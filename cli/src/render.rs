//! `holo render`: the real-time pipeline on one RGB-D frame with the shipped (or given) CNNs: hologram CNN →
//! offset propagation → pre-filter CNN → double phase → SLM codes, plus previews, timings and, with
//! `--evaluate`, the Table 2 scores against an SM-LBM ground truth of the same input.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;
use tensorholo::evaluation::{focal_depths, table2};
use tensorholo::foveation::FoveaReport;
use tensorholo::model::contract;
use tensorholo::optics::{focal_stack, post_encoding_midpoint};
use tensorholo::pipeline::{
    BackendReport, FrameTimings, Heads, HologramPipeline, PipelineConfig, SlmFrame,
};
use tensorholo::reference::{channel_means, preview_depths, ReferencePipeline};
use tensorholo::refine::FrameRefiner;
use tensorholo::scene::RgbdFrame;
use tensorholo::slm::model::{ColourDisplay, DisplayModel};
use tensorholo::synthesis::SmLbm;

use crate::args::Scene;
use crate::model_args::ModelArgs;

/// Arguments of `holo render`.
#[derive(Debug, Args)]
#[command(after_long_help = format!("{EXAMPLES}\n\n{}", crate::output::OUTPUTS_HELP))]
pub struct RenderArgs {
    #[command(flatten)]
    scene: crate::args::SceneArgs,
    #[command(flatten)]
    model: ModelArgs,
    /// Timed repetitions of the frame after the first (warm-up) one; report.json gives their medians.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Also compute the SM-LBM ground truth of the input (--levels planes) and score the CNN's midpoint
    /// hologram and what the SLM shows with the paper's Table 2 protocol (PSNR/SSIM of the amplitude and of
    /// a 15 + 5-depth focal stack), next to SM-LBM + the same double phase method without CNN. With
    /// --display-model, what the SLM shows is what that fitted display shows of the codes (report.json's
    /// `evaluation.display`).
    #[arg(long)]
    evaluate: bool,
    /// SM-LBM depth planes of the --evaluate ground truth.
    #[arg(long, default_value_t = 2048)]
    levels: usize,
    /// Also write cnn_input.npy: the hologram CNN's input, float32 [4·L, H, W] (per input layer R, G, B
    /// amplitude then normalised depth, 0 = near; docs/CONVENTIONS.md §7), e.g. to calibrate int8 files on
    /// real frames (`python -m tensorholo_training.export --calib-npy`).
    #[arg(long)]
    save_cnn_input: bool,
    #[command(flatten)]
    refine: crate::refine::RefineArgs,
    /// Output folder (created if missing). Files of the same names in it are replaced; inputs never are.
    #[arg(long)]
    out: PathBuf,
}

const EXAMPLES: &str = "\
Examples:
  holo render --out out/render
      shipped 8-layer CNN on the built-in scene (384x384), SLM 6 mm away, shipped 6 mm pre-filter CNN (DDPM)
  holo render --no-prefilter --out out/aadpm
      the same encoded with AA-DPM instead of the pre-filter CNN (non-learned; faster)
  holo render --layers 30 --int8 --offset-mm 12 --evaluate --out out/render30
      the 30-layer int8 model, scored against the SM-LBM ground truth
  holo render --rgb derived_rgb_576x768.png --depth disparity_aux_576x768.jpg \\
      --depth-encoding iphone-disparity --out out/vase
  holo render --ldi out/ldi_test0 --depth-encoding relative16 --evaluate --out out/ldi
      a layered depth image (rgb_K.png, depth_K.png, front first) with the shipped LDI CNN, scored
      against the SM-LBM of all its layers
  holo render --model my.onnx --prefilter-model my.prefilter.onnx --out out/mine
  holo render --display lcos_3.74um.json --out out/lcos
      a display profile (docs/DISPLAYS.md): the shipped 8 µm models serve it at the mapped volume and offset";

/// Runs `holo render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    let t_all = Instant::now();
    let refine = args.refine.request(false)?;
    args.refine.core.check_display_model_use(args.evaluate)?;
    let gaze = args.model.fovea.gaze()?;
    if args.model.fovea.gaze_track.is_some() {
        anyhow::bail!(
            "--gaze-track is for holo video's sequences: give holo render one gaze (--gaze X,Y)"
        );
    }
    // The display profile, read once: a bad one stops the command before anything is written; the files it
    // names are inputs too.
    let profile = args.model.profile()?;
    let profile_files = ModelArgs::profile_files(profile.as_ref());
    let mut inputs = args.scene.guard_inputs();
    inputs.extend(args.model.guard_inputs());
    inputs.extend(
        profile_files
            .iter()
            .map(|(what, f)| crate::output::Input::file(what, f)),
    );
    crate::output::guard("--out", &args.out, &inputs)?;
    let t = Instant::now();
    let (scene, source) = args.scene.load()?;
    let load_s = t.elapsed().as_secs_f64();
    // A display no model serves stops the command before anything is written too; an earlier run's report
    // in the folder goes, so that it is not taken for this run's.
    let (pipeline, models) = crate::output::before_writing(
        &args.out,
        args.model.pipeline(scene.input(), profile.as_ref()),
    )?;
    if let Some(g) = &gaze {
        let (h, w) = scene.size();
        g.check(h, w).context("--gaze")?;
    }
    // A display model of another SLM size than the frame's stops the command before anything is written.
    let display_models = args.refine.core.display_models()?;
    {
        let (h, w) = scene.size();
        display_models.check_sizes(h, w)?;
    }
    crate::output::prepare(&args.out, &inputs)?;
    let (h, w) = scene.size();
    // What runs: the model file's own depth and precision (a --model file need not match --layers/--precision).
    let cnn = pipeline.hologram_model().metadata();
    log::info!(
        "{h}×{w} frame ({}), {}-layer {} CNN {}, offset {} mm, {}",
        source["kind"].as_str().unwrap_or("?"),
        cnn.layers,
        scene.input(),
        cnn.precision,
        pipeline.config().offset_m * 1e3,
        if pipeline.prefilter_model().is_some() {
            "pre-filter CNN + DPM (DDPM)".to_string()
        } else {
            format!("{:?}", pipeline.encoding())
        }
    );
    let t = Instant::now();
    let mut session = pipeline
        .session(h, w)
        .map_err(|e| args.model.plans.blame(e))?;
    let session_s = t.elapsed().as_secs_f64();
    args.model
        .plans
        .write_tuning(&args.out, session.plan_report())?;
    let what = || match args.scene.inputs().as_slice() {
        [] => "the built-in scene".to_string(),
        files => files
            .iter()
            .map(|f| format!("`{}`", f.display()))
            .collect::<Vec<_>>()
            .join(" + "),
    };
    // A foveated --evaluate also scores against the full 3D frame of the same session, rendered first.
    let full = match (&scene, &gaze, args.evaluate) {
        (Scene::Frame(frame), Some(_), true) => {
            let out = session.render(frame).with_context(what)?;
            let displayed =
                shown_midpoint(pipeline.config(), display_models.display.as_deref(), out)?;
            let midpoint = session
                .last_heads()
                .context("no frame rendered")?
                .to_field()?;
            Some(crate::fovea::FullFrame {
                midpoint,
                displayed,
            })
        }
        _ => None,
    };
    let mut render = || -> Result<FrameTimings> {
        let out = match (&scene, &gaze) {
            (Scene::Frame(frame), Some(gaze)) => session.render_foveated(frame, gaze),
            (Scene::Frame(frame), None) => session.render(frame),
            (Scene::Ldi(_), Some(_)) => {
                anyhow::bail!(
                    "--gaze: foveated frames take an RGB-D frame, not a layered depth image"
                )
            }
            (Scene::Ldi(ldi), None) => session.render_ldi(ldi),
        };
        Ok(out.with_context(what)?.timings)
    };
    let first = render()?;
    let mut timed = Vec::new();
    for _ in 0..args.repeat {
        timed.push(render()?);
    }
    let med = FrameTimings::median(&timed);
    let fps = if med.total_s > 0.0 {
        1.0 / med.total_s
    } else {
        0.0
    };
    if med.gpu_s > 0.0 {
        // On the GPU the stages run in one submission: the CPU checks (or packs) the input, the GPU does the rest.
        log::info!(
            "session {:.0} ms; first frame {:.0} ms; then (median of {}) input {:.1} ms (CPU: checks, packing where needed), GPU \
             {:.1} ms (upload, both CNNs, optics, encoding, download; `holo bench --backend gpu` times each \
             stage), total {:.1} ms ({fps:.2} FPS)",
            session_s * 1e3,
            first.total_s * 1e3,
            timed.len(),
            med.cnn_s * 1e3,
            med.gpu_s * 1e3,
            med.total_s * 1e3,
        );
    } else {
        log::info!(
            "session {:.0} ms; first frame {:.0} ms; then (median of {}) CNN {:.1} ms, offset {:.1} ms, \
             pre-filter {:.1} ms, encoding {:.1} ms, total {:.1} ms ({fps:.2} FPS)",
            session_s * 1e3,
            first.total_s * 1e3,
            timed.len(),
            med.cnn_s * 1e3,
            med.offset_s * 1e3,
            med.prefilter_s * 1e3,
            med.encoding_s * 1e3,
            med.total_s * 1e3,
        );
    }
    // The peak up to here: the inputs, the session and its frames (the previews' share is reported apart).
    let frames_peak = crate::memory::peak_rss_mib();
    // The previews and reconstructions below need only the last frame: the session's buffers go first.
    let (plan_report, backend_report, fovea) = (
        session.plan_report().clone(),
        session.backend_report().clone(),
        session.fovea_report().copied(),
    );
    let (mut out, heads) = session.into_last_frame();
    let heads = heads.context("no frame rendered")?;
    let refined = match refine {
        Some(request) => {
            let mut refiner = display_models.apply(FrameRefiner::for_pipeline(
                request,
                &pipeline,
                &backend_report,
                args.model.thread_count(),
            )?)?;
            let midpoint = heads.to_field()?;
            let r = refiner.refine(
                &scene.layers(),
                Some(midpoint.view()),
                out.codes.view(),
                &mut crate::refine::log_progress(request.options.iterations),
            )?;
            let report = crate::refine::report(&refiner, &r, &args.refine.core);
            let (target_s, iterations_s) = (r.target_s, r.report.iterations_s);
            crate::refine::apply(r, &mut out);
            Some((report, target_s, iterations_s))
        }
        None => None,
    };
    write_outputs(
        args,
        &pipeline,
        LastFrame {
            out: &out,
            heads,
            backend: &backend_report,
            fovea: fovea.as_ref().zip(full.as_ref()),
            display_model: display_models.display.as_deref(),
        },
        &scene,
        source,
        models,
        |report| {
            report["cnn_plan"] = json!(plan_report);
            report["timings_s"] = json!({
                "load": load_s,
                "session_setup": session_s,
                "first_frame": first,
                "median": med,
                "repeats": timed,
                "fps_median": if med.total_s > 0.0 { 1.0 / med.total_s } else { 0.0 },
            });
            if let Some((refine, target_s, iterations_s)) = &refined {
                report["timings_s"]["refine_target_s"] = json!(target_s);
                report["timings_s"]["refine_iterations_s"] = json!(iterations_s);
                report["refine"] = refine.clone();
            }
            report["frames_peak_rss_mib"] = json!(frames_peak);
            if let Some(fovea) = &fovea {
                report["fovea"] = json!(fovea);
            }
        },
    )?;
    log::info!(
        "wrote {} in {:.1} s",
        args.out.display(),
        t_all.elapsed().as_secs_f64()
    );
    Ok(())
}

/// What [`write_outputs`] needs of a session that has ended ([`tensorholo::pipeline::HologramSession::into_last_frame`]).
struct LastFrame<'a> {
    out: &'a SlmFrame,
    heads: Heads,
    backend: &'a BackendReport,
    /// A foveated frame's report and the full 3D frame it is scored against (`--gaze --evaluate`).
    fovea: Option<(&'a FoveaReport, &'a crate::fovea::FullFrame)>,
    /// The fitted display `--evaluate` scores through (`--display-model`).
    display_model: Option<&'a DisplayModel>,
}

/// The display model of `model` that changes what the display shows: `None` for no model or one without parts
/// (the ideal display, bit for bit).
fn with_parts(model: Option<&DisplayModel>) -> Option<&DisplayModel> {
    model.filter(|m| m.colours.iter().any(|c| *c != ColourDisplay::default()))
}

/// What the display shows of `frame`'s pattern at the midpoint plane, in the encoded hologram's units (the
/// Table 2 protocol's "displayed"): through the fitted display `model` where it has parts (its simulation of
/// the codes, `DisplayModel::shown_midpoint`), else the ideal display of the phase (`post_encoding_midpoint`).
fn shown_midpoint(
    cfg: &PipelineConfig,
    model: Option<&DisplayModel>,
    frame: &SlmFrame,
) -> Result<ndarray::Array3<num_complex::Complex32>> {
    shown_pattern(
        cfg,
        model,
        frame.phase.view(),
        frame.codes.view(),
        frame.amplitude_scale,
    )
}

/// [`shown_midpoint`] of a pattern's phase `[3, H, W]` (radians), its codes `[3, H, W]` and amplitude scale.
fn shown_pattern(
    cfg: &PipelineConfig,
    model: Option<&DisplayModel>,
    phase: ndarray::ArrayView3<f32>,
    codes: ndarray::ArrayView3<u8>,
    amplitude_scale: f32,
) -> Result<ndarray::Array3<num_complex::Complex32>> {
    Ok(match with_parts(model) {
        Some(m) => m
            .shown_midpoint(
                codes,
                amplitude_scale,
                &cfg.optics,
                cfg.offset_m,
                cfg.options,
            )
            .context("--display-model")?,
        None => post_encoding_midpoint(
            phase,
            amplitude_scale,
            &cfg.optics,
            cfg.offset_m,
            cfg.options,
        )?,
    })
}

/// Previews, midpoint, codes, optional evaluation and report.json of the session's last frame.
fn write_outputs(
    args: &RenderArgs,
    pipeline: &HologramPipeline,
    last: LastFrame<'_>,
    scene: &Scene,
    source: serde_json::Value,
    models: serde_json::Value,
    add: impl FnOnce(&mut serde_json::Value),
) -> Result<()> {
    let cfg = pipeline.config();
    let out = last.out;
    let front = scene.front();
    let frame: &RgbdFrame = &front;
    let midpoint = last.heads.to_field()?;
    drop(last.heads);
    let t = Instant::now();
    let displayed = post_encoding_midpoint(
        out.phase.view(),
        out.amplitude_scale,
        &cfg.optics,
        cfg.offset_m,
        cfg.options,
    )?;
    let depths = preview_depths(frame.depth.iter());
    let focus = focal_stack(
        displayed.view(),
        &cfg.optics,
        0.0,
        &depths,
        cfg.options,
        false,
    )?;
    // The displayed field is kept only for the evaluation (50 MB at 1080p); through a fitted display, the
    // evaluation scores what that display shows instead (the previews stay the ideal display's).
    let displayed = match (args.evaluate, with_parts(last.display_model)) {
        (false, _) => {
            // Freed here, before the focal stacks (a match arm that does not move it would keep it alive).
            drop(displayed);
            None
        }
        (true, None) => Some(displayed),
        (true, Some(model)) => {
            drop(displayed);
            Some(shown_midpoint(cfg, Some(model), out)?)
        }
    };
    let ideal = focal_stack(
        midpoint.view(),
        &cfg.optics,
        0.0,
        &depths,
        cfg.options,
        false,
    )?;
    let reconstruction_s = t.elapsed().as_secs_f64();
    let images = crate::output::Images {
        codes: out.codes.view(),
        midpoint: midpoint.view(),
        focus: &focus,
        ideal: Some(&ideal),
        depths: &depths,
    };
    let focus_stats = crate::output::write_images(&args.out, &images, &cfg.optics, frame)?;
    if args.save_cnn_input {
        let layers = pipeline.hologram_model().metadata().input_layers;
        let mut x = ndarray::Array3::<f32>::zeros((4 * layers, frame.height(), frame.width()));
        match scene {
            Scene::Frame(f) if layers == 1 => contract::pack_rgbd(f, x.view_mut())?,
            Scene::Frame(f) => contract::pack_ldi(&f.clone().into(), x.view_mut())?,
            Scene::Ldi(ldi) => contract::pack_ldi(ldi, x.view_mut())?,
        }
        tensorholo::io::write_f32_npy(&args.out.join("cnn_input.npy"), x.view())?;
    }
    let evaluation = match &displayed {
        Some(displayed) => Some(evaluate(
            args,
            pipeline,
            scene,
            frame,
            [&midpoint, displayed],
            last.fovea,
            last.display_model,
        )?),
        None => None,
    };
    let amp = midpoint.mapv(|v| v.norm());
    let mut report = json!({
        "tensorholo_version": env!("CARGO_PKG_VERSION"),
        "command": crate::output::command_line(),
        "input": source,
        "size": [frame.height(), frame.width()],
        "models": models,
        "pipeline": cfg,
        // Which backend ran the frame (every stage: the GPU path runs the whole frame, or none of it) and why.
        "backend": last.backend,
        "frame_backend": out.backend,
        "reconstruction_s": reconstruction_s,
        "statistics": {
            "scene_mean_amplitude_rgb": channel_means(&frame.amplitude),
            "midpoint_mean_amplitude_rgb": channel_means(&amp),
            "midpoint_max_amplitude": amp.iter().copied().fold(0.0f32, f32::max),
            "double_phase_amplitude_scale": out.amplitude_scale,
            "double_phase_mean_phase_rad": out.mean_phase,
            "focus": focus_stats,
        },
        "evaluation": evaluation,
    });
    add(&mut report);
    // The whole run's peak resident memory (session, previews, report images), and what the previews and
    // report images add over the frames' peak (`frames_peak_rss_mib`, set by `add`): scripts/memory-guard.sh.
    let peak = crate::memory::peak_rss_mib();
    report["peak_rss_mib"] = json!(peak);
    let frames = report["frames_peak_rss_mib"].as_f64();
    if let (Some(all), Some(frames)) = (peak, frames) {
        report["previews_added_mib"] = json!((all - frames).max(0.0));
        log::info!(
            "peak resident memory {all:.0} MiB: {frames:.0} MiB up to the last frame, the previews and report \
             images {:.0} MiB more",
            (all - frames).max(0.0)
        );
    }
    crate::args::write_json(&args.out.join("report.json"), &report)
}

/// The Table 2 scores of the CNN midpoint hologram, of what the SLM shows, and of SM-LBM + the same
/// encoding without CNN, all against the SM-LBM ground truth of the input (every layer of an LDI); focal
/// depths from `front`, the scene's front layer.
fn evaluate(
    args: &RenderArgs,
    pipeline: &HologramPipeline,
    scene: &Scene,
    front: &RgbdFrame,
    [midpoint, displayed]: [&ndarray::Array3<num_complex::Complex32>; 2],
    fovea: Option<(&FoveaReport, &crate::fovea::FullFrame)>,
    display_model: Option<&DisplayModel>,
) -> Result<serde_json::Value> {
    let cfg = pipeline.config();
    let t = Instant::now();
    let reference = ReferencePipeline {
        synthesis: SmLbm {
            levels: args.levels,
            setup: cfg.optics,
            options: cfg.options,
            silhouette_masks: true,
        },
        offset_m: cfg.offset_m,
        encoding: cfg.encoding,
    };
    log::info!(
        "--evaluate: SM-LBM ground truth with {} planes ...",
        args.levels
    );
    let gt = reference.run(&scene.layers(), &|_, _| {})?;
    let reference_displayed = shown_pattern(
        cfg,
        display_model,
        gt.double_phase.phase.view(),
        gt.codes.view(),
        gt.double_phase.amplitude_scale,
    )?;
    let depths = focal_depths(front.depth.view(), 200, 15, 5, 0)?;
    let score = |pred: &ndarray::Array3<num_complex::Complex32>| {
        table2(
            pred.view(),
            gt.midpoint.view(),
            &cfg.optics,
            cfg.options,
            &depths,
        )
    };
    let cnn = score(midpoint)?;
    let shown = score(displayed)?;
    let reference_shown = score(&reference_displayed)?;
    // On another display than the model's own, what the mapping itself costs: SM-LBM of the same scene at
    // the model's training display (what a perfect model computes; the SDK shows it on this display as
    // is), scored at this display. The ceiling any mapped model reaches (docs/DISPLAYS.md).
    let mapping = pipeline.display_mapping();
    let mapping_ceiling = if mapping.is_identity() {
        None
    } else {
        let trained = SmLbm {
            levels: args.levels,
            setup: mapping.trained,
            options: cfg.options,
            silhouette_masks: true,
        }
        .synthesize(&scene.layers(), &|_, _| {})?;
        Some(score(&trained)?)
    };
    log::info!(
        "Table 2 vs SM-LBM ({} planes): CNN midpoint {:.2} dB / SSIM {:.3} (focal stack {:.2} dB / {:.3}); \
         displayed {:.2} dB (focal stack {:.2} dB); SM-LBM + {:?} displayed {:.2} dB (focal stack {:.2} dB)",
        args.levels,
        cnn.psnr_amp,
        cnn.ssim_amp,
        cnn.psnr_fs,
        cnn.ssim_fs,
        shown.psnr_amp,
        shown.psnr_fs,
        cfg.encoding,
        reference_shown.psnr_amp,
        reference_shown.psnr_fs
    );
    // A foveated frame: the scores by eccentricity, against the full 3D frame and against SM-LBM.
    let fovea_bins = match fovea {
        Some((report, full)) => Some(crate::fovea::eccentricity_bins(
            report,
            [midpoint, displayed],
            full,
            &gt.midpoint,
            &cfg.optics,
            cfg.options,
        )?),
        None => None,
    };
    Ok(json!({
        "fovea_bins": fovea_bins,
        "ground_truth": {
            "method": match scene {
                Scene::Frame(_) => "SM-LBM (Eq. 1-4) of the RGB-D input",
                Scene::Ldi(_) => "SM-LBM (Eq. 1-4) of every layer of the LDI input",
            },
            "levels": args.levels,
        },
        "focal_depths": depths,
        // Which display "displayed" is what of: the fitted model's simulation of the codes, or the ideal.
        "display": if display_model.is_some() { "model" } else { "ideal" },
        "display_model": args.refine.core.display_model.as_ref().and_then(|p| p.file_name()).map(|n| n.to_string_lossy()),
        "cnn_midpoint": cnn,
        "displayed": shown,
        "smlbm_encoded_displayed": {"encoding": cfg.encoding, "scores": reference_shown},
        // Present on another display than the model's training display: SM-LBM at the training display,
        // shown on this one, against SM-LBM at this one.
        "mapping_ceiling": mapping_ceiling,
        "seconds": t.elapsed().as_secs_f64(),
    }))
}
