//! Fractal lattice noise (value or gradient) with a `1/f`-like amplitude spectrum, the base of the textures.

use std::f32::consts::TAU;

use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use super::sampling::uniform;

/// 32-bit integer hash (lowbias32, C. Wellons).
fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

fn lattice_hash(i: i32, j: i32, seed: u32) -> u32 {
    hash32((i as u32) ^ hash32((j as u32) ^ hash32(seed)))
}

/// Quintic fade (Perlin 2002).
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// Multi-octave (fractal) lattice noise with amplitude ∝ `gain^octave` per doubling of frequency:
/// `gain = ½` gives the `1/f` amplitude spectrum of natural images.
#[derive(Debug, Clone, Copy)]
pub(super) struct Fractal {
    seed: u32,
    /// Frequency of the first octave, cycles per pixel.
    frequency: f32,
    octaves: u32,
    gain: f32,
    /// Gradient (Perlin) noise instead of value noise.
    gradient: bool,
    /// Contrast stretch around ½ applied to the normalised sum.
    contrast: f32,
}

impl Fractal {
    /// Random noise whose coarsest features are about `scale` pixels, with octaves down to ~2 pixels.
    fn random(rng: &mut ChaCha8Rng, scale: f32) -> Self {
        let frequency = 1.0 / scale.max(2.0) * uniform(rng, [0.5, 2.0]);
        let octaves = ((0.5 / frequency).log2().ceil().max(1.0) as u32).min(9);
        Self {
            seed: rng.random(),
            frequency,
            octaves,
            gain: uniform(rng, [0.4, 0.75]),
            gradient: rng.random_bool(0.5),
            contrast: uniform(rng, [1.5, 3.0]),
        }
    }

    /// [`Fractal::random`] with feature size `scale` times a uniform factor from `factor`.
    pub(super) fn random_scaled(rng: &mut ChaCha8Rng, scale: f32, factor: [f32; 2]) -> Self {
        let k = uniform(rng, factor);
        Self::random(rng, scale * k)
    }

    fn octave(&self, u: f32, v: f32, seed: u32) -> f32 {
        let (fu, fv) = (u.floor(), v.floor());
        let (i, j) = (fu as i32, fv as i32);
        let (tu, tv) = (u - fu, v - fv);
        let (su, sv) = (fade(tu), fade(tv));
        if self.gradient {
            let g = |di: i32, dj: i32| {
                let hsh = lattice_hash(i + di, j + dj, seed);
                let a = (hsh >> 8) as f32 * (TAU / (1u32 << 24) as f32);
                let (s, c) = a.sin_cos();
                c * (tu - di as f32) + s * (tv - dj as f32)
            };
            let (a, b) = (g(0, 0), g(1, 0));
            let (c, d) = (g(0, 1), g(1, 1));
            let top = a + (b - a) * su;
            let bottom = c + (d - c) * su;
            // Perlin noise lies within about ±0.71; map to [0, 1].
            0.5 + 0.7 * (top + (bottom - top) * sv)
        } else {
            let val = |di: i32, dj: i32| {
                (lattice_hash(i + di, j + dj, seed) >> 8) as f32 / (1u32 << 24) as f32
            };
            let top = val(0, 0) + (val(1, 0) - val(0, 0)) * su;
            let bottom = val(0, 1) + (val(1, 1) - val(0, 1)) * su;
            top + (bottom - top) * sv
        }
    }

    /// Noise value in `[0, 1]` at pixel offset `(u, v)`.
    pub(super) fn eval(&self, u: f32, v: f32) -> f32 {
        let (mut sum, mut norm, mut amp, mut f) = (0.0, 0.0, 1.0, self.frequency);
        for o in 0..self.octaves {
            // Rotate each octave a little so lattice axes do not line up.
            let (uu, vv) = (0.8 * u - 0.6 * v, 0.6 * u + 0.8 * v);
            let (u2, v2) = if o % 2 == 0 { (u, v) } else { (uu, vv) };
            sum += amp * self.octave(u2 * f, v2 * f, self.seed.wrapping_add(o));
            norm += amp;
            amp *= self.gain;
            f *= 2.0;
        }
        (0.5 + (sum / norm - 0.5) * self.contrast).clamp(0.0, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use rand::SeedableRng;

    #[test]
    fn noise_stays_in_unit_range_and_varies() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..20 {
            let f = Fractal::random(&mut rng, 40.0);
            let vals: Vec<f32> = (0..400)
                .map(|i| f.eval((i % 20) as f32 * 3.1, (i / 20) as f32 * 2.7))
                .collect();
            assert!(vals.iter().all(|v| (0.0..=1.0).contains(v)));
            let mean = vals.iter().sum::<f32>() / vals.len() as f32;
            let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / vals.len() as f32;
            assert!(var > 1e-3, "{f:?}: variance {var}");
        }
    }
}
