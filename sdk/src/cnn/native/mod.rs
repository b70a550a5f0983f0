//! The native engine ([`CnnEngine::Native`]): the TensorHolo residual CNN read by [`crate::model::graph`] on
//! our direct 3×3 convolution kernels (`tensorholo-kernels`, the SIMD row chosen from the CPU at run time).
//!
//! - `f32.rs`: f32 files (`NativePlan`): the frame in strips of at most 16 rows, every layer a row behind the
//!   one before, residual adds and the final concat inside the kernels, row bands on the plan's own threads;
//! - `int8.rs`: int8 QDQ files (`NativeInt8Plan`): the same plan on u8 activations, each buffer on the grid
//!   the file gives its tensor; mixed-precision files' f32 first and last layers on the f32 kernels;
//! - `strips.rs`: the line buffers both plans share (each activation in a window of a few rows);
//! - `slabs.rs`: column slabs, a wide frame run as a few narrower ones so a layer's rows stay in L2 (the f32
//!   plan);
//! - `algorithm.rs`: direct or Winograd, and which kernel row, per layer shape (the plan table's, a saved
//!   tuning's, or timed when asked).
//!
//! [`NativeEngine`]'s [`Engine::tune`] decides each layer shape's row and the threads (timed only with
//! [`crate::cnn::PlanSource::Tune`]); it has no per-model or per-process state beyond the graph the model
//! reads once ([`crate::model::HologramModel::cnn_graph`]).

mod algorithm;
mod f32;
mod int8;
mod slabs;
mod strips;

use std::sync::Arc;
use std::time::Instant;

use algorithm::Rows;

use super::engine::{Engine, EnginePlans, Networks, Tuning};
use super::options::{default_threads, CnnEngine, CnnLayout, ConvAlgorithm, ThreadCount};
use super::plan::{time_plan, CnnPlan};
use super::saved::{network_key, RowAlgorithms};
use super::tuning::{auto_thread_candidates, timing_resolution, PlanRequest, PlanTiming};
use crate::error::{HoloError, Result};
use crate::model::CnnWeights;
use tensorholo_kernels::Isa;

#[cfg(test)]
pub(super) use {f32::NativePlan, int8::NativeInt8Plan};

/// The native engine (registered in `cnn/mod.rs`).
pub(crate) struct NativeEngine;

impl Engine for NativeEngine {
    fn id(&self) -> CnnEngine {
        CnnEngine::Native
    }

    fn supports(&self, nets: Networks<'_>) -> Result<()> {
        for model in nets.each() {
            model.cnn_graph()?;
        }
        active_isa().map(drop)
    }

    fn tune(
        &self,
        nets: Networks<'_>,
        height: usize,
        width: usize,
        request: &PlanRequest,
        time_single: bool,
        _to_beat: Option<f64>,
    ) -> Result<Tuning> {
        let start = Instant::now();
        let isa = active_isa()?;
        let graphs = nets
            .each()
            .map(|m| m.cnn_graph())
            .collect::<Result<Vec<_>>>()?;
        let refs: Vec<&CnnWeights> = graphs.iter().map(|g| g.as_ref()).collect();
        let rows = algorithm::decide(&refs, isa, request.conv, &request.source)?;
        let settings = NativeSettings::of(request)?;
        let mut notes = Vec::new();
        if request.source.saved().is_some() {
            notes.push(format!(
                "{} layer row(s) from the saved plans, {} from the table",
                rows.saved, rows.table
            ));
        }
        let saved = request
            .source
            .saved()
            .and_then(|p| p.session(&network_key(nets.hologram), [height, width]))
            .filter(|s| s.engine == CnnEngine::Native);
        let counts = match request.threads {
            ThreadCount::Auto if request.source.tunes() => auto_thread_candidates(),
            ThreadCount::Auto => match saved.and_then(|s| s.threads) {
                Some(t) => {
                    notes.push(format!("{t} thread(s) from the saved plans"));
                    vec![t]
                }
                None => vec![default_threads()],
            },
            ThreadCount::Fixed(n) => vec![n],
            ThreadCount::ProcessDefault => vec![1],
        };
        let graph = &graphs[0];
        let mut candidates = Vec::new();
        if counts.len() > 1 || time_single {
            let [th, tw] = timing_resolution(height, width);
            for &t in &counts {
                let (mut plan, _) = native_plan(graph.clone(), th, tw, t, isa, &rows, settings)?;
                let s = time_plan(plan.as_mut(), graph.in_channels, th, tw)?;
                candidates.push(PlanTiming {
                    engine: CnnEngine::Native,
                    layout: CnnLayout::ChannelsFirst,
                    threads: Some(t),
                    seconds: Some(s),
                    skipped: None,
                });
            }
        }
        let threads = candidates
            .iter()
            .filter_map(|c| Some((c.seconds?, c.threads?)))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or(counts[0], |(_, t)| t);
        let timed = request.source.tunes() || !candidates.is_empty();
        Ok(Tuning {
            layout: CnnLayout::ChannelsFirst,
            threads: Some(threads),
            candidates,
            seconds: if timed {
                start.elapsed().as_secs_f64()
            } else {
                0.0
            },
            rows: rows.saved_rows(),
            notes,
        })
    }

