//! Loading colour images and RGB-D pairs from files: decode → normalise → fill → (resize).

use std::path::Path;

use image::DynamicImage;
use ndarray::Array3;
use serde::Serialize;

use super::depth::{
    decode_depth_file, fill_invalid, normalise_depth, DecodedDepth, DepthEncoding, DepthMapping,
    DepthRange, OtherAspect,
};
use super::frame::RgbdFrame;
use super::upsample::{upsample_depth, DepthUpsampling};
use crate::color::{srgb8_to_amplitude, srgb_to_linear};
use crate::error::{HoloError, Result};

/// Reads an sRGB colour image (PNG, JPEG, PPM…) into linear amplitude `[3, H, W]`, channels R, G, B,
/// values `√(linear intensity)` in `[0, 1]` ([`crate::color::srgb8_to_amplitude`]). Alpha is dropped,
/// grey is expanded to three equal channels; 16-bit files keep their precision.
///
/// Errors: [`HoloError::Io`] (unreadable) or [`HoloError::Image`] (undecodable), naming `path`;
/// [`HoloError::InvalidData`] for an empty image.
pub fn load_rgb(path: &Path) -> Result<Array3<f32>> {
    decode_rgb_bytes(&crate::io::read_bytes(path)?, path)
}

/// As [`load_rgb`], on the bytes of an image file already in memory (format guessed from the content);
/// `source` names it in errors. Returns amplitude `[3, H, W]`, channels R, G, B, in `[0, 1]`. The image size is
/// checked against [`crate::io::InputLimits`] from the header before decoding; a truncated or corrupt file
/// (JPEG included) is an error, never an image completed with grey.
///
/// Errors: as [`load_rgb`], naming `source`.
pub fn decode_rgb_bytes(bytes: &[u8], source: &Path) -> Result<Array3<f32>> {
    Ok(Colour::decode(bytes, source)?.into_amplitude())
}

/// A decoded colour image before it becomes amplitude: 8-bit sRGB as decoded (most files), or amplitude
/// already (16-bit files).
enum Colour {
    Srgb8(image::RgbImage),
    Amplitude(Array3<f32>),
}

impl Colour {
    /// Decodes an image file's bytes (`source` names it in errors; [`decode_rgb_bytes`]'s checks).
    fn decode(bytes: &[u8], source: &Path) -> Result<Self> {
        let path = source;
        let img = crate::io::decode_image(path, bytes)?;
        let (w, h) = (img.width() as usize, img.height() as usize);
        if w == 0 || h == 0 {
            return Err(HoloError::InvalidData(format!(
                "`{}` is an empty image",
                path.display()
            )));
        }
        Ok(match img {
            // An RGB image as it is (no copy).
            DynamicImage::ImageRgb8(rgb) => Colour::Srgb8(rgb),
            DynamicImage::ImageLuma8(_)
            | DynamicImage::ImageLumaA8(_)
            | DynamicImage::ImageRgba8(_) => Colour::Srgb8(img.to_rgb8()),
            _ => {
                let rgb = img.to_rgb32f();
                let raw = rgb.as_raw();
                Colour::Amplitude(Array3::from_shape_fn((3, h, w), |(c, y, x)| {
                    srgb_to_linear(raw[(y * w + x) * 3 + c]).sqrt()
                }))
            }
        })
    }

    /// `(height, width)`.
    fn dim(&self) -> (usize, usize) {
        match self {
            Colour::Srgb8(rgb) => (rgb.height() as usize, rgb.width() as usize),
            Colour::Amplitude(a) => (a.dim().1, a.dim().2),
        }
    }

    /// The amplitude `[3, H, W]`: 8-bit codes through [`srgb8_to_amplitude`]'s table, each plane written in
    /// one pass over the pixels.
    fn into_amplitude(self) -> Array3<f32> {
        let rgb = match self {
            Colour::Amplitude(a) => return a,
            Colour::Srgb8(rgb) => rgb,
        };
        let (h, w) = (rgb.height() as usize, rgb.width() as usize);
        let lut: [f32; 256] = std::array::from_fn(|c| srgb8_to_amplitude(c as u8));
        let mut out = Array3::<f32>::zeros((3, h, w));
        if let Some(planes) = out.as_slice_mut() {
            let (r, gb) = planes.split_at_mut(h * w);
            let (g, b) = gb.split_at_mut(h * w);
            for (((r, g), b), px) in r
                .iter_mut()
                .zip(g.iter_mut())
                .zip(b.iter_mut())
                .zip(rgb.as_raw().chunks_exact(3))
            {
                *r = lut[px[0] as usize];
                *g = lut[px[1] as usize];
                *b = lut[px[2] as usize];
            }
        }
        out
    }

