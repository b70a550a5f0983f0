//! `--refine N` of `holo render`, `holo video` and `holo reference`: the flags of the SDK's focal-stack
//! refinement (`tensorholo::refine`, docs/REFINE.md), its progress in the log, and its part of report.json.

use std::ops::ControlFlow;
use std::sync::Arc;

use anyhow::{bail, Result};
use clap::{Args, ValueEnum};
use serde_json::json;
use tensorholo::pipeline::SlmFrame;
use tensorholo::refine::{
    loss_depths, FrameRefinement, FrameRefiner, IterationRecord, RefineOptions, RefineStart,
    RefineTarget, RefinedFrame, DEFAULT_TARGET_LEVELS,
};
use tensorholo::slm::model::DisplayModel;
use tensorholo::HoloError;

/// What the refinement aims at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TargetArg {
    /// The SM-LBM ground truth of the input (--refine-levels planes; paper Eq. 1–4).
    Smlbm,
    /// The CNN's own midpoint hologram (no extra synthesis; recovers the encoding's loss, little more).
    Cnn,
}

/// Where the refinement starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum InitArg {
    /// The CNN's SLM codes, as the display shows them (a warm start).
    Cnn,
    /// `holo video`: the previous frame's refined pattern where its loss against this frame's target is lower
    /// than the CNN's codes' (a still camera), else the CNN's codes (the first frame; a new view);
    /// report.json's `started_from` says which.
    Previous,
    /// SM-LBM + the pipeline's double phase encoding, without CNN.
    SmlbmDpm,
    /// Zero phase (the cold start of iterative methods).
    Zero,
    /// Uniform random phase (--refine-seed).
    Random,
}

/// The refinement's iteration count, step and planes (`holo render`, `holo video`, `holo reference`).
#[derive(Debug, Args)]
pub struct RefineCoreArgs {
    /// Refine the SLM pattern with N iterations of focal-stack optimisation (Adam on the SLM phase against
    /// a target's focal stack through the display's Fourier filter and look-up table, docs/REFINE.md), 1 to
    /// 10000; report.json's `refine` gives the loss and PSNR per iteration and the scores at focal planes
    /// the loss never saw.
    #[arg(long, value_name = "N")]
    pub refine: Option<usize>,
    /// Adam's step size, radians of SLM phase (0 < step ≤ π).
    #[arg(long, default_value_t = RefineOptions::default().step_rad, requires = "refine", allow_hyphen_values = true)]
    pub refine_step: f32,
    /// Focal planes of the loss, evenly spaced over the volume, both ends included (1 to 64); the held-out
    /// scores are taken halfway between them.
    #[arg(long, default_value_t = RefineOptions::default().planes, requires = "refine")]
    pub refine_planes: usize,
    /// Refine through a fitted display model (tensorholo.display-model, `holo calibrate model fit`): the
    /// codes are optimised, and scored at the held-out planes, as that display shows them (docs/REFINE.md);
    /// `holo render --evaluate` then scores what that display shows too (with --refine, or alone).
    #[arg(long, value_name = "MODEL")]
    pub display_model: Option<std::path::PathBuf>,
    /// Score the held-out planes as this display model's display shows the patterns (tensorholo.display-model:
    /// a simulated display's hidden.json), instead of the display refined through: what --display-model gains
    /// on that display (docs/REFINE.md); report.json's `refine.held_out_display` names it.
    #[arg(long, value_name = "MODEL", requires = "refine")]
    pub score_display_model: Option<std::path::PathBuf>,
}

/// The refinement's flags of the CNN commands (`holo render`, `holo video`).
#[derive(Debug, Args)]
pub struct RefineArgs {
    #[command(flatten)]
    pub core: RefineCoreArgs,
    /// The refinement's target focal stack.
    #[arg(long, value_enum, default_value_t = TargetArg::Smlbm, requires = "refine")]
    pub refine_target: TargetArg,
    /// The refinement's start (previous: holo video only).
    #[arg(long, value_enum, default_value_t = InitArg::Cnn, requires = "refine")]
    pub refine_init: InitArg,
    /// SM-LBM depth planes of the --refine-target smlbm ground truth (and of --refine-init smlbm-dpm).
    #[arg(long, default_value_t = DEFAULT_TARGET_LEVELS, requires = "refine")]
    pub refine_levels: usize,
    /// Seed of --refine-init random.
    #[arg(long, default_value_t = 0, requires = "refine")]
    pub refine_seed: u64,
}

