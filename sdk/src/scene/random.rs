//! Random layered depth images for the training dataset, in the spirit of the paper's random-scene
//! configuration (MIT-CGH-4K-V2, section "MIT-CGH-4K-V2"; scenes as in TensorHolo V1).
//!
//! A scene is a textured background plane (always present, far, optionally tilted) and a random number
//! of textured shapes in front of, among and occasionally behind each other: planar and tilted discs and
//! ellipses, rotated rectangles, random convex and concave (star-shaped) polygons, and thin structures
//! (round-capped lines, thin bars, rings and arcs, wavy strokes). Every shape covers its pixels with
//! *fragments* (depth, R, G, B amplitude); per pixel the fragments are sorted front to back and the first
//! `L` become the LDI layers ([`ldi_from_fragments`]). That is exactly what depth peeling (paper
//! Algorithm 1) yields: layer `k` holds the `k`-th surface a ray through the pixel centre pierces
//! (paper Fig. 1a). Layer 0 is valid everywhere (the background covers every pixel), so it is an RGB-D
//! image; rear layers are valid only where enough surfaces overlap.
//!
//! Textures follow natural-image statistics: multi-scale value and gradient noise with a `1/f`-like
//! amplitude spectrum (octave gain near ½) mapped through random colour palettes (smooth or banded),
//! linear colour gradients, stripes (square or sinusoidal, optionally warped by noise), checkers,
//! mixtures of two patterns through a noise mask, multiplicative noise shading, and optionally random
//! crops of photos from a folder. Colours are drawn in sRGB and stored as amplitude = √(linear
//! intensity) in `[0, 1]` (`docs/CONVENTIONS.md` §5.5).
//!
//! Everything is a pure function of ([`RandomSceneConfig`], seed): one [`ChaCha8Rng`] per scene, seeded
//! with [`SeedableRng::seed_from_u64`]. Scenes can therefore be generated in parallel and any single one
//! regenerated from its seed.

use std::f32::consts::{PI, TAU};
use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::frame::{LayeredDepthImage, LdiLayer, RgbdFrame};
use super::load::load_rgb;
use crate::color::srgb_to_linear;
use crate::error::{invalid, HoloError, Result};

/// Parameters of the random scenes. `Default` gives the dataset defaults: 384×384, 5 LDI layers, 8–40
/// shapes in front of a far background.
///
/// Lengths marked "fraction" are relative to the short image side `s = min(height, width)`, so a scene
/// looks the same at any resolution; thin-structure widths are in pixels. Depths are normalised
/// (`d ∈ [0, 1]`, 0 = near, `docs/CONVENTIONS.md` §4). Ranges are `[min, max]`, inclusive.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RandomSceneConfig {
    /// Image height `H` in pixels (paper: 384).
    pub height: usize,
    /// Image width `W` in pixels (paper: 384).
    pub width: usize,
    /// Number of LDI layers `L` kept per pixel (paper: 5, chosen with Fig. 2a).
    pub layers: usize,
    /// Number of shapes in front of the background, uniform in `[min, max]`.
    pub shape_count: [usize; 2],
    /// Size (bounding radius) of an ordinary shape, fraction of `s`, log-uniform in `[min, max]`.
    pub shape_size: [f32; 2],
    /// Probability that a (non-thin) shape is large instead, with size from [`Self::large_shape_size`].
    pub large_shape_probability: f32,
    /// Size of a large shape, fraction of `s`, log-uniform in `[min, max]`.
    pub large_shape_size: [f32; 2],
    /// Probability that a shape is a thin structure (line, thin bar, ring or arc, wavy stroke).
    pub thin_probability: f32,
    /// Full width of thin structures in pixels, uniform in `[min, max]`.
    pub thin_width_px: [f32; 2],
    /// Depth of a shape (at its centre), uniform in `[min, max]` ⊂ `[0, 1]`.
    pub shape_depth: [f32; 2],
    /// Probability that a shape is tilted: its depth varies linearly across it (clamped to `[0, 1]`).
    pub tilt_probability: f32,
    /// Largest depth change across a tilted shape's diameter (normalised depth units).
    pub max_tilt: f32,
    /// Depth of the background plane at the image centre, uniform in `[min, max]` ⊂ `[0, 1]`.
    pub background_depth: [f32; 2],
    /// Probability that the background plane is tilted.
    pub background_tilt_probability: f32,
    /// Largest depth change of a tilted background across the image diagonal.
    pub max_background_tilt: f32,
    /// Optional folder of photos (PNG, JPEG, PPM/PGM): textures may then be random crops of them. (Serialised
    /// lossily if its name is not UTF-8.)
    #[serde(serialize_with = "crate::io::lossy_path::option")]
    pub photo_folder: Option<PathBuf>,
    /// Probability that a texture is a photo crop when [`Self::photo_folder`] is set.
    pub photo_probability: f32,
    /// Photos are downscaled on load so that their longer side is at most this many pixels.
    pub photo_max_side: usize,
}

