//! Surface textures: patterns (flat, gradients, noise through palettes, stripes, checkers, photo crops),
//! mixed through noise masks and shaded by noise; colours drawn as natural images have them.

use std::f32::consts::TAU;

use ndarray::Array3;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use super::noise::Fractal;
use super::sampling::{log_uniform, random_dir, uniform};
use crate::color::srgb_to_linear;

/// What textures may use: the photos and how often.
pub(super) struct TextureContext<'a> {
    pub(super) photos: &'a [Array3<f32>],
    pub(super) photo_probability: f32,
}

/// A colour ramp of 2–4 amplitude colours, smooth or banded.
#[derive(Debug, Clone)]
struct Palette {
    colours: Vec<[f32; 3]>,
    bands: Option<u32>,
}

impl Palette {
    fn random(rng: &mut ChaCha8Rng) -> Self {
        let n = rng.random_range(2..=4);
        Self {
            colours: (0..n).map(|_| random_colour(rng)).collect(),
            bands: rng.random_bool(0.25).then(|| rng.random_range(2..=6)),
        }
    }

    fn at(&self, t: f32) -> [f32; 3] {
        let mut t = t.clamp(0.0, 1.0);
        if let Some(b) = self.bands {
            t = ((t * b as f32).floor() / (b - 1) as f32).min(1.0);
        }
        let x = t * (self.colours.len() - 1) as f32;
        let i = (x.floor() as usize).min(self.colours.len() - 2);
        lerp3(self.colours[i], self.colours[i + 1], x - i as f32)
    }
}

/// A base pattern; coordinates are pixels in the shape's own (rotated) frame.
#[derive(Debug, Clone)]
enum Pattern {
    Flat([f32; 3]),
    /// Linear colour gradient along `dir` over `±half_range` pixels.
    Gradient {
        c0: [f32; 3],
        c1: [f32; 3],
        dir: [f32; 2],
        half_range: f32,
    },
    /// Fractal noise through a palette.
    Noise {
        noise: Fractal,
        palette: Palette,
    },
    /// Stripes across `dir`: square (with duty cycle) or sinusoidal, optionally warped by noise.
    Stripes {
        c0: [f32; 3],
        c1: [f32; 3],
        dir: [f32; 2],
        period: f32,
        duty: f32,
        smooth: bool,
        warp: Option<(Fractal, f32)>,
    },
    /// Checkerboard rotated by `dir`.
    Checker {
        c0: [f32; 3],
        c1: [f32; 3],
        dir: [f32; 2],
        period: f32,
    },
    /// A crop of photo `index`: pixel `(u, v)` samples the photo at `origin + k·R·(u, v)` (mirrored at
    /// the borders, bilinear).
    Photo {
        index: usize,
        origin: [f32; 2],
        k: f32,
        dir: [f32; 2],
    },
}

impl Pattern {
    /// A random pattern for a surface whose extent is about `scale` pixels; `procedural_only` excludes
    /// photos.
    fn random(
        rng: &mut ChaCha8Rng,
        ctx: &TextureContext,
        scale: f32,
        procedural_only: bool,
    ) -> Self {
        if !procedural_only && rng.random_bool(f64::from(ctx.photo_probability)) {
            let index = rng.random_range(0..ctx.photos.len());
            let (_, ph, pw) = ctx.photos[index].dim();
            let short = ph.min(pw) as f32;
            // A crop of 15–100 % of the photo's short side spans the shape's diameter.
            let crop = short * log_uniform(rng, [0.15, 1.0]);
            return Pattern::Photo {
                index,
                origin: [
                    uniform(rng, [0.0, pw as f32]),
                    uniform(rng, [0.0, ph as f32]),
                ],
                k: crop / (2.0 * scale.max(1.0)),
                dir: random_dir(rng),
            };
        }
        let r: f32 = rng.random();
        let scale = scale.max(2.0);
        if r < 0.06 {
            Pattern::Flat(random_colour(rng))
        } else if r < 0.18 {
            Pattern::Gradient {
                c0: random_colour(rng),
                c1: random_colour(rng),
                dir: random_dir(rng),
                half_range: scale * uniform(rng, [0.5, 1.5]),
            }
        } else if r < 0.58 {
            Pattern::Noise {
                noise: Fractal::random_scaled(rng, scale, [0.2, 1.0]),
                palette: Palette::random(rng),
            }
        } else if r < 0.82 {
            let period = log_uniform(rng, [3.0, (scale * 0.6).max(3.0)]);
            let warp = rng.random_bool(0.35).then(|| {
                (
                    Fractal::random_scaled(rng, scale, [0.3, 1.0]),
                    period * uniform(rng, [0.5, 3.0]),
                )
            });
            Pattern::Stripes {
                c0: random_colour(rng),
                c1: random_colour(rng),
                dir: random_dir(rng),
                period,
                duty: uniform(rng, [0.2, 0.8]),
                smooth: rng.random_bool(0.3),
                warp,
            }
        } else {
            Pattern::Checker {
                c0: random_colour(rng),
                c1: random_colour(rng),
                dir: random_dir(rng),
                period: log_uniform(rng, [4.0, (scale * 0.8).max(4.0)]),
            }
        }
    }

