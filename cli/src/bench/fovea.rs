//! `holo bench --fovea-deg R,…`: foveated frames (docs/FOVEATION.md) beside the full frame of the same
//! configuration, timed alternately in one run, stage by stage.

use anyhow::Result;
use serde_json::json;
use tensorholo::display::DEFAULT_EYEPIECE_FOCAL_M;
use tensorholo::foveation::{FoveaRadius, FoveationOptions, Gaze};
use tensorholo::model::Precision;
use tensorholo::pipeline::{Backend, FrameTimings, HologramPipeline, PipelineConfig};
use tensorholo::scene::procedural;

use super::{pipeline_engine, selection, time_alternating, BenchArgs, BenchPlans};
use crate::model_args::BackendArg;

/// The foveation tables of `--backend`: the CPU's ([`cpu_fovea_table`]) and the GPU's ([`gpu_fovea_table`]).
pub(super) fn fovea_table(
    args: &BenchArgs,
    plans: &BenchPlans,
    results: &mut Vec<serde_json::Value>,
) -> Result<()> {
    if args.backend.contains(&BackendArg::Cpu) {
        cpu_fovea_table(args, plans, results)?;
    }
    if args.backend.contains(&BackendArg::Gpu) {
        gpu_fovea_table(args, results)?;
    }
    Ok(())
}

/// The foveation table: per size, depth, precision and thread count, the full frame and a frame foveated on
/// the centre for each `--fovea-deg` (behind the paper's 21 mm eyepiece), timed alternately; each stage's
/// median and the frame's time against the full frame's.
fn cpu_fovea_table(
    args: &BenchArgs,
    plans: &BenchPlans,
    results: &mut Vec<serde_json::Value>,
) -> Result<()> {
    println!(
        "Foveated frames (`render_foveated`, gaze at the centre, fovea in degrees behind a {} mm eyepiece, \
         offset {} mm): median stage times in ms, the full frame and each fovea timed alternately\n",
        DEFAULT_EYEPIECE_FOCAL_M * 1e3,
        args.offset_mm
    );
    println!("| CNN | precision | size (HxW) | threads | fovea | R px | CNN share | CNN | periphery | offset | pre-filter | DPM + LUT | frame | × full |");
    println!("|---|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for &(h, w) in &args.sizes {
        let frame = procedural::default_scene(h, w)?;
        let gaze = centre_gaze(h, w);
        for &layers in &args.layers {
            for &p in &args.precision {
                let precision: Precision = p.into();
                let engine = pipeline_engine(args, precision);
                for &threads in &args.threads {
                    let config = |foveation| PipelineConfig {
                        offset_m: args.offset_mm as f64 * 1e-3,
                        backend: Backend::Cpu,
                        cnn: plans.options(engine, tensorholo::cnn::CnnLayout::Auto, threads),
                        foveation,
                        ..PipelineConfig::default()
                    };
                    let make = |f| -> Result<_> {
                        let pipeline = HologramPipeline::embedded(
                            &selection(args, layers, precision),
                            config(f),
                        )?;
                        let mut session = pipeline.session(h, w)?;
                        session.set_full_outputs(!args.lean);
                        Ok(session)
                    };
                    let mut full = make(None)?;
                    let mut foveated = args
                        .fovea_deg
                        .iter()
                        .map(|&d| make(Some(fovea(d))))
                        .collect::<Result<Vec<_>>>()?;
                    let mut timings: Vec<Vec<FrameTimings>> = vec![Vec::new(); 1 + foveated.len()];
                    let (first, rest) = timings.split_at_mut(1);
                    let mut fs: Vec<Box<dyn FnMut() -> Result<()> + '_>> = Vec::new();
                    let frame = &frame;
                    fs.push(Box::new(|| {
                        first[0].push(full.render(frame)?.timings);
                        Ok(())
                    }));
                    for (session, t) in foveated.iter_mut().zip(rest.iter_mut()) {
                        fs.push(Box::new(move || {
                            t.push(session.render_foveated(frame, &gaze)?.timings);
                            Ok(())
                        }));
                    }
                    let times = time_alternating(args.repeat, args.max_seconds, &mut fs)?;
                    drop(fs);
                    let full_s = times[0].0;
                    let reports: Vec<_> =
                        foveated.iter().map(|s| s.fovea_report().copied()).collect();
                    let labels = std::iter::once(None).chain(args.fovea_deg.iter().map(Some));
                    for (i, label) in labels.enumerate() {
                        // The warm-up run is not counted.
                        let med = FrameTimings::median(&timings[i][1..]);
                        let (s, runs) = times[i];
                        let report = i.checked_sub(1).and_then(|k| reports[k]);
                        let (fovea_cell, radius, share) = fovea_cells(label, report);
                        println!(
                            "| holo{layers} | {precision} | {h}x{w} | {threads} | {fovea_cell} | {radius} | {share} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2} |",
                            med.cnn_s * 1e3,
                            med.periphery_s * 1e3,
                            med.offset_s * 1e3,
                            med.prefilter_s * 1e3,
                            med.encoding_s * 1e3,
                            s * 1e3,
                            s / full_s,
                        );
                        results.push(
                            json!({"kind": "fovea", "layers": layers, "precision": precision,
                            "size": [h, w], "threads": threads, "offset_mm": args.offset_mm,
                            "fovea_deg": label, "fovea": report, "median_stages_s": med,
                            "frame_ms": s * 1e3, "relative_to_full": s / full_s, "runs": runs}),
                        );
                    }
                }
            }
        }
    }
    println!();
    Ok(())
}

