//! A built-in, deterministic RGB-D test scene with occlusions, needing no data files (demos, tests,
//! benchmarks, the CLI's default input).
//!
//! Geometry, in units of the short image side `s = min(H, W)`, origin at the image centre, `v` down:
//!
//! | surface | where | depth `d` | texture |
//! |---|---|---|---|
//! | wall (far) | everywhere above the floor | 0.9 | coloured coarse checker × diagonal stripes × fine 6-px checker × gradient |
//! | floor (tilted plane) | `v > 0.18` | ramp 0.9 (top) → 0.6 (bottom edge) | perspective tiles with dark grout × fine 4-px checker |
//! | disc (mid) | centre `(−0.15, 0)`, radius 0.3 | 0.5 | 32-spoke Siemens star, white ring, yellow/blue |
//! | bar (near) | `u ∈ [0.08, 0.2]`, `v ∈ [−0.42, 0.36]` | 0.1 | 5-px red/white stripes, dark centre line |
//!
//! The bar covers the right edge of the disc, the disc covers wall and floor. All textures are binary
//! patterns with hard edges, so the defocus of each depth is measurable in a reconstructed focal stack.
//! Everything is a pure function of `(H, W)`: the same size always gives bit-identical output.

use ndarray::{Array2, Array3};

use super::frame::{LayeredDepthImage, LdiLayer, RgbdFrame};
use crate::error::{invalid, Result};

/// Depth of the far wall.
pub const WALL_DEPTH: f32 = 0.9;
/// Depth of the mid disc.
pub const DISC_DEPTH: f32 = 0.5;
/// Depth of the near bar.
pub const BAR_DEPTH: f32 = 0.1;
/// Depth of the floor's bottom edge (the floor ramps from [`WALL_DEPTH`] at its top to this).
pub const FLOOR_NEAR_DEPTH: f32 = 0.6;

const FLOOR_TOP: f32 = 0.18;
const DISC_CENTRE: (f32, f32) = (-0.15, 0.0);
const DISC_RADIUS: f32 = 0.3;
const BAR_U: (f32, f32) = (0.08, 0.2);
const BAR_V: (f32, f32) = (-0.42, 0.36);

/// One surface sample: linear amplitude R, G, B and normalised depth.
type Sample = ([f32; 3], f32);

/// Pixel context: integer pixel position and normalised coordinates.
struct Px {
    x: usize,
    y: usize,
    u: f32,
    v: f32,
    /// Bottom edge `v` of the image.
    v_max: f32,
    /// Horizontal position in `[0, 1]` across the image.
    t: f32,
}

fn scale(c: [f32; 3], k: f32) -> [f32; 3] {
    [
        (c[0] * k).clamp(0.0, 1.0),
        (c[1] * k).clamp(0.0, 1.0),
        (c[2] * k).clamp(0.0, 1.0),
    ]
}

/// The far wall and the tilted floor; always present.
fn backdrop(p: &Px) -> Sample {
    if p.v > FLOOR_TOP {
        // Floor: a plane tilted toward the viewer; perspective tiles (coordinates ∝ 1/distance below a
        // virtual horizon) with dark grout lines.
        let f = ((p.v - FLOOR_TOP) / (p.v_max - FLOOR_TOP).max(1e-6)).clamp(0.0, 1.0);
        let d = WALL_DEPTH + (FLOOR_NEAR_DEPTH - WALL_DEPTH) * f;
        let below = p.v - (FLOOR_TOP - 0.12);
        let tu = p.u / below * 1.2;
        let tv = 0.12 / below * 12.0;
        let (fu, fv) = (tu - tu.floor(), tv - tv.floor());
        let grout = fu < 0.06 || fv < 0.08;
        let checker = (tu.floor() as i64 + tv.floor() as i64).rem_euclid(2) == 0;
        // Fine 4-pixel speckle inside the tiles: high-frequency texture on the tilted plane.
        let fine = if (p.x / 2 + p.y / 2).is_multiple_of(2) {
            1.0
        } else {
            0.7
        };
        let c = if grout {
            [0.08, 0.07, 0.06]
        } else if checker {
            scale([0.95, 0.82, 0.55], fine)
        } else {
            scale([0.55, 0.32, 0.18], fine)
        };
        (c, d)
    } else {
        // Wall: coloured coarse checker (period 0.25 s) × diagonal stripes (period 0.07 s) × a fine
        // 6-pixel checker × a left-to-right gradient.
        let coarse =
            ((p.u / 0.125).floor() as i64 + (p.v / 0.125).floor() as i64).rem_euclid(2) == 0;
        let base = if coarse {
            [0.2, 0.85, 0.8]
        } else {
            [0.9, 0.3, 0.75]
        };
        let diag = (p.u + p.v) / 0.07;
        let stripe = if diag - diag.floor() < 0.5 { 1.0 } else { 0.55 };
        let fine = if (p.x / 3 + p.y / 3).is_multiple_of(2) {
            1.0
        } else {
            0.7
        };
        let grad = 0.7 + 0.3 * p.t;
        (scale(base, stripe * fine * grad), WALL_DEPTH)
    }
}

