//! `holo bench`: CNN throughput of every shipped variant (layers × precision × size × threads), the post-CNN
//! stages and the end-to-end pipeline, as a Markdown table (docs/BENCHMARKS.md). Compare with
//! `benchmarks/cnn_onnxruntime.py` (onnxruntime and the NumPy matmul peak on the same machine).

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use ndarray::Array3;
use serde_json::json;
use std::sync::Arc;
#[cfg(feature = "tract")]
use tensorholo::cnn::tract::{NodeTiming, TractModel};

use tensorholo::cnn::{
    CnnEngine, CnnLayout, CnnOptions, PlanReport, PlanRequest, PlanSource, SavedPlans, ThreadCount,
};
use tensorholo::model::{embedded, ModelConfig, Precision};
use tensorholo::pipeline::{
    Backend, HologramPipeline, ModelSelection, PipelineConfig, PrefilterMode,
};
use tensorholo::refine::{
    FrameRefinement, FrameRefiner, RefineOptions, RefineStart, RefineTarget, DEFAULT_TARGET_LEVELS,
};
use tensorholo::scene::procedural;
use tensorholo::slm::model::DisplayModel;
use tensorholo::slm::{LutRepresentation, PhaseCurve, TiledCurves};
use tensorholo::synthesis::SceneLayer;

use crate::args::parse_size;

mod fovea;
use crate::model_args::{BackendArg, EngineArg, GpuPrecisionArg, LayoutArg, PrecisionArg};

/// Arguments of `holo bench`.
#[derive(Debug, Args)]
#[command(after_long_help = EXAMPLES)]
pub struct BenchArgs {
    /// Hologram CNN depths to measure.
    #[arg(long, value_delimiter = ',', default_values_t = [8, 15, 30])]
    layers: Vec<usize>,
    /// Weight formats to measure.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = default_precisions())]
    precision: Vec<PrecisionArg>,
    /// Frame sizes HEIGHTxWIDTH.
    #[arg(long, value_delimiter = ',', value_parser = parse_size, default_values = ["384x384", "540x960", "1080x1920"])]
    sizes: Vec<(usize, usize)>,
    /// Memory layouts tract runs the CNNs in (nhwc rows are skipped for int8-qop, which tract cannot move;
    /// auto times both at plan creation, the tuning cost is the `plan ms` column).
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [LayoutArg::Auto])]
    layout: Vec<LayoutArg>,
    /// CPU CNN engines, timed alternately case by case in the CNN table (native: f32 and int8 QDQ models;
    /// auto: as a session chooses); the pipeline table uses the first.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = default_engines())]
    engine: Vec<EngineArg>,
    /// Measure this machine's f32 FMA and int8 dot-product peaks per thread count first (register-only loops
    /// on every thread, about 0.3 s each) and give each CNN row's share of the f32 peak.
    #[arg(long)]
    peak: bool,
    /// CNN thread counts (each plan's own executor).
    #[arg(long, value_delimiter = ',', default_values_t = [1, 2], value_parser = crate::args::parse_threads)]
    threads: Vec<usize>,
    /// Timed runs per case after one warm-up run (fewer once --max-seconds is spent; at least one).
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Time budget per case in seconds.
    #[arg(long, default_value_t = 30.0)]
    max_seconds: f64,
    /// SLM offset (mm) of the pipeline rows (pre-filter CNN of that offset; 0 = AA-DPM, no pre-filter).
    #[arg(long, default_value_t = 6)]
    offset_mm: u32,
    /// Encode the pipeline rows with AA-DPM at any offset (no pre-filter CNN).
    #[arg(long)]
    no_prefilter: bool,
    /// Aberration file (tensorholo.aberration, docs/ABERRATION.md) the pipeline rows correct in every frame
    /// (the correction joins the offset stage; such rows encode with AA-DPM). Compare with --no-prefilter
    /// rows for the correction's cost.
    #[arg(long, value_name = "FILE")]
    aberration: Option<PathBuf>,
    /// Skip the CNN table.
    #[arg(long)]
    skip_cnn: bool,
    /// Skip the pipeline table (post-CNN stages and end-to-end frames).
    #[arg(long)]
    skip_pipeline: bool,
    /// CPU pipeline sessions without full outputs, as an app's generator runs them: the SLM codes only (no
    /// kept heads, no copy of the double phase pattern). By default the sessions keep them, as `holo render`.
    #[arg(long)]
    lean: bool,
    /// After the CNN table, time every tract operator of each CNN case once (one extra run per case) and print
    /// the time per operator kind: where the CNN's time goes (convolution algorithm, adds, activations).
    #[arg(long)]
    profile: bool,
    /// Backends of the pipeline table: cpu (tract + rustfft) and/or gpu (wgpu; a second table gives each GPU
    /// stage's time, work, traffic and arithmetic intensity). f32 CNNs only on the GPU.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [BackendArg::Cpu])]
    backend: Vec<BackendArg>,
    /// The GPU CNNs' arithmetic in the GPU tables.
    #[arg(long, value_enum, default_value_t = GpuPrecisionArg::Auto)]
    gpu_precision: GpuPrecisionArg,
    /// The GPU's peak f32 throughput in GFLOP/s (from its data sheet), to print each GPU stage's fraction of it.
    #[arg(long)]
    gpu_peak_gflops: Option<f64>,
    /// Also time the focal-stack refinement (docs/REFINE.md): N iterations from the 8-layer f32 CNN's codes
    /// against the SM-LBM target, one frame of the built-in scene per --sizes, --backend and --threads case (one
    /// run each: seconds). A table gives the target's time, the iterations' and the gain at the focal planes
    /// the loss never saw.
    #[arg(long, value_name = "N")]
    refine: Option<usize>,
    /// With --refine: time the refinement through a display model of each of these parts (docs/REFINE.md
    /// "Through a display model"; fixed values in the ranges of `holo calibrate model simulate`, the same for
    /// the three colours) beside `ideal` (no model), one run each: the time per iteration each part costs.
    #[arg(long, value_enum, value_delimiter = ',', requires = "refine")]
    display_model_parts: Vec<ModelPart>,
    /// Also time foveated frames (docs/FOVEATION.md): a fovea of each of these radii in degrees (behind the
    /// paper's 21 mm eyepiece, gaze at the centre) beside the full frame, timed alternately, per stage, for
    /// every --sizes × --layers × --precision × --threads case.
    #[arg(long, value_name = "DEGREES", value_delimiter = ',')]
    fovea_deg: Vec<f64>,
    /// Also write every measurement to this JSON file.
    #[arg(long)]
    json: Option<PathBuf>,
    #[command(flatten)]
    plans: crate::args::PlanArgs,
    /// Write the CNN plans every case used (with --tune: what the timings chose) to this tensorholo.cnn-plans
    /// file, for --tuning on later runs.
    #[arg(long, value_name = "FILE")]
    save_tuning: Option<PathBuf>,
}

