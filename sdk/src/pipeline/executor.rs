//! Frame executors: what computes a whole frame from the CNN input planes.
//!
//! The CPU frame (the session's [`super::cnn_stage::CnnStage`] on a [`crate::cnn::CnnPlan`], the colour
//! workers, the pre-filter plan) is always built: it is the reference, the first-frame self-check of
//! [`Backend::Auto`] and the fallback. An accelerator, a [`FrameExecutor`], may run the frames instead: the
//! GPU today (`gpu_frame.rs`, cargo feature `gpu`). The session holds `Option<Accelerator>` and never asks
//! which one it is: an executor is a file plus one arm in `setup.rs`'s `choose_backend`.

use ndarray::Array3;
use num_complex::Complex32;

use super::config::Backend;
use super::frame::{Heads, SlmFrame};
use super::report::StageProfile;
use crate::error::Result;

/// A whole frame on an accelerator: the CNN input planes in, SLM patterns out.
pub(super) trait FrameExecutor: std::fmt::Debug + Send {
    /// The backend this executor is ([`Backend::Gpu`] today), as sessions report it.
    fn backend(&self) -> Backend;

    /// Runs one frame of the CNN input `input` (its `C` planes of `H·W` values, `docs/CONVENTIONS.md` §7) into
    /// `out`:
    /// the codes and the normaliser always; the double phase pattern (`out.phase`) and the heads (returned)
    /// only when `full` (otherwise `out.phase` keeps older values and `None` is returned). Timings and
    /// `out.backend` are the caller's.
    ///
    /// Errors: [`crate::HoloError::Gpu`] when the device fails (the session then falls back to the CPU);
    /// any other error is the frame's fault (e.g. a hologram that is zero everywhere).
    fn run(&mut self, input: &[&[f32]], out: &mut SlmFrame, full: bool) -> Result<Option<Heads>>;

    /// What a viewer sees focused at normalised depth `focus` (`[0, 1]`, 0 = near) from `codes` `[3, H, W]`
    /// shown with normaliser `amplitude_scale` (Eq. 8–10), as amplitudes `[3, H, W]`.
    ///
    /// Errors: as the executor's preview ([`crate::HoloError::InvalidParameter`],
    /// [`crate::HoloError::ShapeMismatch`], [`crate::HoloError::Gpu`]).
    fn preview(
        &mut self,
        codes: &Array3<u8>,
        amplitude_scale: f32,
        focus: f64,
    ) -> Result<Array3<f32>>;

    /// Sets the viewer's aberration correction of the next frames: the kernels `Φ` per colour (R, G, B) as the
    /// CPU frame multiplies them (`super::correction`'s `PupilCorrection`: the session's spectrum layout and
    /// scale), or `None` for none. Called between frames; allocates nothing once a correction was set.
    ///
    /// Errors: [`crate::HoloError::ShapeMismatch`] for kernels of another size; [`crate::HoloError::Gpu`].
    fn set_correction(&mut self, kernels: Option<[&[Complex32]; 3]>) -> Result<()>;

    /// Each stage of the last frame timed on its own (median of `repeats`), with its work and traffic.
    ///
    /// Errors: [`crate::HoloError::Gpu`].
    fn stages(&self, repeats: usize) -> Result<Vec<StageProfile>>;
}

/// The accelerator a session runs on, and whether the self-check of [`Backend::Auto`] has yet to run.
#[derive(Debug)]
pub(super) struct Accelerator {
    pub(super) executor: Box<dyn FrameExecutor>,
    pub(super) pending_check: bool,
}

/// A [`super::BackendReport`] before the session knows what runs.
pub(super) struct BackendReportParts {
    pub(super) requested: Backend,
    pub(super) reason: String,
    pub(super) adapter: Option<String>,
    pub(super) gpu_precision: Option<String>,
}

impl BackendReportParts {
    /// The CPU runs, for `reason`.
    pub(super) fn cpu(requested: Backend, reason: String) -> Self {
        Self {
            requested,
            reason,
            adapter: None,
            gpu_precision: None,
        }
    }
}