impl Default for RandomSceneConfig {
    fn default() -> Self {
        Self {
            height: 384,
            width: 384,
            layers: 5,
            shape_count: [8, 40],
            shape_size: [0.05, 0.5],
            large_shape_probability: 0.2,
            large_shape_size: [0.35, 0.8],
            thin_probability: 0.2,
            thin_width_px: [1.0, 4.0],
            shape_depth: [0.0, 1.0],
            tilt_probability: 0.5,
            max_tilt: 0.5,
            background_depth: [0.8, 1.0],
            background_tilt_probability: 0.5,
            max_background_tilt: 0.2,
            photo_folder: None,
            photo_probability: 0.5,
            photo_max_side: 1024,
        }
    }
}

fn check_probability(name: &'static str, p: f32) -> Result<()> {
    if (0.0..=1.0).contains(&p) {
        Ok(())
    } else {
        Err(invalid(
            name,
            format!("probability must lie in [0, 1], got {p}"),
        ))
    }
}

fn check_range(name: &'static str, r: [f32; 2], lo: f32, hi: f32) -> Result<()> {
    if r[0].is_finite() && r[1].is_finite() && lo <= r[0] && r[0] <= r[1] && r[1] <= hi {
        Ok(())
    } else {
        Err(invalid(
            name,
            format!(
                "range [{}, {}] must satisfy {lo} <= min <= max <= {hi}",
                r[0], r[1]
            ),
        ))
    }
}

impl RandomSceneConfig {
    /// Checks every field.
    ///
    /// Errors: [`HoloError::InvalidParameter`] naming the field: zero size or layers (or more than
    /// 4096 pixels a side, 64 layers), an empty or reversed range, a shape count above 10,000, sizes
    /// outside `(0, 4]`, probabilities outside `[0, 1]`, depths outside `[0, 1]`, tilts outside `[0, 1]`,
    /// thin widths outside `(0, 64]` pixels, `photo_max_side` < 8.
    pub fn validate(&self) -> Result<()> {
        if self.height == 0 || self.width == 0 || self.height > 4096 || self.width > 4096 {
            return Err(invalid(
                "size",
                format!(
                    "height and width must lie in 1..=4096, got {}x{}",
                    self.height, self.width
                ),
            ));
        }
        if self.layers == 0 || self.layers > 64 {
            return Err(invalid(
                "layers",
                format!("must lie in 1..=64, got {}", self.layers),
            ));
        }
        let [lo, hi] = self.shape_count;
        if lo > hi || hi > 10_000 {
            return Err(invalid(
                "shape_count",
                format!("range [{lo}, {hi}] must satisfy min <= max <= 10000"),
            ));
        }
        check_range("shape_size", self.shape_size, f32::MIN_POSITIVE, 4.0)?;
        check_range(
            "large_shape_size",
            self.large_shape_size,
            f32::MIN_POSITIVE,
            4.0,
        )?;
        check_range("thin_width_px", self.thin_width_px, f32::MIN_POSITIVE, 64.0)?;
        check_range("shape_depth", self.shape_depth, 0.0, 1.0)?;
        check_range("background_depth", self.background_depth, 0.0, 1.0)?;
        check_range("max_tilt", [self.max_tilt; 2], 0.0, 1.0)?;
        check_range(
            "max_background_tilt",
            [self.max_background_tilt; 2],
            0.0,
            1.0,
        )?;
        check_probability("large_shape_probability", self.large_shape_probability)?;
        check_probability("thin_probability", self.thin_probability)?;
        check_probability("tilt_probability", self.tilt_probability)?;
        check_probability(
            "background_tilt_probability",
            self.background_tilt_probability,
        )?;
        check_probability("photo_probability", self.photo_probability)?;
        if self.photo_max_side < 8 {
            return Err(invalid(
                "photo_max_side",
                format!("must be at least 8 pixels, got {}", self.photo_max_side),
            ));
        }
        Ok(())
    }
}

