//! The CNN engines behind one interface: a [`CnnPlan`] runs one CNN (hologram or pre-filter) at one resolution
//! on the CPU, whatever computes it. The session's CNN stage ([`crate::pipeline`]) holds a `Box<dyn CnnPlan>`
//! and never asks which engine it is, so adding an engine is a file here, not branches in the session.
//!
//! - [`tract`](self::tract): tract's optimised plan ([`crate::model::ModelPlan`]), which runs any ONNX graph
//!   that passes the contract (`docs/CONVENTIONS.md` §7).
//!
//! The GPU runs whole frames, not CNNs alone: it is a frame executor of the pipeline
//! (`pipeline/executor.rs`), not an engine here.

mod tract;

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

    /// The same network for another thread (a stream's CNN thread): weights shared, run state its own.
    fn spawn(&self) -> Box<dyn CnnPlan>;
}
