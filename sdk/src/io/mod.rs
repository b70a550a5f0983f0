//! File input/output: NumPy `.npy` arrays (complex fields, real maps) and 8-bit PNG images
//! (amplitude previews, SLM phase codes), plus a guard against overwriting input files.
//!
//! `.npy` files follow the NumPy format specification (version 1.0/2.0 headers, C order on write) and
//! are read and written through `ndarray-npy`; complex fields are stored as `complex64` (`'<c8'`),
//! the dtype `numpy.load` gives back as `np.complex64`. Every error names the file.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Component, Path, PathBuf};

use ndarray::{
    Array3, ArrayD, ArrayView, ArrayView2, ArrayView3, ArrayViewD, Axis, Dimension, Ix3,
};
use ndarray_npy::{ReadNpyError, ReadNpyExt, ViewNpyError, ViewNpyExt, WriteNpyExt};
use num_complex::{Complex32, Complex64};

use crate::color::amplitude_to_srgb8;
use crate::error::{invalid, HoloError, Result};

mod json;
mod output;
mod read;

#[cfg(feature = "research")]
pub(crate) use output::node_at;
pub use output::remove_output;

pub(crate) use json::parse_json_object;
pub use json::JsonError;
pub use read::{
    input_limits, read_bytes, read_text, set_input_limits, InputLimits, MAX_STREAM_BYTES,
    MAX_TEXT_BYTES,
};

/// Writes a complex field stack of shape `[C, H, W]` (channel order R, G, B for colour) to `path` as
/// a NumPy `.npy` file of dtype `complex64` (`'<c8'`, little-endian), C order, shape `(C, H, W)`:
/// `numpy.load(path)` returns it unchanged. Any memory layout of `field` is accepted.
///
/// # Errors
/// [`HoloError::Io`] if the file cannot be created or written, [`HoloError::Npy`] if the array
/// cannot be serialised; both carry `path`.
pub fn write_complex_npy(path: &Path, field: ArrayView3<Complex32>) -> Result<()> {
    write_npy_any(path, field)
}

/// Reads a NumPy `.npy` complex field from `path`: shape `[C, H, W]`, or `[H, W]` returned as
/// `[1, H, W]`. Accepts `complex64` (`c8`) and `complex128` (`c16`, converted to single precision),
/// either byte order, C or Fortran order; the result is in standard (C) layout.
///
/// # Errors
/// [`HoloError::Io`] if the file cannot be opened; [`HoloError::Npy`] naming `path` if it is not a
/// valid `.npy` file, its dtype is not complex64/complex128 (e.g. `'<f8'`), or its rank is not 2 or 3.
pub fn read_complex_npy(path: &Path) -> Result<Array3<Complex32>> {
    parse_complex_npy(&read_bytes(path)?, path)
}

/// Parses the bytes of a NumPy `.npy` complex field (the contents of a file, e.g. received over a network),
/// as [`read_complex_npy`]: shape `[C, H, W]`, or `[H, W]` returned as `[1, H, W]`; `complex64` or
/// `complex128`, either byte order, C or Fortran order. The header's shape is checked against the bytes
/// present before the array is allocated, so a short buffer declaring a huge shape is refused, not allocated.
/// `source` names the data in errors.
///
/// # Errors
/// [`HoloError::Npy`] naming `source`, as [`read_complex_npy`].
pub fn parse_complex_npy(bytes: &[u8], source: &Path) -> Result<Array3<Complex32>> {
    let any: ArrayD<Complex32> = match parse_npy::<Complex32>(bytes) {
        Ok(a) => a,
        Err(ReadNpyError::WrongDescriptor(_)) => match parse_npy::<Complex64>(bytes) {
            Ok(a) => a.mapv(|z| Complex32::new(z.re as f32, z.im as f32)),
            Err(ReadNpyError::WrongDescriptor(descr)) => {
                return Err(npy_error(
                    source,
                    format!(
                        "dtype {descr} is not a complex field: expected complex64 ('<c8') or \
                         complex128 ('<c16')"
                    ),
                ))
            }
            Err(e) => return Err(read_error(source, e)),
        },
        Err(e) => return Err(read_error(source, e)),
    };
    let shape = any.shape().to_vec();
    let any = match any.ndim() {
        2 => any.insert_axis(Axis(0)),
        3 => any,
        _ => {
            return Err(npy_error(
                source,
                format!(
                    "complex field has shape {shape:?}: expected rank 2 [H, W] or rank 3 [C, H, W]"
                ),
            ))
        }
    };
    let a = any
        .into_dimensionality::<Ix3>()
        .expect("rank checked above");
    Ok(if a.is_standard_layout() {
        a
    } else {
        a.as_standard_layout().into_owned()
    })
}

