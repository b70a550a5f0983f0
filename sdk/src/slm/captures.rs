//! Camera captures for the display calibration: PNG files (8/16-bit, grey or RGB) decoded row by row and
//! box-downsampled to the SLM's resolution on the fly, so that memory stays bounded by one row of the capture
//! and one SLM-sized frame, whatever the camera's resolution.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use super::calibrate::CaptureStack;
use super::lut::CODES;
use crate::error::{invalid, HoloError, Result};

/// Largest capture accepted, in pixels (a 24-megapixel camera has 24e6; 400 MP leaves room).
pub const MAX_CAPTURE_PIXELS: u64 = 400_000_000;

/// A rectangle of the capture in camera pixels: the SLM's image (`x`, `y` of the top-left corner, `width`,
/// `height`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Crop {
    /// Left column.
    pub x: usize,
    /// Top row.
    pub y: usize,
    /// Width in camera pixels.
    pub width: usize,
    /// Height in camera pixels.
    pub height: usize,
}

impl std::str::FromStr for Crop {
    type Err = HoloError;
    /// Parses `x,y,w,h`.
    fn from_str(s: &str) -> Result<Self> {
        let v: Vec<usize> = s
            .split(',')
            .map(|p| p.trim().parse::<usize>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| invalid("crop", format!("`{s}` is not x,y,width,height in pixels")))?;
        match v[..] {
            [x, y, width, height] if width > 0 && height > 0 => Ok(Self {
                x,
                y,
                width,
                height,
            }),
            _ => Err(invalid(
                "crop",
                format!("`{s}` is not x,y,width,height with width, height ≥ 1"),
            )),
        }
    }
}

/// Maps capture pixels of a crop onto SLM pixels by box averaging: capture column `x` (inside the crop) goes to
/// SLM column `⌊(x − crop.x)·W/crop.width⌋`, likewise for rows.
#[derive(Debug, Clone)]
struct Binning {
    crop: Crop,
    col_bin: Vec<u32>,
    row_bin: Vec<u32>,
    counts: Vec<f32>,
}

impl Binning {
    fn new(crop: Crop, slm: (usize, usize)) -> Self {
        let (h, w) = slm;
        let col_bin: Vec<u32> = (0..crop.width)
            .map(|x| (x * w / crop.width) as u32)
            .collect();
        let row_bin: Vec<u32> = (0..crop.height)
            .map(|y| (y * h / crop.height) as u32)
            .collect();
        let mut cw = vec![0f32; w];
        let mut ch = vec![0f32; h];
        for &c in &col_bin {
            cw[c as usize] += 1.0;
        }
        for &r in &row_bin {
            ch[r as usize] += 1.0;
        }
        let counts = ch
            .iter()
            .flat_map(|a| cw.iter().map(move |b| a * b))
            .collect();
        Self {
            crop,
            col_bin,
            row_bin,
            counts,
        }
    }
}

/// Reads a PNG capture (8- or 16-bit, grey, grey + alpha, RGB or RGBA, palette expanded; colour is averaged to
/// one intensity) and box-downsamples the crop (`None`: the whole image) to `slm = (height, width)`, row by
/// row. `out` gets intensities in units of full scale `[0, 1]`, `clipped` is set where any contributing camera
/// pixel is at full scale. Returns the capture's size `(height, width)`.
///
/// Errors: [`HoloError::Io`] / [`HoloError::Image`] naming `path` for a missing, unreadable, truncated or
/// corrupt file; [`HoloError::InvalidData`] naming it for a capture above [`MAX_CAPTURE_PIXELS`], a crop
/// outside it, or a crop smaller than the SLM (the camera must resolve every SLM pixel).
pub fn read_png_downsampled(
    path: &Path,
    slm: (usize, usize),
    crop: Option<Crop>,
    out: &mut [f32],
    clipped: &mut [bool],
) -> Result<(usize, usize)> {
    let (ch, cw) = png_size(path)?;
    let binning = binning_for(path, (ch, cw), slm, crop)?;
    read_binned(path, &binning, slm, out, clipped)?;
    Ok((ch, cw))
}

fn open(path: &Path) -> Result<BufReader<File>> {
    File::open(path)
        .map(BufReader::new)
        .map_err(|source| HoloError::Io {
            path: path.to_path_buf(),
            source,
        })
}

fn png_error(path: &Path, e: png::DecodingError) -> HoloError {
    match e {
        png::DecodingError::IoError(source) => HoloError::Io {
            path: path.to_path_buf(),
            source,
        },
        other => HoloError::InvalidData(format!(
            "capture `{}` is not a readable PNG: {other}",
            path.display()
        )),
    }
}