/// One surface sample that a ray through a pixel centre meets: the input of [`ldi_from_fragments`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fragment {
    /// Pixel row `y` in `0..H`.
    pub row: u32,
    /// Pixel column `x` in `0..W`.
    pub col: u32,
    /// Normalised depth `d ∈ [0, 1]`, 0 = near.
    pub depth: f32,
    /// Linear amplitude R, G, B (√ linear intensity, ≥ 0, nominally ≤ 1).
    pub amplitude: [f32; 3],
}

/// Builds an `L`-layer LDI of size `height × width` from surface fragments by per-pixel depth sorting:
/// at each pixel the fragments are sorted front to back (stable: equal depths keep their order in
/// `fragments`) and the first `layers` become layers `0..L` (paper Fig. 1a; what depth peeling,
/// Algorithm 1, renders). Where a pixel has fewer than `L` fragments the remaining layers are invalid,
/// with amplitude 0 and depth 1.
///
/// Errors: [`HoloError::InvalidParameter`] for a zero size or zero layers, or a fragment outside the
/// image (`fragments`); [`HoloError::InvalidDepth`] for a depth outside `[0, 1]` or NaN;
/// [`HoloError::InvalidData`] for a negative or non-finite amplitude.
pub fn ldi_from_fragments(
    height: usize,
    width: usize,
    layers: usize,
    fragments: &[Fragment],
) -> Result<LayeredDepthImage> {
    if height == 0 || width == 0 {
        return Err(invalid(
            "size",
            format!("LDI size must be non-zero, got {height}x{width}"),
        ));
    }
    if layers == 0 {
        return Err(invalid("layers", "an LDI needs at least one layer"));
    }
    let n = height * width;
    if fragments.len() > u32::MAX as usize {
        return Err(invalid(
            "fragments",
            format!("too many fragments ({})", fragments.len()),
        ));
    }
    // Counting sort by pixel (keeps insertion order within a pixel) ...
    let mut start = vec![0usize; n + 1];
    for (i, f) in fragments.iter().enumerate() {
        let (y, x) = (f.row as usize, f.col as usize);
        if y >= height || x >= width {
            return Err(invalid(
                "fragments",
                format!(
                    "fragment {i} at (row {y}, column {x}) lies outside the {height}x{width} image"
                ),
            ));
        }
        if !(0.0..=1.0).contains(&f.depth) {
            return Err(HoloError::InvalidDepth(format!(
                "fragment {i} at (row {y}, column {x}) has depth {}; normalised depth must lie in [0, 1]",
                f.depth
            )));
        }
        if f.amplitude.iter().any(|a| !(a.is_finite() && *a >= 0.0)) {
            return Err(HoloError::InvalidData(format!(
                "fragment {i} at (row {y}, column {x}) has amplitude {:?}; amplitudes must be finite and >= 0",
                f.amplitude
            )));
        }
        start[y * width + x + 1] += 1;
    }
    for p in 0..n {
        start[p + 1] += start[p];
    }
    let mut fill = start.clone();
    let mut order = vec![0u32; fragments.len()];
    for (i, f) in fragments.iter().enumerate() {
        let p = f.row as usize * width + f.col as usize;
        order[fill[p]] = i as u32;
        fill[p] += 1;
    }
    // ... then a stable sort by depth within each pixel; the first `layers` fragments are kept.
    let mut out: Vec<LdiLayer> = (0..layers)
        .map(|_| LdiLayer {
            amplitude: Array3::zeros((3, height, width)),
            depth: Array2::ones((height, width)),
            valid: Array2::from_elem((height, width), false),
        })
        .collect();
    for p in 0..n {
        let slice = &mut order[start[p]..start[p + 1]];
        slice.sort_by(|&a, &b| {
            fragments[a as usize]
                .depth
                .total_cmp(&fragments[b as usize].depth)
        });
        let (y, x) = (p / width, p % width);
        for (layer, &i) in out.iter_mut().zip(slice.iter()) {
            let f = &fragments[i as usize];
            // `+ 0.0` turns −0 into +0.
            layer.depth[[y, x]] = f.depth + 0.0;
            layer.valid[[y, x]] = true;
            for c in 0..3 {
                layer.amplitude[[c, y, x]] = f.amplitude[c];
            }
        }
    }
    LayeredDepthImage::new(out)
}