    /// On the x86-64 SIMD levels, where it was measured against tract (2.3–3.5× tract's best in f32 and
    /// 11–20× in int8, on Zen 3 and Zen 4, at 384² and 1080p: the "CNN engine for …" line `holo render`
    /// logs, and docs/BENCHMARKS.md), and only there: on the
    /// portable rows (`TENSORHOLO_ISA=scalar`) and on ARM, measured under emulation only, tract is timed too.
    fn outruns_the_others(&self) -> Option<String> {
        let isa = active_isa().ok()?;
        matches!(
            isa,
            Isa::Avx2Fma | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni
        )
        .then(|| {
            format!(
                "its {isa} SIMD rows (2.3–20× tract's best wherever measured on x86-64); the other engines \
                 not timed (pin one to compare)"
            )
        })
    }

    fn plans(
        &self,
        nets: Networks<'_>,
        height: usize,
        width: usize,
        request: &PlanRequest,
        tuning: &Tuning,
    ) -> Result<EnginePlans> {
        let isa = active_isa()?;
        let threads = tuning.threads.unwrap_or(1);
        let rows = Rows::from_saved(isa, &tuning.rows);
        let settings = NativeSettings::of(request)?;
        let (hologram, kernel) = native_plan(
            nets.hologram.cnn_graph()?,
            height,
            width,
            threads,
            isa,
            &rows,
            settings,
        )?;
        let prefilter = match nets.prefilter {
            Some(p) => {
                Some(native_plan(p.cnn_graph()?, height, width, threads, isa, &rows, settings)?.0)
            }
            None => None,
        };
        Ok(EnginePlans {
            hologram,
            prefilter,
            kernel: Some(kernel),
        })
    }
}

/// What a native plan is made with besides the graph, size, threads, ISA and rows: the f32 convolution
/// algorithms allowed (`conv`) and the layout overrides of [`PlanRequest::strip_rows`] and
/// [`PlanRequest::slabs`].
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct NativeSettings {
    conv: ConvAlgorithm,
    strip_rows: Option<usize>,
    slabs: Option<usize>,
}

impl NativeSettings {
    /// The settings `request` asks for.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`strip_rows`, `slabs`) for 0.
    pub(super) fn of(request: &PlanRequest) -> Result<Self> {
        for (name, v) in [("strip_rows", request.strip_rows), ("slabs", request.slabs)] {
            if v == Some(0) {
                return Err(crate::error::invalid(
                    name,
                    "must be at least 1 (or unset for the engine's rule)",
                ));
            }
        }
        Ok(Self {
            conv: request.conv,
            strip_rows: request.strip_rows,
            slabs: request.slabs,
        })
    }
}