/// A PNG's `(height, width)` from its header alone.
///
/// Errors: as [`read_png_downsampled`].
pub(crate) fn png_size(path: &Path) -> Result<(usize, usize)> {
    let decoder = png::Decoder::new(open(path)?);
    let reader = decoder.read_info().map_err(|e| png_error(path, e))?;
    let info = reader.info();
    let (w, h) = (info.width as u64, info.height as u64);
    check_pixels(path, w, h)?;
    Ok((h as usize, w as usize))
}

/// Refuses a capture of `width × height` above [`MAX_CAPTURE_PIXELS`], naming `path`.
fn check_pixels(path: &Path, width: u64, height: u64) -> Result<()> {
    if width * height > MAX_CAPTURE_PIXELS {
        return Err(HoloError::InvalidData(format!(
            "capture `{}` is {width}×{height} pixels; at most {MAX_CAPTURE_PIXELS} pixels are accepted",
            path.display()
        )));
    }
    Ok(())
}

fn binning_for(
    path: &Path,
    size: (usize, usize),
    slm: (usize, usize),
    crop: Option<Crop>,
) -> Result<Binning> {
    let (ch, cw) = size;
    let crop = crop.unwrap_or(Crop {
        x: 0,
        y: 0,
        width: cw,
        height: ch,
    });
    if crop.x + crop.width > cw || crop.y + crop.height > ch {
        return Err(HoloError::InvalidData(format!(
            "crop {},{},{},{} lies outside capture `{}` ({cw}×{ch})",
            crop.x,
            crop.y,
            crop.width,
            crop.height,
            path.display()
        )));
    }
    if crop.width < slm.1 || crop.height < slm.0 {
        return Err(HoloError::InvalidData(format!(
            "capture `{}`: the SLM's image is {}×{} camera pixels, smaller than the {}×{} SLM; the camera must \
             resolve every SLM pixel (use a capture at least the SLM's resolution, or a larger --crop)",
            path.display(),
            crop.width,
            crop.height,
            slm.1,
            slm.0
        )));
    }
    Ok(Binning::new(crop, slm))
}

fn read_binned(
    path: &Path,
    binning: &Binning,
    slm: (usize, usize),
    out: &mut [f32],
    clipped: &mut [bool],
) -> Result<()> {
    let (h, w) = slm;
    if out.len() != h * w || clipped.len() != h * w {
        return Err(HoloError::ShapeMismatch {
            what: "capture buffers vs the SLM".into(),
            expected: vec![h, w],
            got: vec![out.len(), clipped.len()],
        });
    }
    out.fill(0.0);
    clipped.fill(false);
    let crop = binning.crop;
    for_each_row(path, crop.x..crop.x + crop.width, |y, values, full| {
        if y >= crop.y && y < crop.y + crop.height {
            let r = binning.row_bin[y - crop.y] as usize;
            let dst = &mut out[r * w..(r + 1) * w];
            let dst_clip = &mut clipped[r * w..(r + 1) * w];
            for ((&bin, &v), &f) in binning.col_bin.iter().zip(values).zip(full) {
                dst[bin as usize] += v;
                dst_clip[bin as usize] |= f;
            }
        }
        Ok(())
    })?;
    for (v, c) in out.iter_mut().zip(&binning.counts) {
        *v /= c;
    }
    Ok(())
}

/// Decodes the PNG capture at `path` row by row (8- or 16-bit, grey, grey + alpha, RGB or RGBA, palette
/// expanded; colour averaged to one intensity) and calls `f(y, values, full)` for every row `y` with the
/// columns `cols` of it: `values` in units of full scale `[0, 1]`, `full[i]` where any colour channel of the
/// pixel is at full scale. Memory: one decoded row and one row of `cols`, whatever the capture's size.
///
/// Errors: as [`read_png_downsampled`]; `cols` beyond the capture's width; an interlaced PNG; whatever `f`
/// returns (which stops the decoding).
pub(crate) fn for_each_row(
    path: &Path,
    cols: std::ops::Range<usize>,
    mut f: impl FnMut(usize, &[f32], &[bool]) -> Result<()>,
) -> Result<()> {
    let mut decoder = png::Decoder::new(open(path)?);
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info().map_err(|e| png_error(path, e))?;
    let (width, height) = (reader.info().width as u64, reader.info().height as u64);
    check_pixels(path, width, height)?;
    if cols.end as u64 > width || cols.start > cols.end {
        return Err(HoloError::InvalidData(format!(
            "capture `{}` is {width} pixels wide: columns {}–{} lie outside it",
            path.display(),
            cols.start,
            cols.end
        )));
    }
    if reader.info().interlaced {
        return Err(HoloError::InvalidData(format!(
            "capture `{}` is an interlaced PNG; save captures without interlacing",
            path.display()
        )));
    }
    let (color, depth) = reader.output_color_type();
    let samples = color.samples();
    let colour_channels = match color {
        png::ColorType::Grayscale | png::ColorType::GrayscaleAlpha => 1,
        _ => 3,
    };
    let sixteen = depth == png::BitDepth::Sixteen;
    let full = if sixteen { 65535.0 } else { 255.0 };
    let mut values = vec![0f32; cols.len()];
    let mut at_full = vec![false; cols.len()];
    let mut y = 0usize;
    while let Some(row) = reader.next_row().map_err(|e| png_error(path, e))? {
        let data = row.data();
        for (i, (v, f)) in values.iter_mut().zip(&mut at_full).enumerate() {
            let px = (cols.start + i) * samples;
            let mut sum = 0f32;
            let mut top = false;
            for c in 0..colour_channels {
                let x = if sixteen {
                    u16::from_be_bytes([data[2 * (px + c)], data[2 * (px + c) + 1]]) as f32
                } else {
                    data[px + c] as f32
                };
                top |= x >= full;
                sum += x;
            }
            *v = sum / (colour_channels as f32 * full);
            *f = top;
        }
        f(y, &values, &at_full)?;
        y += 1;
    }
    Ok(())
}