/// The flag that sets an SDK refinement setting.
fn flag_of(e: &HoloError) -> &'static str {
    match e {
        HoloError::InvalidParameter {
            name: "step_rad", ..
        } => "--refine-step",
        HoloError::InvalidParameter { name: "planes", .. } => "--refine-planes",
        HoloError::InvalidParameter { name: "levels", .. } => "--refine-levels",
        _ => "--refine",
    }
}

impl RefineCoreArgs {
    /// Refuses `--display-model` without `--refine` (nor, where `evaluate` is given, `holo render --evaluate`):
    /// it would change nothing.
    pub fn check_display_model_use(&self, evaluate: bool) -> Result<()> {
        if self.display_model.is_some() && self.refine.is_none() && !evaluate {
            bail!(
                "--display-model: the model is used by --refine N (and by holo render --evaluate); give one \
                 of them"
            );
        }
        Ok(())
    }

    /// The `--display-model` and `--score-display-model` files, each read and checked once.
    pub fn display_models(&self) -> Result<DisplayModels> {
        Ok(DisplayModels {
            display: load_model(self.display_model.as_deref(), "--display-model")?,
            scoring: load_model(self.score_display_model.as_deref(), "--score-display-model")?,
        })
    }

    /// The refinement's options, checked, or `None` without --refine. Errors name the flag.
    pub fn options(&self) -> Result<Option<RefineOptions>> {
        let Some(iterations) = self.refine else {
            return Ok(None);
        };
        let options = RefineOptions {
            iterations,
            step_rad: self.refine_step,
            planes: self.refine_planes,
            ..Default::default()
        };
        options.validate().map_err(|e| {
            let flag = flag_of(&e);
            anyhow::Error::new(e).context(flag)
        })?;
        Ok(Some(options))
    }
}

impl RefineArgs {
    /// The SDK's request, checked, or `None` without --refine; `video` says whether `--refine-init previous`
    /// may be given. Errors name the flag.
    pub fn request(&self, video: bool) -> Result<Option<FrameRefinement>> {
        let Some(options) = self.core.options()? else {
            return Ok(None);
        };
        if self.refine_init == InitArg::Previous && !video {
            bail!("--refine-init previous: a single frame has no previous frame (holo video takes it)");
        }
        if video && self.refine_target == TargetArg::Cnn {
            bail!(
                "--refine-target cnn: holo video streams its frames without keeping the CNN's midpoint \
                 hologram; refine video frames against --refine-target smlbm"
            );
        }
        let request = FrameRefinement {
            options,
            target: match self.refine_target {
                TargetArg::Smlbm => RefineTarget::SmLbm {
                    levels: self.refine_levels,
                },
                TargetArg::Cnn => RefineTarget::CnnMidpoint,
            },
            start: match self.refine_init {
                InitArg::Cnn => RefineStart::Cnn,
                InitArg::Previous => RefineStart::Previous,
                InitArg::SmlbmDpm => RefineStart::SmLbmDpm,
                InitArg::Zero => RefineStart::Zero,
                InitArg::Random => RefineStart::Random {
                    seed: self.refine_seed,
                },
            },
        };
        request.validate().map_err(|e| {
            let flag = flag_of(&e);
            anyhow::Error::new(e).context(flag)
        })?;
        Ok(Some(request))
    }
}

/// Logs each iteration (the refinement's progress).
pub fn log_progress(iterations: usize) -> impl FnMut(&IterationRecord) -> ControlFlow<()> {
    move |r| {
        log::info!(
            "--refine: iteration {}/{iterations}: loss {:.4e}, {:.2} dB against the target at the loss planes",
            r.iteration,
            r.loss,
            r.psnr_db
        );
        ControlFlow::Continue(())
    }
}

