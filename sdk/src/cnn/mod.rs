//! The CNN engines behind one interface: a crate-private `CnnPlan` runs one CNN (hologram or pre-filter) at one
//! resolution on the CPU, whatever computes it. The session's CNN stage ([`crate::pipeline`]) holds a
//! `Box<dyn CnnPlan>` and never asks which engine it is, so adding an engine is a file here, not branches in
//! the session.
//!
//! - `cnn/tract.rs` (cargo feature `tract`): tract's optimised plan (`crate::model::ModelPlan`), which runs
//!   any ONNX graph that passes the contract (`docs/CONVENTIONS.md` §7).
//! - `cnn/native.rs`: our direct 3×3 convolutions (`tensorholo-kernels`, SIMD rows chosen at run time) over
//!   the graph read by [`crate::model::graph`]; f32 files.
//! - `cnn/select.rs` picks the engine of a session ([`CnnEngine`]); [`cnn_plan`] does the same for one CNN
//!   (what `holo bench` times).
//!
//! The GPU runs whole frames, not CNNs alone: it is a frame executor of the pipeline
//! (`pipeline/executor.rs`), not an engine here.

mod native;
mod native_int8;
mod select;
mod strips;
#[cfg(feature = "tract")]
mod tract;

pub use crate::model::CnnEngine;
pub(crate) use select::{select, CnnPlans};

use ndarray::{Array3, ArrayView3};

use crate::error::Result;

/// One CNN at one resolution, ready to run on the CPU (after tract's `Runtime → Runnable → State`: the plan
/// owns what a run reuses; [`CnnPlan::spawn`] gives another thread its own).
pub(crate) trait CnnPlan: std::fmt::Debug + Send {
    /// `(channels, height, width)` of the input `[C, H, W]` this plan takes.
    fn input_dim(&self) -> (usize, usize, usize);

    /// Runs the CNN on `input` `[C, H, W]` (f32, the contract's packing, `docs/CONVENTIONS.md` §7): its two
    /// outputs, `[3, H, W]` each (amplitude and phase heads of a hologram CNN; `Re` and `Im` of a
    /// pre-filter's filtered field).
    ///
    /// Errors: [`crate::HoloError::ShapeMismatch`] for an input of another shape; the engine's run errors
    /// ([`crate::HoloError::ModelRun`]).
    fn run_outputs(&mut self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)>;

    /// [`run_outputs`](Self::run_outputs) on an input held plane by plane (`planes[c]`: channel `c`, `H·W`
    /// values, row-major), so that a caller whose channels live apart (the pre-filter's input, one colour per
    /// worker) need not gather them into a `[C, H, W]` array first. The native plans read the planes in
    /// place; the default gathers them (one allocation per call, as tract allocates anyway).
    ///
    /// Errors: [`crate::HoloError::ShapeMismatch`] for a plane count other than `C` or a plane of other than
    /// `H·W` values; as `run_outputs`.
    fn run_planes(&mut self, planes: &[&[f32]]) -> Result<(Array3<f32>, Array3<f32>)> {
        let dim = self.input_dim();
        check_planes(planes, dim)?;
        let (c, h, w) = dim;
        let mut input = Array3::<f32>::zeros((c, h, w));
        for (mut lane, p) in input.outer_iter_mut().zip(planes) {
            for (o, v) in lane.iter_mut().zip(p.iter()) {
                *o = *v;
            }
        }
        self.run_outputs(input.view())
    }

    /// [`run_planes`](Self::run_planes) writing the two outputs into the caller's six planes (`H·W` values
    /// each): `outputs[0..3]` the first output's channels (amplitude heads, or `Re`), `outputs[3..6]` the
    /// second's (phase heads, or `Im`), so that a session's CNN writes straight into its colour workers'
    /// planes (at 1080p, no 50 MB of output arrays per frame). The native plans write in place; the default
    /// copies `run_planes`' arrays.
    ///
    /// Errors: as `run_planes`; [`crate::HoloError::ShapeMismatch`] for an output plane of other than `H·W`
    /// values.
    fn run_planes_into(&mut self, planes: &[&[f32]], outputs: [&mut [f32]; 6]) -> Result<()> {
        let (_, h, w) = self.input_dim();
        check_output_planes(&outputs, h * w)?;
        let (first, second) = self.run_planes(planes)?;
        let channels = first.outer_iter().chain(second.outer_iter());
        for (o, c) in outputs.into_iter().zip(channels) {
            for (d, v) in o.iter_mut().zip(c.iter()) {
                *d = *v;
            }
        }
        Ok(())
    }

    /// The same network for another thread (a stream's CNN thread): weights shared, run state its own.
    fn spawn(&self) -> Box<dyn CnnPlan>;
}