/// Checks that the capture `path` is a regular file (or a link to one): "missing" only where nothing is
/// there. Errors: [`HoloError::InvalidData`] naming the path and `what` (e.g. `capture`, with the plan's
/// context): missing, a folder, or another kind of file (a device, a pipe).
pub(crate) fn check_capture_file(path: &Path, what: &str) -> Result<()> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => Ok(()),
        Ok(m) if m.is_dir() => Err(HoloError::InvalidData(format!(
            "{what} `{}` is a folder, not a PNG file",
            path.display()
        ))),
        Ok(_) => Err(HoloError::InvalidData(format!(
            "{what} `{}` is not a regular file (a device, a pipe or a socket): give the PNG itself",
            path.display()
        ))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(HoloError::InvalidData(format!(
            "missing {what} `{}`",
            path.display()
        ))),
        Err(source) => Err(HoloError::Io {
            path: path.to_path_buf(),
            source,
        }),
    }
}

/// The 256 captures `capture_000.png` … `capture_255.png` of one colour in a folder, read on demand.
#[derive(Debug, Clone)]
pub struct PngCaptureDir {
    paths: Vec<PathBuf>,
    slm: (usize, usize),
    binning: Binning,
}

/// File name of capture `k`.
pub fn capture_name(k: usize) -> String {
    format!("capture_{k:03}.png")
}

impl PngCaptureDir {
    /// Checks the folder: all 256 captures present, every header readable and of the same size, large enough
    /// for the SLM (after the optional crop). Reads headers only.
    ///
    /// Errors: [`HoloError::InvalidData`] naming the folder and the missing captures (first one and count),
    /// or naming the capture whose size differs from `capture_000.png`'s (both sizes); as
    /// [`read_png_downsampled`] for unreadable headers, a bad crop or a capture smaller than the SLM.
    pub fn open(dir: &Path, slm: (usize, usize), crop: Option<Crop>) -> Result<Self> {
        if slm.0 == 0 || slm.1 == 0 {
            return Err(invalid(
                "size",
                format!("SLM size must be ≥ 1×1, got {}×{}", slm.0, slm.1),
            ));
        }
        if !dir.is_dir() {
            return Err(HoloError::InvalidData(format!(
                "capture folder `{}` does not exist or is not a folder",
                dir.display()
            )));
        }
        let paths: Vec<PathBuf> = (0..CODES).map(|k| dir.join(capture_name(k))).collect();
        let missing: Vec<usize> = (0..CODES).filter(|&k| !paths[k].exists()).collect();
        if let Some(&first) = missing.first() {
            return Err(HoloError::InvalidData(format!(
                "capture folder `{}` lacks {} of the 256 captures (first missing: {}); every code 0–255 needs \
                 its capture",
                dir.display(),
                missing.len(),
                capture_name(first)
            )));
        }
        for p in &paths {
            check_capture_file(p, "capture")?;
        }
        let size = png_size(&paths[0])?;
        for p in &paths[1..] {
            let s = png_size(p)?;
            if s != size {
                return Err(HoloError::InvalidData(format!(
                    "capture `{}` is {}×{} but {} is {}×{}: all captures must have one size",
                    p.display(),
                    s.1,
                    s.0,
                    capture_name(0),
                    size.1,
                    size.0
                )));
            }
        }
        let binning = binning_for(&paths[0], size, slm, crop)?;
        Ok(Self {
            paths,
            slm,
            binning,
        })
    }
}

impl CaptureStack for PngCaptureDir {
    fn slm_size(&self) -> (usize, usize) {
        self.slm
    }

    fn name(&self, k: usize) -> String {
        self.paths[k].display().to_string()
    }

