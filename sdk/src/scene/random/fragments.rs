//! Surface fragments and the per-pixel depth sort that turns them into an LDI ([`ldi_from_fragments`]).

use ndarray::{Array2, Array3};

use crate::error::{invalid, HoloError, Result};
use crate::scene::frame::{LayeredDepthImage, LdiLayer};

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
