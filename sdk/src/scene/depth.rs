//! Depth decoders for the sensor and file formats of `docs/CONVENTIONS.md` §6, the mapping from metric depth
//! to TensorHolo's normalised depth `d ∈ [0,1]` (0 = near, `docs/CONVENTIONS.md` §4), and the invalid-pixel
//! fill policy.
//!
//! The steps are separate and individually testable:
//! 1. [`decode_depth_file`] / [`decode_depth`]: file samples → [`DecodedDepth`] (metres or relative, plus a
//!    validity mask), one formula per [`DepthEncoding`];
//! 2. [`normalise_depth`]: metres → `d` with an explicit [`DepthRange`] and [`DepthMapping`];
//! 3. [`fill_invalid`]: holes take the farthest neighbouring valid depth, before any resizing.

use std::fmt;
use std::path::Path;
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};

use image::DynamicImage;
use ndarray::{Array2, Zip};
use serde::Serialize;

use crate::error::{invalid, HoloError, Result};

/// How depth is stored in a file. Each variant is one row of the encoding table in
/// `docs/CONVENTIONS.md` §6; its kebab-case name (see `DepthEncoding::name`, [`fmt::Display`] and
/// [`FromStr`]) is what the CLI accepts.
///
/// | variant | name | bits | to metres / relative | invalid |
/// |---|---|---|---|---|
/// | [`Millimetres16`](Self::Millimetres16) | `mm16` | 16 | `v/1000` m | `v = 0` |
/// | [`Tum5000`](Self::Tum5000) | `tum` | 16 | `v/5000` m | `v = 0` |
/// | [`SunRotated`](Self::SunRotated) | `sun` | 16 | `(((v>>3)\|(v<<13)) & 0xFFFF)/1000` m | `v = 0` |
/// | [`KinectDisparity`](Self::KinectDisparity) | `kinect-disparity` | 16 | `351.3/(1092.5 − v)` m | `v ≥ 1092` |
/// | [`IphoneDisparity`](Self::IphoneDisparity) | `iphone-disparity` | 8 | `1/(0.650879 + v/255·1.858887)` m | none |
/// | [`RelativeNearBright`](Self::RelativeNearBright) | `relative-near-bright` | 8 | `d = 1 − v/255` | `v = 0` |
/// | [`RelativeNearDark`](Self::RelativeNearDark) | `relative-near-dark` | 8 | `d = v/255` | none |
/// | [`Relative16`](Self::Relative16) | `relative16` | 16 | `d = (v − 1)/65534` | `v = 0` |
/// | [`Metres`](Self::Metres) | `metres` | float (OpenEXR) | `v` m | `v ≤ 0`, NaN, ∞ |
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum DepthEncoding {
    /// `mm16`: 16-bit z-depth in millimetres, `z = v/1000` m, `v = 0` invalid (Redwood, `nyu/derived`,
    /// `sun/derived`).
    #[serde(rename = "mm16")]
    Millimetres16,
    /// `tum`: 16-bit z-depth in units of 0.2 mm (TUM RGB-D), `z = v/5000` m, `v = 0` invalid.
    #[serde(rename = "tum")]
    Tum5000,
    /// `sun`: SUN RGB-D raw depth, 16-bit millimetres with the bits rotated left by 3 on disk:
    /// `z = (((v>>3) | (v<<13)) & 0xFFFF)/1000` m, `v = 0` invalid.
    #[serde(rename = "sun")]
    SunRotated,
    /// `kinect-disparity`: NYU Depth v2 raw Kinect v1 disparity (11-bit values in a 16-bit file),
    /// `z = 351.3/(1092.5 − v)` m, `v ≥ 1092` invalid (2047 = no reading). NYU's `.pgm` files are stored
    /// little-endian despite the PGM specification; [`decode_depth_file`] detects the byte order.
    /// Under this formula a larger raw value is *farther* (checked against `nyu/derived`).
    #[serde(rename = "kinect-disparity")]
    KinectDisparity,
    /// `iphone-disparity`: 8-bit normalised disparity from an iPhone (dual camera / portrait matte),
    /// `z = 1/(0.650879 + v/255·1.858887)` m (0.398–1.536 m); no invalid value. Larger = nearer.
    #[serde(rename = "iphone-disparity")]
    IphoneDisparity,
    /// `relative-near-bright`: 8-bit relative depth, larger = nearer, `v = 0` = empty/invalid (odak
    /// renders); decoded to the relative `d = 1 − v/255` (0 = near), unitless.
    #[serde(rename = "relative-near-bright")]
    RelativeNearBright,
    /// `relative-near-dark`: 8-bit relative depth, larger = farther, TensorHolo's own convention
    /// `d = v/255` (0 = near), unitless; no invalid value.
    #[serde(rename = "relative-near-dark")]
    RelativeNearDark,
    /// `relative16`: 16-bit relative depth, larger = farther, `d = (v − 1)/65534` (0 = near), `v = 0` = no
    /// point here; unitless. The exchange format of layered depth images (`holo dataset --export-ldi`):
    /// 65,534 levels, and a 0 that never collides with a depth.
    #[serde(rename = "relative16")]
    Relative16,
    /// `metres`: float z-depth in metres in an OpenEXR file (half or single precision; Record3D's export of
    /// an iPhone's LiDAR depth), `z = v` m; `v ≤ 0`, NaN and ∞ invalid. A single-channel file uses its
    /// channel, else the first of `Z`, `Y`, `R`, `depth` it has. Read through the exr crate (cargo feature
    /// `research`; without it such files are refused, naming the feature).
    #[serde(rename = "metres")]
    Metres,
}

impl DepthEncoding {
    /// Every encoding, in the order of the encoding table (`docs/CONVENTIONS.md` §6.1; for CLI `--help` and
    /// exhaustive tests).
    pub const ALL: [DepthEncoding; 9] = [
        DepthEncoding::Millimetres16,
        DepthEncoding::Tum5000,
        DepthEncoding::SunRotated,
        DepthEncoding::KinectDisparity,
        DepthEncoding::IphoneDisparity,
        DepthEncoding::RelativeNearBright,
        DepthEncoding::RelativeNearDark,
        DepthEncoding::Relative16,
        DepthEncoding::Metres,
    ];