    fn read(&self, k: usize, out: &mut [f32], clipped: &mut [bool]) -> Result<()> {
        read_binned(&self.paths[k], &self.binning, self.slm, out, clipped)
    }
}

/// Box-downsamples an in-memory capture `[ch, cw]` (intensities in `[0, 1]`) to the SLM exactly as the PNG
/// reader does; `clipped` is set where a contributing value is ≥ 1.
///
/// Errors: [`HoloError::InvalidData`] for a capture smaller than the SLM; [`HoloError::ShapeMismatch`] for
/// buffers of the wrong length.
pub fn downsample(
    capture: ndarray::ArrayView2<f32>,
    slm: (usize, usize),
    out: &mut [f32],
    clipped: &mut [bool],
) -> Result<()> {
    let (ch, cw) = capture.dim();
    let binning = binning_for(Path::new("<memory>"), (ch, cw), slm, None)?;
    let w = slm.1;
    if out.len() != slm.0 * w || clipped.len() != slm.0 * w {
        return Err(HoloError::ShapeMismatch {
            what: "capture buffers vs the SLM".into(),
            expected: vec![slm.0, slm.1],
            got: vec![out.len(), clipped.len()],
        });
    }
    out.fill(0.0);
    clipped.fill(false);
    for (y, row) in capture.rows().into_iter().enumerate() {
        let r = binning.row_bin[y] as usize;
        for (x, &v) in row.iter().enumerate() {
            let i = r * w + binning.col_bin[x] as usize;
            out[i] += v;
            clipped[i] |= v >= 1.0;
        }
    }
    for (v, c) in out.iter_mut().zip(&binning.counts) {
        *v /= c;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 256 captures of 6×4 pixels, code `k` at grey level `k`.
    fn captures(dir: &Path) {
        for k in 0..CODES {
            image::GrayImage::from_pixel(6, 4, image::Luma([k as u8]))
                .save(dir.join(capture_name(k)))
                .unwrap();
        }
    }

    #[test]
    fn a_capture_folder_names_what_is_missing_and_what_is_not_a_file() {
        let dir = tempfile::tempdir().unwrap();
        captures(dir.path());
        let c = PngCaptureDir::open(dir.path(), (2, 3), None).unwrap();
        let (mut out, mut clipped) = (vec![0f32; 6], vec![false; 6]);
        c.read(255, &mut out, &mut clipped).unwrap();
        assert!(out.iter().all(|&v| v == 1.0) && clipped.iter().all(|&b| b));
        c.read(51, &mut out, &mut clipped).unwrap();
        assert!(out.iter().all(|&v| v == 51.0 / 255.0) && !clipped.iter().any(|&b| b));
        let path = dir.path().join(capture_name(7));
        std::fs::remove_file(&path).unwrap();
        let e = PngCaptureDir::open(dir.path(), (2, 3), None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("lacks 1 of the 256") && e.contains("capture_007.png"),
            "{e}"
        );
        std::fs::create_dir(&path).unwrap();
        let e = PngCaptureDir::open(dir.path(), (2, 3), None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("capture_007.png") && e.contains("is a folder"),
            "{e}"
        );
        std::fs::remove_dir(&path).unwrap();
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink("/dev/null", &path).unwrap();
            let e = PngCaptureDir::open(dir.path(), (2, 3), None)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("capture_007.png") && e.contains("not a regular file"),
                "{e}"
            );
        }
        let e = PngCaptureDir::open(&dir.path().join("none"), (2, 3), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("does not exist or is not a folder"), "{e}");
    }

    #[test]
    fn rows_average_the_colours_and_flag_full_scale() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rgb16.png");
        let img = image::ImageBuffer::<image::Rgb<u16>, _>::from_fn(5, 3, |x, y| {
            image::Rgb([(1000 * x + 7 * y) as u16, 65535, 300 * y as u16])
        });
        img.save(&path).unwrap();
        let mut rows = Vec::new();
        for_each_row(&path, 1..4, |y, v, f| {
            rows.push((y, v.to_vec(), f.to_vec()));
            Ok(())
        })
        .unwrap();
        assert_eq!(rows.len(), 3);
        for (y, v, f) in rows {
            for (i, (&got, &full)) in v.iter().zip(&f).enumerate() {
                let x = i + 1;
                let want =
                    ((1000 * x + 7 * y) as f32 + 65535.0 + (300 * y) as f32) / (3.0 * 65535.0);
                assert_eq!(got, want, "row {y} column {x}");
                assert!(full, "the green channel is at full scale");
            }
        }
        let e = for_each_row(&path, 3..6, |_, _, _| Ok(()))
            .unwrap_err()
            .to_string();
        assert!(e.contains("5 pixels wide"), "{e}");
    }
}
