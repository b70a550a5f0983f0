//! Layered depth images as folders of image files: what a renderer's depth-peeling pass writes, one colour
//! image and one depth map per layer, front layer first (`docs/CONVENTIONS.md` §6.3).
//!
//! ```text
//! DIR/rgb_0.png   DIR/depth_0.png     layer 0: what an RGB-D camera sees (every pixel a point)
//! DIR/rgb_1.png   DIR/depth_1.png     layer 1: the first surface behind it (stored depth 0 = no point)
//! …
//! ```
//!
//! [`load_ldi_dir`] reads such a folder into a [`LayeredDepthImage`]; [`write_ldi_dir`] writes one (colour as
//! 8-bit sRGB, depth as 16-bit [`DepthEncoding::Relative16`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use ndarray::{concatenate, s, Array2, Array3, Axis, Zip};

use serde::Serialize;

use super::depth::{
    decode_depth, fill_invalid, normalise_depth, read_depth_samples, DecodedDepth, DepthEncoding,
    DepthMapping, DepthRange,
};
use super::frame::{LayeredDepthImage, LdiLayer};
use super::load::{check_invalid_fraction, check_outside_range, load_rgb, LoadOptions};
use crate::error::{HoloError, Result};

/// Extensions of the image files [`ldi_files`] recognises (case-insensitive).
const EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "ppm", "pgm", "pnm"];

/// Most layers a folder may hold (the shipped LDI network takes 5; a renderer's depth peeling rarely needs
/// more than 8). A folder with more is refused before anything is decoded.
pub const MAX_LDI_FOLDER_LAYERS: usize = 16;

/// One layer's files in an LDI folder.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct LdiLayerFiles {
    /// `rgb_K.<ext>`: sRGB colour image.
    #[serde(serialize_with = "crate::io::lossy_path::serialize")]
    pub rgb: PathBuf,
    /// `depth_K.<ext>`: depth map in the folder's encoding; in layers `K ≥ 1` a stored 0 means no point.
    #[serde(serialize_with = "crate::io::lossy_path::serialize")]
    pub depth: PathBuf,
}

/// Lists the layer files of an LDI folder, front to back: `rgb_K.<ext>` and `depth_K.<ext>` for
/// `K = 0, 1, …` (extensions png, jpg, jpeg, ppm, pgm, pnm; other files are ignored).
///
/// Errors: [`HoloError::Io`] naming `dir` if it cannot be read; [`HoloError::InvalidData`] naming the folder
/// when it holds no `rgb_0`/`depth_0` pair, a layer lacks its colour or depth file, the numbering has a gap,
/// an index has two files (e.g. `rgb_1.png` and `rgb_1.jpg`), or there are more than
/// [`MAX_LDI_FOLDER_LAYERS`] layers.
pub fn ldi_files(dir: &Path) -> Result<Vec<LdiLayerFiles>> {
    let io = |source| HoloError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let mut rgb = BTreeMap::<usize, PathBuf>::new();
    let mut depth = BTreeMap::<usize, PathBuf>::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        let Some((kind, index)) = layer_file(&path) else {
            continue;
        };
        let map = if kind == "rgb" { &mut rgb } else { &mut depth };
        if let Some(other) = map.insert(index, path.clone()) {
            return Err(HoloError::InvalidData(format!(
                "LDI folder `{}` has two {kind} files for layer {index}: `{}` and `{}`; keep one",
                dir.display(),
                file_name(&other),
                file_name(&path)
            )));
        }
    }
    let layers = rgb.len().max(depth.len());
    if layers == 0 {
        return Err(HoloError::InvalidData(format!(
            "`{}` holds no layered depth image: expected rgb_0.png and depth_0.png (then rgb_1.png, \
             depth_1.png, … front to back)",
            dir.display()
        )));
    }
    if layers > MAX_LDI_FOLDER_LAYERS {
        return Err(HoloError::InvalidData(format!(
            "LDI folder `{}` has {layers} layers; at most {MAX_LDI_FOLDER_LAYERS} are read",
            dir.display()
        )));
    }
    (0..layers)
        .map(|k| match (rgb.remove(&k), depth.remove(&k)) {
            (Some(rgb), Some(depth)) => Ok(LdiLayerFiles { rgb, depth }),
            (rgb, depth) => {
                let missing = match (rgb, depth) {
                    (None, None) => format!("rgb_{k} and depth_{k} (the numbering has a gap)"),
                    (None, _) => format!("rgb_{k}"),
                    _ => format!("depth_{k}"),
                };
                Err(HoloError::InvalidData(format!(
                    "LDI folder `{}` lacks {missing}: layers are numbered 0, 1, … without gaps, each with \
                     an rgb_K and a depth_K file",
                    dir.display()
                )))
            }
        })
        .collect()
}