/// Where the cases' CNN plans come from, and every case's plans so far (for `--save-tuning`).
struct BenchPlans {
    source: PlanSource,
    /// What the environment sets ([`crate::args::cnn_options_from_env`]: the ISA, the algorithm, the native
    /// engine's strips and slabs); each case sets its engine, layout and threads on top.
    env: CnnOptions,
    used: Option<SavedPlans>,
}

impl BenchPlans {
    fn new(args: &BenchArgs) -> Result<Self> {
        let source = match (args.plans.saved()?, args.plans.tune) {
            (Some(p), _) => PlanSource::Saved(p),
            (None, true) => PlanSource::Tune,
            (None, false) => PlanSource::Table,
        };
        Ok(Self {
            source,
            env: crate::args::cnn_options_from_env()?,
            used: None,
        })
    }

    /// The options of a case on `engine` with `layout` and `threads` (tuned where the source times).
    fn options(&self, engine: CnnEngine, layout: CnnLayout, threads: usize) -> CnnOptions {
        CnnOptions {
            engine,
            layout,
            threads: ThreadCount::Fixed(threads),
            tune: self.source.tunes(),
            ..self.env
        }
    }

    /// A request for `engine`, `layout` and `threads` from this source.
    fn request(&self, engine: CnnEngine, layout: CnnLayout, threads: usize) -> PlanRequest {
        PlanRequest {
            cnn: self.options(engine, layout, threads),
            source: self.source.clone(),
        }
    }

    /// Adds a case's plans to what `--save-tuning` writes.
    fn record(&mut self, report: &PlanReport) -> Result<()> {
        match &mut self.used {
            Some(all) => all.merge(&report.saved())?,
            None => self.used = Some(report.saved()),
        }
        Ok(())
    }
}

const EXAMPLES: &str = "\
Examples:
  holo bench                                   the full table (takes long at 1080p on a small CPU)
  holo bench --sizes 384x384 --layers 8 --threads 1
  holo bench --skip-cnn --sizes 1080x1920      post-CNN stages and end-to-end frames only
  holo bench --skip-pipeline --layers 8 --precision f32 --sizes 384x384 --threads 1 --profile
                                               time per tract operator (which convolution algorithm ran)
  TRACT_DISABLE_DIRECT_SPATIAL=1 holo bench ... tract's own knobs (environment) change what it plans
  holo bench --skip-cnn --backend cpu,gpu --sizes 384x384,1080x1920 --layers 8 --precision f32
                                               CPU against GPU, per GPU stage (--gpu-peak-gflops for % of peak)
  holo bench --skip-cnn --skip-pipeline --refine 10 --sizes 384x384 --threads 2
                                               the focal-stack refinement alone: target, iterations, gain
  holo bench --skip-cnn --skip-pipeline --refine 3 --sizes 384x384 --threads 2 \\
      --display-model-parts ideal,source,response,per-pixel-response,crosstalk,zero-order,aberration,all
                                               its time per iteration through each part of a display model";

