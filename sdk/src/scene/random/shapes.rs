//! The shapes of a scene: planar (optionally tilted) discs, ellipses, rectangles, convex and star-shaped
//! polygons, and thin structures, each textured and rasterised into fragments.

use std::f32::consts::{PI, TAU};

use ndarray::Array3;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use super::config::RandomSceneConfig;
use super::fragments::Fragment;
use super::sampling::{log_uniform, random_dir, uniform};
use super::textures::{Texture, TextureContext};

/// Geometry in the shape's own frame (pixels, origin at the shape centre).
#[derive(Debug, Clone)]
enum Geometry {
    Ellipse {
        a: f32,
        b: f32,
    },
    Rect {
        hw: f32,
        hh: f32,
    },
    Polygon {
        points: Vec<[f32; 2]>,
    },
    /// Round-capped line segment along `u`.
    Capsule {
        half_len: f32,
        radius: f32,
    },
    /// Annulus (or an arc of it, `|angle| <= half_arc`).
    Ring {
        radius: f32,
        half_width: f32,
        half_arc: f32,
    },
    /// Stroke around `v = amp·sin(k·u + phase)`, `|u| <= half_len`.
    Wave {
        half_len: f32,
        amp: f32,
        k: f32,
        phase: f32,
        half_width: f32,
    },
}

impl Geometry {
    /// Radius of a bounding circle.
    fn extent(&self) -> f32 {
        match self {
            Geometry::Ellipse { a, b } => a.max(*b),
            Geometry::Rect { hw, hh } => hw.hypot(*hh),
            Geometry::Polygon { points } => {
                points.iter().map(|p| p[0].hypot(p[1])).fold(0.0, f32::max)
            }
            Geometry::Capsule { half_len, radius } => half_len + radius,
            Geometry::Ring {
                radius, half_width, ..
            } => radius + half_width,
            Geometry::Wave {
                half_len,
                amp,
                half_width,
                ..
            } => half_len.hypot(amp + half_width),
        }
    }

    fn contains(&self, u: f32, v: f32) -> bool {
        match self {
            Geometry::Ellipse { a, b } => (u / a).powi(2) + (v / b).powi(2) <= 1.0,
            Geometry::Rect { hw, hh } => u.abs() <= *hw && v.abs() <= *hh,
            Geometry::Polygon { points } => {
                // Even-odd crossing rule.
                let mut inside = false;
                let mut j = points.len() - 1;
                for i in 0..points.len() {
                    let ([xi, yi], [xj, yj]) = (points[i], points[j]);
                    if (yi > v) != (yj > v) && u < (xj - xi) * (v - yi) / (yj - yi) + xi {
                        inside = !inside;
                    }
                    j = i;
                }
                inside
            }
            Geometry::Capsule { half_len, radius } => {
                let du = (u.abs() - half_len).max(0.0);
                du * du + v * v <= radius * radius
            }
            Geometry::Ring {
                radius,
                half_width,
                half_arc,
            } => (u.hypot(v) - radius).abs() <= *half_width && v.atan2(u).abs() <= *half_arc,
            Geometry::Wave {
                half_len,
                amp,
                k,
                phase,
                half_width,
            } => {
                if u.abs() > *half_len {
                    return false;
                }
                // Vertical distance scaled by the local slope ≈ perpendicular distance.
                let slope = amp * k * (k * u + phase).cos();
                (v - amp * (k * u + phase).sin()).abs() <= half_width * (1.0 + slope * slope).sqrt()
            }
        }
    }
}

/// A textured planar (possibly tilted) shape placed in the image.
#[derive(Debug, Clone)]
pub(super) struct Shape {
    geometry: Geometry,
    centre: [f32; 2],
    /// `(cos θ, sin θ)` of the rotation from image to shape frame.
    rotation: [f32; 2],
    /// Depth at the centre and its gradient per pixel (image axes).
    depth: f32,
    gradient: [f32; 2],
    texture: Texture,
}