    /// Amplitude R, G, B at `(u, v)`.
    fn at(&self, u: f32, v: f32, photos: &[Array3<f32>]) -> [f32; 3] {
        match self {
            Pattern::Flat(c) => *c,
            Pattern::Gradient {
                c0,
                c1,
                dir,
                half_range,
            } => {
                let t = (u * dir[0] + v * dir[1]) / (2.0 * half_range) + 0.5;
                lerp3(*c0, *c1, t.clamp(0.0, 1.0))
            }
            Pattern::Noise { noise, palette } => palette.at(noise.eval(u, v)),
            Pattern::Stripes {
                c0,
                c1,
                dir,
                period,
                duty,
                smooth,
                warp,
            } => {
                let mut p = u * dir[0] + v * dir[1];
                if let Some((noise, amount)) = warp {
                    p += (noise.eval(u, v) - 0.5) * amount;
                }
                let phase = (p / period).rem_euclid(1.0);
                let t = if *smooth {
                    0.5 + 0.5 * (TAU * phase).cos()
                } else if phase < *duty {
                    1.0
                } else {
                    0.0
                };
                lerp3(*c1, *c0, t)
            }
            Pattern::Checker {
                c0,
                c1,
                dir,
                period,
            } => {
                let a = ((u * dir[0] + v * dir[1]) / period).floor() as i64;
                let b = ((-u * dir[1] + v * dir[0]) / period).floor() as i64;
                if (a + b).rem_euclid(2) == 0 {
                    *c0
                } else {
                    *c1
                }
            }
            Pattern::Photo {
                index,
                origin,
                k,
                dir,
            } => {
                let x = origin[0] + k * (u * dir[0] - v * dir[1]);
                let y = origin[1] + k * (u * dir[1] + v * dir[0]);
                sample_mirrored(&photos[*index], x, y)
            }
        }
    }
}

/// Mirrored index into `0..n`.
fn mirror(i: i64, n: usize) -> usize {
    let n = n as i64;
    let period = 2 * n;
    let m = i.rem_euclid(period);
    (if m < n { m } else { period - 1 - m }) as usize
}

/// Bilinear sample of a `[3, h, w]` image at pixel coordinates `(x, y)` (pixel centres at `i + 0.5`),
/// mirrored outside.
fn sample_mirrored(img: &Array3<f32>, x: f32, y: f32) -> [f32; 3] {
    let (_, h, w) = img.dim();
    let (x, y) = (x - 0.5, y - 0.5);
    let (fx, fy) = (x.floor(), y.floor());
    let (tx, ty) = (x - fx, y - fy);
    let (x0, y0) = (fx as i64, fy as i64);
    let (xa, xb) = (mirror(x0, w), mirror(x0 + 1, w));
    let (ya, yb) = (mirror(y0, h), mirror(y0 + 1, h));
    std::array::from_fn(|c| {
        let top = img[[c, ya, xa]] * (1.0 - tx) + img[[c, ya, xb]] * tx;
        let bottom = img[[c, yb, xa]] * (1.0 - tx) + img[[c, yb, xb]] * tx;
        top * (1.0 - ty) + bottom * ty
    })
}

