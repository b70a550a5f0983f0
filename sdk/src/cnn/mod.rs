//! The CNN engines behind one interface: a [`CnnPlan`] runs one CNN (hologram or pre-filter) at one resolution
//! on the CPU, whatever computes it. The session's CNN stage ([`crate::pipeline`]) holds a `Box<dyn CnnPlan>`
//! and never asks which engine it is, so adding an engine is a file here, not branches in the session.
//!
//! - [`tract`](self::tract): tract's optimised plan ([`crate::model::ModelPlan`]), which runs any ONNX graph
//!   that passes the contract (`docs/CONVENTIONS.md` §7).
//! - [`native`](self::native): our direct 3×3 convolutions (`tensorholo-kernels`, SIMD rows chosen at run
//!   time) over the graph read by [`crate::model::graph`]; f32 files.
//!
//! [`select`](self::select) picks the engine of a session ([`CnnEngine`]).
//!
//! The GPU runs whole frames, not CNNs alone: it is a frame executor of the pipeline
//! (`pipeline/executor.rs`), not an engine here.

mod native;
mod select;
mod tract;

pub(crate) use select::{select, CnnPlans};

use ndarray::{Array3, ArrayView3};

use crate::error::{invalid, Result};

/// The engine that runs a session's CNNs on the CPU
/// ([`PipelineConfig::cnn_engine`](crate::pipeline::PipelineConfig::cnn_engine)).
///
/// - [`CnnEngine::Native`]: our direct 3×3 convolution kernels (`tensorholo-kernels`: AVX-512, AVX2+FMA,
///   NEON or portable scalar rows, chosen at run time from the CPU's features), row bands on the plan's own
///   threads. f32 model files; agrees with tract to float rounding (tests/native_engine.rs).
/// - [`CnnEngine::Tract`]: tract's optimised plans (any file that passes the contract, int8 included).
/// - [`CnnEngine::Auto`] (the default): for an f32 file, both are timed at session creation on this
///   machine ([`crate::model::timing_resolution`]) and the faster runs; other files run on tract. The
///   choice and the timings are in [`PlanReport`](crate::model::PlanReport).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CnnEngine {
    /// Time both engines where the native one can run the file; keep the faster.
    #[default]
    Auto,
    /// Our direct-convolution kernels (an error at session creation for a file they cannot run).
    Native,
    /// tract.
    Tract,
}

impl CnnEngine {
    /// Short name: `auto`, `native`, `tract`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Native => "native",
            Self::Tract => "tract",
        }
    }

    /// Parses [`CnnEngine::name`]. Errors: [`crate::HoloError::InvalidParameter`] (`engine`) naming the
    /// choices.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "auto" => Ok(Self::Auto),
            "native" => Ok(Self::Native),
            "tract" => Ok(Self::Tract),
            other => Err(invalid(
                "engine",
                format!("unknown CNN engine `{other}` (auto, native or tract)"),
            )),
        }
    }
}

impl std::fmt::Display for CnnEngine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

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

    /// The same network for another thread (a stream's CNN thread): weights shared, run state its own.
    fn spawn(&self) -> Box<dyn CnnPlan>;
}

#[cfg(all(test, feature = "embedded-models"))]
mod tests;