    /// The kebab-case name used by [`fmt::Display`], [`FromStr`] and serde (e.g. `"mm16"`).
    pub(crate) fn name(&self) -> &'static str {
        match self {
            DepthEncoding::Millimetres16 => "mm16",
            DepthEncoding::Tum5000 => "tum",
            DepthEncoding::SunRotated => "sun",
            DepthEncoding::KinectDisparity => "kinect-disparity",
            DepthEncoding::IphoneDisparity => "iphone-disparity",
            DepthEncoding::RelativeNearBright => "relative-near-bright",
            DepthEncoding::RelativeNearDark => "relative-near-dark",
            DepthEncoding::Relative16 => "relative16",
            DepthEncoding::Metres => "metres",
        }
    }

    /// One line describing the stored quantity and its conversion, for CLI `--help`.
    pub(crate) fn description(&self) -> &'static str {
        match self {
            DepthEncoding::Millimetres16 => {
                "16-bit z-depth in mm, v/1000 m, 0 = invalid (Redwood, NYU/SUN derived)"
            }
            DepthEncoding::Tum5000 => "16-bit z-depth, v/5000 m, 0 = invalid (TUM RGB-D)",
            DepthEncoding::SunRotated => {
                "16-bit mm with bits rotated left by 3, ((v>>3)|(v<<13))&0xFFFF /1000 m, 0 = invalid (SUN RGB-D raw)"
            }
            DepthEncoding::KinectDisparity => {
                "16-bit raw Kinect v1 disparity (NYU raw, little-endian PGM), 351.3/(1092.5-v) m, v>=1092 invalid"
            }
            DepthEncoding::IphoneDisparity => {
                "8-bit iPhone normalised disparity, 1/(0.650879 + v/255*1.858887) m, larger = nearer"
            }
            DepthEncoding::RelativeNearBright => {
                "8-bit relative depth, larger = nearer, 0 = empty/invalid (odak renders), unitless"
            }
            DepthEncoding::RelativeNearDark => {
                "8-bit relative depth, larger = farther, d = v/255 (TensorHolo convention), unitless"
            }
            DepthEncoding::Relative16 => {
                "16-bit relative depth, larger = farther, d = (v-1)/65534, 0 = no point (LDI exchange), unitless"
            }
            DepthEncoding::Metres => {
                "float z-depth in metres in OpenEXR (half or float; Record3D), <= 0, NaN or inf = invalid"
            }
        }
    }

    /// Bits per sample the file must have: 16 for the sensor formats, 8 for the others, 32 for
    /// [`DepthEncoding::Metres`] (float samples: half-precision files are read as float too).
    pub(crate) fn bits_per_sample(&self) -> u32 {
        match self {
            DepthEncoding::Metres => 32,
            DepthEncoding::Millimetres16
            | DepthEncoding::Tum5000
            | DepthEncoding::SunRotated
            | DepthEncoding::KinectDisparity
            | DepthEncoding::Relative16 => 16,
            DepthEncoding::IphoneDisparity
            | DepthEncoding::RelativeNearBright
            | DepthEncoding::RelativeNearDark => 8,
        }
    }

    /// `true` when the decoded values are metres, `false` when they are relative `d ∈ [0,1]`.
    pub fn is_metric(&self) -> bool {
        !matches!(
            self,
            DepthEncoding::RelativeNearBright
                | DepthEncoding::RelativeNearDark
                | DepthEncoding::Relative16
        )
    }

    /// Decodes one stored sample: `Some(metres)` (metric encodings) or `Some(d)` (relative encodings,
    /// `d ∈ [0,1]`, 0 = near), `None` when the sample is invalid. Samples above 255 are invalid for the
    /// 8-bit encodings. Formulas: `docs/CONVENTIONS.md` §6. [`DepthEncoding::Metres`] stores floats, not
    /// integer samples: `None` (its files are decoded by [`decode_depth_bytes`]).
    pub(crate) fn decode_sample(&self, v: u16) -> Option<f32> {
        match self {
            DepthEncoding::Metres => None,
            DepthEncoding::Millimetres16 => (v != 0).then(|| v as f32 / 1000.0),
            DepthEncoding::Tum5000 => (v != 0).then(|| v as f32 / 5000.0),
            DepthEncoding::SunRotated => {
                // ((v >> 3) | (v << 13)) & 0xFFFF is a 16-bit rotate right by 3.
                let mm = v.rotate_right(3);
                (mm != 0).then(|| mm as f32 / 1000.0)
            }
            DepthEncoding::KinectDisparity => (v < 1092).then(|| 351.3 / (1092.5 - v as f32)),
            DepthEncoding::IphoneDisparity => {
                (v <= 255).then(|| 1.0 / (0.650_879 + v as f32 / 255.0 * 1.858_887))
            }
            DepthEncoding::RelativeNearBright => {
                (v != 0 && v <= 255).then(|| 1.0 - v as f32 / 255.0)
            }
            DepthEncoding::RelativeNearDark => (v <= 255).then(|| v as f32 / 255.0),
            DepthEncoding::Relative16 => (v != 0).then(|| (v - 1) as f32 / 65534.0),
        }
    }
}

impl fmt::Display for DepthEncoding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for DepthEncoding {
    type Err = HoloError;

    /// Parses the kebab-case name (case-insensitive). Error: [`HoloError::InvalidParameter`] listing the
    /// accepted names.
    fn from_str(s: &str) -> Result<Self> {
        let t = s.trim();
        DepthEncoding::ALL
            .into_iter()
            .find(|e| e.name().eq_ignore_ascii_case(t))
            .ok_or_else(|| {
                let names: Vec<&str> = DepthEncoding::ALL.iter().map(|e| e.name()).collect();
                invalid(
                    "depth_encoding",
                    format!(
                        "unknown depth encoding `{s}`; expected one of {}",
                        names.join(", ")
                    ),
                )
            })
    }
}

/// Decoded depth before normalisation (output of [`decode_depth`] / [`decode_depth_file`]).
///
/// `values` and `valid` are `[H, W]`. When `metric` is `true`, valid `values` are z-depths in metres
/// (> 0); otherwise they are relative depths `d ∈ [0,1]` with 0 = near. Invalid pixels hold `0.0` and must
/// never be read as depth (use `valid`).
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedDepth {
    /// `[H, W]` metres (metric) or relative `d ∈ [0,1]`, 0 = near; `0.0` where invalid.
    pub values: Array2<f32>,
    /// `[H, W]`, `true` where the sensor/file reported a depth.
    pub valid: Array2<bool>,
    /// `true`: `values` are metres; `false`: relative, unitless.
    pub metric: bool,
}

/// The largest relative difference in aspect ratio between a depth map and its colour image for which the
/// depth is taken to cover the colour's field of view and is brought to the colour's resolution
/// (`DecodedDepth::into_resolution`): 2 % (a phone's 256 × 192 LiDAR depth under a 1920 × 1440 image is 0 %).
/// Beyond it, the other-aspect rule decides (files refuse, cameras warn and stretch).
pub const MAX_DEPTH_ASPECT_MISMATCH: f64 = 0.02;

/// The other-aspect rule, written once for files and cameras: what a source does with a depth map whose
/// aspect ratio differs from its colour's by more than [`MAX_DEPTH_ASPECT_MISMATCH`] (so it cannot cover
/// the colour's field of view as it is), applied by [`DecodedDepth::check_aspect`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum OtherAspect {
    /// Refused with [`HoloError::ShapeMismatch`]: files ([`crate::scene::load_rgbd`]), paired by hand, where
    /// another aspect ratio means another field of view or a wrong pair (NYU's raw depth has the RGB's size).
    Refuse,
    /// Stretched onto the colour frame, logged as a warning once per process: camera buffers
    /// ([`crate::scene::CameraFrame::to_rgbd`]), delivered together by one sensor for one field of view, where
    /// a mismatch is a missing colour crop (ARCore's 4:3 CPU image under its 16:9 depth) that still gives a
    /// usable, stretched frame, and refusing would drop every frame of a live stream.
    WarnAndStretch,
}

/// Set once a depth map of another aspect ratio has been stretched with a warning (once per process, not
/// per frame).
static STRETCH_WARNED: AtomicBool = AtomicBool::new(false);