/// Checks an input given plane by plane against `(C, H, W)`. Errors: [`crate::HoloError::ShapeMismatch`].
pub(crate) fn check_planes(planes: &[&[f32]], (c, h, w): (usize, usize, usize)) -> Result<()> {
    if planes.len() != c || planes.iter().any(|p| p.len() != h * w) {
        return Err(crate::HoloError::ShapeMismatch {
            what: "CNN input planes (count, values per plane)".into(),
            expected: vec![c, h * w],
            got: vec![
                planes.len(),
                planes.iter().map(|p| p.len()).max().unwrap_or(0),
            ],
        });
    }
    Ok(())
}

/// Checks six output planes hold `hw` values each ([`CnnPlan::run_planes_into`]). Errors:
/// [`crate::HoloError::ShapeMismatch`].
pub(crate) fn check_output_planes(outputs: &[&mut [f32]; 6], hw: usize) -> Result<()> {
    match outputs.iter().find(|p| p.len() != hw) {
        Some(p) => Err(crate::HoloError::ShapeMismatch {
            what: "CNN output plane (values)".into(),
            expected: vec![hw],
            got: vec![p.len()],
        }),
        None => Ok(()),
    }
}

/// One CNN at one resolution on the engine [`cnn_plan`] chose: what `holo bench` times, engine against
/// engine. A session builds its own plans; this is for measuring the CNN alone.
#[derive(Debug)]
pub struct CpuCnnPlan(Box<dyn CnnPlan>);

impl CpuCnnPlan {
    /// `(channels, height, width)` of the input `[C, H, W]`.
    pub fn input_dim(&self) -> (usize, usize, usize) {
        self.0.input_dim()
    }

    /// Runs the CNN on `input` `[C, H, W]`: its two outputs `[3, H, W]` (amplitude and phase of a hologram
    /// CNN; `Re`, `Im` of a pre-filter). Errors: [`crate::HoloError::ShapeMismatch`]; the engine's run
    /// errors.
    pub fn run_outputs(&mut self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)> {
        self.0.run_outputs(input)
    }
}

/// `model`'s CNN for `height × width` inputs on `engine` (tract's layout and threads from `request`; the
/// native engine uses `request.threads`), and how it was chosen, as a session chooses
/// ([`PipelineConfig::cnn_engine`](crate::pipeline::PipelineConfig::cnn_engine)).
///
/// Errors: [`crate::HoloError::InvalidParameter`] (`engine`) for [`CnnEngine::Native`] with a file it
/// cannot run (int8 QOperator, or a graph that is not the TensorHolo CNN); as
/// `HologramModel::tuned_plan` (feature `tract`).
pub fn cnn_plan(
    model: &crate::model::HologramModel,
    height: usize,
    width: usize,
    engine: CnnEngine,
    request: crate::model::PlanRequest,
) -> Result<(CpuCnnPlan, crate::model::PlanReport)> {
    let plans = select(model, None, height, width, engine, request)?;
    Ok((CpuCnnPlan(plans.hologram), plans.report))
}

/// The CPU features the native engine's kernels use on this machine (`avx2`, `avx512`, `neondot`, …;
/// lowered by the `TENSORHOLO_ISA` environment variable), or why it cannot run.
pub fn native_isa() -> Result<&'static str> {
    active_isa().map(|i| i.name())
}

/// A native plan for `graph` at `height × width` on `threads` threads: the int8 engine for an int8 (QDQ)
/// file, the f32 engine otherwise; with the name of the kernel row its layers run. Errors: as
/// `NativePlan::new` / `NativeInt8Plan::new`.
pub(crate) fn native_plan(
    graph: std::sync::Arc<crate::model::CnnWeights>,
    height: usize,
    width: usize,
    threads: usize,
    isa: tensorholo_kernels::Isa,
) -> Result<(Box<dyn CnnPlan>, &'static str)> {
    if graph.quant.is_some() {
        let p = native_int8::NativeInt8Plan::new(graph, height, width, threads, isa)?;
        let k = p.kernel_name();
        Ok((Box::new(p), k))
    } else {
        let p = native::NativePlan::new(graph, height, width, threads, isa)?;
        let k = p.kernel_name();
        Ok((Box::new(p), k))
    }
}

/// [`tensorholo_kernels::Isa::active`] with its error as the SDK's ([`kernel_err`]).
pub(crate) fn active_isa() -> Result<tensorholo_kernels::Isa> {
    tensorholo_kernels::Isa::active().map_err(kernel_err)
}

/// A kernel-crate error as [`crate::HoloError::ModelRun`], naming the native engine.
pub(crate) fn kernel_err(e: tensorholo_kernels::KernelError) -> crate::HoloError {
    crate::HoloError::ModelRun(format!("native CNN engine: {e}"))
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

#[cfg(all(test, feature = "embedded-models"))]
mod tests;
