//! Shared helpers for integration tests (a deterministic RNG, energies, gradients).
#![allow(dead_code)]

pub mod viewer;

use ndarray::{Array2, ArrayView2};
use num_complex::Complex32;

/// Deterministic xorshift generator: uniform values in [0, 1).
pub struct Rng(u64);

impl Rng {
    /// A generator seeded with `seed` (any value).
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// The next uniform value in [0, 1).
    pub fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Total energy Σ|u|² of a field (f64 accumulation).
pub fn energy(field: &[Complex32]) -> f64 {
    field.iter().map(|v| v.norm_sqr() as f64).sum()
}

/// Mean squared gradient (forward differences) of an image over a boolean region.
pub fn gradient_energy(img: ArrayView2<f32>, region: Option<&Array2<bool>>) -> f64 {
    let (h, w) = img.dim();
    let (mut acc, mut n) = (0.0f64, 0usize);
    for y in 0..h - 1 {
        for x in 0..w - 1 {
            if let Some(r) = region {
                if !(r[[y, x]] && r[[y + 1, x]] && r[[y, x + 1]]) {
                    continue;
                }
            }
            let gx = (img[[y, x + 1]] - img[[y, x]]) as f64;
            let gy = (img[[y + 1, x]] - img[[y, x]]) as f64;
            acc += gx * gx + gy * gy;
            n += 1;
        }
    }
    acc / n.max(1) as f64
}

/// Relative L2 error |a − b| / |b|.
pub fn rel_error(a: &[Complex32], b: &[Complex32]) -> f64 {
    let num: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).norm_sqr() as f64)
        .sum();
    (num / energy(b)).sqrt()
}