/// The mid-depth disc: a Siemens star (32 spokes) with a white ring.
fn disc(p: &Px) -> Option<Sample> {
    let (du, dv) = (p.u - DISC_CENTRE.0, p.v - DISC_CENTRE.1);
    let r = (du * du + dv * dv).sqrt();
    if r > DISC_RADIUS {
        return None;
    }
    let c = if (0.17..0.19).contains(&r) || r > DISC_RADIUS - 0.015 {
        [1.0, 1.0, 1.0]
    } else {
        let a = dv.atan2(du) / std::f32::consts::TAU + 0.5; // [0, 1]
        let spoke = ((a * 32.0).floor() as i64).rem_euclid(2) == 0;
        if spoke {
            [1.0, 0.85, 0.1]
        } else {
            [0.1, 0.15, 0.6]
        }
    };
    Some((c, DISC_DEPTH))
}

/// The near bar: horizontal 5-pixel stripes with a dark centre line.
fn bar(p: &Px) -> Option<Sample> {
    if !(BAR_U.0..=BAR_U.1).contains(&p.u) || !(BAR_V.0..=BAR_V.1).contains(&p.v) {
        return None;
    }
    let centre = (BAR_U.0 + BAR_U.1) / 2.0;
    let c = if (p.u - centre).abs() < 0.008 {
        [0.05, 0.05, 0.05]
    } else if (p.y / 5).is_multiple_of(2) {
        [0.95, 0.15, 0.1]
    } else {
        [1.0, 0.95, 0.9]
    };
    Some((c, BAR_DEPTH))
}

/// Renders every surface and returns the first two (front to back) per pixel.
fn render(height: usize, width: usize) -> Result<LayeredDepthImage> {
    if height == 0 || width == 0 {
        return Err(invalid(
            "size",
            format!("scene size must be non-zero, got {height}x{width}"),
        ));
    }
    let s = height.min(width) as f32;
    let mut amp = [
        Array3::<f32>::zeros((3, height, width)),
        Array3::<f32>::zeros((3, height, width)),
    ];
    let mut depth = [
        Array2::<f32>::ones((height, width)),
        Array2::<f32>::ones((height, width)),
    ];
    let mut valid = [
        Array2::from_elem((height, width), true),
        Array2::from_elem((height, width), false),
    ];
    for y in 0..height {
        for x in 0..width {
            let p = Px {
                x,
                y,
                u: (x as f32 + 0.5 - width as f32 / 2.0) / s,
                v: (y as f32 + 0.5 - height as f32 / 2.0) / s,
                v_max: height as f32 / (2.0 * s),
                t: (x as f32 + 0.5) / width as f32,
            };
            // Already in front-to-back order: bar (0.1) < disc (0.5) < backdrop (≥ 0.6).
            let surfaces = [bar(&p), disc(&p), Some(backdrop(&p))];
            for (k, (c, d)) in surfaces.into_iter().flatten().take(2).enumerate() {
                for ch in 0..3 {
                    amp[k][[ch, y, x]] = c[ch];
                }
                depth[k][[y, x]] = d;
                valid[k][[y, x]] = true;
            }
        }
    }
    let [a0, a1] = amp;
    let [d0, d1] = depth;
    let [v0, v1] = valid;
    LayeredDepthImage::new(vec![
        LdiLayer {
            amplitude: a0,
            depth: d0,
            valid: v0,
        },
        LdiLayer {
            amplitude: a1,
            depth: d1,
            valid: v1,
        },
    ])
}

/// The built-in RGB-D scene at `height × width` (see the module docs for its layout): far textured wall
/// (`d = 0.9`), tilted textured floor (`d` 0.9 → 0.6), mid Siemens-star disc (`d = 0.5`), near striped bar
/// (`d = 0.1`) partly covering the disc. Amplitude `[3, H, W]` in `[0, 1]`, depth `[H, W]`.
/// Deterministic. Error: [`crate::HoloError::InvalidParameter`] if a size is 0.
pub fn default_scene(height: usize, width: usize) -> Result<RgbdFrame> {
    Ok(render(height, width)?.to_rgbd())
}