/// Writes a real `f32` array of any dimension (depth map `[H, W]`, amplitude stack `[C, H, W]`…) to
/// `path` as a NumPy `.npy` file of dtype `float32` (`'<f4'`), C order, same shape.
///
/// # Errors
/// [`HoloError::Io`] / [`HoloError::Npy`] carrying `path`, as [`write_complex_npy`].
pub fn write_f32_npy<D: Dimension>(path: &Path, a: ArrayView<f32, D>) -> Result<()> {
    write_npy_any(path, a)
}

/// Saves an amplitude image as an 8-bit sRGB PNG. `amplitude` is `[3, H, W]` (R, G, B → RGB PNG) or
/// `[1, H, W]` (→ greyscale PNG), with amplitude ≥ 0 and `1` = white (`docs/CONVENTIONS.md` §5.5: amplitude =
/// √linear intensity). Each value is multiplied by `scale`, then encoded by
/// [`crate::color::amplitude_to_srgb8`]: intensity `amplitude²`, clamped to `[0, 1]`, sRGB transfer
/// curve, rounded. Negative amplitudes and NaN are written as 0 (black). The file is written as PNG
/// whatever the extension of `path`.
///
/// # Errors
/// - [`HoloError::InvalidParameter`] (`scale`) if `scale` is negative or not finite;
/// - [`HoloError::ShapeMismatch`] if the channel count is neither 1 nor 3;
/// - [`HoloError::InvalidData`] if the image is empty or larger than PNG allows;
/// - [`HoloError::Image`] (with `path`) if encoding or writing fails.
pub fn save_amplitude_png(path: &Path, amplitude: ArrayView3<f32>, scale: f32) -> Result<()> {
    if !(scale.is_finite() && scale >= 0.0) {
        return Err(invalid(
            "scale",
            format!("must be finite and >= 0, got {scale}"),
        ));
    }
    let (c, h, w) = amplitude.dim();
    if c != 1 && c != 3 {
        return Err(HoloError::ShapeMismatch {
            what: "amplitude image channels (1 = grey or 3 = R, G, B)".into(),
            expected: vec![3, h, w],
            got: vec![c, h, w],
        });
    }
    let (w32, h32) = png_dims(w, h)?;
    let code = |a: f32| amplitude_to_srgb8((a * scale).max(0.0));
    // Interleave to row-major H, W, C bytes.
    let bytes: Vec<u8> = amplitude
        .permuted_axes([1, 2, 0])
        .iter()
        .map(|&a| code(a))
        .collect();
    let color = if c == 3 {
        image::ExtendedColorType::Rgb8
    } else {
        image::ExtendedColorType::L8
    };
    save_png(path, &bytes, w32, h32, color)
}

/// Saves one 8-bit plane `[H, W]` (e.g. SLM phase codes of one laser) as a greyscale 8-bit PNG, codes
/// unchanged. The file is written as PNG whatever the extension of `path`.
///
/// # Errors
/// [`HoloError::InvalidData`] if the plane is empty or too large for PNG; [`HoloError::Image`] (with
/// `path`) if encoding or writing fails.
pub fn save_u8_png(path: &Path, codes: ArrayView2<u8>) -> Result<()> {
    let (h, w) = codes.dim();
    let (w32, h32) = png_dims(w, h)?;
    let bytes: Vec<u8> = codes.iter().copied().collect();
    save_png(path, &bytes, w32, h32, image::ExtendedColorType::L8)
}

