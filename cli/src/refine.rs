//! `--refine N` of `holo render`: the focal-stack refinement of the frame's SLM pattern
//! (`tensorholo::refine`, docs/REFINE.md), its flags, and its part of report.json.

use std::ops::ControlFlow;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use ndarray::Array3;
use num_complex::Complex32;
use serde_json::json;
use tensorholo::optics::simulate_phase_only;
use tensorholo::pipeline::{Heads, HologramPipeline, SlmFrame};
use tensorholo::reference::ReferencePipeline;
use tensorholo::refine::{
    codes_of, displayed_phase, focal_psnr, held_out_depths, initial_phase, loss_depths,
    FocalTarget, RefineOptions, RefineStart, Refiner,
};
use tensorholo::synthesis::{SceneLayer, SmLbm};
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
    /// `holo video`: the previous frame's refined pattern (the first frame starts from the CNN's).
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
    #[arg(long, default_value_t = RefineOptions::default().step_rad, requires = "refine")]
    pub refine_step: f32,
    /// Focal planes of the loss, evenly spaced over the volume, both ends included (1 to 64); the held-out
    /// scores are taken halfway between them.
    #[arg(long, default_value_t = RefineOptions::default().planes, requires = "refine")]
    pub refine_planes: usize,
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
    #[arg(long, default_value_t = DEFAULT_LEVELS, requires = "refine")]
    pub refine_levels: usize,
    /// Seed of --refine-init random.
    #[arg(long, default_value_t = 0, requires = "refine")]
    pub refine_seed: u64,
}

/// SM-LBM planes of the default target (docs/REFINE.md: the target's cost against its levels).
pub const DEFAULT_LEVELS: usize = 512;

impl RefineCoreArgs {
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
        if let Err(e) = options.validate() {
            let flag = match &e {
                HoloError::InvalidParameter {
                    name: "iterations", ..
                } => "--refine",
                HoloError::InvalidParameter {
                    name: "step_rad", ..
                } => "--refine-step",
                HoloError::InvalidParameter { name: "planes", .. } => "--refine-planes",
                _ => "--refine",
            };
            return Err(anyhow::Error::new(e).context(flag));
        }
        Ok(Some(options))
    }
}

impl RefineArgs {
    /// [`RefineCoreArgs::options`], with the CNN commands' own flags checked: `video` says whether
    /// `--refine-init previous` may be given.
    pub fn options(&self, video: bool) -> Result<Option<RefineOptions>> {
        let Some(options) = self.core.options()? else {
            return Ok(None);
        };
        if self.refine_levels == 0 {
            bail!("--refine-levels: 0 SM-LBM planes; give at least 1 (default {DEFAULT_LEVELS})");
        }
        if self.refine_init == InitArg::Previous && !video {
            bail!("--refine-init previous: a single frame has no previous frame (holo video takes it)");
        }
        if video && self.refine_target == TargetArg::Cnn {
            bail!(
                "--refine-target cnn: holo video streams its frames without keeping the CNN's midpoint \
                 hologram; refine video frames against --refine-target smlbm"
            );
        }
        Ok(Some(options))
    }
}

/// A refined pattern and what report.json says of it.
pub struct Refined {
    /// The refined phase `[3, H, W]`, radians in `[0, 2π)`.
    pub phase: Array3<f32>,
    /// Its 8-bit codes through the display's look-up tables.
    pub codes: Array3<u8>,
    /// The least-squares scale of what the codes show against the target midpoint's amplitude (the frame's
    /// `amplitude_scale`, for previews and `--evaluate`).
    pub amplitude_scale: f32,
    /// report.json's `refine`.
    pub report: serde_json::Value,
    /// Seconds to make the target (and an SM-LBM start).
    pub target_s: f64,
    /// Seconds of all iterations.
    pub iterations_s: f64,
}

impl Refined {
    /// Puts the refined pattern into the session's frame `out` (its phase, codes and amplitude scale).
    pub fn apply(self, out: &mut SlmFrame) -> serde_json::Value {
        out.phase = self.phase;
        out.codes = self.codes;
        out.amplitude_scale = self.amplitude_scale;
        self.report
    }
}

/// The display a pattern is refined for: the pipeline's optics, offset and propagation options.
#[derive(Clone, Copy)]
pub struct Display {
    pub optics: tensorholo::optics::OpticalSetup,
    pub options: tensorholo::optics::PropagationOptions,
    pub offset_m: f64,
}

