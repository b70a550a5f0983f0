//! The photo mode's settings ([`RefineSettings`], [`RefineTargetKind`]) and its progress callback
//! ([`RefineProgress`]), for [`HologramGenerator::render_refined`](crate::HologramGenerator::render_refined).

use std::ops::ControlFlow;
use std::sync::Arc;

use tensorholo::refine as core;

/// What the photo mode refines a frame against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum RefineTargetKind {
    /// The SM-LBM ground truth of the frame (`target_levels` depth planes): the better image, at the cost of
    /// a synthesis.
    SmLbm,
    /// The CNN's own midpoint hologram: no synthesis; recovers the encoding's loss, little more.
    CnnMidpoint,
}

/// The photo mode's settings (docs/REFINE.md). The defaults are the SDK's: 10 iterations of Adam, step
/// 0.02 rad, 7 focal planes, against SM-LBM of 512 planes, from the CNN's codes.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct RefineSettings {
    /// Iterations, 1 to 10000.
    #[uniffi(default = 10)]
    pub iterations: u32,
    /// Adam's step size, radians (0 < step ≤ π).
    #[uniffi(default = 0.02)]
    pub step_rad: f32,
    /// Focal planes of the loss (1 to 64).
    #[uniffi(default = 7)]
    pub planes: u32,
    /// What the frame is refined against (none: SM-LBM).
    #[uniffi(default = None)]
    pub target: Option<RefineTargetKind>,
    /// SM-LBM depth planes of the `SmLbm` target (≥ 1).
    #[uniffi(default = 512)]
    pub target_levels: u32,
}

impl RefineSettings {
    /// The core's request (checked by the core).
    pub(crate) fn to_core(&self) -> core::FrameRefinement {
        core::FrameRefinement {
            options: core::RefineOptions {
                iterations: self.iterations as usize,
                step_rad: self.step_rad,
                planes: self.planes as usize,
                ..core::RefineOptions::default()
            },
            target: match self.target.unwrap_or(RefineTargetKind::SmLbm) {
                RefineTargetKind::SmLbm => core::RefineTarget::SmLbm {
                    levels: self.target_levels as usize,
                },
                RefineTargetKind::CnnMidpoint => core::RefineTarget::CnnMidpoint,
            },
            start: core::RefineStart::Cnn,
        }
    }
}

/// The photo mode's progress, implemented by the app: called on the calling thread with the start's score
/// (`iteration` 0) and after every iteration. Return `false` to cancel (the call then fails with
/// [`TensorholoError::Cancelled`](crate::TensorholoError::Cancelled)).
#[uniffi::export(with_foreign)]
pub trait RefineProgress: Send + Sync {
    /// `iteration` of `iterations` done; `psnr_db`: the pattern against the target at the loss planes.
    fn on_iteration(&self, iteration: u32, iterations: u32, psnr_db: f64) -> bool;
}

/// The core's progress callback calling `progress` (every iteration continues without one).
pub(crate) fn progress_of(
    progress: Option<Arc<dyn RefineProgress>>,
    iterations: u32,
) -> impl FnMut(&core::IterationRecord) -> ControlFlow<()> {
    move |r| match &progress {
        Some(p) if !p.on_iteration(r.iteration as u32, iterations, r.psnr_db) => {
            ControlFlow::Break(())
        }
        _ => ControlFlow::Continue(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The record's defaults are the core's.
    #[test]
    fn the_defaults_are_the_cores() {
        let ours = RefineSettings {
            iterations: 10,
            step_rad: 0.02,
            planes: 7,
            target: None,
            target_levels: 512,
        };
        assert_eq!(ours.to_core(), core::FrameRefinement::default());
    }
}
