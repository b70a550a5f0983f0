//! The draws every part of a scene shares: uniform and log-uniform numbers, directions.

use std::f32::consts::TAU;

use rand::RngExt;
use rand_chacha::ChaCha8Rng;

/// Uniform in `[r[0], r[1]]` (no panic when `r[0] == r[1]`).
pub(super) fn uniform(rng: &mut ChaCha8Rng, r: [f32; 2]) -> f32 {
    r[0] + (r[1] - r[0]) * rng.random::<f32>()
}

/// Log-uniform in `[r[0], r[1]]`, `0 < r[0] <= r[1]`.
pub(super) fn log_uniform(rng: &mut ChaCha8Rng, r: [f32; 2]) -> f32 {
    (r[0].ln() + (r[1].ln() - r[0].ln()) * rng.random::<f32>()).exp()
}

/// A unit vector in a uniformly random direction.
pub(super) fn random_dir(rng: &mut ChaCha8Rng) -> [f32; 2] {
    let a = uniform(rng, [0.0, TAU]);
    [a.cos(), a.sin()]
}