/// File extensions read from a photo folder.
const PHOTO_EXTENSIONS: [&str; 5] = ["png", "jpg", "jpeg", "ppm", "pgm"];

/// The photos in `folder` that [`RandomSceneGenerator`] uses: regular files with extension PNG, JPEG,
/// PPM or PGM (any case), sorted by path so that the list (and hence every scene) is reproducible.
///
/// Errors: [`HoloError::Io`] if the folder cannot be read; [`HoloError::InvalidParameter`]
/// (`photo_folder`) if it holds no such file.
pub fn list_photos(folder: &Path) -> Result<Vec<PathBuf>> {
    let io = |source| HoloError::Io {
        path: folder.to_path_buf(),
        source,
    };
    let mut photos = Vec::new();
    for entry in std::fs::read_dir(folder).map_err(io)? {
        let path = entry.map_err(io)?.path();
        let ok = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| PHOTO_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
        if ok && path.is_file() {
            photos.push(path);
        }
    }
    if photos.is_empty() {
        return Err(invalid(
            "photo_folder",
            format!(
                "`{}` holds no PNG, JPEG, PPM or PGM image",
                folder.display()
            ),
        ));
    }
    photos.sort();
    Ok(photos)
}

/// Generates random scenes of one [`RandomSceneConfig`]; holds the decoded photos (if any) so that
/// many scenes can be generated, in parallel (`Sync`), without reloading them.
#[derive(Debug, Clone)]
pub struct RandomSceneGenerator {
    config: RandomSceneConfig,
    photo_paths: Vec<PathBuf>,
    /// Photos as linear amplitude `[3, h, w]`.
    photos: Vec<Array3<f32>>,
}