/// `("rgb" | "depth", K)` for a file named `rgb_K.<ext>` / `depth_K.<ext>` with a recognised extension.
fn layer_file(path: &Path) -> Option<(&'static str, usize)> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    if !EXTENSIONS.contains(&ext.as_str()) {
        return None;
    }
    let stem = path.file_stem()?.to_str()?;
    let (kind, index) = stem.split_once('_')?;
    let kind = match kind {
        "rgb" => "rgb",
        "depth" => "depth",
        _ => return None,
    };
    if index.is_empty() || !index.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((kind, index.parse().ok()?))
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    )
}

/// What [`load_ldi_dir`] found in an LDI folder (serialisable to JSON, for logs and CLI reports).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LdiReport {
    /// The encoding every depth file was decoded with.
    pub encoding: DepthEncoding,
    /// The files, front to back.
    pub files: Vec<LdiLayerFiles>,
    /// Per layer, the fraction of pixels holding a scene point (layer 0: 1 after hole filling).
    pub valid_fraction: Vec<f32>,
    /// Fraction of layer 0's depth pixels that were invalid and were filled (as for an RGB-D frame).
    pub front_invalid_fraction: f32,
    /// Metric range mapped to `d ∈ [0,1]` for all layers together (given or from the 1st/99th percentiles
    /// of every layer's valid depths); `None` for relative encodings.
    pub range_used: Option<DepthRange>,
    /// `(height, width)` of the files, before any resize.
    pub source_size: (usize, usize),
}

/// Loads an LDI folder ([`ldi_files`]) into a [`LayeredDepthImage`], layers front to back.
///
/// - Every colour image is read as [`load_rgb`] reads one (`[3, H, W]` linear amplitude); every depth map is
///   decoded with `encoding`; all must have layer 0's `H × W`.
/// - Layer 0 is the RGB-D image: its invalid depth pixels are holes, checked against
///   `options.max_invalid_fraction` and filled as [`super::load_rgbd`] fills them.
/// - In layers `K ≥ 1` a stored sample of 0 (and any sample `encoding` calls invalid) means "no point here".
///   A point may appear in layer `K` only where layer `K − 1` holds one (depth peeling never leaves a gap),
///   and no nearer than it: `d[K] ≥ d[K − 1]`.
/// - Metric depths of all layers map to `d ∈ [0, 1]` with one range: `options.range`, or the 1st/99th
///   percentiles of every layer's valid depths together, and `options.mapping`.
/// - Resized to `options.size` last (`LayeredDepthImage::resize`).
///
/// Errors: as [`ldi_files`], [`load_rgb`] and [`super::decode_depth_file`];
/// [`HoloError::ShapeMismatch`] naming the file whose size differs from `rgb_0`'s (expected = `[H, W]` of
/// `rgb_0`); [`HoloError::InvalidDepth`] naming the files for too many holes in layer 0, depths outside an
/// explicit range, a layer nearer than the one in front of it (with the count and the first pixel) or a point
/// behind a pixel where the layer in front holds none.
pub fn load_ldi_dir(
    dir: &Path,
    encoding: DepthEncoding,
    options: &LoadOptions,
) -> Result<(LayeredDepthImage, LdiReport)> {
    let files = ldi_files(dir)?;
    let mut amplitudes = Vec::with_capacity(files.len());
    let mut decoded = Vec::with_capacity(files.len());
    let mut size = (0, 0);
    for (k, f) in files.iter().enumerate() {
        let amplitude = load_rgb(&f.rgb)?;
        let (_, h, w) = amplitude.dim();
        if k == 0 {
            size = (h, w);
        }
        let check = |path: &Path, got: (usize, usize)| {
            if got == size {
                return Ok(());
            }
            Err(HoloError::ShapeMismatch {
                what: format!(
                    "LDI layer {k} `{}` vs layer 0 `{}` (every layer has one size)",
                    path.display(),
                    files[0].rgb.display()
                ),
                expected: vec![size.0, size.1],
                got: vec![got.0, got.1],
            })
        };
        check(&f.rgb, (h, w))?;
        let raw = read_depth_samples(&crate::io::read_bytes(&f.depth)?, &f.depth, encoding)?;
        check(&f.depth, raw.dim())?;
        let mut d = decode_depth(&raw, encoding);
        if k == 0 {
            check_invalid_fraction(&d, encoding, options, &f.depth)?;
        } else {
            Zip::from(&mut d.valid)
                .and(&raw)
                .for_each(|ok, &v| *ok &= v != 0);
        }
        amplitudes.push(amplitude);
        decoded.push(d);
    }

    check_outside_range(
        &stack_layers(&decoded),
        options,
        &format!("the layers of `{}`", dir.display()),
    )?;
    let valid_fraction: Vec<f32> = std::iter::once(1.0)
        .chain(decoded[1..].iter().map(|d| 1.0 - d.invalid_fraction()))
        .collect();
    let front_invalid_fraction = decoded[0].invalid_fraction();
    let names: Vec<String> = files
        .iter()
        .map(|f| format!("`{}`", file_name(&f.depth)))
        .collect();
    let (ldi, range_used) =
        assemble_layers(amplitudes, decoded, &names, options.range, options.mapping)
            .map_err(|e| super::load::name_depth_file(e, dir))?;
    let report = LdiReport {
        encoding,
        files,
        valid_fraction,
        front_invalid_fraction,
        range_used,
        source_size: size,
    };
    log::info!(
        "loaded LDI `{}` ({encoding}): {} layers of {}x{}, valid {:?}, range {}",
        dir.display(),
        ldi.num_layers(),
        size.0,
        size.1,
        report
            .valid_fraction
            .iter()
            .map(|f| format!("{:.0} %", 100.0 * f))
            .collect::<Vec<_>>(),
        range_used.map_or_else(|| "relative".to_string(), |r| r.to_string())
    );
    let ldi = match options.size {
        Some((height, width)) => ldi.resize(height, width)?,
        None => ldi,
    };
    Ok((ldi, report))
}