/// A surface texture: a base pattern, optionally mixed with a second one through a noise mask, and
/// optionally shaded by multiplicative noise.
#[derive(Debug, Clone)]
pub(super) struct Texture {
    base: Pattern,
    overlay: Option<(Pattern, Fractal, f32)>,
    shade: Option<(Fractal, f32)>,
}

impl Texture {
    /// A random texture for a surface of extent about `scale` pixels.
    pub(super) fn random(rng: &mut ChaCha8Rng, ctx: &TextureContext, scale: f32) -> Self {
        let base = Pattern::random(rng, ctx, scale, false);
        let overlay = rng.random_bool(0.3).then(|| {
            (
                Pattern::random(rng, ctx, scale, true),
                Fractal::random_scaled(rng, scale, [0.3, 1.0]),
                // Edge sharpness of the mixing mask: 1 soft … 12 almost binary.
                log_uniform(rng, [1.0, 12.0]),
            )
        });
        let shade = rng.random_bool(0.4).then(|| {
            (
                Fractal::random_scaled(rng, scale, [0.1, 1.0]),
                uniform(rng, [0.2, 0.7]),
            )
        });
        Self {
            base,
            overlay,
            shade,
        }
    }

    /// Amplitude R, G, B in `[0, 1]` at `(u, v)`.
    pub(super) fn amplitude(&self, u: f32, v: f32, photos: &[Array3<f32>]) -> [f32; 3] {
        let mut c = self.base.at(u, v, photos);
        if let Some((pattern, mask, sharpness)) = &self.overlay {
            let m = (0.5 + (mask.eval(u, v) - 0.5) * sharpness).clamp(0.0, 1.0);
            if m > 0.0 {
                c = lerp3(c, pattern.at(u, v, photos), m);
            }
        }
        if let Some((noise, strength)) = &self.shade {
            let k = 1.0 - strength + 2.0 * strength * noise.eval(u, v);
            // Shade in intensity, keep amplitude = √intensity: scale amplitude by √k.
            let k = k.max(0.0).sqrt();
            c = c.map(|a| a * k);
        }
        c.map(|a| {
            if a.is_finite() {
                a.clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
    }
}

// ---------------------------------------------------------------------------------------------------
// Colours

/// A random colour as linear amplitude: hue uniform, saturation skewed low and value spread wide as in
/// natural images, drawn in sRGB then decoded (amplitude = √ linear intensity).
fn random_colour(rng: &mut ChaCha8Rng) -> [f32; 3] {
    let hue = rng.random::<f32>();
    let sat = rng.random::<f32>().powf(1.5);
    let val = 0.04 + 0.96 * rng.random::<f32>().powf(0.8);
    let srgb = hsv_to_rgb(hue, sat, val);
    srgb.map(|v| srgb_to_linear(v).sqrt())
}

fn hsv_to_rgb(h: f32, s: f32, v: f32) -> [f32; 3] {
    let h6 = (h.fract() * 6.0).min(5.999_999);
    let i = h6.floor();
    let f = h6 - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    match i as u32 {
        0 => [v, t, p],
        1 => [q, v, p],
        2 => [p, v, t],
        3 => [p, q, v],
        4 => [t, p, v],
        _ => [v, p, q],
    }
}

fn lerp3(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn palette_hits_its_end_colours() {
        let p = Palette {
            colours: vec![[0.0; 3], [1.0; 3]],
            bands: Some(3),
        };
        assert_eq!(p.at(0.0), [0.0; 3]);
        assert_eq!(p.at(1.0), [1.0; 3]);
        assert_eq!(p.at(0.5), [0.5; 3]);
    }

    #[test]
    fn mirror_indexing_reflects() {
        let idx: Vec<usize> = (-3..7).map(|i| mirror(i, 3)).collect();
        assert_eq!(idx, [2, 1, 0, 0, 1, 2, 2, 1, 0, 0]);
    }
}