    /// The amplitude resized to `height × width` ([`super::frame::resize_amplitude`], bit for bit), an 8-bit
    /// image's intensities computed row by row from its codes as the resampling reads them (the full-size
    /// amplitude never made: a phone's 1920 × 1440 colour is 33 MB of f32).
    fn resized(self, height: usize, width: usize) -> Array3<f32> {
        let rgb = match self {
            Colour::Amplitude(a) => return super::frame::resize_amplitude(&a, height, width),
            Colour::Srgb8(rgb) => rgb,
        };
        let (h, w) = (rgb.height() as usize, rgb.width() as usize);
        let lut: [f32; 256] = std::array::from_fn(|c| srgb8_to_amplitude(c as u8));
        let raw = rgb.as_raw();
        super::frame::resize_intensity_rows(
            3,
            (h, w),
            (height, width),
            // The largest intensity: the table rises with the code, and so does its square.
            |ch| {
                let top = raw.iter().skip(ch).step_by(3).copied().max().unwrap_or(0);
                lut[top as usize] * lut[top as usize]
            },
            |ch, y, row| {
                for (i, px) in row
                    .iter_mut()
                    .zip(raw[y * w * 3..(y + 1) * w * 3].chunks_exact(3))
                {
                    let a = lut[px[ch] as usize];
                    *i = a * a;
                }
            },
        )
    }
}

/// Options of [`load_rgbd`]. `Default`: automatic range (1st/99th percentiles), linear in diopters,
/// native size, at most 75 % invalid depth pixels and 50 % of the valid ones outside a given range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadOptions {
    /// Metric range mapped to `d ∈ [0,1]`; `None` = 1st/99th percentiles of the valid depths. Ignored for
    /// relative encodings.
    pub range: Option<DepthRange>,
    /// Metric → `d` mapping ([`DepthMapping::LinearDiopters`] by default).
    pub mapping: DepthMapping,
    /// Output size `(height, width)`; `None` keeps the files' size. Resizing happens after hole filling
    /// ([`RgbdFrame::resize`]).
    pub size: Option<(usize, usize)>,
    /// Largest fraction of invalid depth pixels accepted (default 0.75; a scene on an empty background has
    /// ~0.7): above it the depth map is refused, since a wrong encoding is the likelier cause.
    pub max_invalid_fraction: f32,
    /// Largest fraction of the valid depths that may lie outside an explicit `range` (default 0.5; they are
    /// clamped to its ends, so beyond that most of the scene would sit on one plane). Ignored without a range.
    pub max_outside_range_fraction: f32,
    /// How a depth map of lower resolution than the colour is brought to the colour's
    /// ([`crate::scene::upsample_depth`]; joint bilateral by default).
    pub depth_upsampling: DepthUpsampling,
    /// With a confidence map ([`load_rgbd_with_confidence`]): depth pixels of lower confidence are invalid
    /// ([`crate::scene::apply_confidence`]; default [`crate::scene::DEFAULT_MIN_CONFIDENCE`], ARKit's medium).
    pub min_confidence: u8,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            range: None,
            mapping: DepthMapping::default(),
            size: None,
            max_invalid_fraction: 0.75,
            max_outside_range_fraction: 0.5,
            depth_upsampling: DepthUpsampling::default(),
            min_confidence: super::depth::DEFAULT_MIN_CONFIDENCE,
        }
    }
}

/// A depth error that does not name the depth file `depth` (a map that leaves no valid pixel once normalised),
/// with it named.
pub(super) fn name_depth_file(e: HoloError, depth: &Path) -> HoloError {
    match e {
        HoloError::InvalidDepth(m) if !m.contains(&*depth.to_string_lossy()) => {
            HoloError::InvalidDepth(format!("`{}`: {m}", depth.display()))
        }
        other => other,
    }
}

/// The sanity checks of [`load_rgbd`] on a decoded depth map (see [`LoadOptions`]).
fn check_depth_sanity(
    decoded: &DecodedDepth,
    encoding: DepthEncoding,
    options: &LoadOptions,
    depth: &Path,
) -> Result<()> {
    check_invalid_fraction(decoded, encoding, options, depth)?;
    check_outside_range(decoded, options, &format!("`{}`", depth.display()))
}

/// Refuses a depth map with more invalid pixels than `options.max_invalid_fraction` (a wrong encoding is the
/// likelier cause), naming the file `depth`.
pub(super) fn check_invalid_fraction(
    decoded: &DecodedDepth,
    encoding: DepthEncoding,
    options: &LoadOptions,
    depth: &Path,
) -> Result<()> {
    let invalid = decoded.invalid_fraction();
    if invalid > options.max_invalid_fraction {
        return Err(HoloError::InvalidDepth(format!(
            "{:.0} % of the depth pixels of `{}` are invalid under the {encoding} encoding (limit {:.0} %): \
             check --depth-encoding; if the scene really is mostly empty, raise --max-invalid-depth",
            100.0 * invalid,
            depth.display(),
            100.0 * options.max_invalid_fraction
        )));
    }
    Ok(())
}

