//! [`RandomSceneConfig`]: the parameters of the random scenes and their checks.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::error::{invalid, Result};

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
    /// Errors: [`HoloError::InvalidParameter`](crate::HoloError::InvalidParameter) naming the field: zero
    /// size or layers (or more than 4096 pixels a side, 64 layers), an empty or reversed range, a shape
    /// count above 10,000, sizes outside `(0, 4]`, probabilities outside `[0, 1]`, depths outside `[0, 1]`,
    /// tilts outside `[0, 1]`, thin widths outside `(0, 64]` pixels, `photo_max_side` < 8.
    pub(crate) fn validate(&self) -> Result<()> {
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