/// The CNN commands' refinement of their frames: one [`Refiner`] for the session's size (made at the first
/// frame, its target replaced per frame) and, for `--refine-init previous`, the last refined pattern.
pub struct FrameRefiner<'a> {
    args: &'a RefineArgs,
    options: RefineOptions,
    threads: usize,
    refiner: Option<Refiner>,
    previous: Option<Array3<f32>>,
}

impl<'a> FrameRefiner<'a> {
    /// A refiner of `pipeline`'s frames. Errors: a pipeline with a viewer's aberration (not modelled yet).
    pub fn new(
        args: &'a RefineArgs,
        options: RefineOptions,
        pipeline: &HologramPipeline,
        threads: usize,
    ) -> Result<Self> {
        if pipeline.aberration().is_some() {
            bail!(
                "--refine with a viewer's aberration or prescription is not supported yet: the refinement's \
                 model has no correction, and would undo the display's"
            );
        }
        Ok(Self {
            args,
            options,
            threads,
            refiner: None,
            previous: None,
        })
    }

    /// Refines one frame: `layers` its scene points (SM-LBM), `heads` the CNN's midpoint hologram (for
    /// `--refine-target cnn`), `codes` the CNN's SLM codes.
    pub fn refine(
        &mut self,
        pipeline: &HologramPipeline,
        layers: &[SceneLayer],
        heads: Option<&Heads>,
        codes: &Array3<u8>,
    ) -> Result<Refined> {
        let args = self.args;
        let cfg = pipeline.config();
        let display = Display {
            optics: cfg.optics,
            options: cfg.options,
            offset_m: cfg.offset_m,
        };
        let t = Instant::now();
        let needs_smlbm =
            args.refine_target == TargetArg::Smlbm || args.refine_init == InitArg::SmlbmDpm;
        let reference = if needs_smlbm {
            log::info!(
                "--refine: SM-LBM with {} planes for the {} ...",
                args.refine_levels,
                if args.refine_target == TargetArg::Smlbm {
                    "target"
                } else {
                    "start"
                }
            );
            let reference = ReferencePipeline {
                synthesis: SmLbm {
                    levels: args.refine_levels,
                    setup: cfg.optics,
                    options: cfg.options,
                    silhouette_masks: true,
                },
                offset_m: cfg.offset_m,
                encoding: cfg.encoding,
            };
            Some(
                reference
                    .run(layers, &|_, _| {})
                    .context("--refine: the SM-LBM target")?,
            )
        } else {
            None
        };
        let midpoint: Array3<Complex32> = match (&reference, args.refine_target, heads) {
            (Some(r), TargetArg::Smlbm, _) => r.midpoint.clone(),
            (_, TargetArg::Cnn, Some(heads)) => heads.to_field()?,
            _ => bail!("--refine-target cnn: no CNN midpoint hologram at hand"),
        };
        let target_s = t.elapsed().as_secs_f64();
        let calibration = pipeline.calibration().map(|c| c.as_ref());
        let cnn_phase = displayed_phase(codes.view(), calibration)?;
        let (h, w) = (codes.dim().1, codes.dim().2);
        let start = match (args.refine_init, &reference, &self.previous) {
            (InitArg::Cnn, _, _) | (InitArg::Previous, _, None) => cnn_phase.clone(),
            (InitArg::Previous, _, Some(previous)) => previous.clone(),
            (InitArg::SmlbmDpm, Some(r), _) => r.double_phase.phase.clone(),
            (InitArg::SmlbmDpm, None, _) => {
                bail!("--refine-init smlbm-dpm: no SM-LBM was made (a bug)")
            }
            (InitArg::Zero, _, _) => initial_phase(RefineStart::Zero, h, w)?,
            (InitArg::Random, _, _) => initial_phase(
                RefineStart::Random {
                    seed: args.refine_seed,
                },
                h,
                w,
            )?,
        };
        let mut outcome = refine_pattern(
            &mut self.refiner,
            self.options,
            self.threads,
            &display,
            calibration,
            &midpoint,
            &start,
            Some(&cnn_phase),
        )?;
        if args.refine_init == InitArg::Previous {
            self.previous = Some(outcome.phase.clone());
        }
        outcome.target_s = target_s;
        outcome.report["target"] = json!({
            "kind": match args.refine_target {
                TargetArg::Smlbm => "SM-LBM (Eq. 1-4) of the input",
                TargetArg::Cnn => "the CNN's midpoint hologram",
            },
            "levels": needs_smlbm.then_some(args.refine_levels),
            "loss_depths": loss_depths(self.options.planes)?,
        });
        outcome.report["start"] = json!(format!("{:?}", args.refine_init).to_lowercase());
        Ok(outcome)
    }
}