impl DecodedDepth {
    /// The relative difference `|h_d·w_c / (h_c·w_d) − 1|` between this map's aspect ratio and a colour
    /// frame's of `height × width` (0 for the same shape).
    pub(crate) fn aspect_mismatch(&self, height: usize, width: usize) -> f64 {
        let (hd, wd) = self.values.dim();
        let (a, b) = (hd as f64 * width as f64, height as f64 * wd as f64);
        if b == 0.0 {
            return f64::INFINITY;
        }
        (a / b - 1.0).abs()
    }

    /// Applies the other-aspect `rule` to this map against a colour frame of `height × width`: `Ok` when the
    /// aspect ratios differ by at most [`MAX_DEPTH_ASPECT_MISMATCH`]; beyond it, with
    /// [`OtherAspect::WarnAndStretch`] `Ok` after `what()` is logged as a warning (once per process), with
    /// [`OtherAspect::Refuse`] an error.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] (`what()`, expected = the colour's `[height, width]`, got = this
    /// map's `[H, W]`) with [`OtherAspect::Refuse`].
    pub(crate) fn check_aspect(
        &self,
        height: usize,
        width: usize,
        rule: OtherAspect,
        what: impl FnOnce() -> String,
    ) -> Result<()> {
        if self.aspect_mismatch(height, width) <= MAX_DEPTH_ASPECT_MISMATCH {
            return Ok(());
        }
        match rule {
            OtherAspect::Refuse => Err(HoloError::ShapeMismatch {
                what: what(),
                expected: vec![height, width],
                got: self.values.shape().to_vec(),
            }),
            OtherAspect::WarnAndStretch => {
                if !STRETCH_WARNED.swap(true, Ordering::Relaxed) {
                    log::warn!("{}; warned once", what());
                }
                Ok(())
            }
        }
    }

    /// This map at `height × width` pixels covering the same field of view (the colour's resolution, e.g. a
    /// phone's 256 × 192 LiDAR depth under its 1920 × 1440 image): values and validity by nearest neighbour,
    /// so that no depth is invented between a near and a far sample and an invalid sample stays invalid. The
    /// camera path ([`crate::scene::CameraFrame::to_rgbd`], the bindings) and the file loader
    /// ([`crate::scene::load_rgbd`]) both bring depth to the colour this way. The same map where the size is
    /// already `height × width`.
    pub(crate) fn into_resolution(self, height: usize, width: usize) -> Self {
        if self.values.dim() == (height, width) {
            return self;
        }
        Self {
            values: super::frame::resize_nearest(&self.values, height, width),
            valid: super::frame::resize_nearest(&self.valid, height, width),
            metric: self.metric,
        }
    }

    /// Fraction of pixels that are invalid, in `[0, 1]` (0 for an empty map).
    pub fn invalid_fraction(&self) -> f32 {
        let n = self.valid.len();
        if n == 0 {
            return 0.0;
        }
        self.valid.iter().filter(|&&v| !v).count() as f32 / n as f32
    }

    /// `(min, max)` of the valid values (metres when `metric`), `None` when no pixel is valid.
    pub fn valid_min_max(&self) -> Option<(f32, f32)> {
        let mut it = self
            .values
            .iter()
            .zip(self.valid.iter())
            .filter(|(_, &ok)| ok)
            .map(|(&v, _)| v);
        let first = it.next()?;
        Some(it.fold((first, first), |(lo, hi), v| (lo.min(v), hi.max(v))))
    }
}

/// Decodes raw samples `[H, W]` with `encoding`, pixel by pixel (`DepthEncoding::decode_sample`; formulas
/// from `docs/CONVENTIONS.md` §6). Pure and infallible: out-of-range samples (e.g. > 255 for an 8-bit
/// encoding) are marked invalid.
pub fn decode_depth(raw: &Array2<u16>, encoding: DepthEncoding) -> DecodedDepth {
    let mut values = Array2::<f32>::zeros(raw.raw_dim());
    let mut valid = Array2::<bool>::from_elem(raw.raw_dim(), false);
    Zip::from(&mut values)
        .and(&mut valid)
        .and(raw)
        .for_each(|val, ok, &r| {
            if let Some(x) = encoding.decode_sample(r) {
                *val = x;
                *ok = true;
            }
        });
    DecodedDepth {
        values,
        valid,
        metric: encoding.is_metric(),
    }
}

/// Reads a depth file (PNG, JPEG or PNM) and decodes it with `encoding` ([`decode_depth`]).
///
/// Multi-channel files (odak stores depth as 8-bit ×3) use the first channel. The file's bit depth must
/// match `DepthEncoding::bits_per_sample`. For [`DepthEncoding::KinectDisparity`] a binary PGM (`P5`)
/// is read by hand: NYU stores it little-endian despite the PGM spec, so the byte order under which every
/// sample is a valid 11-bit Kinect value (≤ 2047) is used, little-endian when both are.
///
/// Errors: [`HoloError::Io`] (unreadable file) or [`HoloError::Image`] (undecodable), both naming `path`;
/// [`HoloError::InvalidDepth`] naming the file and encoding when the bit depth is wrong, the image is
/// empty or floating-point, or Kinect samples exceed 11 bits in both byte orders.
pub fn decode_depth_file(path: &Path, encoding: DepthEncoding) -> Result<DecodedDepth> {
    decode_depth_bytes(&crate::io::read_bytes(path)?, path, encoding)
}

/// As [`decode_depth_file`], on the bytes of a depth file already in memory (PNG, PGM/PPM, JPEG; format
/// guessed from the content); `source` names it in errors. Shape of the result: `[H, W]`, metres or relative
/// as the encoding says. The image size is checked against [`crate::io::InputLimits`] from the header before
/// decoding.
///
/// Errors: as [`decode_depth_file`], naming `source`.
pub fn decode_depth_bytes(
    bytes: &[u8],
    source: &Path,
    encoding: DepthEncoding,
) -> Result<DecodedDepth> {
    if encoding == DepthEncoding::Metres {
        return decode_float_depth(bytes, source);
    }
    Ok(decode_depth(
        &read_depth_samples(bytes, source, encoding)?,
        encoding,
    ))
}

/// The magic number that starts every OpenEXR file.
const EXR_MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];

/// A [`DepthEncoding::Metres`] file: OpenEXR through the exr crate.
#[cfg(feature = "research")]
fn decode_float_depth(bytes: &[u8], source: &Path) -> Result<DecodedDepth> {
    if !bytes.starts_with(&EXR_MAGIC) {
        return Err(HoloError::InvalidDepth(format!(
            "`{}` is not an OpenEXR file, which depth encoding `metres` reads ({})",
            source.display(),
            DepthEncoding::Metres.description()
        )));
    }
    let samples = super::exr::read_exr_depth(bytes, source)?;
    let valid = samples.mapv(|z| z.is_finite() && z > 0.0);
    let values = Zip::from(&samples)
        .and(&valid)
        .map_collect(|&z, &ok| if ok { z } else { 0.0 });
    Ok(DecodedDepth {
        values,
        valid,
        metric: true,
    })
}

#[cfg(not(feature = "research"))]
fn decode_float_depth(_bytes: &[u8], source: &Path) -> Result<DecodedDepth> {
    Err(HoloError::InvalidDepth(format!(
        "`{}`: depth encoding `metres` (OpenEXR) needs the library's `research` feature, off in this build",
        source.display()
    )))
}

