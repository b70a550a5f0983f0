//! Wave optics: the angular spectrum method (paper Eq. 2), offset propagation (Eq. 6, Eq. 10), the Fourier
//! (aperture) filter (Eq. 8–9), focal-stack reconstruction, and the aberrations' Zernike terms and pupil kernel
//! (Eq. 14–19, [`zernike`]).
//!
//! Fields are `Complex32`, row-major `[height, width]`; colour stacks are `[channel, height, width]` in R, G, B
//! order and are processed one colour per thread (rayon).

mod channels;
pub mod fft;
pub mod filter;
pub(crate) mod multiplier;
pub mod propagation;
pub mod reconstruct;
mod setup;
pub mod zernike;

pub use channels::propagate_colour;
pub(crate) use channels::{check_colour_stack, check_finite_field, par_channels};

pub use filter::FourierFilter;
pub(crate) use propagation::carrier_free_phase_rad;
pub use propagation::{
    Carrier, EvenMultiplier, Padding, PropagationOptions, Propagator, Scratch, SpectralPlan,
    TransferFunction,
};
pub use reconstruct::{focal_stack, post_encoding_midpoint, simulate_phase_only};
pub use zernike::{ZernikeCoefficients, MAX_COEFFICIENT_RAD};

pub use setup::{
    check_offset, OpticalSetup, MAX_OFFSET_M, MAX_VOLUME_DEPTH_M, PITCH_RANGE_M, WAVELENGTH_RANGE_M,
};