/// Saves one 16-bit plane `[H, W]` (e.g. a depth map in the `relative16` encoding) as a greyscale 16-bit
/// PNG, samples unchanged. The file is written as PNG whatever the extension of `path`.
///
/// # Errors
/// [`HoloError::InvalidData`] if the plane is empty or too large for PNG; [`HoloError::Image`] (with
/// `path`) if encoding or writing fails.
pub fn save_u16_png(path: &Path, samples: ArrayView2<u16>) -> Result<()> {
    let (h, w) = samples.dim();
    let (w32, h32) = png_dims(w, h)?;
    // The image crate takes 16-bit samples in native byte order.
    let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_ne_bytes()).collect();
    save_png(path, &bytes, w32, h32, image::ExtendedColorType::L16)
}

/// Refuses to let `output` be written over one of `inputs`. Paths are compared after resolving them:
/// a path that exists is canonicalised (symbolic links, `.`/`..`, relative spellings); a path that
/// does not exist yet is resolved through its nearest existing ancestor. On Unix two existing paths
/// that are hard links to the same file (same device and inode) also count as the same.
///
/// # Errors
/// [`HoloError::WouldOverwriteInput`] carrying `output` if it names the same file as an input.
pub fn ensure_not_input(output: &Path, inputs: &[&Path]) -> Result<()> {
    let out = resolve(output);
    for input in inputs {
        if resolve(input) == out || same_file(output, input) {
            return Err(HoloError::WouldOverwriteInput(output.to_path_buf()));
        }
    }
    Ok(())
}

/// Best-effort absolute, normalised form of `p`: canonicalise the longest existing prefix, then append
/// the rest with `.` dropped and `..` popped lexically. The form [`ensure_not_input`] compares; also what
/// `holo`'s output guard compares folders in (an output folder inside, equal to or holding an input).
pub fn resolve(p: &Path) -> PathBuf {
    if let Ok(c) = p.canonicalize() {
        return c;
    }
    let abs = if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir()
            .map(|d| d.join(p))
            .unwrap_or_else(|_| p.to_path_buf())
    };
    // Find the longest existing ancestor.
    let mut base = abs.as_path();
    let canon_base = loop {
        if let Ok(c) = base.canonicalize() {
            break c;
        }
        match base.parent() {
            Some(parent) => base = parent,
            None => break base.to_path_buf(),
        }
    };
    // Re-walk the non-existing tail lexically.
    let tail = abs.strip_prefix(base).unwrap_or(Path::new(""));
    let mut out = canon_base;
    for comp in tail.components() {
        match comp {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

#[cfg(unix)]
fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(ma), Ok(mb)) => ma.dev() == mb.dev() && ma.ino() == mb.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_a: &Path, _b: &Path) -> bool {
    false
}

fn npy_error(path: &Path, reason: impl Into<String>) -> HoloError {
    HoloError::Npy {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

fn read_error(path: &Path, e: ReadNpyError) -> HoloError {
    match e {
        ReadNpyError::Io(source) => HoloError::Io {
            path: path.to_path_buf(),
            source,
        },
        other => npy_error(path, other.to_string()),
    }
}

/// Parses `.npy` bytes whose declared shape is checked against the bytes present before the array is
/// allocated (`ndarray-npy`'s reader allocates by the declared shape first, so a 200-byte file declaring a huge
/// shape would abort): the bytes are viewed in place, which checks the header, the dtype and the data length;
/// only then is the array copied out.
pub(crate) fn parse_npy<T: ndarray_npy::ReadableElement + ndarray_npy::ViewElement + Clone>(
    bytes: &[u8],
) -> std::result::Result<ArrayD<T>, ReadNpyError> {
    check_npy_header_length(bytes)?;
    // Viewing needs the data aligned for `T`. The data of a `.npy` file starts at a multiple of 16 bytes, so
    // a buffer starting 16-aligned will do; a caller's buffer (a subslice, a fuzzer's input) need not be.
    let native = if (bytes.as_ptr() as usize).is_multiple_of(16) {
        ArrayViewD::<T>::view_npy(bytes).map(|view| view.to_owned())
    } else {
        let (copy, at) = aligned_copy(bytes);
        ArrayViewD::<T>::view_npy(&copy[at..]).map(|view| view.to_owned())
    };
    match native {
        Ok(array) => return Ok(array),
        Err(ViewNpyError::NonNativeEndian) => {}
        Err(e) => return Err(view_to_read_error(e)),
    }
    // The other byte order: check the length on a copy with the header's byte order flipped, then let
    // ndarray-npy convert the data from the original bytes.
    let (mut copy, at) = aligned_copy(bytes);
    flip_descr_byte_order(&mut copy[at..]).ok_or_else(|| {
        ReadNpyError::ParseData("cannot find the byte order of the dtype in the header".into())
    })?;
    let checked = ArrayViewD::<T>::view_npy(&copy[at..])
        .map(|_| ())
        .map_err(view_to_read_error);
    drop(copy);
    checked?;
    ArrayD::<T>::read_npy(bytes)
}

/// Refuses `.npy` bytes whose header length (a `u16` at byte 8 in format version 1, a `u32` in versions 2 and
/// 3) runs past their end: `ndarray-npy` allocates the declared length before reading the header, so 17 bytes
/// declaring a 4 GB header made it allocate 4 GB (found by the `npy` fuzz target). Anything else malformed is
/// left to `ndarray-npy`'s checks.
fn check_npy_header_length(bytes: &[u8]) -> std::result::Result<(), ReadNpyError> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Ok(());
    }
    let (start, len) = match bytes[6] {
        1 => (10, u16::from_le_bytes([bytes[8], bytes[9]]) as u64),
        2 | 3 if bytes.len() >= 12 => (
            12,
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as u64,
        ),
        _ => return Ok(()),
    };
    if start + len > bytes.len() as u64 {
        return Err(ReadNpyError::ParseData(
            format!(
                "the header declares {len} bytes, but the file holds {} after its {start}-byte preamble \
                 (truncated or corrupt)",
                bytes.len() - start as usize
            )
            .into(),
        ));
    }
    Ok(())
}