/// The stored samples `[H, W]` of a depth file already in memory, before decoding (the first step of
/// [`decode_depth_bytes`]; layered depth images read them to tell "no point here", a stored 0).
///
/// Errors: as [`decode_depth_file`], naming `source`.
pub(crate) fn read_depth_samples(
    bytes: &[u8],
    source: &Path,
    encoding: DepthEncoding,
) -> Result<Array2<u16>> {
    let path = source;
    if bytes.starts_with(&EXR_MAGIC) {
        return Err(HoloError::InvalidDepth(format!(
            "`{}` is an OpenEXR file (float depth), but depth encoding `{encoding}` reads {}-bit integer \
             samples: an OpenEXR depth map in metres (Record3D's export) takes depth encoding `metres`",
            path.display(),
            encoding.bits_per_sample()
        )));
    }
    if encoding == DepthEncoding::Metres {
        return Err(HoloError::InvalidDepth(format!(
            "`{}`: depth encoding `metres` is float depth in OpenEXR files, not integer samples",
            path.display()
        )));
    }
    let (raw, bits) = if encoding == DepthEncoding::KinectDisparity && bytes.starts_with(b"P5") {
        read_kinect_pgm(bytes, path)?
    } else {
        let img = crate::io::decode_image(path, bytes)?;
        first_channel(&img, path, encoding)?
    };
    if raw.is_empty() {
        return Err(HoloError::InvalidDepth(format!(
            "`{}` is an empty image",
            path.display()
        )));
    }
    let expected = encoding.bits_per_sample();
    if bits != expected {
        return Err(HoloError::InvalidDepth(format!(
            "`{}` has {bits}-bit samples, but depth encoding `{encoding}` expects {expected}-bit samples ({})",
            path.display(),
            encoding.description()
        )));
    }
    Ok(raw)
}

/// First channel of a decoded image as `u16` samples, with the image's bits per sample.
fn first_channel(
    img: &DynamicImage,
    path: &Path,
    encoding: DepthEncoding,
) -> Result<(Array2<u16>, u32)> {
    fn take<T: Copy + Into<u16>>(raw: &[T], w: u32, h: u32, channels: usize) -> Array2<u16> {
        let (w, h) = (w as usize, h as usize);
        Array2::from_shape_fn((h, w), |(y, x)| raw[(y * w + x) * channels].into())
    }
    let (w, h) = (img.width(), img.height());
    Ok(match img {
        DynamicImage::ImageLuma8(b) => (take(b.as_raw(), w, h, 1), 8),
        DynamicImage::ImageLumaA8(b) => (take(b.as_raw(), w, h, 2), 8),
        DynamicImage::ImageRgb8(b) => (take(b.as_raw(), w, h, 3), 8),
        DynamicImage::ImageRgba8(b) => (take(b.as_raw(), w, h, 4), 8),
        DynamicImage::ImageLuma16(b) => (take(b.as_raw(), w, h, 1), 16),
        DynamicImage::ImageLumaA16(b) => (take(b.as_raw(), w, h, 2), 16),
        DynamicImage::ImageRgb16(b) => (take(b.as_raw(), w, h, 3), 16),
        DynamicImage::ImageRgba16(b) => (take(b.as_raw(), w, h, 4), 16),
        other => {
            return Err(HoloError::InvalidDepth(format!(
                "`{}` has unsupported sample type {:?} for depth encoding `{encoding}` (expected {}-bit integer samples)",
                path.display(),
                other.color(),
                encoding.bits_per_sample()
            )))
        }
    })
}

/// Parses a binary PGM (`P5`) holding raw Kinect disparity, choosing the byte order of 16-bit samples
/// (see [`decode_depth_file`]). Returns the samples and the bits per sample (8 when maxval ≤ 255).
fn read_kinect_pgm(bytes: &[u8], path: &Path) -> Result<(Array2<u16>, u32)> {
    let bad = |why: &str| HoloError::InvalidDepth(format!("`{}`: {why}", path.display()));
    let mut pos = 2usize;
    let mut fields = [0usize; 3];
    for field in fields.iter_mut() {
        // Skip whitespace and comments.
        loop {
            match bytes.get(pos) {
                Some(b) if b.is_ascii_whitespace() => pos += 1,
                Some(b'#') => {
                    while bytes.get(pos).is_some_and(|&b| b != b'\n') {
                        pos += 1;
                    }
                }
                _ => break,
            }
        }
        let start = pos;
        while bytes.get(pos).is_some_and(u8::is_ascii_digit) {
            pos += 1;
        }
        *field = std::str::from_utf8(&bytes[start..pos])
            .ok()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| bad("malformed PGM header"))?;
    }
    // Exactly one whitespace byte separates the header from the samples.
    if !bytes.get(pos).is_some_and(u8::is_ascii_whitespace) {
        return Err(bad("malformed PGM header"));
    }
    pos += 1;
    let [w, h, maxval] = fields;
    if maxval == 0 || maxval > 65535 {
        return Err(bad("PGM maxval out of range"));
    }
    let bps = if maxval > 255 { 2 } else { 1 };
    if w == 0 || h == 0 {
        return Err(bad(&format!("PGM of {w}×{h} pixels holds no image")));
    }
    // Sizes come from the file: checked arithmetic, and the data must be there before anything is allocated.
    let n = w
        .checked_mul(h)
        .ok_or_else(|| bad(&format!("PGM size {w}×{h} overflows")))?;
    let end = n
        .checked_mul(bps)
        .and_then(|len| pos.checked_add(len))
        .ok_or_else(|| bad(&format!("PGM size {w}×{h} overflows")))?;
    let data = bytes.get(pos..end).ok_or_else(|| {
        bad(&format!(
            "truncated PGM data: the header declares {w}×{h} samples of {bps} byte(s), the file holds {} bytes \
             after it",
            bytes.len() - pos
        ))
    })?;
    if bps == 1 {
        return Ok((
            Array2::from_shape_fn((h, w), |(y, x)| data[y * w + x] as u16),
            8,
        ));
    }
    let le = |i: usize| u16::from_le_bytes([data[2 * i], data[2 * i + 1]]);
    let be = |i: usize| u16::from_be_bytes([data[2 * i], data[2 * i + 1]]);
    const KINECT_MAX: u16 = 2047;
    let use_le = if (0..n).all(|i| le(i) <= KINECT_MAX) {
        true
    } else if (0..n).all(|i| be(i) <= KINECT_MAX) {
        log::warn!(
            "`{}`: big-endian (spec-conformant) Kinect PGM; NYU files are usually little-endian",
            path.display()
        );
        false
    } else {
        return Err(bad(
            "samples exceed the 11-bit Kinect disparity range (2047) in both byte orders; not raw Kinect disparity",
        ));
    };
    let raw = Array2::from_shape_fn((h, w), |(y, x)| {
        let i = y * w + x;
        if use_le {
            le(i)
        } else {
            be(i)
        }
    });
    Ok((raw, 16))
}

/// How metric depth `z` maps to normalised depth `d ∈ [0,1]` (0 = near). Default: linear in diopters,
/// the usual choice for displays (defocus is linear in diopters). Parsed from `"diopters"` / `"metres"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize)]
pub enum DepthMapping {
    /// `d = (1/z_near − 1/z)/(1/z_near − 1/z_far)`, clamped to `[0,1]`. Name: `diopters`.
    #[default]
    #[serde(rename = "diopters")]
    LinearDiopters,
    /// `d = (z − z_near)/(z_far − z_near)`, clamped to `[0,1]`. Name: `metres`.
    #[serde(rename = "metres")]
    LinearMetres,
}

