//! Phase-only encoding of complex holograms: the double phase method (paper Eq. 7) and its pre-filtered
//! variants AA-DPM (TensorHolo V1, Shi et al. 2021) and BL-DPM (Sui et al., Opt. Express 29, 2597, 2021), phase
//! wrapping, 8-bit SLM codes through a linear look-up table, and what changes between consecutive patterns
//! (`temporal`: phase churn, global phase alignment).

mod double_phase;
mod lut;
pub mod temporal;

pub(crate) use double_phase::PassOneLayout;
pub use double_phase::{
    double_phase_encode, normaliser, ChannelEncoder, ChannelStats, DoublePhase, DoublePhaseMethod,
};
pub use lut::{phase_to_codes, wrap_phase, LinearLut};
pub use temporal::{phase_churn, PhaseChurn, PhaseContinuity, TemporalStep, TemporalSummary};
