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

pub(super) use algorithm::{Choice, Rows};

use super::engine::{Engine, EnginePlans, Networks, Tuning};
use super::options::{default_threads, CnnEngine, CnnLayout, CnnOptions, ThreadCount};
use super::plan::{time_plan, CnnPlan};
use super::saved::network_key;
use super::tuning::{auto_thread_candidates, timing_resolution, PlanRequest, PlanTiming};
#[cfg(doc)]
use crate::error::HoloError;
use crate::error::Result;
use crate::model::CnnWeights;
use tensorholo_kernels::Isa;

#[cfg(test)]
pub(super) use {algorithm::TABLE_ROWS, f32::NativePlan, int8::NativeInt8Plan};

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
        Ok(())
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
        let isa = request.cnn.kernel_isa()?;
        let graphs = nets
            .each()
            .map(|m| m.cnn_graph())
            .collect::<Result<Vec<_>>>()?;
        let refs: Vec<&CnnWeights> = graphs.iter().map(|g| g.as_ref()).collect();
        let rows = algorithm::decide(&refs, isa, request.cnn.algorithm, &request.source)?;
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
        let counts = match request.cnn.threads {
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
                let (mut plan, _) =
                    native_plan(graph.clone(), th, tw, t, isa, &rows, &request.cnn)?;
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
    /// portable rows ([`Isa::Scalar`]) and on ARM, measured under emulation only, tract is timed too.
    fn outruns_the_others(&self, isa: Isa) -> Option<String> {
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
        let isa = request.cnn.kernel_isa()?;
        let threads = tuning.threads.unwrap_or(1);
        let rows = Rows::from_saved(isa, &tuning.rows);
        // The hologram CNN's plan and its pre-filter's: the same size, threads, rows and options.
        let plan = |graph| native_plan(graph, height, width, threads, isa, &rows, &request.cnn);
        let (hologram, kernel) = plan(nets.hologram.cnn_graph()?)?;
        let prefilter = match nets.prefilter {
            Some(p) => Some(plan(p.cnn_graph()?)?.0),
            None => None,
        };
        Ok(EnginePlans {
            hologram,
            prefilter,
            kernel: Some(kernel),
        })
    }
}

/// What a native plan is made for besides its graph and rows: `height × width` frames on `threads` threads
/// (≥ 1) of `isa`'s kernel rows, in strips of `strip_rows` frame rows and `slabs` column slabs where given
/// (`None`: the rules of `strips.rs` and `slabs.rs`; [`CnnOptions::strip_rows`], [`CnnOptions::slabs`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct PlanSpec {
    pub(crate) height: usize,
    pub(crate) width: usize,
    pub(crate) threads: usize,
    pub(crate) isa: Isa,
    pub(crate) strip_rows: Option<usize>,
    pub(crate) slabs: Option<usize>,
}

impl PlanSpec {
    /// `height × width` frames on `threads` threads of `isa`'s rows, strips and slabs by the engine's rules.
    pub(crate) fn new(height: usize, width: usize, threads: usize, isa: Isa) -> Self {
        Self {
            height,
            width,
            threads,
            isa,
            strip_rows: None,
            slabs: None,
        }
    }
}

/// A native plan for `graph` at `height × width` on `threads` threads: the int8 engine for an int8 (QDQ)
/// file, the f32 engine otherwise, each f32 layer on the row `rows` decided for its shape (chosen among the
/// algorithms `options.algorithm` allows), in the strips and slabs `options` gives (the engine's rules where
/// `None`; checked by [`CnnOptions::validate`]); with the kernel rows its layers run (`NativePlan::kernel_name`).
/// Errors: as `NativePlan::new` / `NativeInt8Plan::new`.
pub(super) fn native_plan(
    graph: Arc<CnnWeights>,
    height: usize,
    width: usize,
    threads: usize,
    isa: Isa,
    rows: &Rows,
    options: &CnnOptions,
) -> Result<(Box<dyn CnnPlan>, String)> {
    let spec = PlanSpec {
        strip_rows: options.strip_rows,
        slabs: options.slabs,
        ..PlanSpec::new(height, width, threads, isa)
    };
    if graph.quant.is_some() {
        let p = int8::NativeInt8Plan::new(graph, spec, rows)?;
        let k = p.kernel_name().to_string();
        Ok((Box::new(p), k))
    } else {
        let p = f32::NativePlan::new(graph, spec, Choice::Rows(rows, options.algorithm))?;
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
    isa: Isa,
) -> Result<(Box<dyn CnnPlan>, String)> {
    native_plan(
        graph,
        height,
        width,
        threads,
        isa,
        &Rows::default(),
        &CnnOptions::default(),
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
    table_plan(model.cnn_graph()?, height, width, 1, isa).map(|(plan, _)| plan)
}

/// This machine's measured f32 peak in GFLOP/s for `threads` threads: one FMA loop per thread in registers
/// (the widest FMA of `isa`), about `millis` ms, all threads at once: the denominator of "% of peak" in
/// `holo bench --peak`. Errors: [`HoloError::InvalidParameter`] (`isa`) for a level this CPU lacks.
pub fn f32_peak_gflops(isa: Isa, threads: usize, millis: u64) -> Result<f64> {
    on_threads(isa, threads, |isa| {
        tensorholo_kernels::peak::f32_fma_gflops(isa, millis)
    })
}

/// This machine's measured int8 multiply-accumulate peak in GOP/s (a multiply-add counts 2) for `threads`
/// threads: the best int8 dot-product instruction of `isa` (`vpdpbusd` with VNNI, `vpmaddwd` on AVX2,
/// `USDOT`/`SDOT`/`SMLAL` on aarch64) in a register loop on every thread, about `millis` ms.
/// Errors: as [`f32_peak_gflops`].
pub fn int8_peak_gops(isa: Isa, threads: usize, millis: u64) -> Result<f64> {
    on_threads(isa, threads, |isa| {
        tensorholo_kernels::peak::int8_dot_gops(isa, millis)
    })
}

/// Runs `f` on `threads` threads at once and sums what they measured.
fn on_threads(
    isa: Isa,
    threads: usize,
    f: impl Fn(tensorholo_kernels::Isa) -> std::result::Result<f64, tensorholo_kernels::KernelError>
        + Sync,
) -> Result<f64> {
    let isa = super::options::available(isa)?;
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