/// A copy of `bytes` in a new buffer, and the offset in it where the copy starts 16-byte aligned.
fn aligned_copy(bytes: &[u8]) -> (Vec<u8>, usize) {
    let mut storage = vec![0u8; bytes.len() + 16];
    let at = (16 - storage.as_ptr() as usize % 16) % 16;
    storage.truncate(at + bytes.len());
    storage[at..].copy_from_slice(bytes);
    (storage, at)
}

/// Flips `<` and `>` of the `'descr'` entry in a `.npy` header held in `bytes`; `None` if it has none.
fn flip_descr_byte_order(bytes: &mut [u8]) -> Option<()> {
    let key = b"'descr': '";
    let header = &bytes[..bytes.len().min(1 << 16)];
    let at = header.windows(key.len()).position(|w| w == key)? + key.len();
    let c = bytes.get_mut(at)?;
    *c = match *c {
        b'<' => b'>',
        b'>' => b'<',
        _ => return None,
    };
    Some(())
}

fn view_to_read_error(e: ViewNpyError) -> ReadNpyError {
    match e {
        ViewNpyError::Io(e) => ReadNpyError::Io(e),
        ViewNpyError::ParseHeader(e) => ReadNpyError::ParseHeader(e),
        ViewNpyError::InvalidData(e) => ReadNpyError::ParseData(e),
        ViewNpyError::LengthOverflow => ReadNpyError::LengthOverflow,
        ViewNpyError::WrongNdim(a, b) => ReadNpyError::WrongNdim(a, b),
        ViewNpyError::WrongDescriptor(d) => ReadNpyError::WrongDescriptor(d),
        ViewNpyError::MissingBytes(n) => ReadNpyError::ParseData(
            format!("the header's shape needs {n} more bytes of data than the file holds").into(),
        ),
        ViewNpyError::ExtraBytes(n) => ReadNpyError::ExtraBytes(n),
        other => ReadNpyError::ParseData(other.to_string().into()),
    }
}

/// Writes `a` in C order (copying if its layout is not standard) as `.npy`.
fn write_npy_any<T, D>(path: &Path, a: ArrayView<T, D>) -> Result<()>
where
    T: ndarray_npy::WritableElement + Clone,
    D: Dimension,
{
    let io_err = |source| HoloError::Io {
        path: path.to_path_buf(),
        source,
    };
    write_output(path, false, |writer| {
        a.as_standard_layout()
            .write_npy(writer)
            .map_err(|e| match e {
                ndarray_npy::WriteNpyError::Io(source) => io_err(source),
                other => npy_error(path, other.to_string()),
            })
    })
}

