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
use tensorholo::synthesis::SmLbm;
use tensorholo::HoloError;

use crate::args::Scene;

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
    /// SM-LBM + the pipeline's double phase encoding, without CNN.
    SmlbmDpm,
    /// Zero phase (the cold start of iterative methods).
    Zero,
    /// Uniform random phase (--refine-seed).
    Random,
}

/// The refinement's flags.
#[derive(Debug, Args)]
pub struct RefineArgs {
    /// Refine the SLM pattern with N iterations of focal-stack optimisation (Adam on the SLM phase against
    /// the --refine-target's focal stack, docs/REFINE.md), 1 to 10000; report.json's `refine` gives the
    /// loss and PSNR per iteration and the scores at focal planes the loss never saw.
    #[arg(long, value_name = "N")]
    pub refine: Option<usize>,
    /// The refinement's target focal stack.
    #[arg(long, value_enum, default_value_t = TargetArg::Smlbm, requires = "refine")]
    pub refine_target: TargetArg,
    /// The refinement's start.
    #[arg(long, value_enum, default_value_t = InitArg::Cnn, requires = "refine")]
    pub refine_init: InitArg,
    /// Adam's step size, radians of SLM phase (0 < step ≤ π).
    #[arg(long, default_value_t = RefineOptions::default().step_rad, requires = "refine")]
    pub refine_step: f32,
    /// Focal planes of the loss, evenly spaced over the volume, both ends included (1 to 64); the held-out
    /// scores are taken halfway between them.
    #[arg(long, default_value_t = RefineOptions::default().planes, requires = "refine")]
    pub refine_planes: usize,
    /// SM-LBM depth planes of the --refine-target smlbm ground truth (and of --refine-init smlbm-dpm).
    #[arg(long, default_value_t = DEFAULT_LEVELS, requires = "refine")]
    pub refine_levels: usize,
    /// Seed of --refine-init random.
    #[arg(long, default_value_t = 0, requires = "refine")]
    pub refine_seed: u64,
}

/// SM-LBM planes of the default target (docs/REFINE.md: the target's cost against its levels).
pub const DEFAULT_LEVELS: usize = 512;

impl RefineArgs {
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
        if self.refine_levels == 0 {
            bail!("--refine-levels: 0 SM-LBM planes; give at least 1 (default {DEFAULT_LEVELS})");
        }
        Ok(Some(options))
    }
}

/// What a refinement adds to report.json: its section and its two timings.
pub struct Refined {
    /// report.json's `refine`.
    pub report: serde_json::Value,
    /// Seconds to make the target (and an SM-LBM start).
    pub target_s: f64,
    /// Seconds of all iterations.
    pub iterations_s: f64,
}