/// Refines `start` `[3, H, W]` (radians) against the focal stack of `midpoint` on `display`, through
/// `calibration`'s look-up tables, with the refiner in `slot` (made here the first time, its target
/// replaced after); scores the start, the refined phase and its codes (and `cnn`, the CNN's pattern, where
/// given) at the held-out planes. `target_s` is left 0 for the caller.
#[allow(clippy::too_many_arguments)]
pub fn refine_pattern(
    slot: &mut Option<Refiner>,
    options: RefineOptions,
    threads: usize,
    display: &Display,
    calibration: Option<&tensorholo::slm::DisplayCalibration>,
    midpoint: &Array3<Complex32>,
    start: &Array3<f32>,
    cnn: Option<&Array3<f32>>,
) -> Result<Refined> {
    let loss_planes = loss_depths(options.planes)?;
    let target = FocalTarget::from_midpoint(
        midpoint.view(),
        &display.optics,
        display.options,
        &loss_planes,
    )?;
    let refiner = match slot {
        Some(r) => {
            r.set_target(target)?;
            r
        }
        None => slot.insert(
            Refiner::new(
                &display.optics,
                display.options,
                display.offset_m,
                target,
                options,
                threads,
            )?
            .with_calibration(calibration)?,
        ),
    };
    let mut phase = start.clone();
    let report = refiner.refine(phase.view_mut(), &mut |r| {
        log::info!(
            "--refine: iteration {}/{}: loss {:.4e}, {:.2} dB against the target at the loss planes",
            r.iteration,
            options.iterations,
            r.loss,
            r.psnr_db
        );
        ControlFlow::Continue(())
    })?;
    let codes = codes_of(phase.view(), calibration)?;
    let shown = displayed_phase(codes.view(), calibration)?;
    // Scored at the planes halfway between the loss planes, which the loss never saw.
    let held = held_out_depths(options.planes)?;
    let score = |p: &Array3<f32>| -> Result<f64> {
        let target =
            FocalTarget::from_midpoint(midpoint.view(), &display.optics, display.options, &held)?;
        Ok(focal_psnr(
            p.view(),
            &display.optics,
            display.options,
            display.offset_m,
            target,
        )?)
    };
    let cnn_db = cnn.map(score).transpose()?;
    let (start_db, refined_db, codes_db) = (score(start)?, score(&phase)?, score(&shown)?);
    let base = cnn_db.unwrap_or(start_db);
    log::info!(
        "--refine: at {} held-out focal planes, the start {start_db:.2} dB, refined {refined_db:.2} dB, its 8-bit \
         codes {codes_db:.2} dB ({:+.2} dB over the {}); {} iterations in {:.2} s",
        held.len(),
        codes_db - base,
        if cnn.is_some() { "CNN's codes" } else { "start" },
        options.iterations,
        report.iterations_s,
    );
    let amplitude_scale = amplitude_scale(&shown, midpoint, display)?;
    Ok(Refined {
        phase,
        codes,
        amplitude_scale,
        report: json!({
            "options": options,
            "history": report.history,
            "held_out": {
                "depths": held,
                "cnn_codes_psnr_db": cnn_db,
                "start_psnr_db": start_db,
                "refined_psnr_db": refined_db,
                "refined_codes_psnr_db": codes_db,
                "gain_db": codes_db - base,
            },
            "amplitude_scale": amplitude_scale,
        }),
        target_s: 0.0,
        iterations_s: report.iterations_s,
    })
}

/// The least-squares scale of what the refined codes show at the midpoint plane against the target
/// midpoint's amplitude, over every colour: the refined frame's `amplitude_scale` (the double phase
/// encoding's normaliser has no meaning for it), so that `--evaluate` compares like with like.
fn amplitude_scale(
    shown: &Array3<f32>,
    midpoint: &Array3<Complex32>,
    display: &Display,
) -> Result<f32> {
    let field = simulate_phase_only(
        shown.view(),
        &display.optics,
        display.offset_m,
        display.options,
    )?;
    let (mut a, mut b) = (0.0f64, 0.0f64);
    for (d, t) in field.iter().zip(midpoint.iter()) {
        let (d, t) = (f64::from(d.norm()), f64::from(t.norm()));
        a += d * t;
        b += d * d;
    }
    Ok(if b > 0.0 { (a / b) as f32 } else { 1.0 })
}