/// With an explicit metric `options.range`, refuses depths of which more than
/// `options.max_outside_range_fraction` of the valid ones lie outside it; `what` names them in the error.
pub(super) fn check_outside_range(
    decoded: &DecodedDepth,
    options: &LoadOptions,
    what: &str,
) -> Result<()> {
    if let (Some(r), true) = (options.range, decoded.metric) {
        let (mut valid, mut outside) = (0usize, 0usize);
        for (&v, &ok) in decoded.values.iter().zip(decoded.valid.iter()) {
            if ok {
                valid += 1;
                if v < r.z_near_m || v > r.z_far_m {
                    outside += 1;
                }
            }
        }
        let fraction = outside as f32 / valid.max(1) as f32;
        if fraction > options.max_outside_range_fraction {
            let (lo, hi) = decoded.valid_min_max().unwrap_or((f32::NAN, f32::NAN));
            return Err(HoloError::InvalidDepth(format!(
                "{:.0} % of the valid depths of {what} (which span {lo:.3}–{hi:.3} m) lie outside the range {r} \
                 and would be clamped onto its ends (limit {:.0} %): fix --z-near-m/--z-far-m, or raise \
                 --max-depth-outside-range",
                100.0 * fraction,
                100.0 * options.max_outside_range_fraction
            )));
        }
    }
    Ok(())
}

/// What [`load_rgbd`] found in the depth file, for logs and CLI output (serialisable to JSON).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DepthReport {
    /// The encoding used to decode the file.
    pub encoding: DepthEncoding,
    /// Fraction of pixels that were invalid (holes, no reading, empty background) and were filled.
    pub invalid_fraction: f32,
    /// Smallest valid depth in metres (`None` for relative encodings or no valid pixel).
    pub metric_min_m: Option<f32>,
    /// Largest valid depth in metres (`None` for relative encodings or no valid pixel).
    pub metric_max_m: Option<f32>,
    /// Range mapped to `d ∈ [0,1]` (given or automatic); `None` for relative encodings.
    pub range_used: Option<DepthRange>,
    /// `(height, width)` of the colour file, before any resize.
    pub source_size: (usize, usize),
    /// `(height, width)` of the depth file: the colour's, or a lower (or higher) resolution of the same field
    /// of view, brought to the colour's (`DecodedDepth::into_resolution`).
    pub depth_size: (usize, usize),
    /// With a confidence map: the fraction of the depth map's pixels invalidated for a confidence below
    /// [`LoadOptions::min_confidence`] (`None` without one).
    pub low_confidence_fraction: Option<f32>,
}

/// Loads an RGB-D pair into an [`RgbdFrame`]: [`load_rgb`], [`decode_depth_file`], a depth map of another
/// resolution brought to the colour's as the camera path does ([`crate::scene::upsample_depth`] with
/// `options.depth_upsampling`: the same field of view, e.g. a phone's 256 × 192 LiDAR depth under its
/// 1920 × 1440 image),
/// [`normalise_depth`] with `options.range`/`options.mapping`, [`fill_invalid`] (so holes are never read as
/// near), then [`RgbdFrame::resize`] to `options.size` if given. A depth map of another aspect ratio (beyond
/// [`MAX_DEPTH_ASPECT_MISMATCH`](crate::scene::MAX_DEPTH_ASPECT_MISMATCH)) is refused, never stretched (NYU's
/// raw depth is unregistered but has the RGB's size, so it loads).
///
/// Errors: those of the steps above; [`HoloError::ShapeMismatch`] naming both files when their aspect ratios
/// differ (expected = RGB `[H, W]`, got = depth `[H, W]`).
pub fn load_rgbd(
    rgb: &Path,
    depth: &Path,
    encoding: DepthEncoding,
    options: &LoadOptions,
) -> Result<(RgbdFrame, DepthReport)> {
    load_rgbd_with_confidence(rgb, depth, None, encoding, options)
}

