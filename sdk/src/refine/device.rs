//! Where a frame refiner's iterations run, chosen once when the refiner is made
//! (`FrameRefiner::for_pipeline`): the CPU (no device), or a [`RefineDevice`] that prepares the refinement
//! on itself (the GPU, `super::gpu`, cargo feature `gpu`), the device's iterations then behind the same
//! [`Iterations`] as the CPU's.

use super::engine::Refiner;
use super::iterations::Iterations;
use crate::error::Result;

/// What a device makes of a refinement it is handed ([`RefineDevice::prepare`]).
// Made by the devices there are: the GPU's (cargo feature `gpu`); a build without one only matches on it.
#[cfg_attr(not(feature = "gpu"), allow(dead_code))]
pub(crate) enum Prepared {
    /// The refinement uploaded, ready to run.
    Ready(Box<dyn DeviceIterations>),
    /// The device does not run this refinement, for the reason given (it runs on the CPU).
    Declined(String),
}

/// A refinement prepared on a device: it runs there ([`Iterations`]) and takes a next frame's target.
pub(crate) trait DeviceIterations: Iterations + std::fmt::Debug + Send {
    /// Takes `refiner`'s current target (after `Refiner::set_target`: the next video frame) without
    /// uploading the rest again.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a refiner of another size or plane count.
    fn set_target(&mut self, refiner: &Refiner) -> Result<()>;
}

/// A device a frame refiner's iterations may run on (chosen once, when the refiner is made:
/// `FrameRefiner::for_pipeline`).
pub(crate) trait RefineDevice: std::fmt::Debug + Send + Sync {
    /// The device's name, as [`super::RefinedFrame::backend`] reports it.
    fn name(&self) -> String;

    /// `refiner`'s refinement prepared on this device, or why it runs on the CPU.
    ///
    /// Errors: the device's ([`HoloError::Gpu`]: memory beyond its limits, a kernel that does not compile).
    fn prepare(&self, refiner: &Refiner) -> Result<Prepared>;
}