impl RandomSceneGenerator {
    /// Validates `config` and loads the photos of [`RandomSceneConfig::photo_folder`] (see
    /// [`list_photos`]), each downscaled to at most [`RandomSceneConfig::photo_max_side`] pixels.
    ///
    /// Errors: as [`RandomSceneConfig::validate`] and [`list_photos`]; [`HoloError::Io`] /
    /// [`HoloError::Image`] naming a photo that cannot be read or decoded.
    pub fn new(config: RandomSceneConfig) -> Result<Self> {
        config.validate()?;
        let mut photo_paths = Vec::new();
        let mut photos = Vec::new();
        if let Some(folder) = &config.photo_folder {
            photo_paths = list_photos(folder)?;
            for path in &photo_paths {
                let amplitude = load_rgb(path)?;
                let (_, h, w) = amplitude.dim();
                let max_side = h.max(w);
                let photo = if max_side > config.photo_max_side {
                    let k = config.photo_max_side as f64 / max_side as f64;
                    let nh = ((h as f64 * k).round() as usize).max(1);
                    let nw = ((w as f64 * k).round() as usize).max(1);
                    let frame = RgbdFrame {
                        amplitude,
                        depth: Array2::zeros((h, w)),
                    };
                    frame.resize(nh, nw)?.amplitude
                } else {
                    amplitude
                };
                photos.push(photo);
            }
        }
        Ok(Self {
            config,
            photo_paths,
            photos,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &RandomSceneConfig {
        &self.config
    }

    /// The photo files in use (empty without a photo folder), sorted.
    pub fn photo_paths(&self) -> &[PathBuf] {
        &self.photo_paths
    }

    /// The scene of `seed` as an LDI of [`RandomSceneConfig::layers`] layers, each amplitude
    /// `[3, H, W]` (R, G, B, `[0, 1]`), depth `[H, W]` (`[0, 1]`, 0 = near; 1 where invalid), valid
    /// `[H, W]`. Layer 0 is valid everywhere. The same seed always gives the same scene.
    ///
    /// Errors: none for a generator built by [`RandomSceneGenerator::new`] (the result passes
    /// [`LayeredDepthImage::new`]); the `Result` guards the invariants.
    pub fn generate(&self, seed: u64) -> Result<LayeredDepthImage> {
        let c = &self.config;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (h, w) = (c.height, c.width);
        let s = h.min(w) as f32;
        let ctx = TextureContext {
            photos: &self.photos,
            photo_probability: if self.photos.is_empty() {
                0.0
            } else {
                c.photo_probability
            },
        };

        // Background: a plane through the image centre at a far depth, optionally tilted.
        let bg_depth = uniform(&mut rng, c.background_depth);
        let (bg_gx, bg_gy) = if rng.random_bool(f64::from(c.background_tilt_probability)) {
            let diag = ((h * h + w * w) as f32).sqrt();
            let t = uniform(&mut rng, [-c.max_background_tilt, c.max_background_tilt]);
            let a = uniform(&mut rng, [0.0, TAU]);
            (t / diag * a.cos(), t / diag * a.sin())
        } else {
            (0.0, 0.0)
        };
        let bg_texture = Texture::random(&mut rng, &ctx, s);

        let count = rng.random_range(c.shape_count[0]..=c.shape_count[1]);
        let mut fragments: Vec<Fragment> = Vec::with_capacity(h * w * 4);
        for _ in 0..count {
            let shape = Shape::random(&mut rng, c, &ctx, h, w);
            shape.rasterise(h, w, &self.photos, &mut fragments);
        }
        // The background last, so that a shape at exactly the background's depth lies in front of it.
        let (cx, cy) = (w as f32 / 2.0, h as f32 / 2.0);
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                fragments.push(Fragment {
                    row: y as u32,
                    col: x as u32,
                    depth: (bg_depth + bg_gx * dx + bg_gy * dy).clamp(0.0, 1.0),
                    amplitude: bg_texture.amplitude(dx, dy, &self.photos),
                });
            }
        }
        ldi_from_fragments(h, w, c.layers, &fragments)
    }
}

/// The random LDI of `seed` for `config` (see the module docs and [`RandomSceneGenerator::generate`]);
/// a convenience that builds a [`RandomSceneGenerator`] (loading photos) for this one scene.
///
/// Errors: as [`RandomSceneGenerator::new`].
pub fn random_ldi(config: &RandomSceneConfig, seed: u64) -> Result<LayeredDepthImage> {
    RandomSceneGenerator::new(config.clone())?.generate(seed)
}

// ---------------------------------------------------------------------------------------------------
// Random helpers

/// Uniform in `[r[0], r[1]]` (no panic when `r[0] == r[1]`).
fn uniform(rng: &mut ChaCha8Rng, r: [f32; 2]) -> f32 {
    r[0] + (r[1] - r[0]) * rng.random::<f32>()
}

/// Log-uniform in `[r[0], r[1]]`, `0 < r[0] <= r[1]`.
fn log_uniform(rng: &mut ChaCha8Rng, r: [f32; 2]) -> f32 {
    (r[0].ln() + (r[1].ln() - r[0].ln()) * rng.random::<f32>()).exp()
}

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

// ---------------------------------------------------------------------------------------------------
// Noise

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
struct Fractal {
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
    fn random_scaled(rng: &mut ChaCha8Rng, scale: f32, factor: [f32; 2]) -> Self {
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
    fn eval(&self, u: f32, v: f32) -> f32 {
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

// ---------------------------------------------------------------------------------------------------
// Textures

/// What textures may use: the photos and how often.
struct TextureContext<'a> {
    photos: &'a [Array3<f32>],
    photo_probability: f32,
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

fn random_dir(rng: &mut ChaCha8Rng) -> [f32; 2] {
    let a = uniform(rng, [0.0, TAU]);
    [a.cos(), a.sin()]
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
struct Texture {
    base: Pattern,
    overlay: Option<(Pattern, Fractal, f32)>,
    shade: Option<(Fractal, f32)>,
}

impl Texture {
    /// A random texture for a surface of extent about `scale` pixels.
    fn random(rng: &mut ChaCha8Rng, ctx: &TextureContext, scale: f32) -> Self {
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
    fn amplitude(&self, u: f32, v: f32, photos: &[Array3<f32>]) -> [f32; 3] {
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
// Shapes

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
struct Shape {
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
    fn random(
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
    fn rasterise(&self, h: usize, w: usize, photos: &[Array3<f32>], out: &mut Vec<Fragment>) {
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