/// The layers' decoded depths `[H, W]` stacked along the rows into one `[L·H, W]` map.
fn stack_layers(decoded: &[DecodedDepth]) -> DecodedDepth {
    let values: Vec<_> = decoded.iter().map(|d| d.values.view()).collect();
    let valid: Vec<_> = decoded.iter().map(|d| d.valid.view()).collect();
    DecodedDepth {
        values: concatenate(Axis(0), &values).expect("layers of one size"),
        valid: concatenate(Axis(0), &valid).expect("layers of one size"),
        metric: decoded.iter().all(|d| d.metric),
    }
}

/// [`normalise_depth`] of every layer with one range: `range`, or the 1st/99th percentiles of all layers'
/// valid depths together. Returns the normalised depths `[H, W]` per layer (0 where invalid) and the range.
///
/// Errors: as [`normalise_depth`]. The layers must have one size.
pub(super) fn normalise_layers(
    decoded: &[DecodedDepth],
    range: Option<DepthRange>,
    mapping: DepthMapping,
) -> Result<(Vec<Array2<f32>>, Option<DepthRange>)> {
    let h = decoded.first().map_or(0, |d| d.values.nrows());
    let (d, range) = normalise_depth(&stack_layers(decoded), range, mapping)?;
    let layers = (0..decoded.len())
        .map(|k| d.slice(s![k * h..(k + 1) * h, ..]).to_owned())
        .collect();
    Ok((layers, range))
}

/// The layers of an LDI from their colour (`[3, H, W]` amplitude each) and decoded depth (`[H, W]`, validity as
/// the source says: layer 0's invalid pixels are holes, the back layers' are "no point"), front to back: one
/// depth range for all ([`normalise_layers`]), order and gaps checked on the sources' own validity
/// ([`check_layer_order`], `names[k]` naming layer `k`), then layer 0's holes filled ([`fill_invalid`]).
/// Returns the LDI and the range used. The common part of [`load_ldi_dir`] and
/// [`super::ldi_from_camera_frames`].
///
/// Errors: as [`normalise_layers`], [`check_layer_order`], [`fill_invalid`] and [`LayeredDepthImage::new`].
pub(super) fn assemble_layers(
    amplitudes: Vec<Array3<f32>>,
    decoded: Vec<DecodedDepth>,
    names: &[String],
    range: Option<DepthRange>,
    mapping: DepthMapping,
) -> Result<(LayeredDepthImage, Option<DepthRange>)> {
    let (depths, range_used) = normalise_layers(&decoded, range, mapping)?;
    for k in 1..decoded.len() {
        check_layer_order(
            k,
            &[names[k - 1].clone(), names[k].clone()],
            [&depths[k - 1], &depths[k]],
            [&decoded[k - 1].valid, &decoded[k].valid],
        )?;
    }
    let mut layers = Vec::with_capacity(depths.len());
    for (k, ((amplitude, depth), dec)) in
        amplitudes.into_iter().zip(depths).zip(decoded).enumerate()
    {
        let (depth, valid) = if k == 0 {
            let filled = fill_invalid(&depth, &dec.valid)?;
            let all = Array2::from_elem(filled.raw_dim(), true);
            (filled, all)
        } else {
            (depth, dec.valid)
        };
        layers.push(LdiLayer {
            amplitude,
            depth,
            valid,
        });
    }
    Ok((LayeredDepthImage::new(layers)?, range_used))
}