/// Writes the output `path` through `write(writer)`, by the rule of [`output::open_output`]: a regular file (or
/// nothing, or a link to neither a device nor a FIFO) is written to a temporary file in the same folder, renamed
/// over `path` once complete and removed on error, so that a failed or interrupted write (a full disk, Ctrl-C)
/// never leaves a truncated `path` and a symlink planted at `path` is replaced rather than followed; a character
/// device or a FIFO with a reader is written straight into; anything else is refused. `sync`: flush the
/// temporary file to disk before the rename. Errors name `path`.
pub(crate) fn write_output(
    path: &Path,
    sync: bool,
    write: impl FnOnce(&mut dyn Write) -> Result<()>,
) -> Result<()> {
    let io_err = |source| HoloError::Io {
        path: path.to_path_buf(),
        source,
    };
    match output::open_output(path)? {
        output::Target::Stream(node) => {
            let mut w = BufWriter::new(node);
            write(&mut w)?;
            w.flush().map_err(io_err)
        }
        output::Target::Replace => {
            let tmp = temporary_sibling(path);
            let result = (|| {
                let mut w = BufWriter::new(File::create(&tmp).map_err(io_err)?);
                write(&mut w)?;
                w.flush().map_err(io_err)?;
                if sync {
                    w.get_ref().sync_all().map_err(io_err)?;
                }
                drop(w);
                std::fs::rename(&tmp, path).map_err(io_err)
            })();
            if result.is_err() {
                let _ = std::fs::remove_file(&tmp);
            }
            result
        }
    }
}

/// PNG sizes are non-zero `u32`s.
fn png_dims(w: usize, h: usize) -> Result<(u32, u32)> {
    match (u32::try_from(w), u32::try_from(h)) {
        (Ok(w32), Ok(h32)) if w32 > 0 && h32 > 0 => Ok((w32, h32)),
        _ => Err(HoloError::InvalidData(format!(
            "cannot write a {h}x{w} image as PNG (each side must be 1..=2^32-1 pixels)"
        ))),
    }
}

/// Encodes 8- or 16-bit (native byte order) samples as PNG into the output `path` ([`write_output`]).
pub(crate) fn save_png(
    path: &Path,
    bytes: &[u8],
    w: u32,
    h: u32,
    color: image::ExtendedColorType,
) -> Result<()> {
    use image::ImageEncoder;
    write_output(path, false, |writer| {
        image::codecs::png::PngEncoder::new(writer)
            .write_image(bytes, w, h, color)
            .map_err(|source| HoloError::Image {
                path: path.to_path_buf(),
                source,
            })
    })
    .map_err(|e| match e {
        // The file's own errors (create, write, rename) as the image's, as documented.
        HoloError::Io { path, source } => HoloError::Image {
            path,
            source: image::ImageError::IoError(source),
        },
        other => other,
    })
}

/// Decodes an image file's bytes with the `image` crate (format guessed from the content), naming `path` in
/// the error ([`HoloError::Image`]). The size is read from the header first: an image above
/// [`InputLimits::max_image_pixels`] is refused before it is decoded ([`HoloError::InvalidData`] naming the
/// limit), and the decoder may allocate no more than that size needs. JPEGs are decoded strictly
/// ([`decode_jpeg_strict`]).
pub(crate) fn decode_image(path: &Path, bytes: &[u8]) -> Result<image::DynamicImage> {
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|source| HoloError::Io {
                path: path.to_path_buf(),
                source,
            })
    };
    let image_error = |source| HoloError::Image {
        path: path.to_path_buf(),
        source,
    };
    if reader()?.format() == Some(image::ImageFormat::Jpeg) {
        return decode_jpeg_strict(path, bytes);
    }
    let (w, h) = reader()?.into_dimensions().map_err(image_error)?;
    let pixels = check_image_pixels(path, w as u64, h as u64)?;
    let mut limits = image::Limits::default();
    // 16-bit RGBA is 8 bytes a pixel; a decoder's own buffers fit in twice that.
    limits.max_alloc = Some(pixels.saturating_mul(16).max(1 << 20));
    let mut r = reader()?;
    r.limits(limits);
    r.decode().map_err(image_error)
}