/// A native plan for `graph` at `height × width` on `threads` threads: the int8 engine for an int8 (QDQ)
/// file, the f32 engine otherwise, each f32 layer on the row `rows` decided for its shape (chosen among the
/// algorithms `settings.conv` allows), in the strips and slabs `settings` gives (the engine's rules where
/// `None`); with the kernel rows its layers run (`NativePlan::kernel_name`). Errors: as `NativePlan::new` /
/// `NativeInt8Plan::new`.
pub(super) fn native_plan(
    graph: Arc<CnnWeights>,
    height: usize,
    width: usize,
    threads: usize,
    isa: tensorholo_kernels::Isa,
    rows: &Rows,
    settings: NativeSettings,
) -> Result<(Box<dyn CnnPlan>, String)> {
    if graph.quant.is_some() {
        let p = int8::NativeInt8Plan::with_rows(
            graph,
            height,
            width,
            threads,
            isa,
            rows,
            settings.strip_rows,
        )?;
        let k = p.kernel_name().to_string();
        Ok((Box::new(p), k))
    } else {
        let set = RowAlgorithms::of_request(settings.conv);
        let p = f32::NativePlan::with_rows(
            graph,
            height,
            width,
            threads,
            isa,
            (rows, set),
            (settings.strip_rows, settings.slabs),
        )?;
        let k = p.kernel_name();
        Ok((Box::new(p), k))
    }
}

/// [`native_plan`] with the plan table's rows (tests).
#[cfg(test)]
pub(super) fn table_plan(
    graph: Arc<CnnWeights>,
    height: usize,
    width: usize,
    threads: usize,
    isa: tensorholo_kernels::Isa,
) -> Result<(Box<dyn CnnPlan>, String)> {
    let rows = Rows::default();
    native_plan(
        graph,
        height,
        width,
        threads,
        isa,
        &rows,
        NativeSettings::default(),
    )
}

/// `model`'s native plan for `height × width` frames on one thread of `isa`'s kernel rows, whatever the
/// active ISA (the per-runtime suite, `pipeline/suite.rs`).
#[cfg(all(test, feature = "tract"))]
pub(crate) fn native_plan_on(
    model: &crate::model::HologramModel,
    height: usize,
    width: usize,
    isa: tensorholo_kernels::Isa,
) -> Result<Box<dyn CnnPlan>> {
    let rows = Rows::default();
    native_plan(
        model.cnn_graph()?,
        height,
        width,
        1,
        isa,
        &rows,
        NativeSettings::default(),
    )
    .map(|(plan, _)| plan)
}

/// [`tensorholo_kernels::Isa::active`] with its error as the SDK's (`From<KernelError> for HoloError`).
fn active_isa() -> Result<tensorholo_kernels::Isa> {
    tensorholo_kernels::Isa::active().map_err(HoloError::from)
}

/// The CPU features the native engine's kernels use on this machine (`avx2`, `avx512`, `neondot`, …;
/// lowered by the `TENSORHOLO_ISA` environment variable), or why it cannot run.
///
/// Errors: [`HoloError::ModelRun`] where the `TENSORHOLO_ISA` override names an unknown or unavailable ISA.
pub fn native_isa() -> Result<&'static str> {
    active_isa().map(|i| i.name())
}

/// This machine's measured f32 peak in GFLOP/s for `threads` threads: one FMA loop per thread in registers
/// (the widest FMA of [`native_isa`]), about `millis` ms, all threads at once: the denominator of "% of
/// peak" in `holo bench --peak`. Errors: as [`native_isa`].
pub fn f32_peak_gflops(threads: usize, millis: u64) -> Result<f64> {
    on_threads(threads, |isa| {
        tensorholo_kernels::peak::f32_fma_gflops(isa, millis)
    })
}

/// This machine's measured int8 multiply-accumulate peak in GOP/s (a multiply-add counts 2) for `threads`
/// threads: the best int8 dot-product instruction of [`native_isa`] (`vpdpbusd` with VNNI, `vpmaddwd` on
/// AVX2, `USDOT`/`SDOT`/`SMLAL` on aarch64) in a register loop on every thread, about `millis` ms.
/// Errors: as [`native_isa`].
pub fn int8_peak_gops(threads: usize, millis: u64) -> Result<f64> {
    on_threads(threads, |isa| {
        tensorholo_kernels::peak::int8_dot_gops(isa, millis)
    })
}

/// Runs `f` on `threads` threads at once and sums what they measured.
fn on_threads(
    threads: usize,
    f: impl Fn(tensorholo_kernels::Isa) -> std::result::Result<f64, tensorholo_kernels::KernelError>
        + Sync,
) -> Result<f64> {
    let isa = active_isa()?;
    let f = &f;
    let per: Vec<f64> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads.max(1))
            .map(|_| s.spawn(move || f(isa)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().ok().and_then(|r| r.ok()).unwrap_or(0.0))
            .collect()
    });
    Ok(per.iter().sum())
}