/// [`load_rgbd`] with the depth map's confidence map `confidence` (an 8-bit file at the depth map's
/// resolution: ARKit's `confidenceMap`, Stray Scanner's `confidence/N.png`, ARCore's raw depth confidence;
/// `scene::depth::decode_confidence_file`): depth pixels below `options.min_confidence` are invalid before
/// the sanity checks, the upsampling and the hole filling, so uncertain depth takes its confident
/// neighbours' values and is never read as near.
///
/// Errors: those of [`load_rgbd`]; those of `scene::depth::decode_confidence_file` and
/// [`crate::scene::apply_confidence`] (another resolution than the depth map's), naming the file.
pub fn load_rgbd_with_confidence(
    rgb: &Path,
    depth: &Path,
    confidence: Option<&Path>,
    encoding: DepthEncoding,
    options: &LoadOptions,
) -> Result<(RgbdFrame, DepthReport)> {
    let colour = Colour::decode(&crate::io::read_bytes(rgb)?, rgb)?;
    let mut decoded = decode_depth_file(depth, encoding)?;
    let low_confidence_fraction = match confidence {
        Some(path) => {
            let map = super::depth::decode_confidence_file(path)?;
            let dropped =
                super::depth::apply_confidence(&mut decoded, &map, options.min_confidence, path)?;
            Some(dropped as f32 / decoded.values.len().max(1) as f32)
        }
        None => None,
    };
    let (h, w) = colour.dim();
    let depth_size = decoded.values.dim();
    // Another aspect ratio: the files' rule, refused (`OtherAspect::Refuse`).
    decoded.check_aspect(h, w, OtherAspect::Refuse, || {
        format!(
            "depth map `{}` vs RGB image `{}` (another aspect ratio: a depth map of another resolution is \
             brought to the colour's only where it covers the same field of view, aspect ratios within 2 %)",
            depth.display(),
            rgb.display()
        )
    })?;
    check_depth_sanity(&decoded, encoding, options, depth).map_err(|e| {
        match (e, low_confidence_fraction.filter(|&f| f > 0.0)) {
            (HoloError::InvalidDepth(m), Some(f)) => HoloError::InvalidDepth(format!(
                "{m} ({:.0} % of its pixels are below confidence {}: lower --min-confidence)",
                100.0 * f,
                options.min_confidence
            )),
            (e, _) => e,
        }
    })?;
    if depth_size != (h, w) {
        log::info!(
            "depth map `{}` is {}x{}: brought to the colour's {h}x{w} ({}, as the camera path)",
            depth.display(),
            depth_size.0,
            depth_size.1,
            options.depth_upsampling.name()
        );
    }
    // A depth map of another resolution is upsampled at the output size, guided by the colour already brought
    // there (the camera path's order; a phone's 1920×1440 colour is not guided at full size only to be shrunk
    // after): within `docs/CONVENTIONS.md` §6's bound of resizing after (`sdk/tests/recording.rs`).
    let amplitude = match options.size {
        Some((oh, ow)) if depth_size != (h, w) && oh <= h && ow <= w && (oh, ow) != (h, w) => {
            super::frame::check_target_size(oh, ow)?;
            colour.resized(oh, ow)
        }
        _ => colour.into_amplitude(),
    };
    let decoded = upsample_depth(decoded, amplitude.view(), options.depth_upsampling);
    let (d, range_used) = normalise_depth(&decoded, options.range, options.mapping)
        .map_err(|e| name_depth_file(e, depth))?;
    let filled = fill_invalid(&d, &decoded.valid).map_err(|e| name_depth_file(e, depth))?;
    let min_max = decoded.valid_min_max().filter(|_| decoded.metric);
    let report = DepthReport {
        encoding,
        invalid_fraction: decoded.invalid_fraction(),
        metric_min_m: min_max.map(|m| m.0),
        metric_max_m: min_max.map(|m| m.1),
        range_used,
        source_size: (h, w),
        depth_size,
        low_confidence_fraction,
    };
    log::info!(
        "loaded `{}` + `{}` ({encoding}): {h}x{w}, {:.1} % invalid, range {}",
        rgb.display(),
        depth.display(),
        100.0 * report.invalid_fraction,
        range_used.map_or_else(|| "relative".to_string(), |r| r.to_string())
    );
    let frame = RgbdFrame::new(amplitude, filled).map_err(|e| name_depth_file(e, depth))?;
    let frame = match options.size {
        Some((height, width)) => frame.resize(height, width)?,
        None => frame,
    };
    Ok((frame, report))
}

/// The shared TUM frame (`../shared/data/tum`) loaded at `height × width`: the real frame unit tests of other
/// modules run on.
#[cfg(test)]
pub(crate) fn shared_tum_frame(height: usize, width: usize) -> RgbdFrame {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/tum");
    let options = LoadOptions {
        size: Some((height, width)),
        ..LoadOptions::default()
    };
    load_rgbd(
        &root.join("TUM_color.png"),
        &root.join("TUM_depth.png"),
        DepthEncoding::Tum5000,
        &options,
    )
    .expect("the shared TUM frame")
    .0
}