/// `--backend gpu --fovea-deg R,…`: foveated frames on the GPU (the tile's CNN, the periphery's blur and
/// blend in WGSL, the frame's stages with the pre-filter over the whole frame) beside the GPU's full frame,
/// timed alternately; f32 CNNs. A software adapter (lavapipe) is labelled a CPU emulation.
#[cfg(feature = "gpu")]
fn gpu_fovea_table(args: &BenchArgs, results: &mut Vec<serde_json::Value>) -> Result<()> {
    println!(
        "Foveated frames on the GPU (--backend gpu, f32 weights, gaze at the centre, fovea in degrees behind a \
         {} mm eyepiece, offset {} mm): median ms; input and periphery on the CPU (the tile's packing, the gaze's \
         depth), the rest in one GPU submission\n",
        DEFAULT_EYEPIECE_FOCAL_M * 1e3,
        args.offset_mm
    );
    println!("| CNN | size (HxW) | adapter | fovea | R px | CNN share | input | periphery | GPU | frame | × full |");
    println!("|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|");
    for &(h, w) in &args.sizes {
        let frame = procedural::default_scene(h, w)?;
        let gaze = centre_gaze(h, w);
        for &layers in &args.layers {
            let make = |degrees: Option<f64>| -> Result<_> {
                let foveation = degrees.map(fovea);
                let pipeline = HologramPipeline::embedded(
                    &selection(args, layers, Precision::F32),
                    PipelineConfig {
                        offset_m: args.offset_mm as f64 * 1e-3,
                        backend: Backend::Gpu,
                        gpu_precision: args.gpu_precision.into(),
                        foveation,
                        ..PipelineConfig::default()
                    },
                )?;
                let mut session = pipeline.session(h, w)?;
                session.set_full_outputs(false);
                Ok(session)
            };
            let mut full = make(None)?;
            let adapter = full.backend_report().adapter.clone().unwrap_or_default();
            let label = if adapter.contains(", cpu)") {
                format!("{adapter} — CPU emulation, not GPU timings")
            } else {
                adapter.clone()
            };
            let mut foveated = args
                .fovea_deg
                .iter()
                .map(|&d| make(Some(d)))
                .collect::<Result<Vec<_>>>()?;
            let mut timings: Vec<Vec<FrameTimings>> = vec![Vec::new(); 1 + foveated.len()];
            let (first, rest) = timings.split_at_mut(1);
            let mut fs: Vec<Box<dyn FnMut() -> Result<()> + '_>> = Vec::new();
            let frame = &frame;
            fs.push(Box::new(|| {
                first[0].push(full.render(frame)?.timings);
                Ok(())
            }));
            for (session, t) in foveated.iter_mut().zip(rest.iter_mut()) {
                fs.push(Box::new(move || {
                    let out = session.render_foveated(frame, &gaze)?;
                    anyhow::ensure!(
                        out.backend == Backend::Gpu,
                        "the foveated frame ran on the {}",
                        out.backend
                    );
                    t.push(out.timings);
                    Ok(())
                }));
            }
            let times = time_alternating(args.repeat, args.max_seconds, &mut fs)?;
            drop(fs);
            let full_s = times[0].0;
            let reports: Vec<_> = foveated.iter().map(|s| s.fovea_report().copied()).collect();
            let labels = std::iter::once(None).chain(args.fovea_deg.iter().map(Some));
            for (i, degrees) in labels.enumerate() {
                let med = FrameTimings::median(&timings[i][1..]);
                let (s, runs) = times[i];
                let report = i.checked_sub(1).and_then(|k| reports[k]);
                let (fovea_cell, radius, share) = fovea_cells(degrees, report);
                println!(
                    "| holo{layers} | {h}x{w} | {label} | {fovea_cell} | {radius} | {share} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2} |",
                    med.cnn_s * 1e3,
                    med.periphery_s * 1e3,
                    med.gpu_s * 1e3,
                    s * 1e3,
                    s / full_s,
                );
                results.push(
                    json!({"kind": "gpu_fovea", "layers": layers, "size": [h, w],
                    "adapter": adapter, "offset_mm": args.offset_mm, "fovea_deg": degrees,
                    "fovea": report, "median_stages_s": med, "frame_ms": s * 1e3,
                    "relative_to_full": s / full_s, "runs": runs}),
                );
            }
        }
    }
    println!();
    Ok(())
}

#[cfg(not(feature = "gpu"))]
fn gpu_fovea_table(_: &BenchArgs, _: &mut Vec<serde_json::Value>) -> Result<()> {
    anyhow::bail!("--backend gpu: this holo was built without the `gpu` feature")
}

/// A row's fovea cells: its radius in degrees and pixels and the share of the frame the CNN ran on, or the
/// full frame's (`degrees` `None`, or no report).
fn fovea_cells(
    degrees: Option<&f64>,
    report: Option<tensorholo::foveation::FoveaReport>,
) -> (String, String, String) {
    match (degrees, report) {
        (Some(d), Some(r)) => (
            format!("{d}°"),
            format!("{:.0}", r.radius_px),
            format!("{:.3}", r.cnn_share),
        ),
        _ => ("full".into(), "–".into(), "1".into()),
    }
}

/// The gaze at the centre of an `h × w` frame, the scene's depth there.
fn centre_gaze(h: usize, w: usize) -> Gaze {
    Gaze {
        x: (w as f64 - 1.0) / 2.0,
        y: (h as f64 - 1.0) / 2.0,
        depth_m: None,
    }
}

/// A fovea of `degrees` behind the paper's 21 mm eyepiece, the other options the defaults.
fn fovea(degrees: f64) -> FoveationOptions {
    FoveationOptions {
        radius: FoveaRadius::Degrees {
            degrees,
            eyepiece_focal_m: DEFAULT_EYEPIECE_FOCAL_M,
        },
        ..FoveationOptions::default()
    }
}