/// Refuses layer `k` where it holds a point nearer than layer `k − 1` at the same pixel, or a point where
/// layer `k − 1` holds none, naming both layers (`names`: layer `k − 1`, then `k`), the number of pixels and
/// the first one (row, column).
pub(super) fn check_layer_order(
    k: usize,
    names: &[String; 2],
    [front, back]: [&Array2<f32>; 2],
    [front_valid, back_valid]: [&Array2<bool>; 2],
) -> Result<()> {
    let (mut nearer, mut gaps) = (Vec::new(), Vec::new());
    Zip::indexed(back)
        .and(back_valid)
        .and(front)
        .and(front_valid)
        .for_each(|(y, x), &d1, &v1, &d0, &v0| {
            if v1 && !v0 {
                gaps.push((y, x));
            } else if v1 && d1 < d0 {
                nearer.push((y, x));
            }
        });
    let name = |i: usize| &names[i + 1 - k];
    if let Some(&(y, x)) = nearer.first() {
        return Err(HoloError::InvalidDepth(format!(
            "LDI layer {k} ({}) is nearer than layer {} ({}) at {} pixels, the first at row {y}, column \
             {x}: layers go front to back, each one no nearer than the one before it",
            name(k),
            k - 1,
            name(k - 1),
            nearer.len()
        )));
    }
    if let Some(&(y, x)) = gaps.first() {
        return Err(HoloError::InvalidDepth(format!(
            "LDI layer {k} ({}) holds a point where layer {} ({}) holds none, at {} pixels, the first at \
             row {y}, column {x}: a depth-peeling pass never leaves a gap (move the point to the front layer)",
            name(k),
            k - 1,
            name(k - 1),
            gaps.len()
        )));
    }
    Ok(())
}

/// Writes `ldi` as an LDI folder (the layout [`load_ldi_dir`] reads): `rgb_K.png` (8-bit sRGB,
/// [`crate::color::amplitude_to_srgb8`]; black where layer `K` holds no point) and `depth_K.png` (16-bit
/// [`DepthEncoding::Relative16`]: `v = 1 + round(d · 65534)`, 0 where the layer holds no point), for every
/// layer. Returns the files written, front to back. Files of these names in `dir` are replaced; `dir` must
/// exist.
///
/// Errors: as [`crate::io::save_amplitude_png`] and [`crate::io::save_u16_png`] (e.g. [`HoloError::Image`]
/// naming a file that cannot be written).
pub fn write_ldi_dir(ldi: &LayeredDepthImage, dir: &Path) -> Result<Vec<LdiLayerFiles>> {
    let mut written = Vec::with_capacity(ldi.num_layers());
    for (k, layer) in ldi.layers().iter().enumerate() {
        let files = LdiLayerFiles {
            rgb: dir.join(format!("rgb_{k}.png")),
            depth: dir.join(format!("depth_{k}.png")),
        };
        let mut amplitude = layer.amplitude.clone();
        for mut plane in amplitude.outer_iter_mut() {
            plane.zip_mut_with(&layer.valid, |a, &ok| {
                if !ok {
                    *a = 0.0;
                }
            });
        }
        crate::io::save_amplitude_png(&files.rgb, amplitude.view(), 1.0)?;
        let samples = Zip::from(&layer.depth)
            .and(&layer.valid)
            .map_collect(|&d, &ok| if ok { relative16(d) } else { 0 });
        crate::io::save_u16_png(&files.depth, samples.view())?;
        written.push(files);
    }
    Ok(written)
}

/// The [`DepthEncoding::Relative16`] sample of a normalised depth `d ∈ [0, 1]` (clamped): `1 + round(d ·
/// 65534)`, never 0.
fn relative16(d: f32) -> u16 {
    1 + (d.clamp(0.0, 1.0) * 65534.0).round() as u16
}