impl Shape {
    pub(super) fn random(
        rng: &mut ChaCha8Rng,
        c: &RandomSceneConfig,
        ctx: &TextureContext,
        h: usize,
        w: usize,
    ) -> Self {
        let s = h.min(w) as f32;
        let thin_w = |rng: &mut ChaCha8Rng| uniform(rng, c.thin_width_px) / 2.0;
        let geometry = if rng.random_bool(f64::from(c.thin_probability)) {
            let len = s * log_uniform(rng, [0.1, 0.9]) / 2.0;
            match rng.random_range(0..4u32) {
                0 => Geometry::Capsule {
                    half_len: len,
                    radius: thin_w(rng),
                },
                1 => Geometry::Rect {
                    hw: len,
                    hh: thin_w(rng),
                },
                2 => Geometry::Ring {
                    radius: len * uniform(rng, [0.15, 0.8]),
                    half_width: thin_w(rng),
                    half_arc: if rng.random_bool(0.5) {
                        PI
                    } else {
                        uniform(rng, [0.25 * PI, PI])
                    },
                },
                _ => Geometry::Wave {
                    half_len: len,
                    amp: len * uniform(rng, [0.05, 0.3]),
                    k: TAU / (len * uniform(rng, [0.3, 1.5])),
                    phase: uniform(rng, [0.0, TAU]),
                    half_width: thin_w(rng),
                },
            }
        } else {
            let size = if rng.random_bool(f64::from(c.large_shape_probability)) {
                c.large_shape_size
            } else {
                c.shape_size
            };
            let r = (s * log_uniform(rng, size)).max(1.0);
            match rng.random_range(0..4u32) {
                0 => {
                    let aspect = if rng.random_bool(0.3) {
                        1.0
                    } else {
                        uniform(rng, [0.25, 1.0])
                    };
                    Geometry::Ellipse {
                        a: r,
                        b: r * aspect,
                    }
                }
                1 => Geometry::Rect {
                    hw: r,
                    hh: r * uniform(rng, [0.15, 1.0]),
                },
                2 => {
                    // Convex: vertices on an ellipse in angular order.
                    let n = rng.random_range(3..=8usize);
                    let b = r * uniform(rng, [0.4, 1.0]);
                    let mut angles: Vec<f32> = (0..n).map(|_| uniform(rng, [0.0, TAU])).collect();
                    angles.sort_by(f32::total_cmp);
                    Geometry::Polygon {
                        points: angles.iter().map(|a| [r * a.cos(), b * a.sin()]).collect(),
                    }
                }
                _ => {
                    // Concave (star-shaped): jittered angles, random radii.
                    let n = rng.random_range(5..=14usize);
                    let points = (0..n)
                        .map(|i| {
                            let a = (i as f32 + uniform(rng, [-0.35, 0.35])) * TAU / n as f32;
                            let rr = r * uniform(rng, [0.3, 1.0]);
                            [rr * a.cos(), rr * a.sin()]
                        })
                        .collect();
                    Geometry::Polygon { points }
                }
            }
        };
        let extent = geometry.extent().max(1.0);
        let centre = [
            uniform(rng, [-0.1 * w as f32, 1.1 * w as f32]),
            uniform(rng, [-0.1 * h as f32, 1.1 * h as f32]),
        ];
        let angle = uniform(rng, [0.0, TAU]);
        let depth = uniform(rng, c.shape_depth);
        let gradient = if rng.random_bool(f64::from(c.tilt_probability)) {
            let t = uniform(rng, [-c.max_tilt, c.max_tilt]) / (2.0 * extent);
            let d = random_dir(rng);
            [t * d[0], t * d[1]]
        } else {
            [0.0, 0.0]
        };
        let texture = Texture::random(rng, ctx, extent);
        Shape {
            geometry,
            centre,
            rotation: [angle.cos(), angle.sin()],
            depth,
            gradient,
            texture,
        }
    }

    /// Appends one fragment per covered pixel centre.
    pub(super) fn rasterise(
        &self,
        h: usize,
        w: usize,
        photos: &[Array3<f32>],
        out: &mut Vec<Fragment>,
    ) {
        let e = self.geometry.extent();
        let [cx, cy] = self.centre;
        let range = |c: f32, n: usize| {
            let lo = (c - e - 0.5).floor().max(0.0) as usize;
            let hi = ((c + e + 0.5).ceil().max(0.0) as usize).min(n);
            lo..hi
        };
        let [co, si] = self.rotation;
        for y in range(cy, h) {
            for x in range(cx, w) {
                let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                let (u, v) = (co * dx + si * dy, -si * dx + co * dy);
                if !self.geometry.contains(u, v) {
                    continue;
                }
                let depth =
                    (self.depth + self.gradient[0] * dx + self.gradient[1] * dy).clamp(0.0, 1.0);
                out.push(Fragment {
                    row: y as u32,
                    col: x as u32,
                    depth,
                    amplitude: self.texture.amplitude(u, v, photos),
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometry_contains_its_centre_and_not_far_points() {
        let shapes = [
            Geometry::Ellipse { a: 5.0, b: 2.0 },
            Geometry::Rect { hw: 4.0, hh: 1.0 },
            Geometry::Polygon {
                points: vec![[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]],
            },
            Geometry::Capsule {
                half_len: 5.0,
                radius: 1.0,
            },
        ];
        for g in &shapes {
            assert!(g.contains(0.0, 0.0), "{g:?}");
            assert!(!g.contains(g.extent() + 0.1, 0.0), "{g:?}");
            assert!(!g.contains(0.0, -(g.extent() + 0.1)), "{g:?}");
        }
        let ring = Geometry::Ring {
            radius: 5.0,
            half_width: 1.0,
            half_arc: PI,
        };
        assert!(!ring.contains(0.0, 0.0) && ring.contains(5.0, 0.0) && ring.contains(0.0, -5.5));
        // A concave (L-shaped) polygon: the notch is outside.
        let l = Geometry::Polygon {
            points: vec![
                [0.0, 0.0],
                [4.0, 0.0],
                [4.0, 1.0],
                [1.0, 1.0],
                [1.0, 4.0],
                [0.0, 4.0],
            ],
        };
        assert!(l.contains(0.5, 3.0) && l.contains(3.0, 0.5) && !l.contains(3.0, 3.0));
    }
}