/// Refines the session's last frame `out` in place (its phase, codes and amplitude scale become the refined
/// pattern's), from the start `args` names, against its target.
pub fn refine_frame(
    args: &RefineArgs,
    options: RefineOptions,
    pipeline: &HologramPipeline,
    scene: &Scene,
    heads: &Heads,
    out: &mut SlmFrame,
    threads: usize,
) -> Result<Refined> {
    if pipeline.aberration().is_some() {
        bail!(
            "--refine with a viewer's aberration or prescription is not supported yet: the refinement's model \
             has no correction, and would undo the display's"
        );
    }
    let cfg = pipeline.config();
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
                .run(&scene.layers(), &|_, _| {})
                .context("--refine: the SM-LBM target")?,
        )
    } else {
        None
    };
    let midpoint: Array3<Complex32> = match (&reference, args.refine_target) {
        (Some(r), TargetArg::Smlbm) => r.midpoint.clone(),
        _ => heads.to_field()?,
    };
    let loss_planes = loss_depths(options.planes)?;
    let target =
        FocalTarget::from_midpoint(midpoint.view(), &cfg.optics, cfg.options, &loss_planes)?;
    let target_s = t.elapsed().as_secs_f64();
    let calibration = pipeline.calibration().map(|c| c.as_ref());
    let cnn_phase = displayed_phase(out.codes.view(), calibration)?;
    let (h, w) = (out.codes.dim().1, out.codes.dim().2);
    let start = match (args.refine_init, &reference) {
        (InitArg::Cnn, _) => cnn_phase.clone(),
        (InitArg::SmlbmDpm, Some(r)) => r.double_phase.phase.clone(),
        (InitArg::SmlbmDpm, None) => bail!("--refine-init smlbm-dpm: no SM-LBM was made (a bug)"),
        (InitArg::Zero, _) => initial_phase(RefineStart::Zero, h, w)?,
        (InitArg::Random, _) => initial_phase(
            RefineStart::Random {
                seed: args.refine_seed,
            },
            h,
            w,
        )?,
    };
    let mut refiner = Refiner::new(
        &cfg.optics,
        cfg.options,
        cfg.offset_m,
        target,
        options,
        threads,
    )?;
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
        let target = FocalTarget::from_midpoint(midpoint.view(), &cfg.optics, cfg.options, &held)?;
        Ok(focal_psnr(
            p.view(),
            &cfg.optics,
            cfg.options,
            cfg.offset_m,
            target,
        )?)
    };
    let (cnn_db, start_db, refined_db, codes_db) = (
        score(&cnn_phase)?,
        score(&start)?,
        score(&phase)?,
        score(&shown)?,
    );
    log::info!(
        "--refine: at {} held-out focal planes, the CNN's codes {cnn_db:.2} dB, the start {start_db:.2} dB, \
         refined {refined_db:.2} dB ({:+.2} dB over the CNN), its 8-bit codes {codes_db:.2} dB; {} iterations \
         in {:.2} s, target {:.2} s",
        held.len(),
        codes_db - cnn_db,
        options.iterations,
        report.iterations_s,
        target_s
    );
    let scale = amplitude_scale(&shown, &midpoint, pipeline)?;
    out.phase = phase;
    out.codes = codes;
    out.amplitude_scale = scale;
    Ok(Refined {
        report: json!({
            "options": options,
            "target": {
                "kind": match args.refine_target {
                    TargetArg::Smlbm => "SM-LBM (Eq. 1-4) of the input",
                    TargetArg::Cnn => "the CNN's midpoint hologram",
                },
                "levels": needs_smlbm.then_some(args.refine_levels),
                "loss_depths": loss_planes,
            },
            "start": format!("{:?}", args.refine_init).to_lowercase(),
            "history": report.history,
            "held_out": {
                "depths": held,
                "cnn_codes_psnr_db": cnn_db,
                "start_psnr_db": start_db,
                "refined_psnr_db": refined_db,
                "refined_codes_psnr_db": codes_db,
                "gain_over_cnn_db": codes_db - cnn_db,
            },
            "amplitude_scale": scale,
        }),
        target_s,
        iterations_s: report.iterations_s,
    })
}

/// The least-squares scale of what the refined codes show at the midpoint plane against the target
/// midpoint's amplitude, over every colour: the refined frame's `amplitude_scale` (the double phase
/// encoding's normaliser has no meaning for it), so that `--evaluate` compares like with like.
fn amplitude_scale(
    shown: &Array3<f32>,
    midpoint: &Array3<Complex32>,
    pipeline: &HologramPipeline,
) -> Result<f32> {
    let cfg = pipeline.config();
    let field = simulate_phase_only(shown.view(), &cfg.optics, cfg.offset_m, cfg.options)?;
    let (mut a, mut b) = (0.0f64, 0.0f64);
    for (d, t) in field.iter().zip(midpoint.iter()) {
        let (d, t) = (f64::from(d.norm()), f64::from(t.norm()));
        a += d * t;
        b += d * d;
    }
    Ok(if b > 0.0 { (a / b) as f32 } else { 1.0 })
}
