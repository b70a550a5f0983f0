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
//!
//! The module is one file a concept: [`RandomSceneConfig`] (`config.rs`), the fragments and their per-pixel
//! depth sort ([`ldi_from_fragments`], `fragments.rs`), the shapes (`shapes.rs`), their textures
//! (`textures.rs`) over fractal noise (`noise.rs`), the draws they share (`sampling.rs`), and here the
//! generator that puts a scene together.

mod config;
mod fragments;
mod noise;
mod sampling;
mod shapes;
mod textures;

use std::f32::consts::TAU;
use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::frame::{LayeredDepthImage, RgbdFrame};
use super::load::load_rgb;
use crate::error::{invalid, HoloError, Result};
use sampling::uniform;
use shapes::Shape;
use textures::{Texture, TextureContext};

pub use config::RandomSceneConfig;
pub use fragments::{ldi_from_fragments, Fragment};

/// File extensions read from a photo folder.
const PHOTO_EXTENSIONS: [&str; 5] = ["png", "jpg", "jpeg", "ppm", "pgm"];

/// The photos in `folder` that [`RandomSceneGenerator`] uses: regular files with extension PNG, JPEG,
/// PPM or PGM (any case), sorted by path so that the list (and hence every scene) is reproducible.
///
/// Errors: [`HoloError::Io`] if the folder cannot be read; [`HoloError::InvalidParameter`]
/// (`photo_folder`) if it holds no such file.
pub(crate) fn list_photos(folder: &Path) -> Result<Vec<PathBuf>> {
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
    /// `list_photos`), each downscaled to at most [`RandomSceneConfig::photo_max_side`] pixels.
    ///
    /// Errors: as `RandomSceneConfig::validate` and `list_photos`; [`HoloError::Io`] /
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