/// The same scene as a 2-layer LDI: layer 0 is exactly [`default_scene`] (valid everywhere); layer 1 is
/// what the bar and disc hide (disc behind the bar, wall/floor behind the disc or bar), valid only there,
/// with amplitude 0 and depth 1 elsewhere. Error: as [`default_scene`].
pub fn default_scene_ldi(height: usize, width: usize) -> Result<LayeredDepthImage> {
    render(height, width)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Axis;

    /// Fraction of pixels with depth in `[lo, hi]`.
    fn frac(d: &Array2<f32>, lo: f32, hi: f32) -> f32 {
        d.iter().filter(|&&v| v >= lo && v <= hi).count() as f32 / d.len() as f32
    }

    #[test]
    fn has_near_mid_far_content_and_is_valid() {
        for (h, w) in [(384, 384), (270, 480), (480, 270), (64, 96)] {
            let f = default_scene(h, w).unwrap();
            assert_eq!(f.amplitude.dim(), (3, h, w));
            // Passes the constructor's checks.
            RgbdFrame::new(f.amplitude.clone(), f.depth.clone()).unwrap();
            assert!(frac(&f.depth, 0.1, 0.1) > 0.03, "{h}x{w} near");
            assert!(frac(&f.depth, 0.5, 0.5) > 0.1, "{h}x{w} mid");
            assert!(frac(&f.depth, 0.9, 0.9) > 0.2, "{h}x{w} far");
            // The tilted floor: many distinct depths strictly between the disc and the wall.
            let ramp: std::collections::BTreeSet<u32> = f
                .depth
                .iter()
                .filter(|&&d| d > 0.6 && d < 0.9)
                .map(|d| d.to_bits())
                .collect();
            assert!(ramp.len() > h / 10, "{h}x{w} ramp {}", ramp.len());
            assert!(f.amplitude.iter().all(|&a| (0.0..=1.0).contains(&a)));
        }
    }

    #[test]
    fn is_deterministic() {
        assert_eq!(
            default_scene(200, 300).unwrap(),
            default_scene(200, 300).unwrap()
        );
        assert_eq!(
            default_scene_ldi(50, 40).unwrap(),
            default_scene_ldi(50, 40).unwrap()
        );
        assert!(default_scene(0, 10).is_err() && default_scene_ldi(10, 0).is_err());
        assert!(default_scene(1, 1).is_ok());
    }

    #[test]
    fn near_bar_partly_covers_the_disc() {
        let (h, w) = (384, 384);
        let ldi = default_scene_ldi(h, w).unwrap();
        let l1 = &ldi.layers()[1];
        let l0 = &ldi.layers()[0];
        let bar_over_disc = ndarray::Zip::from(&l0.depth)
            .and(&l1.depth)
            .and(&l1.valid)
            .fold(0, |n, &a, &b, &ok| {
                n + usize::from(ok && a == BAR_DEPTH && b == DISC_DEPTH)
            });
        assert!(bar_over_disc > 500, "{bar_over_disc}");
        // ... but not all of it: most of the disc stays visible.
        assert!(
            frac(&l0.depth, DISC_DEPTH, DISC_DEPTH) * (h * w) as f32 > 10.0 * bar_over_disc as f32
        );
    }

    #[test]
    fn every_depth_has_strong_edges() {
        // Mean absolute horizontal+vertical luminance step inside each depth class (both neighbours in the
        // same class) must be large: binary textures, not smooth gradients.
        let f = default_scene(384, 384).unwrap();
        let lum = f
            .amplitude
            .map_axis(Axis(0), |c| (c[0] + c[1] + c[2]) / 3.0);
        for (lo, hi) in [(0.1, 0.1), (0.5, 0.5), (0.9, 0.9), (0.6001, 0.8999)] {
            let (mut sum, mut n, mut strong) = (0.0f32, 0usize, 0usize);
            for y in 0..383 {
                for x in 0..383 {
                    let d = f.depth[[y, x]];
                    let inside = |v: f32| v >= lo && v <= hi;
                    if !inside(d) {
                        continue;
                    }
                    for (yy, xx) in [(y, x + 1), (y + 1, x)] {
                        if inside(f.depth[[yy, xx]]) {
                            let step = (lum[[y, x]] - lum[[yy, xx]]).abs();
                            sum += step;
                            n += 1;
                            strong += usize::from(step > 0.2);
                        }
                    }
                }
            }
            assert!(n > 1000, "depth [{lo}, {hi}]: {n}");
            assert!(
                strong > 100,
                "depth [{lo}, {hi}]: only {strong} strong edges"
            );
            assert!(
                sum / n as f32 > 0.03,
                "depth [{lo}, {hi}]: mean step {}",
                sum / n as f32
            );
        }
    }

    #[test]
    fn ldi_second_layer_is_what_the_front_hides() {
        let (h, w) = (120, 160);
        let ldi = default_scene_ldi(h, w).unwrap();
        assert_eq!(ldi.num_layers(), 2);
        let (l0, l1) = (&ldi.layers()[0], &ldi.layers()[1]);
        assert_eq!(ldi.to_rgbd(), default_scene(h, w).unwrap());
        assert!(l0.valid.iter().all(|&v| v));
        for ((idx, &d0), &ok1) in l0.depth.indexed_iter().zip(l1.valid.iter()) {
            // Hidden content exists exactly behind the bar and the disc.
            assert_eq!(ok1, d0 <= DISC_DEPTH, "{idx:?}");
            if ok1 {
                assert!(l1.depth[idx] > d0);
            } else {
                assert_eq!(l1.depth[idx], 1.0);
                assert_eq!(l1.amplitude[[0, idx.0, idx.1]], 0.0);
            }
        }
    }
}