impl DepthMapping {
    /// Both mappings, default first.
    pub const ALL: [DepthMapping; 2] = [DepthMapping::LinearDiopters, DepthMapping::LinearMetres];

    /// The name used by [`fmt::Display`] / [`FromStr`]: `"diopters"` or `"metres"`.
    pub(crate) fn name(&self) -> &'static str {
        match self {
            DepthMapping::LinearDiopters => "diopters",
            DepthMapping::LinearMetres => "metres",
        }
    }

    /// Maps a z-depth in metres to `d ∈ [0,1]` (clamped) within `range` (assumed valid).
    pub fn apply(&self, z_m: f32, range: &DepthRange) -> f32 {
        let (n, f) = (range.z_near_m, range.z_far_m);
        let d = match self {
            DepthMapping::LinearDiopters => (1.0 / n - 1.0 / z_m) / (1.0 / n - 1.0 / f),
            DepthMapping::LinearMetres => (z_m - n) / (f - n),
        };
        d.clamp(0.0, 1.0)
    }
}

impl fmt::Display for DepthMapping {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for DepthMapping {
    type Err = HoloError;

    /// Accepts `diopters` (or `linear-diopters`, `dioptres`) and `metres` (or `meters`,
    /// `linear-metres`), case-insensitive. Error: [`HoloError::InvalidParameter`].
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "diopters" | "dioptres" | "linear-diopters" | "linear-dioptres" => {
                Ok(DepthMapping::LinearDiopters)
            }
            "metres" | "meters" | "linear-metres" | "linear-meters" => {
                Ok(DepthMapping::LinearMetres)
            }
            _ => Err(invalid(
                "depth_mapping",
                format!("unknown depth mapping `{s}`; expected `diopters` or `metres`"),
            )),
        }
    }
}

/// Metric depth range `[z_near_m, z_far_m]` in metres mapped to `d = 0` and `d = 1`.
/// Valid when `0 < z_near_m < z_far_m` and both are finite ([`DepthRange::new`], `DepthRange::validate`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DepthRange {
    /// Distance mapped to `d = 0` (near), metres.
    pub z_near_m: f32,
    /// Distance mapped to `d = 1` (far), metres.
    pub z_far_m: f32,
}

impl DepthRange {
    /// Checked constructor. Error: [`HoloError::InvalidParameter`] unless `0 < z_near_m < z_far_m`, finite.
    pub fn new(z_near_m: f32, z_far_m: f32) -> Result<Self> {
        let r = DepthRange { z_near_m, z_far_m };
        r.validate()?;
        Ok(r)
    }

    /// Checks `0 < z_near_m < z_far_m`, both finite (the fields are public, so callers of
    /// [`normalise_depth`] may pass an unchecked value). Error: [`HoloError::InvalidParameter`].
    pub(crate) fn validate(&self) -> Result<()> {
        let (n, f) = (self.z_near_m, self.z_far_m);
        if !(n.is_finite() && f.is_finite() && n > 0.0 && n < f) {
            return Err(invalid(
                "depth_range",
                format!("need finite 0 < z_near_m < z_far_m, got [{n}, {f}] m"),
            ));
        }
        Ok(())
    }
}

impl fmt::Display for DepthRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{:.3}, {:.3}] m", self.z_near_m, self.z_far_m)
    }
}

/// Percentile (nearest rank on `p·(n−1)`) of an already sorted, non-empty slice; `p ∈ [0,1]`.
fn percentile_sorted(sorted: &[f32], p: f32) -> f32 {
    let idx = (p * (sorted.len() - 1) as f32).round() as usize;
    sorted[idx.min(sorted.len() - 1)]
}

/// Converts decoded depth to normalised depth `d ∈ [0,1]` (0 = near, `docs/CONVENTIONS.md` §4), `[H, W]`.
///
/// * Metric input: `d = mapping.apply(z, range)` ([`DepthMapping`]; default linear in diopters,
///   `d = (1/z_near − 1/z)/(1/z_near − 1/z_far)`, clamped). With `range = None` the range is the 1st and
///   99th percentiles of the valid values (logged at `info`); when those coincide (a flat scene) a range of
///   ±1 % in diopters around that depth is used, which puts it at `d = 0.5`.
/// * Relative input: `d = values` (range and mapping ignored; the returned range is `None`).
///
/// Invalid pixels are set to `0.0` in the output; fill them with [`fill_invalid`] (never read as near).
/// Returns `(d, range used)`.
///
/// Errors: [`HoloError::ShapeMismatch`] if `values` and `valid` differ in shape;
/// [`HoloError::InvalidParameter`] for an invalid `range`; [`HoloError::InvalidDepth`] if no pixel is
/// valid (metric, automatic range), a valid value is non-finite, ≤ 0 m (metric) or outside `[0,1]`
/// (relative), or the mapping of a valid value overflows (depths of 1e-40 m).
pub fn normalise_depth(
    decoded: &DecodedDepth,
    range: Option<DepthRange>,
    mapping: DepthMapping,
) -> Result<(Array2<f32>, Option<DepthRange>)> {
    let DecodedDepth {
        values,
        valid,
        metric,
    } = decoded;
    if values.shape() != valid.shape() {
        return Err(HoloError::ShapeMismatch {
            what: "depth validity mask vs depth values".into(),
            expected: values.shape().to_vec(),
            got: valid.shape().to_vec(),
        });
    }
    let bad = Zip::from(values).and(valid).fold(0usize, |n, &v, &ok| {
        let out = if *metric {
            !(v.is_finite() && v > 0.0)
        } else {
            !(v.is_finite() && (0.0..=1.0).contains(&v))
        };
        n + usize::from(ok && out)
    });
    if bad > 0 {
        let what = if *metric {
            "non-finite or non-positive metric depths"
        } else {
            "relative depths that are non-finite or outside [0, 1]"
        };
        return Err(HoloError::InvalidDepth(format!(
            "{bad} valid pixels hold {what}"
        )));
    }
    if !*metric {
        let d = Zip::from(values)
            .and(valid)
            .map_collect(|&v, &ok| if ok { v } else { 0.0 });
        return Ok((d, None));
    }
    let range = match range {
        Some(r) => {
            r.validate()?;
            r
        }
        None => {
            let mut z: Vec<f32> =
                Zip::from(values)
                    .and(valid)
                    .fold(Vec::new(), |mut acc, &v, &ok| {
                        if ok {
                            acc.push(v);
                        }
                        acc
                    });
            if z.is_empty() {
                return Err(HoloError::InvalidDepth(
                    "no valid depth pixel to derive a depth range from".into(),
                ));
            }
            z.sort_unstable_by(f32::total_cmp);
            let (p1, p99) = (percentile_sorted(&z, 0.01), percentile_sorted(&z, 0.99));
            let r = if p1 < p99 {
                DepthRange {
                    z_near_m: p1,
                    z_far_m: p99,
                }
            } else {
                DepthRange {
                    z_near_m: p1 / 1.01,
                    z_far_m: p1 / 0.99,
                }
            };
            log::info!(
                "automatic depth range from 1st/99th percentiles of {} valid pixels: {r}",
                z.len()
            );
            r
        }
    };
    let d =
        Zip::from(values)
            .and(valid)
            .map_collect(|&z, &ok| if ok { mapping.apply(z, &range) } else { 0.0 });
    // Depths so small or so close that the mapping's arithmetic overflows (1/z of 1e-40 m) leave no pixel a
    // normalised depth: refused here, not passed on as NaN.
    let lost = Zip::from(&d)
        .and(values)
        .and(valid)
        .fold(None, |first, &dv, &z, &ok| {
            first.or((ok && !dv.is_finite()).then_some(z))
        });
    if let Some(z) = lost {
        return Err(HoloError::InvalidDepth(format!(
            "the valid depths leave no usable pixel: {z:e} m maps to no normalised depth in the range \
             [{:e}, {:e}] m ({mapping}); values this small are not metres (check --depth-encoding, or give \
             --z-near-m/--z-far-m)",
            range.z_near_m, range.z_far_m
        )));
    }
    Ok((d, Some(range)))
}