/// A part of a display model for `holo bench --display-model-parts`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum ModelPart {
    /// No model: the ideal display.
    Ideal,
    /// A Gaussian beam with a smooth phase.
    Source,
    /// A non-linear phase response.
    Response,
    /// A phase response per pixel (tiles of 16 pixels, as a calibration's).
    PerPixelResponse,
    /// A 3×3 crosstalk kernel.
    Crosstalk,
    /// A zero order of 5 %.
    ZeroOrder,
    /// Focus and astigmatism.
    Aberration,
    /// Every part above (the global response).
    All,
}

/// The display model of `part` for a `[h, w]` SLM, the same for the three colours (`None` for `ideal`): a
/// Gaussian beam with a smooth phase, a response `2π·(1.02·x + 0.15·x(1 − x))`, 2–3 % crosstalk to each
/// neighbour, a zero order of 5 %, focus 0.3 rad and astigmatism 0.1 rad; or per-pixel responses in tiles of 16
/// pixels whose range runs from 2π to 1.04·2π and gamma from 0.95 to 1.05 across the panel.
fn bench_model(part: ModelPart, h: usize, w: usize) -> Result<Option<Arc<DisplayModel>>> {
    if part == ModelPart::PerPixelResponse {
        let (rows, cols) = (h.div_ceil(16), w.div_ceil(16));
        let curves = (0..rows * cols)
            .map(|t| {
                let (fy, fx) = (
                    (t / cols) as f32 / rows.max(2) as f32,
                    (t % cols) as f32 / cols.max(2) as f32,
                );
                PhaseCurve::gamma(std::f32::consts::TAU * (1.0 + 0.04 * fx), 0.95 + 0.1 * fy)
            })
            .collect::<tensorholo::Result<Vec<_>>>()?;
        let tiled = LutRepresentation::Tiled(TiledCurves::new(h, w, 16.min(h), 16.min(w), curves)?);
        let mut model = DisplayModel {
            slm_size: [h, w],
            ..Default::default()
        };
        for c in &mut model.colours {
            c.response = Some(tiled.clone());
        }
        return Ok(Some(Arc::new(model)));
    }
    let phases: Vec<f64> = (0..256)
        .map(|k| {
            let x = f64::from(k) / 256.0;
            std::f64::consts::TAU * (1.02 * x + 0.15 * x * (1.0 - x))
        })
        .collect();
    let every = json!({
        "source": {"log_amplitude": [0.1, -0.05, -0.35, -0.35, 0.02], "phase_rad": [0.2, -0.1, 0.3, 0.2, 0.0]},
        "response": {"phases_rad": phases},
        "crosstalk": {"size": [3, 3], "weights": [0.0, 0.02, 0.0, 0.03, 0.9, 0.03, 0.0, 0.02, 0.0]},
        "zero_order": [0.05, -0.02],
        "aberration": {"focus": 0.3, "astigmatism_vertical": 0.1},
    });
    let key = match part {
        ModelPart::Ideal => return Ok(None),
        ModelPart::Source => "source",
        ModelPart::Response => "response",
        ModelPart::PerPixelResponse => unreachable!("made above"),
        ModelPart::Crosstalk => "crosstalk",
        ModelPart::ZeroOrder => "zero_order",
        ModelPart::Aberration => "aberration",
        ModelPart::All => "",
    };
    let colour = if key.is_empty() {
        every
    } else {
        json!({ key: every[key].clone() })
    };
    let text = json!({"format": "tensorholo.display-model", "version": 1, "slm_size": [h, w],
                      "red": colour, "green": colour, "blue": colour})
    .to_string();
    Ok(Some(Arc::new(DisplayModel::from_json_str(
        &text,
        "holo bench's display model",
    )?)))
}

/// Median and count of timed runs of `f` after one warm-up, within `budget` seconds.
fn time_runs(
    repeat: usize,
    budget: f64,
    mut f: impl FnMut() -> Result<()>,
) -> Result<(f64, usize)> {
    f()?;
    let start = Instant::now();
    let mut v = Vec::new();
    while v.len() < repeat.max(1) {
        let t = Instant::now();
        f()?;
        v.push(t.elapsed().as_secs_f64());
        if start.elapsed().as_secs_f64() > budget {
            break;
        }
    }
    v.sort_by(|a, b| a.total_cmp(b));
    Ok((v[v.len() / 2], v.len()))
}

/// The `--profile` runs: per case, the time of each tract node.
#[cfg(feature = "tract")]
type Profiles = Vec<(String, Vec<NodeTiming>)>;
/// Without tract there is nothing to profile (`--profile` is refused).
#[cfg(not(feature = "tract"))]
type Profiles = Vec<(String, ())>;

/// The `--engine` values by default: the native engine, and tract where this build has it.
fn default_engines() -> Vec<EngineArg> {
    let mut engines = vec![EngineArg::Native];
    if cfg!(feature = "tract") {
        engines.push(EngineArg::Tract);
    }
    engines
}

/// The `--precision` values by default: f32 and int8 QDQ, and int8 QOperator (tract's alone) where this build
/// has tract.
fn default_precisions() -> Vec<PrecisionArg> {
    let mut precisions = vec![PrecisionArg::F32];
    if cfg!(feature = "tract") {
        precisions.push(PrecisionArg::Int8Qop);
    }
    precisions.push(PrecisionArg::Int8Qdq);
    precisions
}

