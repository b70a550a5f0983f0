//! The display: its profile file (`profile.rs`: [`DisplayProfile`], what `holo --display FILE` and apps
//! read) and how a model trained for one display serves another (`equivalence.rs`: the depth scale `σ`, the
//! mapping, its ceiling and cost, the non-paraxial residual, and the rules that serve or refuse a display:
//! [`DisplayMapping`]; a refusal, [`DisplayRefusal`], is defined with the error that carries it) and the
//! viewer in front of it (`prescription.rs`: [`Prescription`], a spectacle prescription as the Zernike
//! coefficients that correct it) and its measured aberrations (`aberration.rs`: [`AberrationProfile`], the
//! `tensorholo.aberration` file, and [`AberrationSource`], the one rule for which aberration a session
//! corrects). `docs/DISPLAYS.md` is the user's page.
//!
//! Imports `optics` and `error` only: the model's metadata check (`model::metadata`) reads this module,
//! never the reverse.

pub(crate) mod aberration;
mod equivalence;
mod prescription;
mod profile;

pub use crate::error::{DisplayRefusal, NearestDisplay, RETRAIN_COST};
pub use aberration::{
    AberrationProfile, AberrationSample, AberrationSource, ABERRATION_FORMAT,
    ABERRATION_FORMAT_VERSION,
};
pub(crate) use equivalence::{close, sig};
pub use equivalence::{
    mapping_cost_db, predicted_ceiling_db, rule_tolerance, DisplayMapping, VolumeFit,
    CEILING_AT_1PCT_DB, MAPPING_COST_BUDGET_DB, MAX_NONPARAXIAL_RESIDUAL_RAD, SPREAD_NOISE,
    VOLUME_ROUNDING,
};
pub use prescription::{
    Prescription, DEFAULT_EYEPIECE_FOCAL_M, EYEPIECE_FOCAL_RANGE_M, MAX_CYLINDER_D, MAX_SPHERE_D,
};
pub use profile::{
    DisplayProfile, MAX_OFFSETS, MAX_OFFSET_M, MAX_SLM_PIXELS, MAX_SLM_SIDE, MAX_WAVELENGTH_M,
    MIN_WAVELENGTH_M,
};