/// The usual lowest confidence kept by [`apply_confidence`]: 1, ARKit's `ARConfidenceLevel.medium` (0 low,
/// 1 medium, 2 high; Stray Scanner's confidence PNGs store the same values). ARCore's raw depth confidence is
/// 0–255 (255 = most confident): give a threshold on that scale, e.g. 128.
pub const DEFAULT_MIN_CONFIDENCE: u8 = 1;

/// Reads a depth confidence map `[H, W]` from an 8-bit image file (PNG or PNM; the first channel of a
/// colour file): ARKit's `confidenceMap` or Stray Scanner's `confidence/N.png` (0, 1, 2), ARCore's raw depth
/// confidence (0–255).
///
/// Errors: [`HoloError::Io`] / [`HoloError::Image`] naming `path`; [`HoloError::InvalidDepth`] for samples
/// of more than 8 bits or an empty image.
pub(crate) fn decode_confidence_file(path: &Path) -> Result<Array2<u8>> {
    let bytes = crate::io::read_bytes(path)?;
    let img = crate::io::decode_image(path, &bytes)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w == 0 || h == 0 {
        return Err(HoloError::InvalidDepth(format!(
            "confidence map `{}` is an empty image",
            path.display()
        )));
    }
    let channels = match &img {
        DynamicImage::ImageLuma8(_) => 1,
        DynamicImage::ImageLumaA8(_) => 2,
        DynamicImage::ImageRgb8(_) => 3,
        DynamicImage::ImageRgba8(_) => 4,
        other => {
            return Err(HoloError::InvalidDepth(format!(
                "confidence map `{}` has {:?} samples: a confidence map is 8-bit (0/1/2 as ARKit and Stray \
                 Scanner store it, or 0–255 as ARCore)",
                path.display(),
                other.color()
            )))
        }
    };
    let raw = img.as_bytes();
    Ok(Array2::from_shape_fn((h, w), |(y, x)| {
        raw[(y * w + x) * channels]
    }))
}

/// Invalidates the pixels of `depth` whose `confidence` (`[H, W]`, the depth map's own resolution) is below
/// `min`, so that uncertain depth is filled from its confident neighbours ([`fill_invalid`]) and never read
/// as near. Returns the number of valid pixels it invalidated.
///
/// Errors: [`HoloError::ShapeMismatch`] naming `source` (the confidence file) when the shapes differ.
pub fn apply_confidence(
    depth: &mut DecodedDepth,
    confidence: &Array2<u8>,
    min: u8,
    source: &Path,
) -> Result<usize> {
    if confidence.dim() != depth.values.dim() {
        return Err(HoloError::ShapeMismatch {
            what: format!(
                "confidence map `{}` vs its depth map (a confidence map has the depth map's resolution)",
                source.display()
            ),
            expected: depth.values.shape().to_vec(),
            got: confidence.shape().to_vec(),
        });
    }
    let mut dropped = 0;
    Zip::from(&mut depth.valid)
        .and(&mut depth.values)
        .and(confidence)
        .for_each(|ok, v, &c| {
            if *ok && c < min {
                *ok = false;
                *v = 0.0;
                dropped += 1;
            }
        });
    Ok(dropped)
}

