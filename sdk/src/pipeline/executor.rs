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
use super::models::HologramPipeline;
use super::report::StageProfile;
use crate::error::{HoloError, Result};
use crate::foveation::TileGeometry;

/// One foveated frame's inputs to [`FrameExecutor::run_foveated`] (`super::foveated`).
#[derive(Debug, Clone, Copy)]
#[cfg_attr(not(feature = "gpu"), allow(dead_code))]
pub(super) struct FoveatedInput<'a> {
    /// The tile's CNN input: `C` planes of `T_h·T_w` values, packed as the frame's input is
    /// (`super::fovea_tiles::FoveatedState::pack_tile`).
    pub(super) tile: &'a [&'a [f32]],
    /// The frame's amplitude R, G, B after a calibration's intensity maps, `H·W` values each.
    pub(super) amplitude: [&'a [f32]; 3],
    /// The frame's normalised depth, `H·W` values.
    pub(super) depth: &'a [f32],
    /// The gaze point `(x, y)`, pixels of the frame.
    pub(super) gaze: (f64, f64),
    /// The gaze's normalised depth.
    pub(super) gaze_depth: f32,
    /// The tile's top-left pixel `(y, x)`.
    pub(super) origin: (usize, usize),
    /// The double phase normaliser `a` (`> 0`): [`crate::foveation::FOVEATED_NORMALISER_GAIN`]` · max A`.
    pub(super) normaliser: f32,
}

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

    /// Prepares the foveated frames of `pipeline`'s session (`docs/FOVEATION.md`): the tile `geometry` (one
    /// size for every gaze), the periphery's blur radius per unit of depth difference `blur_px` (pixels, per
    /// colour). Called once, when the session is made. Returns whether this executor runs them
    /// ([`FrameExecutor::run_foveated`]); by default it does not, and the CPU frame runs them.
    ///
    /// Errors: the executor's (e.g. [`crate::HoloError::Gpu`]); the session then runs them on the CPU, or
    /// fails where the GPU was asked for.
    fn plan_foveated(
        &mut self,
        _pipeline: &HologramPipeline,
        _geometry: &TileGeometry,
        _blur_px: [f64; 3],
    ) -> Result<bool> {
        Ok(false)
    }

    /// Runs one foveated frame planned by [`FrameExecutor::plan_foveated`] into `out`, as
    /// [`FrameExecutor::run`] runs a frame (the codes and the normaliser always, the pattern and the
    /// composed heads only when `full`): the tile's CNN, the periphery's blur and blend, then the frame's
    /// stages with the normaliser `input.normaliser`. Returns the heads (with `full`) and the periphery's
    /// phase per colour (radians).
    ///
    /// Errors: [`crate::HoloError::Internal`] where the executor runs no foveated frames; otherwise as
    /// [`FrameExecutor::run`].
    fn run_foveated(
        &mut self,
        _input: &FoveatedInput<'_>,
        _out: &mut SlmFrame,
        _full: bool,
    ) -> Result<(Option<Heads>, [f32; 3])> {
        Err(HoloError::Internal(
            "this executor runs no foveated frames".into(),
        ))
    }
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