/// The pixel count `w·h` of an image whose header says `w × h`, if within [`InputLimits::max_image_pixels`].
pub(crate) fn check_image_pixels(path: &Path, w: u64, h: u64) -> Result<u64> {
    let pixels = w.saturating_mul(h);
    let max = input_limits().max_image_pixels;
    if pixels > max {
        return Err(HoloError::InvalidData(format!(
            "`{}` is {w}×{h} = {pixels} pixels, above the input limit of {max} (raise it with \
             --max-image-pixels or tensorholo::io::set_input_limits)",
            path.display()
        )));
    }
    Ok(pixels)
}

/// Decodes a JPEG in strict mode: `image` runs zune-jpeg leniently, which completes a truncated or corrupt
/// entropy-coded stream with grey instead of failing. Output: 8-bit grey (grey JPEGs) or RGB(A).
fn decode_jpeg_strict(path: &Path, bytes: &[u8]) -> Result<image::DynamicImage> {
    use zune_core::colorspace::ColorSpace;
    let fail = |reason: String| HoloError::InvalidData(format!("`{}`: {reason}", path.display()));
    let options = zune_core::options::DecoderOptions::default()
        .set_strict_mode(true)
        .set_max_width(usize::MAX)
        .set_max_height(usize::MAX);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(
        zune_core::bytestream::ZCursor::new(bytes),
        options,
    );
    decoder
        .decode_headers()
        .map_err(|e| fail(format!("corrupt JPEG header ({e:?})")))?;
    // The size from the header, before the decoder allocates the image.
    let (w, h) = decoder
        .dimensions()
        .ok_or_else(|| fail("JPEG without dimensions".into()))?;
    check_image_pixels(path, w as u64, h as u64)?;
    let input = decoder.input_colorspace().unwrap_or(ColorSpace::RGB);
    let out = match input {
        ColorSpace::Luma | ColorSpace::LumaA | ColorSpace::RGB | ColorSpace::RGBA => input,
        _ => ColorSpace::RGB,
    };
    decoder.set_options(decoder.options().jpeg_set_out_colorspace(out));
    let data = decoder.decode().map_err(|e| {
        fail(format!(
            "corrupt or truncated JPEG data ({e:?}); refusing to complete the image with grey"
        ))
    })?;
    let (w, h) = (w as u32, h as u32);
    let short = || fail("the JPEG decoder returned fewer samples than the image has".into());
    match decoder.output_colorspace().unwrap_or(out) {
        ColorSpace::Luma => {
            image::GrayImage::from_raw(w, h, data).map(image::DynamicImage::ImageLuma8)
        }
        ColorSpace::LumaA => {
            image::GrayAlphaImage::from_raw(w, h, data).map(image::DynamicImage::ImageLumaA8)
        }
        ColorSpace::RGBA => {
            image::RgbaImage::from_raw(w, h, data).map(image::DynamicImage::ImageRgba8)
        }
        _ => image::RgbImage::from_raw(w, h, data).map(image::DynamicImage::ImageRgb8),
    }
    .ok_or_else(short)
}

/// A temporary file name beside an output (`.<name>.tmp-<pid>-<n>` in the same folder), for write-then-rename.
/// While it lives it is listed for [`remove_temporary_files`], so that a program interrupted mid-write (Ctrl-C)
/// can remove what it was writing.
pub(crate) struct Temporary(PathBuf);

static TEMPORARIES: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

impl std::ops::Deref for Temporary {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Temporary {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Temporary {
    fn drop(&mut self) {
        let mut list = TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(i) = list.iter().position(|p| *p == self.0) {
            list.swap_remove(i);
        }
    }
}

/// A [`Temporary`] name beside `path`.
pub(crate) fn temporary_sibling(path: &Path) -> Temporary {
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.tmp-{}-{n}", std::process::id()));
    TEMPORARIES
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(tmp.clone());
    Temporary(tmp)
}

/// Removes the temporary files of the writes in progress (every output is written to a temporary name and
/// renamed when complete), returning how many there were. For a program's interrupt handler (the `holo` CLI
/// calls it on Ctrl-C before exiting), so that an interrupted run leaves no temporary files; the outputs
/// already complete keep their final names, and none is ever left truncated.
///
/// Errors: none (a file that cannot be removed is skipped).
pub fn remove_temporary_files() -> usize {
    let list = TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner());
    for p in list.iter() {
        let _ = std::fs::remove_file(p);
    }
    list.len()
}

/// Writes `bytes` to `path` atomically: to a temporary file in the same folder, flushed to disk, then renamed
/// over `path`, so that a reader (or a crash) sees the old file or the new one, never a partial one. What is at
/// `path` is looked at first (docs/INPUTS.md, "Outputs"): a symbolic link is replaced, not followed; a
/// character device or a FIFO with a reader (itself or at the end of links, e.g. `/dev/null`, `/dev/stdout`)
/// is written straight into, never renamed over nor removed.
///
/// # Errors
/// [`HoloError::Io`] naming `path` (the temporary file is removed on failure); [`HoloError::InvalidData`]
/// naming it and what it is for a FIFO with no reader (refused, never waited on), a block device, a socket or
/// a folder.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_output(path, true, |w| {
        w.write_all(bytes).map_err(|source| HoloError::Io {
            path: path.to_path_buf(),
            source,
        })
    })
}