/// Fills invalid pixels of `depth` `[H, W]`; call it before any resizing so holes are never read as near.
///
/// Policy: iterative 3×3 dilation. In each pass every still-unfilled pixel with at least one filled
/// 8-neighbour takes the **largest** (farthest, for `d` with 0 = near) of those neighbours' values: holes
/// in depth cameras sit on the background side of occlusion edges. Valid pixels are returned unchanged.
/// Non-finite values are treated as invalid even where `valid` is `true`. Works for any units in which
/// larger = farther. Cost `O(H·W)`.
///
/// Errors: [`HoloError::ShapeMismatch`] if the shapes differ; [`HoloError::InvalidDepth`] if no pixel is
/// valid (and finite).
pub fn fill_invalid(depth: &Array2<f32>, valid: &Array2<bool>) -> Result<Array2<f32>> {
    if depth.shape() != valid.shape() {
        return Err(HoloError::ShapeMismatch {
            what: "depth validity mask vs depth map".into(),
            expected: depth.shape().to_vec(),
            got: valid.shape().to_vec(),
        });
    }
    let (h, w) = depth.dim();
    let mut out = depth.to_owned();
    // filled_pass[i]: pass in which pixel i received its value (0 = originally valid), u32::MAX = not yet.
    const UNFILLED: u32 = u32::MAX;
    let mut filled_pass = vec![UNFILLED; h * w];
    let mut n_valid = 0usize;
    for ((y, x), &d) in depth.indexed_iter() {
        if valid[[y, x]] && d.is_finite() {
            filled_pass[y * w + x] = 0;
            n_valid += 1;
        }
    }
    if n_valid == 0 {
        return Err(HoloError::InvalidDepth(format!(
            "no valid depth pixel in a {h}x{w} depth map; nothing to fill holes from"
        )));
    }
    if n_valid == h * w {
        return Ok(out);
    }
    let neighbours = |i: usize| {
        let (y, x) = ((i / w) as isize, (i % w) as isize);
        (-1isize..=1)
            .flat_map(move |dy| (-1isize..=1).map(move |dx| (y + dy, x + dx)))
            .filter(move |&(yy, xx)| {
                (yy, xx) != (y, x) && yy >= 0 && xx >= 0 && yy < h as isize && xx < w as isize
            })
            .map(move |(yy, xx)| yy as usize * w + xx as usize)
    };
    // Frontier: unfilled pixels with a filled neighbour.
    let mut queued = vec![false; h * w];
    let mut frontier: Vec<usize> = Vec::new();
    for i in 0..h * w {
        if filled_pass[i] == UNFILLED && neighbours(i).any(|j| filled_pass[j] == 0) {
            queued[i] = true;
            frontier.push(i);
        }
    }
    let mut pass = 0u32;
    let flat = out
        .as_slice_mut()
        .expect("owned array from to_owned() is contiguous");
    while !frontier.is_empty() {
        pass += 1;
        let values: Vec<f32> = frontier
            .iter()
            .map(|&i| {
                neighbours(i)
                    .filter(|&j| filled_pass[j] < pass)
                    .map(|j| flat[j])
                    .fold(f32::NEG_INFINITY, f32::max)
            })
            .collect();
        for (&i, &v) in frontier.iter().zip(&values) {
            flat[i] = v;
            filled_pass[i] = pass;
        }
        let mut next = Vec::new();
        for &i in &frontier {
            for j in neighbours(i) {
                if filled_pass[j] == UNFILLED && !queued[j] {
                    queued[j] = true;
                    next.push(j);
                }
            }
        }
        frontier = next;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn encoding_names_round_trip_and_are_unique() {
        let mut names = std::collections::HashSet::new();
        for e in DepthEncoding::ALL {
            assert_eq!(e.to_string().parse::<DepthEncoding>().unwrap(), e);
            assert!(names.insert(e.name()));
            assert!(!e.description().contains('\n'));
        }
        assert!("mm".parse::<DepthEncoding>().is_err());
        assert_eq!(
            "KINECT-DISPARITY".parse::<DepthEncoding>().unwrap(),
            DepthEncoding::KinectDisparity
        );
    }

    #[test]
    fn serde_names_match_display() {
        for e in DepthEncoding::ALL {
            let json = serde_json::to_string(&e).unwrap();
            assert_eq!(json, format!("\"{e}\""));
        }
        for m in DepthMapping::ALL {
            assert_eq!(serde_json::to_string(&m).unwrap(), format!("\"{m}\""));
            assert_eq!(m.to_string().parse::<DepthMapping>().unwrap(), m);
        }
        assert_eq!(DepthMapping::default(), DepthMapping::LinearDiopters);
        assert_eq!(
            "meters".parse::<DepthMapping>().unwrap(),
            DepthMapping::LinearMetres
        );
        assert!("log".parse::<DepthMapping>().is_err());
    }

    #[test]
    fn sample_formulas_follow_the_encoding_table() {
        use DepthEncoding::*;
        assert_eq!(Millimetres16.decode_sample(1500), Some(1.5));
        assert_eq!(Millimetres16.decode_sample(0), None);
        assert_eq!(Tum5000.decode_sample(5000), Some(1.0));
        assert_eq!(Tum5000.decode_sample(0), None);
        // SUN: the table's formula, literally, against the rotate.
        for v in [1u16, 7, 8, 1234, 0x8001, 0xFFFF, 12000] {
            let mm = ((((v as u32) >> 3) | ((v as u32) << 13)) & 0xFFFF) as f32;
            assert_eq!(SunRotated.decode_sample(v), Some(mm / 1000.0));
        }
        // 1500 mm stored rotated left by 3.
        assert_eq!(SunRotated.decode_sample(1500u16.rotate_left(3)), Some(1.5));
        assert_eq!(SunRotated.decode_sample(0), None);
        assert!((KinectDisparity.decode_sample(800).unwrap() - 351.3 / 292.5).abs() < 1e-6);
        assert_eq!(KinectDisparity.decode_sample(1092), None);
        assert_eq!(KinectDisparity.decode_sample(2047), None);
        assert!(KinectDisparity.decode_sample(1091).is_some());
        let near = IphoneDisparity.decode_sample(255).unwrap();
        let far = IphoneDisparity.decode_sample(0).unwrap();
        assert!((near - 0.3984).abs() < 1e-3 && (far - 1.5364).abs() < 1e-3);
        assert_eq!(IphoneDisparity.decode_sample(256), None);
        assert_eq!(RelativeNearBright.decode_sample(0), None);
        assert_eq!(RelativeNearBright.decode_sample(255), Some(0.0));
        assert_eq!(RelativeNearDark.decode_sample(0), Some(0.0));
        assert_eq!(RelativeNearDark.decode_sample(255), Some(1.0));
        assert_eq!(Relative16.decode_sample(0), None);
        assert_eq!(Relative16.decode_sample(1), Some(0.0));
        assert_eq!(Relative16.decode_sample(65535), Some(1.0));
        assert_eq!(Relative16.decode_sample(32768), Some(32767.0 / 65534.0));
        // Larger stored value = nearer for disparity-like encodings, farther for z-depth ones.
        for e in DepthEncoding::ALL {
            if e == Metres {
                // Floats in OpenEXR files: no integer samples (decode_depth_bytes reads them).
                assert_eq!(e.decode_sample(100), None);
                continue;
            }
            // SUN compares decoded millimetres: store 100 and 200 rotated left by 3.
            let (a, b) = if e == SunRotated {
                (
                    e.decode_sample(100u16.rotate_left(3)).unwrap(),
                    e.decode_sample(200u16.rotate_left(3)).unwrap(),
                )
            } else {
                (e.decode_sample(100).unwrap(), e.decode_sample(200).unwrap())
            };
            // Kinect raw "disparity" grows with distance under its formula (351.3/(1092.5 − v)),
            // although a disparity would shrink; the formula is the one confirmed by nyu/derived (see
            // tests/scene.rs).
            let larger_is_nearer = matches!(e, IphoneDisparity | RelativeNearBright);
            assert_eq!(b < a, larger_is_nearer, "{e}");
        }
    }

    #[test]
    fn decode_depth_marks_invalid_as_zero_and_false() {
        let raw = array![[0u16, 1000], [2000, 0]];
        let d = decode_depth(&raw, DepthEncoding::Millimetres16);
        assert!(d.metric);
        assert_eq!(d.valid, array![[false, true], [true, false]]);
        assert_eq!(d.values, array![[0.0, 1.0], [2.0, 0.0]]);
        assert_eq!(d.invalid_fraction(), 0.5);
        assert_eq!(d.valid_min_max(), Some((1.0, 2.0)));
        assert!(!decode_depth(&raw, DepthEncoding::RelativeNearDark).metric);
    }

    #[test]
    fn diopter_mapping_sends_near_to_0_far_to_1_and_is_monotone() {
        let r = DepthRange::new(0.5, 4.0).unwrap();
        for m in DepthMapping::ALL {
            assert!(m.apply(0.5, &r).abs() < 1e-6, "{m}");
            assert!((m.apply(4.0, &r) - 1.0).abs() < 1e-6, "{m}");
            assert_eq!(m.apply(0.1, &r), 0.0);
            assert_eq!(m.apply(100.0, &r), 1.0);
            let mut prev = -1.0;
            for i in 0..=200 {
                let z = 0.5 + 3.5 * i as f32 / 200.0;
                let d = m.apply(z, &r);
                assert!(d >= prev, "{m} not monotone at z={z}");
                prev = d;
            }
        }
        // Linear in diopters: the dioptric midpoint (1/z = (2 + 0.25)/2) maps to 0.5.
        let z_mid = 1.0 / 1.125;
        assert!((DepthMapping::LinearDiopters.apply(z_mid, &r) - 0.5).abs() < 1e-5);
        assert!((DepthMapping::LinearMetres.apply(2.25, &r) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn depth_range_is_validated() {
        assert!(DepthRange::new(1.0, 1.0).is_err());
        assert!(DepthRange::new(0.0, 1.0).is_err());
        assert!(DepthRange::new(-1.0, 1.0).is_err());
        assert!(DepthRange::new(1.0, f32::INFINITY).is_err());
        assert!(DepthRange::new(f32::NAN, 1.0).is_err());
        let dec = decode_depth(&array![[1000u16]], DepthEncoding::Millimetres16);
        let bad = DepthRange {
            z_near_m: 2.0,
            z_far_m: 1.0,
        };
        assert!(matches!(
            normalise_depth(&dec, Some(bad), DepthMapping::default()),
            Err(HoloError::InvalidParameter { .. })
        ));
    }

    #[test]
    fn normalise_uses_percentiles_and_passes_relative_through() {
        // 1..=100 mm-ish metres; percentiles 1 % and 99 % by nearest rank.
        let raw = Array2::from_shape_fn((10, 10), |(y, x)| (1000 + 10 * (y * 10 + x)) as u16);
        let dec = decode_depth(&raw, DepthEncoding::Millimetres16);
        let (d, r) = normalise_depth(&dec, None, DepthMapping::LinearMetres).unwrap();
        let r = r.unwrap();
        assert!((r.z_near_m - 1.01).abs() < 1e-6 && (r.z_far_m - 1.98).abs() < 1e-6);
        assert_eq!(d[[0, 0]], 0.0);
        assert_eq!(d[[9, 9]], 1.0);
        // Flat scene: d = 0.5 in diopters.
        let flat = decode_depth(
            &Array2::from_elem((4, 4), 2000u16),
            DepthEncoding::Millimetres16,
        );
        let (d, r) = normalise_depth(&flat, None, DepthMapping::LinearDiopters).unwrap();
        assert!(r.unwrap().validate().is_ok());
        assert!(d.iter().all(|&v| (v - 0.5).abs() < 1e-4));
        // Relative: passthrough, invalid -> 0, range None.
        let rel = decode_depth(&array![[0u16, 51, 255]], DepthEncoding::RelativeNearBright);
        let (d, r) = normalise_depth(
            &rel,
            DepthRange::new(1.0, 2.0).ok(),
            DepthMapping::default(),
        )
        .unwrap();
        assert!(r.is_none());
        assert_eq!(d, array![[0.0, 0.8, 0.0]]);
        // No valid pixel, metric, automatic range: error.
        let none = decode_depth(&array![[0u16, 0]], DepthEncoding::Millimetres16);
        assert!(matches!(
            normalise_depth(&none, None, DepthMapping::default()),
            Err(HoloError::InvalidDepth(_))
        ));
        // NaN in a valid pixel of user-built input: error, not propagated.
        let mut nan = dec.clone();
        nan.values[[3, 3]] = f32::NAN;
        assert!(matches!(
            normalise_depth(&nan, None, DepthMapping::default()),
            Err(HoloError::InvalidDepth(_))
        ));
    }

    #[test]
    fn fill_invalid_keeps_valid_and_takes_farthest_neighbour() {
        let depth = array![
            [0.2, 0.2, 0.9, 0.9],
            [0.2, 0.0, 0.0, 0.9],
            [0.2, 0.2, 0.9, 0.9]
        ];
        let valid = depth.mapv(|v: f32| v != 0.0);
        let out = fill_invalid(&depth, &valid).unwrap();
        for ((idx, &v), &ok) in depth.indexed_iter().zip(valid.iter()) {
            if ok {
                assert_eq!(out[idx], v);
            }
        }
        // Both holes touch the far (0.9) side, so both take 0.9, never the near 0.2 nor 0.
        assert_eq!(out[[1, 1]], 0.9);
        assert_eq!(out[[1, 2]], 0.9);
    }

    #[test]
    fn fill_invalid_propagates_over_large_holes_and_treats_nan_as_invalid() {
        let mut depth = Array2::<f32>::zeros((40, 50));
        let mut valid = Array2::from_elem((40, 50), false);
        depth[[20, 10]] = 0.3;
        valid[[20, 10]] = true;
        depth[[5, 45]] = 0.7;
        valid[[5, 45]] = true;
        depth[[0, 0]] = f32::NAN;
        valid[[0, 0]] = true; // claims valid, but NaN: must be filled
        let out = fill_invalid(&depth, &valid).unwrap();
        assert!(out.iter().all(|v| *v == 0.3 || *v == 0.7));
        assert_eq!(out[[20, 10]], 0.3);
        assert_eq!(out[[5, 45]], 0.7);
        assert_eq!(out[[39, 0]], 0.3); // closer to the 0.3 seed (Chebyshev distance 19 vs 35)
        assert_eq!(out[[0, 49]], 0.7);
        // Tie at equal distance goes to the farther value.
        let d = array![[0.1, 0.0, 0.8]];
        let v = array![[true, false, true]];
        assert_eq!(fill_invalid(&d, &v).unwrap(), array![[0.1, 0.8, 0.8]]);
    }

    #[test]
    fn fill_invalid_errors() {
        let d = Array2::<f32>::zeros((3, 3));
        assert!(matches!(
            fill_invalid(&d, &Array2::from_elem((3, 3), false)),
            Err(HoloError::InvalidDepth(_))
        ));
        let nan = Array2::from_elem((2, 2), f32::NAN);
        assert!(matches!(
            fill_invalid(&nan, &Array2::from_elem((2, 2), true)),
            Err(HoloError::InvalidDepth(_))
        ));
        assert!(matches!(
            fill_invalid(&d, &Array2::from_elem((3, 4), true)),
            Err(HoloError::ShapeMismatch { .. })
        ));
    }

    #[test]
    fn kinect_pgm_with_an_overflowing_or_empty_size_is_refused() {
        let path = Path::new("bad.pgm");
        for (header, why) in [
            (
                &b"P5\n18446744073709551615 18446744073709551615\n65535\n\0\0"[..],
                "overflows",
            ),
            (&b"P5\n4294967296 4294967297\n65535\n\0\0"[..], "overflows"),
            (&b"P5\n0 5\n255\n\0"[..], "no image"),
            (&b"P5\n3000 2000\n65535\n\0\0\0\0"[..], "truncated"),
        ] {
            let err = read_kinect_pgm(header, path).unwrap_err().to_string();
            assert!(err.contains(why) && err.contains("bad.pgm"), "{err}");
        }
    }

    #[test]
    fn kinect_pgm_byte_order_is_detected() {
        let dir = std::env::temp_dir().join(format!("tensorholo-pgm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let samples = [800u16, 2047, 1000, 0];
        for (name, le) in [("le.pgm", true), ("be.pgm", false)] {
            let mut bytes = b"P5\n# comment\n2 2\n65535\n".to_vec();
            for s in samples {
                bytes.extend(if le { s.to_le_bytes() } else { s.to_be_bytes() });
            }
            let p = dir.join(name);
            std::fs::write(&p, bytes).unwrap();
            let dec = decode_depth_file(&p, DepthEncoding::KinectDisparity).unwrap();
            assert_eq!(dec.valid, array![[true, false], [true, true]], "{name}");
            assert!((dec.values[[0, 0]] - 351.3 / 292.5).abs() < 1e-6, "{name}");
        }
        // A 16-bit PGM through mm16 goes through the spec-conformant (big-endian) decoder.
        let p = dir.join("be.pgm");
        let dec = decode_depth_file(&p, DepthEncoding::Millimetres16).unwrap();
        assert_eq!(dec.values[[0, 0]], 0.8);
        std::fs::remove_dir_all(&dir).ok();
    }
}