/// A refinement's display models: what the loss sees (`--display-model`) and what the held-out planes are
/// scored through (`--score-display-model`).
pub struct DisplayModels {
    /// `--display-model`.
    pub display: Option<Arc<DisplayModel>>,
    /// `--score-display-model`.
    scoring: Option<Arc<DisplayModel>>,
}

impl DisplayModels {
    /// A model of another SLM size than the frame's `[h, w]` stops the command before anything is written.
    pub fn check_sizes(&self, h: usize, w: usize) -> Result<()> {
        for (model, flag) in [
            (&self.display, "--display-model"),
            (&self.scoring, "--score-display-model"),
        ] {
            if let Some(m) = model.as_deref().filter(|m| m.slm_size != [h, w]) {
                bail!(
                    "{flag}: the model is fitted for a {}x{} SLM, the frame is {h}x{w} (render at the \
                     model's size, or fit a model for this one)",
                    m.slm_size[0],
                    m.slm_size[1]
                );
            }
        }
        Ok(())
    }

    /// `refiner` through `--display-model` and scored at the held-out planes through `--score-display-model`;
    /// errors name the flag.
    pub fn apply(&self, refiner: FrameRefiner) -> Result<FrameRefiner> {
        refiner
            .with_display_model(self.display.clone())
            .map_err(|e| anyhow::Error::new(e).context("--display-model"))?
            .with_scoring_model(self.scoring.clone())
            .map_err(|e| anyhow::Error::new(e).context("--score-display-model"))
    }
}

/// A display model file of `flag`, read and checked (`None` without one).
fn load_model(path: Option<&std::path::Path>, flag: &str) -> Result<Option<Arc<DisplayModel>>> {
    path.map(|p| {
        DisplayModel::load(p)
            .map(Arc::new)
            .map_err(|e| anyhow::Error::new(e).context(flag.to_string()))
    })
    .transpose()
}

/// report.json's `refine` of a refined frame (and the summary line in the log); `core`'s
/// `--score-display-model` names the display the held-out planes were scored through
/// (`held_out_display`: the file's name, or "refined through" for the display the loss sees).
pub fn report(
    refiner: &FrameRefiner,
    refined: &RefinedFrame,
    core: &RefineCoreArgs,
) -> serde_json::Value {
    let request = refiner.request();
    let s = &refined.held_out;
    let base = s.cnn_codes_psnr_db.unwrap_or(s.start_psnr_db);
    log::info!(
        "--refine: at {} held-out focal planes, the start {:.2} dB, refined {:.2} dB, its 8-bit codes {:.2} dB \
         ({:+.2} dB over the {}); {} iterations in {:.2} s on {}, target {:.2} s",
        s.depths.len(),
        s.start_psnr_db,
        s.refined_psnr_db,
        s.refined_codes_psnr_db,
        s.refined_codes_psnr_db - base,
        if s.cnn_codes_psnr_db.is_some() {
            "CNN's codes"
        } else {
            "start"
        },
        request.options.iterations,
        refined.report.iterations_s,
        refined.backend,
        refined.target_s
    );
    json!({
        "options": request.options,
        "target": request.target,
        "start": request.start,
        "started_from": refined.start,
        "loss_depths": loss_depths(request.options.planes).ok(),
        "history": refined.report.history,
        "held_out": s,
        "held_out_display": core.score_display_model.as_deref().map_or_else(
            || "refined through".to_string(),
            |p| p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned()),
        ),
        "gain_db": s.refined_codes_psnr_db - base,
        "amplitude_scale": refined.amplitude_scale,
        "backend": refined.backend,
        "backend_reason": refined.backend_reason,
    })
}

/// Puts a refined pattern into the session's frame `out` (its phase, codes and amplitude scale).
pub fn apply(refined: RefinedFrame, out: &mut SlmFrame) {
    out.phase = refined.phase;
    out.codes = refined.codes;
    out.amplitude_scale = refined.amplitude_scale;
}