/// Writes a little-endian float32 `.npy` file of `shape` whose C-order data `fill` produces chunk by chunk
/// (`fill(start, buffer)` writes elements `start..start + buffer.len()`), so that arrays larger than memory
/// can be written. The file appears atomically (temporary name, then renamed); a character device or a FIFO
/// with a reader is written straight into, as by [`write_atomic`].
///
/// # Errors
/// [`HoloError::Io`] naming `path`; whatever `fill` returns.
pub fn write_f32_npy_streaming(
    path: &Path,
    shape: &[usize],
    chunk: usize,
    mut fill: impl FnMut(usize, &mut [f32]) -> Result<()>,
) -> Result<()> {
    let total = shape
        .iter()
        .try_fold(1usize, |a, &b| a.checked_mul(b))
        .ok_or_else(|| invalid("shape", format!("{shape:?} overflows")))?;
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let tuple = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut header =
        format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {tuple}, }}").into_bytes();
    // Magic (6) + version (2) + length (2) + header, padded with spaces to a multiple of 64, newline last.
    let pad = (64 - (10 + header.len() + 1) % 64) % 64;
    header.extend(std::iter::repeat_n(b' ', pad));
    header.push(b'\n');
    let io_err = |source| HoloError::Io {
        path: path.to_path_buf(),
        source,
    };
    write_output(path, true, |w| {
        w.write_all(b"\x93NUMPY\x01\x00").map_err(io_err)?;
        w.write_all(&(header.len() as u16).to_le_bytes())
            .map_err(io_err)?;
        w.write_all(&header).map_err(io_err)?;
        let mut buf = vec![0f32; chunk.max(1).min(total.max(1))];
        let mut start = 0;
        while start < total {
            let n = buf.len().min(total - start);
            fill(start, &mut buf[..n])?;
            for v in &buf[..n] {
                w.write_all(&v.to_le_bytes()).map_err(io_err)?;
            }
            start += n;
        }
        Ok(())
    })
}

/// Serde helpers that write paths as text, lossily: a name that is not UTF-8 is written with U+FFFD where its
/// bytes are not text, instead of failing (serde's own `Path` serialisation refuses such a name). For report
/// and manifest fields (`#[serde(serialize_with = "...")]`); reading them back gives the lossy text as a path.
pub mod lossy_path {
    use std::path::Path;
    #[cfg(feature = "research")]
    use std::path::PathBuf;

    use serde::Serializer;

    /// One path.
    pub(crate) fn serialize<S: Serializer>(
        path: &Path,
        s: S,
    ) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(&path.to_string_lossy())
    }

    #[cfg(feature = "research")]
    /// An optional path (`null` when absent).
    pub(crate) fn option<S: Serializer>(
        path: &Option<PathBuf>,
        s: S,
    ) -> std::result::Result<S::Ok, S::Error> {
        match path {
            Some(p) => s.serialize_some(&p.to_string_lossy()),
            None => s.serialize_none(),
        }
    }

    #[cfg(feature = "research")]
    /// A list of paths.
    pub(crate) fn list<S: Serializer>(
        paths: &[PathBuf],
        s: S,
    ) -> std::result::Result<S::Ok, S::Error> {
        s.collect_seq(paths.iter().map(|p| p.to_string_lossy()))
    }
}