/// Prints the `--profile` table: per case, the time of each tract operator kind (summed over its nodes) and
/// its share of the run, largest first; adds each row to `results`.
#[cfg(feature = "tract")]
fn print_profiles(profiles: &Profiles, results: &mut Vec<serde_json::Value>) {
    println!("Time per tract operator (one profiled run per case; `--profile`)\n");
    println!("| CNN | precision | layout | size (HxW) | threads | operator | nodes | ms | share |");
    println!("|---|---|---|---|---:|---|---:|---:|---:|");
    for (case, timings) in profiles {
        let total: f64 = timings.iter().map(|t| t.seconds).sum();
        let mut by_op: Vec<(String, usize, f64)> = Vec::new();
        for t in timings {
            match by_op.iter_mut().find(|(op, _, _)| *op == t.op) {
                Some(e) => {
                    e.1 += 1;
                    e.2 += t.seconds;
                }
                None => by_op.push((t.op.clone(), 1, t.seconds)),
            }
        }
        by_op.sort_by(|a, b| b.2.total_cmp(&a.2));
        for (op, nodes, sec) in by_op {
            println!(
                "| {case} | {op} | {nodes} | {:.1} | {:.1} % |",
                sec * 1e3,
                100.0 * sec / total.max(f64::MIN_POSITIVE)
            );
            results.push(
                json!({"kind": "profile", "case": case, "operator": op, "nodes": nodes,
                "ms": sec * 1e3, "share": sec / total.max(f64::MIN_POSITIVE)}),
            );
        }
    }
    println!();
}

/// The shipped CNNs of a pipeline row: the pre-filter of `--offset-mm` (required), none at 0 mm.
fn selection(args: &BenchArgs, layers: usize, precision: Precision) -> ModelSelection {
    ModelSelection {
        layers,
        precision,
        prefilter: if args.offset_mm != 0 && !args.no_prefilter && args.aberration.is_none() {
            PrefilterMode::Required
        } else {
            PrefilterMode::Off
        },
        ..ModelSelection::default()
    }
}

/// `--backend gpu`: end-to-end GPU frames, then each GPU stage on its own (one submission and wait each).
#[cfg(feature = "gpu")]
fn gpu_tables(args: &BenchArgs, results: &mut Vec<serde_json::Value>) -> Result<()> {
    use anyhow::Context;
    let mut stage_rows = Vec::new();
    println!("GPU frames (--backend gpu; f32 weights; downloads: the three code planes)\n");
    println!("| CNN | size (HxW) | adapter | GPU arithmetic | frame ms | FPS | runs |");
    println!("|---|---|---|---|---:|---:|---:|");
    for &(h, w) in &args.sizes {
        let frame = procedural::default_scene(h, w)?;
        for &layers in &args.layers {
            let pipeline = HologramPipeline::embedded(
                &selection(args, layers, Precision::F32),
                PipelineConfig {
                    offset_m: args.offset_mm as f64 * 1e-3,
                    backend: Backend::Gpu,
                    gpu_precision: args.gpu_precision.into(),
                    ..PipelineConfig::default()
                },
            )?;
            let mut session = pipeline.session(h, w)?;
            session.set_full_outputs(false);
            let report = session.backend_report().clone();
            let adapter = report.adapter.clone().unwrap_or_default();
            let emulated = adapter.contains(", cpu)");
            let label = if emulated {
                format!("{adapter} — CPU emulation, not GPU timings")
            } else {
                adapter.clone()
            };
            let (s, runs) = time_runs(args.repeat, args.max_seconds, || {
                session.render(&frame)?;
                Ok(())
            })?;
            let arithmetic = report.gpu_precision.clone().unwrap_or_default();
            println!(
                "| holo{layers} | {h}x{w} | {label} | {arithmetic} | {:.1} | {:.2} | {runs} |",
                s * 1e3,
                1.0 / s
            );
            results.push(
                json!({"kind": "gpu_frame", "layers": layers, "size": [h, w],
                "adapter": adapter, "software_adapter": emulated, "offset_mm": args.offset_mm,
                "gpu_precision": report.gpu_precision,
                "frame_ms": s * 1e3, "fps": 1.0 / s, "runs": runs}),
            );
            let stages = session
                .accelerator_stages(args.repeat)
                .context("the session fell back to the CPU")??;
            for stage in stages {
                stage_rows.push((layers, h, w, label.clone(), stage));
            }
        }
    }
    println!(
        "\nGPU stages, each on its own (median of {} submissions; intensity = FLOP / byte)\n",
        args.repeat.max(1)
    );
    println!("| CNN | size (HxW) | stage | ms | GFLOP | MB | FLOP/B | GFLOP/s | % of peak |");
    println!("|---|---|---|---:|---:|---:|---:|---:|---:|");
    for (layers, h, w, label, stage) in stage_rows {
        let (name, secs) = (stage.name, stage.seconds);
        let gflops = stage.flops / secs.max(1e-9) / 1e9;
        let peak = args
            .gpu_peak_gflops
            .map_or("–".to_string(), |p| format!("{:.1}", 100.0 * gflops / p));
        println!(
            "| holo{layers} | {h}x{w} | {name} | {:.2} | {:.2} | {:.1} | {:.1} | {:.1} | {peak} |",
            secs * 1e3,
            stage.flops / 1e9,
            stage.bytes / 1e6,
            stage.flops / stage.bytes.max(1.0),
            gflops,
        );
        results.push(
            json!({"kind": "gpu_stage", "layers": layers, "size": [h, w], "adapter": label,
            "stage": name, "ms": secs * 1e3, "flops": stage.flops, "bytes": stage.bytes,
            "gflops_per_s": gflops, "peak_gflops": args.gpu_peak_gflops}),
        );
    }
    println!();
    Ok(())
}

#[cfg(not(feature = "gpu"))]
fn gpu_tables(_: &BenchArgs, _: &mut Vec<serde_json::Value>) -> Result<()> {
    anyhow::bail!("--backend gpu: this holo was built without the `gpu` feature")
}

/// The `--layout` values that apply to `precision`: tract 0.23 cannot move QOperator int8 graphs
/// channels-last.
fn layouts(args: &BenchArgs, precision: Precision) -> Vec<CnnLayout> {
    args.layout
        .iter()
        .map(|&l| CnnLayout::from(l))
        .filter(|&l| l != CnnLayout::ChannelsLast || precision != Precision::Int8QOperator)
        .collect()
}

/// Median seconds and run count of each of `fs`, timed alternately (one run of each per round, after one
/// warm-up round) so that a machine's drift hits every case alike; at most `repeat` rounds, fewer once
/// `budget` seconds are spent (at least one).
fn time_alternating(
    repeat: usize,
    budget: f64,
    fs: &mut [Box<dyn FnMut() -> Result<()> + '_>],
) -> Result<Vec<(f64, usize)>> {
    for f in fs.iter_mut() {
        f()?;
    }
    let start = Instant::now();
    let mut v = vec![Vec::new(); fs.len()];
    for _ in 0..repeat.max(1) {
        for (f, times) in fs.iter_mut().zip(&mut v) {
            let t = Instant::now();
            f()?;
            times.push(t.elapsed().as_secs_f64());
        }
        if start.elapsed().as_secs_f64() > budget {
            break;
        }
    }
    Ok(v.into_iter()
        .map(|mut t| {
            t.sort_by(|a, b| a.total_cmp(b));
            (t[t.len() / 2], t.len())
        })
        .collect())
}

/// The CNN table: every size × depth × precision × threads case on every `--engine` (and tract `--layout`),
/// the engines of one case timed alternately.
fn cnn_table(
    args: &BenchArgs,
    config: &ModelConfig,
    results: &mut Vec<serde_json::Value>,
    profiles: &mut Profiles,
    plans: &mut BenchPlans,
) -> Result<()> {
    #[cfg(not(feature = "tract"))]
    let _ = profiles;
    let mut peaks = std::collections::BTreeMap::new();
    if args.peak {
        for &t in &args.threads {
            let isa = plans.env.kernel_isa()?;
            let g = tensorholo::cnn::f32_peak_gflops(isa, t, 300)?;
            let q = tensorholo::cnn::int8_peak_gops(isa, t, 300)?;
            println!("peak, {t} thread(s): f32 {g:.1} GFLOP/s, int8 {q:.1} GOP/s (register loops, {isa})");
            results.push(json!({"kind": "peak", "threads": t, "gflops": g, "int8_gops": q}));
            peaks.insert(t, (g, q));
        }
        println!();
    }
    println!(
        "| CNN | precision | engine | layout / kernel | size (HxW) | threads | ms | FPS | GFLOP/s (int8: GOP/s) | % peak (f32 or int8) | runs | plan ms |"
    );
    println!("|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|");
    for &(h, w) in &args.sizes {
        for &layers in &args.layers {
            for &p in &args.precision {
                let precision: Precision = p.into();
                let model =
                    std::sync::Arc::new(embedded::hologram_model(layers, precision, config)?);
                let macs = model.metadata().macs_per_pixel().unwrap_or(0);
                let input = Array3::<f32>::from_shape_fn((4, h, w), |(c, y, x)| {
                    ((x * 7 + y * 3 + c) % 13) as f32 / 12.0
                });
                for &threads in &args.threads {
                    // (engine label, layout or kernel label, plan, plan ms)
                    let mut cases = Vec::new();
                    for &e in &args.engine {
                        let engine = CnnEngine::from(e);
                        if engine == CnnEngine::Native && precision == Precision::Int8QOperator {
                            continue;
                        }
                        let layouts = match engine {
                            CnnEngine::Native => vec![CnnLayout::ChannelsFirst],
                            _ => layouts(args, precision),
                        };
                        for requested in layouts {
                            let t = Instant::now();
                            let request = plans.request(engine, requested, threads);
                            let (plan, report) = tensorholo::cnn::cnn_plan(&model, h, w, &request)?;
                            let plan_ms = t.elapsed().as_secs_f64() * 1e3;
                            plans.record(&report)?;
                            let engine_label = match engine {
                                CnnEngine::Auto => format!("auto → {}", report.engine),
                                e => e.to_string(),
                            };
                            let detail = match (&report.kernel, requested) {
                                (Some(k), _) => k.clone(),
                                (None, CnnLayout::Auto) => format!("auto → {}", report.layout),
                                (None, l) => l.to_string(),
                            };
                            cases.push((engine_label, detail, report, plan, plan_ms));
                        }
                    }
                    let times = {
                        let input = &input;
                        let mut fs: Vec<Box<dyn FnMut() -> Result<()>>> = cases
                            .iter_mut()
                            .map(|c| {
                                let plan = &mut c.3;
                                Box::new(move || {
                                    plan.run_outputs(input.view())?;
                                    Ok(())
                                }) as Box<dyn FnMut() -> Result<()>>
                            })
                            .collect();
                        time_alternating(args.repeat, args.max_seconds, &mut fs)?
                    };
                    for ((engine, detail, report, _, plan_ms), (s, runs)) in cases.iter().zip(times)
                    {
                        let gflops = 2.0 * macs as f64 * (h * w) as f64 / s / 1e9;
                        // int8 rows against the int8 dot-product peak, f32 rows against the FMA peak.
                        let peak_of = |&(f, q): &(f64, f64)| match precision {
                            Precision::F32 => f,
                            _ => q,
                        };
                        let peak = peaks.get(&threads).map_or("–".to_string(), |p| {
                            format!("{:.0} %", 100.0 * gflops / peak_of(p))
                        });
                        println!(
                            "| holo{layers} | {precision} | {engine} | {detail} | {h}x{w} | {threads} | {:.1} | {:.2} | {:.1} | {peak} | {runs} | {plan_ms:.0} |",
                            s * 1e3,
                            1.0 / s,
                            gflops,
                        );
                        results.push(
                            json!({"kind": "cnn", "layers": layers, "precision": precision,
                            "engine": engine, "layout": report.layout, "kernel": report.kernel,
                            "size": [h, w], "threads": threads, "ms": s * 1e3, "fps": 1.0 / s,
                            "gflops": gflops, "peak_gflops": peaks.get(&threads).map(peak_of),
                            "runs": runs, "macs_per_pixel": macs, "plan_ms": plan_ms}),
                        );
                        #[cfg(feature = "tract")]
                        if args.profile && report.engine == CnnEngine::Tract {
                            let case = format!(
                                "holo{layers} | {precision} | {detail} | {h}x{w} | {threads}"
                            );
                            let request = plans.request(CnnEngine::Tract, report.layout, threads);
                            let (plan, _) = TractModel::of(&model)?.tuned_plan(h, w, &request)?;
                            profiles.push((case, plan.profile(input.view())?));
                        }
                    }
                }
            }
        }
    }
    println!();
    Ok(())
}

/// The pipeline table's engine: the first `--engine`, with tract for the int8 QOperator files the native
/// engine does not run.
fn pipeline_engine(args: &BenchArgs, precision: Precision) -> CnnEngine {
    match args.engine.first().map_or(CnnEngine::Auto, |&e| e.into()) {
        CnnEngine::Native if precision == Precision::Int8QOperator => CnnEngine::Tract,
        e => e,
    }
}

/// Runs `holo bench`.
/// The refinement table (`--refine N`): per size, backend and thread count, one frame of the built-in scene
/// rendered by the 8-layer f32 CNN, its codes refined for `iterations` against the SM-LBM target (the defaults
/// of `holo render --refine`); with `--display-model-parts`, once through each part's model.
fn refine_table(
    args: &BenchArgs,
    iterations: usize,
    results: &mut Vec<serde_json::Value>,
) -> Result<()> {
    let levels = DEFAULT_TARGET_LEVELS;
    let env = crate::args::cnn_options_from_env()?;
    let request = FrameRefinement {
        options: RefineOptions {
            iterations,
            ..RefineOptions::default()
        },
        target: RefineTarget::SmLbm { levels },
        start: RefineStart::Cnn,
    };
    request.validate().context("--refine")?;
    println!(
        "Refinement (`--refine {iterations}`, docs/REFINE.md): one frame of the built-in scene, the 8-layer f32 \
         CNN's codes refined against the SM-LBM target ({} levels, {} loss planes), offset {} mm; one run per \
         case; held-out: PSNR at the focal planes between the loss's\n",
        levels, request.options.planes, args.offset_mm
    );
    let parts = if args.display_model_parts.is_empty() {
        vec![None]
    } else {
        args.display_model_parts.iter().copied().map(Some).collect()
    };
    let model_column = if parts[0].is_some() {
        " display model |"
    } else {
        ""
    };
    let model_rule = if parts[0].is_some() { "---|" } else { "" };
    println!("| size (HxW) | backend | threads |{model_column} target s | iterations s | ms per iteration | held-out dB: CNN's codes → refined codes |");
    println!("|---|---|---:|{model_rule}---:|---:|---:|---|");
    for &(h, w) in &args.sizes {
        let frame = procedural::default_scene(h, w)?;
        for &backend in &args.backend {
            for &threads in &args.threads {
                let pipeline = HologramPipeline::embedded(
                    &ModelSelection::default(),
                    PipelineConfig {
                        offset_m: args.offset_mm as f64 * 1e-3,
                        backend: backend.into(),
                        cnn: CnnOptions {
                            threads: ThreadCount::Fixed(threads),
                            ..env
                        },
                        ..PipelineConfig::default()
                    },
                )?;
                let mut session = pipeline.session(h, w)?;
                session.render(&frame)?;
                let backend_report = session.backend_report().clone();
                let (out, heads) = session.into_last_frame();
                let midpoint = heads.context("no frame rendered")?.to_field()?;
                for &part in &parts {
                    let model = part.map(|p| bench_model(p, h, w)).transpose()?.flatten();
                    let mut refiner =
                        FrameRefiner::for_pipeline(request, &pipeline, &backend_report, threads)?
                            .with_display_model(model)?;
                    let r = refiner.refine(
                        &[SceneLayer::from(&frame)],
                        Some(midpoint.view()),
                        out.codes.view(),
                        &mut |_| ControlFlow::Continue(()),
                    )?;
                    let s = &r.held_out;
                    let base = s.cnn_codes_psnr_db.unwrap_or(s.start_psnr_db);
                    let per_iteration_ms = r.report.iterations_s / iterations as f64 * 1e3;
                    let part_cell = part.map_or(String::new(), |p| {
                        format!(
                            " {} |",
                            p.to_possible_value()
                                .map_or("?".into(), |v| v.get_name().to_string())
                        )
                    });
                    println!(
                    "| {h}x{w} | {} | {threads} |{part_cell} {:.2} | {:.2} | {per_iteration_ms:.1} | {base:.2} → {:.2} ({:+.2}) |",
                    r.backend,
                    r.target_s,
                    r.report.iterations_s,
                    s.refined_codes_psnr_db,
                    s.refined_codes_psnr_db - base
                );
                    results.push(
                        json!({"kind": "refine", "size": [h, w], "backend": r.backend,
                    "threads": threads, "iterations": iterations, "target_s": r.target_s,
                    "display_model": part.map(|p| format!("{p:?}")),
                    "iterations_s": r.report.iterations_s, "per_iteration_ms": per_iteration_ms,
                    "held_out": s, "gain_db": s.refined_codes_psnr_db - base}),
                    );
                }
            }
        }
    }
    println!();
    Ok(())
}

pub fn run(args: &BenchArgs) -> Result<()> {
    #[cfg(not(feature = "tract"))]
    if args.profile {
        anyhow::bail!(
            "--profile times tract's operators: this holo was built without the `tract` feature"
        );
    }
    // The refinement's frames, as render's, are at least the SSIM window: refused before any table runs.
    let min = tensorholo::metrics::SSIM_WINDOW;
    if let Some(&(h, w)) = args.sizes.iter().find(|(h, w)| *h < min || *w < min) {
        if args.refine.is_some() {
            anyhow::bail!(
                "--sizes {h}x{w} with --refine: the refinement needs at least {min}×{min} pixels"
            );
        }
    }
    if let Some(path) = &args.json {
        // A stale file from an earlier run must not pass for this one's if the run fails: removed now,
        // written at the end.
        crate::output::remove_old_report(path)?;
    }
    let config = ModelConfig {
        offset_m: 0.0,
        ..ModelConfig::default()
    };
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|v| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "holo bench {}: {cpu}, {cores} logical cores; tract 0.23 (multithread-mm executor); median of up to {} \
         runs after a warm-up, ≤ {} s per case\n",
        env!("CARGO_PKG_VERSION"),
        args.repeat,
        args.max_seconds
    );
    let mut results = Vec::new();
    let mut profiles = Vec::new();
    let mut plans = BenchPlans::new(args)?;
    if !args.skip_cnn {
        cnn_table(args, &config, &mut results, &mut profiles, &mut plans)?;
    }
    #[cfg(feature = "tract")]
    if !profiles.is_empty() {
        print_profiles(&profiles, &mut results);
    }
    if !args.skip_pipeline && args.backend.contains(&BackendArg::Cpu) {
        let aberration = match &args.aberration {
            Some(path) => Some(Arc::new(crate::aberration::load("--aberration", path)?)),
            None => None,
        };
        println!(
            "Pipeline (`HologramSession`, offset {} mm{}): median stage times in ms, end-to-end FPS of single \
             frames and of a stream (CNN of frame n+1 overlapping the optics of frame n); setup: the session's creation \
             (CNN plans, transfer functions, encoder) with the row's engine and threads\n",
            args.offset_mm,
            match (&args.aberration, args.offset_mm == 0 || args.no_prefilter) {
                (Some(_), _) => ", aberration corrected (--aberration), AA-DPM",
                (None, true) => ", AA-DPM",
                (None, false) => ", pre-filter CNN + DPM",
            }
        );
        println!("| CNN | precision | layout | size (HxW) | threads | CNN | offset | pre-filter | DPM + LUT | frame | FPS | stream FPS | setup ms | peak MiB frame / stream |");
        println!("|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
        for &(h, w) in &args.sizes {
            let frame = procedural::default_scene(h, w)?;
            for &layers in &args.layers {
                for &p in &args.precision {
                    let precision: Precision = p.into();
                    let engine = pipeline_engine(args, precision);
                    // The native engine has one layout of its own; tract's --layout values apply to tract.
                    let pipeline_layouts = match engine {
                        CnnEngine::Native => vec![CnnLayout::ChannelsFirst],
                        _ => layouts(args, precision),
                    };
                    for layout in pipeline_layouts {
                        for &threads in &args.threads {
                            // Peak resident memory of this case: from here (the previous case's
                            // session is gone) to its last frame.
                            let reset = crate::memory::reset_peak_rss();
                            let mut pipeline = HologramPipeline::embedded(
                                &selection(args, layers, precision),
                                PipelineConfig {
                                    offset_m: args.offset_mm as f64 * 1e-3,
                                    backend: Backend::Cpu,
                                    cnn: plans.options(engine, layout, threads),
                                    ..PipelineConfig::default()
                                },
                            )?;
                            if let Some(p) = plans.source.saved() {
                                pipeline = pipeline.with_saved_plans(Arc::new(p.clone()))?;
                            }
                            if let Some(a) = &aberration {
                                pipeline = pipeline.with_aberration(a.clone())?;
                            }
                            let t = Instant::now();
                            let mut session = pipeline.session(h, w)?;
                            let setup_s = t.elapsed().as_secs_f64();
                            plans.record(session.plan_report())?;
                            session.set_full_outputs(!args.lean);
                            let layout = match layout {
                                CnnLayout::Auto => {
                                    format!("auto → {}", session.plan_report().layout)
                                }
                                l => l.to_string(),
                            };
                            let layout = match &session.plan_report().kernel {
                                Some(k) => format!("native {k}"),
                                None => format!("tract {layout}"),
                            };
                            let mut timings = Vec::new();
                            let (s, runs) = time_runs(args.repeat, args.max_seconds, || {
                                timings.push(session.render(&frame)?.timings);
                                Ok(())
                            })?;
                            let med = tensorholo::pipeline::FrameTimings::median(&timings[1..]);
                            // The session's peak over single frames; the stream below holds two frames in
                            // flight (the CNN of frame n + 1 beside the optics of frame n), so its peak is
                            // reported apart.
                            let peak = crate::memory::peak_rss_mib().filter(|_| reset);
                            let n = 4usize;
                            let t = Instant::now();
                            session
                                .render_stream((0..n).map(|_| Ok(frame.clone())), |_, _| Ok(()))?;
                            let stream_fps = n as f64 / t.elapsed().as_secs_f64();
                            let stream_peak = crate::memory::peak_rss_mib().filter(|_| reset);
                            let peak_cell = match (peak, stream_peak) {
                                (Some(f), Some(s)) => format!("{f:.0} / {s:.0}"),
                                _ => "–".to_string(),
                            };
                            println!(
                            "| holo{layers} | {precision} | {layout} | {h}x{w} | {threads} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2} | {:.2} | {:.0} | {peak_cell} |",
                            med.cnn_s * 1e3,
                            med.offset_s * 1e3,
                            med.prefilter_s * 1e3,
                            med.encoding_s * 1e3,
                            s * 1e3,
                            1.0 / s,
                            stream_fps,
                            setup_s * 1e3
                        );
                            results.push(
                            json!({"kind": "pipeline", "layers": layers, "precision": precision,
                            "layout": layout, "size": [h, w], "threads": threads, "offset_mm": args.offset_mm,
                            "median_stages_s": med, "frame_ms": s * 1e3, "fps": 1.0 / s,
                            "stream_fps": stream_fps, "runs": runs, "peak_rss_mib": peak,
                            "stream_peak_rss_mib": stream_peak,
                            "session_setup_s": setup_s}),
                        );
                        }
                    }
                }
            }
        }
        println!();
    }
    if !args.fovea_deg.is_empty() {
        fovea::fovea_table(args, &plans, &mut results)?;
    }
    if args.backend.contains(&BackendArg::Gpu) {
        gpu_tables(args, &mut results)?;
    }
    if let Some(iterations) = args.refine {
        refine_table(args, iterations, &mut results)?;
    }
    let peak = crate::memory::peak_rss_mib();
    if let Some(p) = peak {
        println!("Peak resident memory of the whole run: {p:.0} MiB");
    }
    if let Some(path) = &args.json {
        crate::args::write_json(
            path,
            &json!({"cpu": cpu, "cores": cores, "results": results, "peak_rss_mib": peak,
                    "command": crate::output::command_line()}),
        )?;
    }
    if let Some(path) = &args.save_tuning {
        let Some(used) = &plans.used else {
            anyhow::bail!("--save-tuning: no CPU case ran, so there are no CNN plans to save");
        };
        tensorholo::io::write_atomic(path, used.to_json().as_bytes())
            .with_context(|| format!("--save-tuning {}", path.display()))?;
        println!("CNN plans of every case written to {}", path.display());
    }
    Ok(())
}
