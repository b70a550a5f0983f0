//! The exported API: one thin wrapper per item of [`tensorholo::generator`] (the core owns every rule; this
//! module converts types and errors, nothing else). Names are the bindings' contract: Python
//! `tensorholo.HologramGenerator`, Kotlin `tensorholo.HologramGenerator`, Swift `HologramGenerator`.

use std::sync::Arc;

use ndarray::Axis;
use tensorholo::cnn::ThreadCount;
use tensorholo::display as core_display;
use tensorholo::generator as core;
use tensorholo::model::DEFAULT_INT8;
use tensorholo::optics::OpticalSetup;
use tensorholo::scene::{self, DepthRange};

use crate::{guard, TensorholoError};

type Result<T> = std::result::Result<T, TensorholoError>;

fn invalid(message: impl Into<String>) -> TensorholoError {
    TensorholoError::InvalidInput {
        message: message.into(),
    }
}

/// Weight format of the shipped CNNs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum Precision {
    /// 32-bit float (the default).
    F32,
    /// 8-bit integer weights (the int8 form that loses at most 0.5 dB; see the model card).
    Int8,
}

/// The scene the hologram CNN takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum SceneInput {
    /// One RGB-D frame per hologram ([`HologramGenerator::render`]; the default).
    Rgbd,
    /// A layered depth image of up to 5 layers front to back ([`HologramGenerator::render_ldi`]; the shipped
    /// 8-layer LDI CNN, paper Fig. 1). `render` still works: a frame is a one-layer LDI.
    Ldi,
}

/// Whether the DDPM pre-filter CNN runs (paper Eq. 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum PrefilterMode {
    /// Where one is shipped for the offset (6 or 12 mm) and was trained with this CNN depth (the default).
    Auto,
    /// Never: AA-DPM encoding.
    Off,
    /// Always; an error at an offset without a shipped pre-filter.
    Required,
}

/// Where frames are computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum Backend {
    /// The phone's GPU (Metal, Vulkan) where the first frame agrees with the CPU, else the CPU (the default).
    Auto,
    /// The CPU (tract and rustfft), the reference.
    Cpu,
    /// The GPU always; an `Unsupported` error at creation where there is none.
    Gpu,
}

/// The GPU CNNs' arithmetic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum GpuPrecision {
    /// f16 where the GPU has it, else f32 (the default).
    Auto,
    /// f32.
    F32,
    /// f16 activations, f32 products and sums: half the GPU memory; f32 where the GPU lacks f16.
    F16,
}

/// The engine that runs the CNNs on the CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum CnnEngine {
    /// Time tensorholo's own kernels and tract when the generator is created and keep the faster (the
    /// default).
    Auto,
    /// tensorholo's own direct 3×3 convolution kernels (f32 and int8 models).
    Native,
    /// tract.
    Tract,
}

/// How the camera frame fits the hologram's size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum Fit {
    /// Centred crop to the hologram's aspect ratio (the default).
    Crop,
    /// Fit inside, black (and far) margins.
    Letterbox,
    /// Resample ignoring the aspect ratio.
    Stretch,
}

/// Byte layout of an interleaved 8-bit sRGB colour pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum ColorFormat {
    /// R, G, B, A (Android `Bitmap.Config.ARGB_8888` bytes).
    Rgba8,
    /// B, G, R, A (iOS `kCVPixelFormatType_32BGRA`).
    Bgra8,
    /// R, G, B.
    Rgb8,
}

/// Depth sample format, little-endian.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum DepthFormat {
    /// f32 metres (AVDepthData `DepthFloat32`).
    MetresF32,
    /// f16 metres (AVDepthData `DepthFloat16`).
    MetresF16,
    /// f32 disparity in 1/m (AVDepthData `DisparityFloat32`).
    DisparityF32,
    /// f16 disparity in 1/m (AVDepthData `DisparityFloat16`).
    DisparityF16,
    /// u16 millimetres (ARCore `acquireDepthImage16Bits`).
    MillimetresU16,
    /// Android `ImageFormat.DEPTH16`: low 13 bits millimetres, high 3 bits confidence.
    Depth16,
}

/// Clockwise rotation that makes the camera buffers upright.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum Rotation {
    /// None.
    Deg0,
    /// 90° clockwise.
    Deg90,
    /// 180°.
    Deg180,
    /// 270° clockwise.
    Deg270,
}

/// Everything a [`HologramGenerator`] needs. Only `width` and `height` (the SLM's resolution in pixels) are
/// required; every other field has the default named in its comment.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct GeneratorConfig {
    /// Hologram (SLM) width in pixels.
    pub width: u32,
    /// Hologram (SLM) height in pixels.
    pub height: u32,
    /// Hologram CNN depth: 8 (default), 15 or 30 layers (RGB-D); 8 (LDI).
    #[uniffi(default = 8)]
    pub layers: u32,
    /// The scene the hologram CNN takes; `None` = [`SceneInput::Rgbd`].
    #[uniffi(default = None)]
    pub input: Option<SceneInput>,
    /// Weight format; `None` = [`Precision::F32`].
    #[uniffi(default = None)]
    pub precision: Option<Precision>,
    /// Distance from the midpoint hologram to the SLM in millimetres (default 6; pre-filters are shipped for
    /// 6 and 12).
    #[uniffi(default = 6.0)]
    pub offset_mm: f64,
    /// Pre-filter CNN; `None` = [`PrefilterMode::Auto`].
    #[uniffi(default = None)]
    pub prefilter: Option<PrefilterMode>,
    /// CNN threads; 0 (default) = the cores the device reports (with `tune`: the fastest of 1, half and all,
    /// timed).
    #[uniffi(default = 0)]
    pub threads: u32,
    /// How camera frames fit the hologram; `None` = [`Fit::Crop`].
    #[uniffi(default = None)]
    pub fit: Option<Fit>,
    /// SLM pixel pitch in metres (default 8e-6).
    #[uniffi(default = 8e-6)]
    pub pixel_pitch_m: f64,
    /// Laser wavelengths in metres, red, green, blue; empty (default) = 638e-9, 520e-9, 450e-9.
    #[uniffi(default = [])]
    pub wavelengths_m: Vec<f64>,
    /// Depth of the 3D volume in metres, centred on the midpoint hologram (default 6e-3).
    #[uniffi(default = 6e-3)]
    pub volume_depth_m: f64,
    /// Nearest scene depth in metres mapped to the front of the volume; `None` (default, with `z_far_m`) =
    /// 1st percentile of each frame's valid depths (a stream keeps its first frame's range).
    #[uniffi(default = None)]
    pub z_near_m: Option<f64>,
    /// Farthest scene depth in metres mapped to the back of the volume; give both or neither.
    #[uniffi(default = None)]
    pub z_far_m: Option<f64>,
    /// Where frames are computed; `None` = [`Backend::Auto`] ([`GeneratorInfo::backend`] says which runs).
    #[uniffi(default = None)]
    pub backend: Option<Backend>,
    /// The GPU CNNs' arithmetic; `None` = [`GpuPrecision::Auto`].
    #[uniffi(default = None)]
    pub gpu_precision: Option<GpuPrecision>,
    /// The CPU CNN engine; `None` = [`CnnEngine::Auto`] ([`GeneratorInfo::cnn_engine`] says which runs).
    #[uniffi(default = None)]
    pub engine: Option<CnnEngine>,
    /// Largest relative spread (a fraction: 0.01 = 1 %) of the lasers' depth scales accepted when the CNNs
    /// were trained for another, Fresnel-equivalent display (`docs/DISPLAYS.md`); `None` (default): the
    /// serving rule's, an estimated cost within 0.3 dB of the model's own score (about 1.8–2 %). A value
    /// wider than that shows as "widened" in [`GeneratorInfo::display_mapping`], with its cost.
    #[uniffi(default = None)]
    pub wavelength_ratio_tolerance: Option<f64>,
    /// Time the CNN candidates on this device at creation (engines, each layer's kernel row, threads; up to
    /// a few seconds) instead of taking the plan table's (default `false`: the same SLM codes on every run).
    /// [`GeneratorInfo::saved_plans`] then holds the result, to store and pass as `saved_plans` later.
    #[uniffi(default = false)]
    pub tune: bool,
    /// CNN plans stored from an earlier generator's [`GeneratorInfo::saved_plans`] (a
    /// `tensorholo.cnn-plans` JSON text): repeated without timing, so every run gives the same codes.
    /// `None` (default): the plan table (or `tune`). Refused with `tune`, or when made on a device whose
    /// kernels differ (another CPU class).
    #[uniffi(default = None)]
    pub saved_plans: Option<String>,
}

impl GeneratorConfig {
    /// The core configuration. Errors: [`TensorholoError::InvalidInput`] for a non-finite or out-of-range
    /// number, a wavelength list that is neither empty nor 3 long, or only one of `z_near_m`/`z_far_m`.
    fn to_core(&self) -> Result<core::GeneratorConfig> {
        // Every field left `None` keeps the core's default (`core::GeneratorConfig::new`); the numeric
        // fields' uniffi defaults restate the core's, which `tests::uniffi_defaults_are_the_cores` pins.
        let mut c = core::GeneratorConfig::new(self.width as usize, self.height as usize);
        if let Some(input) = self.input {
            c.models.input = match input {
                SceneInput::Rgbd => tensorholo::model::SceneInput::Rgbd,
                SceneInput::Ldi => tensorholo::model::SceneInput::Ldi,
            };
        }
        c.models.layers = self.layers as usize;
        if let Some(precision) = self.precision {
            c.models.precision = match precision {
                Precision::F32 => tensorholo::model::Precision::F32,
                Precision::Int8 => DEFAULT_INT8,
            };
        }
        if let Some(prefilter) = self.prefilter {
            c.models.prefilter = match prefilter {
                PrefilterMode::Auto => tensorholo::pipeline::PrefilterMode::Auto,
                PrefilterMode::Off => tensorholo::pipeline::PrefilterMode::Off,
                PrefilterMode::Required => tensorholo::pipeline::PrefilterMode::Required,
            };
        }
        c.offset_m = self.offset_mm * 1e-3;
        c.threads = ThreadCount::from_count(self.threads as usize);
        if let Some(fit) = self.fit {
            c.fit = fit.into();
        }
        if let Some(backend) = self.backend {
            c.backend = match backend {
                Backend::Auto => tensorholo::pipeline::Backend::Auto,
                Backend::Cpu => tensorholo::pipeline::Backend::Cpu,
                Backend::Gpu => tensorholo::pipeline::Backend::Gpu,
            };
        }
        if let Some(engine) = self.engine {
            c.engine = match engine {
                CnnEngine::Auto => tensorholo::cnn::CnnEngine::Auto,
                CnnEngine::Native => tensorholo::cnn::CnnEngine::Native,
                CnnEngine::Tract => tensorholo::cnn::CnnEngine::Tract,
            };
        }
        if let Some(precision) = self.gpu_precision {
            c.gpu_precision = match precision {
                GpuPrecision::Auto => tensorholo::pipeline::GpuPrecision::Auto,
                GpuPrecision::F32 => tensorholo::pipeline::GpuPrecision::F32,
                GpuPrecision::F16 => tensorholo::pipeline::GpuPrecision::F16,
            };
        }
        let wavelengths_m = match self.wavelengths_m[..] {
            [] => c.optics.wavelengths_m,
            [r, g, b] => [r, g, b],
            _ => {
                return Err(invalid(format!(
                    "wavelengths_m holds red, green, blue (3 values) or nothing, got {}",
                    self.wavelengths_m.len()
                )))
            }
        };
        c.optics = OpticalSetup {
            wavelengths_m,
            pixel_pitch_m: self.pixel_pitch_m,
            volume_depth_m: self.volume_depth_m,
        };
        c.depth_range = match (self.z_near_m, self.z_far_m) {
            (None, None) => None,
            (Some(n), Some(f)) => Some(DepthRange::new(n as f32, f as f32)?),
            _ => {
                return Err(invalid(
                    "give both z_near_m and z_far_m, or neither (automatic range)",
                ))
            }
        };
        c.wavelength_ratio_tolerance = self.wavelength_ratio_tolerance;
        c.tune = self.tune;
        c.saved_plans = match &self.saved_plans {
            Some(json) => Some(Arc::new(tensorholo::cnn::SavedPlans::from_json(json)?)),
            None => None,
        };
        c.validate()?;
        Ok(c)
    }
}

impl From<core::GeneratorConfig> for GeneratorConfig {
    /// The record of a core configuration (every field the record has; the core's `layout`, `options`,
    /// `encoding` and `depth_mapping` have no field here and are the defaults on the way back).
    fn from(c: core::GeneratorConfig) -> Self {
        Self {
            width: c.width as u32,
            height: c.height as u32,
            layers: c.models.layers as u32,
            input: Some(match c.models.input {
                tensorholo::model::SceneInput::Rgbd => SceneInput::Rgbd,
                tensorholo::model::SceneInput::Ldi => SceneInput::Ldi,
            }),
            precision: Some(match c.models.precision {
                tensorholo::model::Precision::F32 => Precision::F32,
                tensorholo::model::Precision::Int8QOperator
                | tensorholo::model::Precision::Int8Qdq => Precision::Int8,
            }),
            offset_mm: c.offset_m * 1e3,
            prefilter: Some(match c.models.prefilter {
                tensorholo::pipeline::PrefilterMode::Auto => PrefilterMode::Auto,
                tensorholo::pipeline::PrefilterMode::Off => PrefilterMode::Off,
                tensorholo::pipeline::PrefilterMode::Required => PrefilterMode::Required,
            }),
            threads: match c.threads {
                ThreadCount::Auto => 0,
                ThreadCount::Fixed(n) => n as u32,
                // tract's one-thread default executor: one thread.
                ThreadCount::ProcessDefault => 1,
            },
            fit: Some(match c.fit {
                scene::Fit::Crop => Fit::Crop,
                scene::Fit::Letterbox => Fit::Letterbox,
                scene::Fit::Stretch => Fit::Stretch,
            }),
            pixel_pitch_m: c.optics.pixel_pitch_m,
            wavelengths_m: c.optics.wavelengths_m.to_vec(),
            volume_depth_m: c.optics.volume_depth_m,
            z_near_m: c.depth_range.map(|r| r.z_near_m as f64),
            z_far_m: c.depth_range.map(|r| r.z_far_m as f64),
            backend: Some(match c.backend {
                tensorholo::pipeline::Backend::Auto => Backend::Auto,
                tensorholo::pipeline::Backend::Cpu => Backend::Cpu,
                tensorholo::pipeline::Backend::Gpu => Backend::Gpu,
            }),
            gpu_precision: Some(match c.gpu_precision {
                tensorholo::pipeline::GpuPrecision::Auto => GpuPrecision::Auto,
                tensorholo::pipeline::GpuPrecision::F32 => GpuPrecision::F32,
                tensorholo::pipeline::GpuPrecision::F16 => GpuPrecision::F16,
            }),
            engine: Some(match c.engine {
                tensorholo::cnn::CnnEngine::Auto => CnnEngine::Auto,
                tensorholo::cnn::CnnEngine::Native => CnnEngine::Native,
                tensorholo::cnn::CnnEngine::Tract => CnnEngine::Tract,
            }),
            wavelength_ratio_tolerance: c.wavelength_ratio_tolerance,
            tune: c.tune,
            saved_plans: c.saved_plans.map(|p| p.to_json()),
        }
    }
}

/// A holographic display as its profile file describes it (`docs/DISPLAYS.md`): the SLM's pitch and
/// resolution, the lasers, the volume and the offsets, in SI units (metres). Read one with
/// [`display_profile_from_json`] or fill the fields; [`generator_config_for_display`] checks it and makes
/// the [`GeneratorConfig`] for that display. The shipped CNNs (8 µm, 638/520/450 nm, 6 mm volume) serve any
/// display with one depth scale `σ = (λ/λ')·(p'/8 µm)²` for the three lasers, a volume of `σ`·6 mm and
/// offsets of `σ`·6 or `σ`·12 mm: at 4 µm, `σ` = 0.25, a 1.5 mm volume and offsets of 1.5 and 3 mm.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct DisplayProfile {
    /// `pixel_pitch_m`: SLM pixel pitch in metres (finite, > 0), e.g. 4e-6.
    pub pixel_pitch_m: f64,
    /// `resolution`: SLM size `[height, width]` in pixels (2 values, each ≥ 1).
    pub resolution: Vec<u32>,
    /// `wavelengths_m`: laser wavelengths `[R, G, B]` in metres (3 values within 380–780 nm), e.g.
    /// 638e-9, 520e-9, 450e-9.
    pub wavelengths_m: Vec<f64>,
    /// `volume_depth_m`: depth of the 3D volume in metres (finite, > 0), centred on the midpoint hologram.
    pub volume_depth_m: f64,
    /// `offsets_m`: hologram-plane offsets `s` in metres (finite, at least one); the first is the one
    /// [`generator_config_for_display`] takes.
    pub offsets_m: Vec<f64>,
    /// `name`: free text for reports; `None` (default) = none.
    #[uniffi(default = None)]
    pub name: Option<String>,
    /// `calibration`: the display's `.holocal` file as the profile gives it (a relative path stays relative),
    /// or `None` (default) for an ideal SLM. Not read by the library: the app loads the file's bytes and
    /// passes them to [`HologramGenerator::set_calibration`].
    #[uniffi(default = None)]
    pub calibration: Option<String>,
}

impl DisplayProfile {
    /// The core's profile, checked by the core ([`core_display::DisplayProfile::new`]).
    ///
    /// Errors: [`TensorholoError::InvalidInput`] naming the key: as the core's profile rules (e.g.
    /// `resolution` not 2 values, a non-positive `pixel_pitch_m`, a wavelength outside 380–780 nm).
    fn to_core(&self) -> Result<core_display::DisplayProfile> {
        let resolution: Vec<usize> = self.resolution.iter().map(|&n| n as usize).collect();
        Ok(core_display::DisplayProfile::new(
            self.name.clone(),
            self.pixel_pitch_m,
            &resolution,
            &self.wavelengths_m,
            self.volume_depth_m,
            self.offsets_m.clone(),
            self.calibration.clone().map(Into::into),
        )?)
    }

    /// The record of a core profile.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] (`resolution`) for a size beyond `u32`.
    fn from_core(p: core_display::DisplayProfile) -> Result<Self> {
        let resolution = p
            .resolution
            .iter()
            .map(|&n| u32::try_from(n))
            .collect::<std::result::Result<Vec<u32>, _>>()
            .map_err(|_| {
                invalid(format!(
                    "display profile key `resolution`: {:?} exceeds {} pixels",
                    p.resolution,
                    u32::MAX
                ))
            })?;
        Ok(Self {
            pixel_pitch_m: p.pixel_pitch_m,
            resolution,
            wavelengths_m: p.wavelengths_m.to_vec(),
            volume_depth_m: p.volume_depth_m,
            offsets_m: p.offsets_m,
            name: p.name,
            calibration: p.calibration.map(|c| c.to_string_lossy().into_owned()),
        })
    }
}

/// Reads a display profile from its JSON text (a profile file's contents, `docs/DISPLAYS.md`): keys
/// `pixel_pitch_m`, `resolution`, `wavelengths_m`, `volume_depth_m`, `offsets_m` (SI units), optional `name`
/// and `calibration`; unknown keys are refused.
///
/// Errors: [`TensorholoError::InvalidInput`] whose message names the key at fault (a missing key, a wrong
/// type or array length, a non-positive pitch or volume, a wavelength outside 380–780 nm, an unknown key) or
/// says the text is not a JSON object.
#[uniffi::export]
pub fn display_profile_from_json(json: String) -> Result<DisplayProfile> {
    guard(|| DisplayProfile::from_core(core_display::DisplayProfile::from_json_str(&json)?))
}

/// The [`GeneratorConfig`] for a display: `width`/`height` from its `resolution`, its pitch, lasers and
/// volume, its first offset; every other field at its default (change them before making the generator).
///
/// Errors: [`TensorholoError::InvalidInput`] naming the key for a profile that breaks the profile rules (as
/// [`display_profile_from_json`]). Whether the CNNs serve the display is checked by [`HologramGenerator::new`]
/// ([`TensorholoError::InvalidModel`] naming `wavelengths_m` for lasers whose spread costs more than the
/// rule allows, `volume_depth_m` for a volume deeper than `σ`·6 mm, `pixel_pitch_m` for a pitch too fine,
/// each with what would serve) and beforehand by [`check_display`].
#[uniffi::export]
pub fn generator_config_for_display(profile: DisplayProfile) -> Result<GeneratorConfig> {
    guard(|| Ok(core::GeneratorConfig::for_display(&profile.to_core()?).into()))
}

/// One shipped CNN against a display ([`check_display`]): whether it serves the display at one offset and
/// at what estimated cost, or why not and what would serve.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct ShippedModelCheck {
    /// The embedded file (`holo8_rgbd.onnx`, …); empty where no pre-filter is shipped for the offset.
    pub file: String,
    /// `hologram-cnn` or `prefilter-cnn`.
    pub kind: String,
    /// Layers of the hologram CNN (a pre-filter: of the CNN it pairs with).
    pub layers: u32,
    /// `rgbd` or `ldi`.
    pub input: String,
    /// `f32` or `int8-qdq`.
    pub precision: String,
    /// The offset checked, millimetres.
    pub offset_mm: f64,
    /// Whether the model serves the display at this offset.
    pub served: bool,
    /// `σ`, the depth scale of the mapping (served only).
    pub scale: Option<f64>,
    /// The lasers' spread, percent (served only).
    pub spread_pct: Option<f64>,
    /// The mapping's predicted ceiling in dB (served with a spread; `None` for no spread: no ceiling).
    pub ceiling_db: Option<f64>,
    /// The mapping's estimated cost in dB (served only).
    pub cost_db: Option<f64>,
    /// The mapping in one line (served), or why not and what would serve (refused), or why no model was
    /// checked.
    pub detail: String,
    /// Refused: the nearest display this model serves, as a profile JSON to save (this profile with the
    /// lasers, volume or offset changed).
    pub nearest_profile_json: Option<String>,
    /// Refused for its lasers: the `wavelength_ratio_tolerance` that serves the display as it is.
    pub tolerance: Option<f64>,
    /// The estimated cost in dB at that tolerance.
    pub tolerance_cost_db: Option<f64>,
}

/// Which shipped CNNs serve a display, before making a generator (`holo display check`): at each of the
/// profile's offsets, every hologram CNN of this library (each depth, f32 and int8) and the pre-filter each
/// pairs with, with `wavelength_ratio_tolerance` (`None`: the serving rule's).
///
/// Errors: [`TensorholoError::InvalidInput`] for a profile that breaks the profile rules or a bad tolerance;
/// [`TensorholoError::Unsupported`] in a library built without the shipped CNNs.
#[uniffi::export]
pub fn check_display(
    profile: DisplayProfile,
    wavelength_ratio_tolerance: Option<f64>,
) -> Result<Vec<ShippedModelCheck>> {
    guard(|| shipped_checks(profile.to_core()?, wavelength_ratio_tolerance))
}

#[cfg(not(feature = "embedded-models"))]
fn shipped_checks(
    _profile: core_display::DisplayProfile,
    _tolerance: Option<f64>,
) -> Result<Vec<ShippedModelCheck>> {
    Err(TensorholoError::Unsupported {
        message:
            "this library was built without the shipped CNNs (cargo feature `embedded-models`)"
                .into(),
    })
}

#[cfg(feature = "embedded-models")]
fn shipped_checks(
    profile: core_display::DisplayProfile,
    tolerance: Option<f64>,
) -> Result<Vec<ShippedModelCheck>> {
    let checks = tensorholo::model::embedded::check_display(
        &profile.optics(),
        &profile.offsets_m,
        tolerance,
    )?;
    Ok(checks
        .into_iter()
        .map(|c| {
            let m = c.mapping.as_ref();
            let detail = match (&c.mapping, &c.refusal, &c.note) {
                (Some(m), _, _) => m.description(&c.file),
                (None, Some(r), _) => r.to_string(),
                (None, None, note) => note.clone().unwrap_or_default(),
            };
            let nearest = c
                .refusal
                .as_ref()
                .and_then(|r| Some(profile.with_display(&r.nearest?).to_json()));
            let tolerance = c.refusal.as_ref().and_then(|r| r.tolerance);
            ShippedModelCheck {
                file: c.file.clone(),
                kind: c.kind.to_string(),
                layers: c.layers as u32,
                input: c.input.clone(),
                precision: c.precision.to_string(),
                offset_mm: c.offset_m * 1e3,
                served: c.served(),
                scale: m.map(|m| m.scale),
                spread_pct: m.map(|m| m.spread() * 100.0),
                ceiling_db: m.map(|m| m.ceiling_db).filter(|x| x.is_finite()),
                cost_db: m.map(|m| m.cost_db),
                detail,
                nearest_profile_json: nearest,
                tolerance: tolerance.map(|t| t.0),
                tolerance_cost_db: tolerance.map(|t| t.1),
            }
        })
        .collect())
}

impl From<Fit> for scene::Fit {
    fn from(f: Fit) -> Self {
        match f {
            Fit::Crop => Self::Crop,
            Fit::Letterbox => Self::Letterbox,
            Fit::Stretch => Self::Stretch,
        }
    }
}

impl From<ColorFormat> for scene::ColorFormat {
    fn from(f: ColorFormat) -> Self {
        match f {
            ColorFormat::Rgba8 => Self::Rgba8,
            ColorFormat::Bgra8 => Self::Bgra8,
            ColorFormat::Rgb8 => Self::Rgb8,
        }
    }
}

impl From<DepthFormat> for scene::DepthFormat {
    fn from(f: DepthFormat) -> Self {
        match f {
            DepthFormat::MetresF32 => Self::MetresF32,
            DepthFormat::MetresF16 => Self::MetresF16,
            DepthFormat::DisparityF32 => Self::DisparityF32,
            DepthFormat::DisparityF16 => Self::DisparityF16,
            DepthFormat::MillimetresU16 => Self::MillimetresU16,
            DepthFormat::Depth16 => Self::Depth16,
        }
    }
}

impl From<Rotation> for scene::Rotation {
    fn from(r: Rotation) -> Self {
        match r {
            Rotation::Deg0 => Self::Deg0,
            Rotation::Deg90 => Self::Deg90,
            Rotation::Deg180 => Self::Deg180,
            Rotation::Deg270 => Self::Deg270,
        }
    }
}

/// One camera frame as the phone delivers it: an interleaved 8-bit colour buffer and a depth buffer of the
/// same field of view, each at its own resolution with its own row stride (bytes; 0 = packed).
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct RgbdFrame {
    /// Colour bytes (`color_format`), rows `color_row_stride` apart.
    pub color: Vec<u8>,
    /// Colour pixel layout.
    pub color_format: ColorFormat,
    /// Colour width in pixels.
    pub color_width: u32,
    /// Colour height in pixels.
    pub color_height: u32,
    /// Depth bytes (`depth_format`, little-endian), rows `depth_row_stride` apart.
    pub depth: Vec<u8>,
    /// Depth sample format.
    pub depth_format: DepthFormat,
    /// Depth width in pixels.
    pub depth_width: u32,
    /// Depth height in pixels.
    pub depth_height: u32,
    /// Bytes from one colour row to the next; 0 (default) = packed.
    #[uniffi(default = 0)]
    pub color_row_stride: u32,
    /// Bytes from one depth row to the next; 0 (default) = packed.
    #[uniffi(default = 0)]
    pub depth_row_stride: u32,
    /// Clockwise rotation making both buffers upright; `None` (default) = none.
    #[uniffi(default = None)]
    pub rotation: Option<Rotation>,
    /// The rectangle of the colour buffer (colour pixels, before the rotation) that covers the depth
    /// buffer's field of view; `None` (default) = the whole colour buffer. ARCore needs it: its depth covers
    /// the GPU texture's field of view (usually 16:9), a band of the 4:3 CPU image (Android:
    /// `RgbdFrames.fromArFrame` fills it). Errors: [`TensorholoError::InvalidInput`] when it is empty or not
    /// inside the colour buffer.
    #[uniffi(default = None)]
    pub color_crop: Option<CropRect>,
}

/// A rectangle of a colour buffer in pixels, before any rotation: columns `x .. x + width`, rows
/// `y .. y + height` (`(x, y)` = its top-left pixel).
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Record)]
pub struct CropRect {
    /// First column.
    pub x: u32,
    /// First row.
    pub y: u32,
    /// Columns (≥ 1).
    pub width: u32,
    /// Rows (≥ 1).
    pub height: u32,
}

impl From<CropRect> for scene::CropRect {
    fn from(c: CropRect) -> Self {
        Self {
            x: c.x as usize,
            y: c.y as usize,
            width: c.width as usize,
            height: c.height as usize,
        }
    }
}

impl RgbdFrame {
    /// The core's owned frame (the byte vectors move, nothing is copied).
    fn into_core(self) -> scene::CameraFrameBuf {
        scene::CameraFrameBuf {
            color: scene::ColorImageBuf {
                data: self.color,
                format: self.color_format.into(),
                width: self.color_width as usize,
                height: self.color_height as usize,
                row_stride: self.color_row_stride as usize,
            },
            depth: scene::DepthImageBuf {
                data: self.depth,
                format: self.depth_format.into(),
                width: self.depth_width as usize,
                height: self.depth_height as usize,
                row_stride: self.depth_row_stride as usize,
            },
            rotation: self.rotation.unwrap_or(Rotation::Deg0).into(),
            color_crop: self.color_crop.map(Into::into),
        }
    }
}

/// A camera frame as the CNN receives it ([`convert_frame`]): `width × height` pixels, upright, registered
/// and fitted.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct ConvertedFrame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear amplitude (√ of the linear intensity, in [0, 1]): three planes R, G, B of `width · height`
    /// values each, row-major (`3 · width · height` values).
    pub amplitude: Vec<f32>,
    /// Normalised depth `d` in [0, 1], 0 = near, row-major (`width · height` values); holes filled with
    /// the farthest neighbouring depth.
    pub depth: Vec<f32>,
    /// Nearest depth in metres mapped to `d = 0` (the 1st percentile of the frame's valid depths).
    pub z_near_m: Option<f64>,
    /// Farthest depth in metres mapped to `d = 1` (the 99th percentile).
    pub z_far_m: Option<f64>,
}

/// Converts a camera frame the way a generator does before its CNN (crop, rotation, depth to the colour
/// grid, automatic depth range, hole filling, `fit` to `width × height`; `fit` `None` = [`Fit::Crop`]),
/// without rendering: to check the orientation and the depth–colour registration on a device, e.g. by
/// drawing `depth` over `amplitude`.
///
/// Errors: [`TensorholoError::InvalidInput`] for a `width` or `height` of 0, buffers that do not match
/// their sizes, strides and formats, a bad `color_crop`, or a depth map without one valid pixel.
#[uniffi::export]
pub fn convert_frame(
    frame: RgbdFrame,
    width: u32,
    height: u32,
    fit: Option<Fit>,
) -> Result<ConvertedFrame> {
    guard(|| {
        let frame = frame.into_core();
        let options = scene::FrameOptions {
            fit: fit.unwrap_or(Fit::Crop).into(),
            ..scene::FrameOptions::default()
        };
        let (rgbd, report) = frame
            .view()
            .to_rgbd(height as usize, width as usize, &options)?;
        Ok(ConvertedFrame {
            width,
            height,
            amplitude: rgbd.amplitude.iter().copied().collect(),
            depth: rgbd.depth.iter().copied().collect(),
            z_near_m: report.range_used.map(|r| r.z_near_m as f64),
            z_far_m: report.range_used.map(|r| r.z_far_m as f64),
        })
    })
}

/// Milliseconds of each stage of one frame.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct StageTimings {
    /// Camera buffers → the CNN's input (decode, rotate, fill holes, fit).
    pub convert_ms: f64,
    /// Hologram CNN.
    pub cnn_ms: f64,
    /// Offset propagation to the SLM (Eq. 6).
    pub offset_ms: f64,
    /// Pre-filter CNN alone (0 without one).
    pub prefilter_ms: f64,
    /// Double phase encoding and look-up table (Eq. 7), with turning the pre-filter CNN's output into the
    /// field where there is one.
    pub encoding_ms: f64,
    /// On the GPU: the whole GPU frame (CNNs and optics; the three stage fields above are then 0 and
    /// `cnn_ms` is the CPU's input checks and packing). 0 on the CPU.
    pub gpu_ms: f64,
    /// CNN to codes (in a stream: the frame period).
    pub total_ms: f64,
}

/// One frame's SLM patterns: three 8-bit planes, one per laser (field-sequential colour), `width · height`
/// codes each, row-major; code `c` displays phase `2π·c/256`.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct SlmPatterns {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Red laser's pattern.
    pub red: Vec<u8>,
    /// Green laser's pattern.
    pub green: Vec<u8>,
    /// Blue laser's pattern.
    pub blue: Vec<u8>,
    /// Nearest scene depth (metres) mapped to the volume in this frame, if the depth was metric.
    pub z_near_m: Option<f64>,
    /// Farthest scene depth (metres) mapped to the volume in this frame.
    pub z_far_m: Option<f64>,
    /// Stage timings.
    pub timings: StageTimings,
}

impl From<core::SlmPatterns> for SlmPatterns {
    fn from(p: core::SlmPatterns) -> Self {
        let plane = |c: usize| p.codes.index_axis(Axis(0), c).iter().copied().collect();
        let t = p.timings;
        Self {
            width: p.width as u32,
            height: p.height as u32,
            red: plane(0),
            green: plane(1),
            blue: plane(2),
            z_near_m: p.depth_range.map(|r| r.z_near_m as f64),
            z_far_m: p.depth_range.map(|r| r.z_far_m as f64),
            timings: t.into(),
        }
    }
}

impl From<core::PatternTimings> for StageTimings {
    fn from(t: core::PatternTimings) -> Self {
        Self {
            convert_ms: t.convert_s * 1e3,
            cnn_ms: t.frame.cnn_s * 1e3,
            offset_ms: t.frame.offset_s * 1e3,
            prefilter_ms: t.frame.prefilter_s * 1e3,
            encoding_ms: t.frame.encoding_s * 1e3,
            gpu_ms: t.frame.gpu_s * 1e3,
            total_ms: t.frame.total_s * 1e3,
        }
    }
}

/// The 32-bit frame colour-sequential SLM drivers take over HDMI: `width · height · 4` bytes, row-major, the
/// red laser's pattern in R, green in G, blue in B, alpha 255.
///
/// Errors: [`TensorholoError::InvalidInput`] if a plane does not hold `width · height` codes.
#[uniffi::export]
pub fn pack_rgba(patterns: SlmPatterns) -> Result<Vec<u8>> {
    guard(|| {
        let n = (patterns.width as usize)
            .checked_mul(patterns.height as usize)
            .ok_or_else(|| invalid("width · height overflows"))?;
        for (name, p) in [
            ("red", &patterns.red),
            ("green", &patterns.green),
            ("blue", &patterns.blue),
        ] {
            if p.len() != n {
                return Err(invalid(format!(
                    "the {name} plane holds {} codes, expected width · height = {n}",
                    p.len()
                )));
            }
        }
        Ok(core::pack_rgba_planes(
            &patterns.red,
            &patterns.green,
            &patterns.blue,
        )?)
    })
}

/// A simulated view of the hologram for the phone's screen: `width · height · 4` sRGB bytes (RGBA, alpha
/// 255), row-major.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct Preview {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// RGBA8 bytes.
    pub rgba: Vec<u8>,
}

/// What a generator runs.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct GeneratorInfo {
    /// Library version.
    pub version: String,
    /// Hologram width in pixels.
    pub width: u32,
    /// Hologram height in pixels.
    pub height: u32,
    /// Hologram CNN depth.
    pub layers: u32,
    /// Weight format (`f32`, `int8-qdq`, …).
    pub precision: String,
    /// Hologram CNN (embedded file name).
    pub hologram_model: String,
    /// Pre-filter CNN, if one runs.
    pub prefilter_model: Option<String>,
    /// Why a pre-filter runs or not.
    pub prefilter_reason: String,
    /// SLM offset in millimetres.
    pub offset_mm: f64,
    /// CPU CNN engine that runs (`native` or `tract`).
    pub cnn_engine: String,
    /// Why that engine (e.g. "faster on this CPU (2.41× tract's best)").
    pub cnn_engine_reason: String,
    /// The native engine's kernel row (e.g. `conv3x3.f32.6x2.avx2`, `conv3x3.u8s8.4x1.avx2`), if it runs.
    pub cnn_kernel: Option<String>,
    /// Chosen CNN memory layout (`nchw` or `nhwc`).
    pub cnn_layout: String,
    /// Chosen CNN threads.
    pub cnn_threads: u32,
    /// Whether the plan was chosen by timing candidates on this device.
    pub autotuned: bool,
    /// Where the CNN plan came from: `table` (the plan table, nothing timed), `saved`
    /// ([`GeneratorConfig::saved_plans`]) or `tuned` ([`GeneratorConfig::tune`]).
    pub cnn_plan_source: String,
    /// The same in words (with saved plans: what they decided and what the table filled in).
    pub cnn_plan_detail: String,
    /// This generator's CNN plans as a `tensorholo.cnn-plans` JSON text: store it (after a `tune` run) and
    /// pass it as [`GeneratorConfig::saved_plans`] to repeat them.
    pub saved_plans: String,
    /// What computes the frames now: `cpu` or `gpu`.
    pub backend: String,
    /// Why (no GPU, the first frame's self-check, a GPU failure mid-stream, …).
    pub backend_reason: String,
    /// The GPU adapter, where one was used or tried.
    pub gpu_adapter: Option<String>,
    /// The display calibration applied ([`HologramGenerator::set_calibration`]), in words, e.g.
    /// `"1080×1920 SLM: red tiled (16×16 px), green global, blue linear; intensity map: none"`.
    pub calibration: Option<String>,
    /// How the hologram CNN's training display maps onto this display, in one line, e.g. "the 8-layer
    /// hologram CNN (trained at 8 µm, 6 mm volume) serves 4 µm with a 1.5 mm volume (σ = 0.250000); offset
    /// 1.5 mm ↔ 6 mm trained; wavelength mismatch 0.00 % (tolerance 0.50 %); non-paraxial residual 0.084 rad
    /// (bound 0.25 rad)" (`docs/DISPLAYS.md`).
    pub display_mapping: String,
    /// Everything above and the autotuning timings, as JSON.
    pub json: String,
}

/// Median per-stage timings of [`HologramGenerator::benchmark`].
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct BenchmarkReport {
    /// Frames timed (after one warm-up frame).
    pub frames: u32,
    /// Median stage timings.
    pub median: StageTimings,
    /// Frames per second of the median frame (`1000 / (convert_ms + total_ms)`).
    pub fps: f64,
    /// The generator's [`GeneratorInfo`] (chosen plan, threads).
    pub info: GeneratorInfo,
}

/// RGB-D camera frames → SLM patterns with the shipped CNNs. Any thread may call it; calls run one at a time.
#[derive(Debug, uniffi::Object)]
pub struct HologramGenerator {
    inner: core::HologramGenerator,
}

#[uniffi::export]
impl HologramGenerator {
    /// Loads the shipped CNNs and prepares everything for `config.width × config.height` frames (the CNN
    /// plans from the plan table, or timed on the device with `config.tune`: up to a few seconds).
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for a bad configuration (sizes, NaN or negative numbers,
    /// layers other than 8/15/30, a required pre-filter that is not shipped for the offset);
    /// [`TensorholoError::InvalidModel`] if an embedded model fails its checks.
    /// [`TensorholoError::Unsupported`] in a library built without the shipped CNNs (cargo feature
    /// `embedded-models` off): use [`HologramGenerator::with_models`].
    #[uniffi::constructor]
    pub fn new(config: GeneratorConfig) -> Result<Arc<Self>> {
        guard(|| {
            let config = config.to_core()?;
            #[cfg(feature = "embedded-models")]
            let inner = core::HologramGenerator::new(config)?;
            #[cfg(not(feature = "embedded-models"))]
            let inner: core::HologramGenerator = {
                let _ = config;
                Err(TensorholoError::Unsupported {
                    message: "this library was built without the shipped CNNs (cargo feature \
                              `embedded-models`); pass ONNX files to HologramGenerator.withModels"
                        .into(),
                })?
            };
            Ok(Arc::new(Self { inner }))
        })
    }

    /// As [`HologramGenerator::new`] with ONNX files instead of the embedded CNNs: the app's own trained
    /// weights, or the shipped `models/` files downloaded at run time by an app that leaves them out of its
    /// binary. `hologram_onnx`: an RGB-D hologram CNN (e.g. `holo8_rgbd.onnx`); `prefilter_onnx`: a DDPM
    /// pre-filter CNN for `config.offset_mm` (e.g. `prefilter_6mm.onnx`), or none for AA-DPM encoding.
    /// `config.layers`, `precision` and `prefilter` are ignored: the files say what they are.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for a bad configuration; [`TensorholoError::InvalidModel`]
    /// for bytes that are not such a model, or a model trained for another display (wavelengths, pixel
    /// pitch, volume depth) or, for the pre-filter, another offset (the message names the key and both
    /// values).
    #[uniffi::constructor]
    pub fn with_models(
        config: GeneratorConfig,
        hologram_onnx: Vec<u8>,
        prefilter_onnx: Option<Vec<u8>>,
    ) -> Result<Arc<Self>> {
        guard(|| {
            let inner = core::HologramGenerator::from_onnx(
                config.to_core()?,
                &hologram_onnx,
                prefilter_onnx.as_deref(),
            )?;
            Ok(Arc::new(Self { inner }))
        })
    }

    /// Renders one camera frame into SLM patterns.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for buffers that do not match their sizes, strides and
    /// formats, or a depth map without one valid pixel; the generator stays usable.
    pub fn render(&self, frame: RgbdFrame) -> Result<SlmPatterns> {
        guard(|| {
            let frame = frame.into_core();
            Ok(self.inner.render(&frame.view())?.into())
        })
    }

    /// Renders a layered depth image into SLM patterns: one [`RgbdFrame`] per layer, front to back (what a
    /// renderer's depth-peeling pass gives), each with the buffer rules of [`HologramGenerator::render`]. In
    /// the layers behind the first, a depth sample of 0 (or NaN, or confidence 0 %) means "no point here"; a
    /// point may appear only where the layer in front holds one, no nearer than it. All layers share one
    /// depth range (`z_near_m`/`z_far_m`, or the 1st/99th percentiles of every layer's depths). Needs a
    /// generator made with `input` = [`SceneInput::Ldi`]; fewer layers than its CNN takes (5) are padded with
    /// empty ones.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for no layer, more layers than the CNN takes (with an RGB-D
    /// generator: more than one), layers whose colour sizes differ, a back layer nearer than the one in front
    /// of it, and as [`HologramGenerator::render`]; the generator stays usable.
    pub fn render_ldi(&self, layers: Vec<RgbdFrame>) -> Result<SlmPatterns> {
        guard(|| {
            let buffers: Vec<scene::CameraFrameBuf> =
                layers.into_iter().map(RgbdFrame::into_core).collect();
            let views: Vec<scene::CameraFrame<'_>> =
                buffers.iter().map(scene::CameraFrameBuf::view).collect();
            Ok(self.inner.render_ldi(&views)?.into())
        })
    }

    /// Renders `frame` and returns what a viewer sees focused at normalised depth `focus` ∈ [0, 1]
    /// (0 = near), for the phone's screen.
    ///
    /// Errors: as [`HologramGenerator::render`], and for a focus outside [0, 1].
    pub fn preview(&self, frame: RgbdFrame, focus: f32) -> Result<Preview> {
        guard(|| {
            let frame = frame.into_core();
            let p = self.inner.preview(&frame.view(), focus)?;
            Ok(Preview {
                width: p.width as u32,
                height: p.height as u32,
                rgba: p.rgba,
            })
        })
    }

    /// Applies a display calibration file (the bytes of a `.holocal` made by `holo calibrate`, e.g. bundled
    /// with the app or downloaded per device) to the frames rendered from now on and to streams started
    /// later; `None` returns to an ideal SLM (linear look-up tables, no intensity map). Its per-colour
    /// look-up tables turn the double phase pattern into the codes this SLM needs, and its laser intensity
    /// map evens out the illumination (`docs/CALIBRATION.md`).
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for bytes that are not a valid `.holocal` file (truncated,
    /// corrupt, another version: the message says which), a calibration for another SLM size than this
    /// generator's, or one measured at other wavelengths; the generator keeps its calibration.
    pub fn set_calibration(&self, calibration: Option<Vec<u8>>) -> Result<()> {
        guard(|| {
            let calibration = calibration
                .map(|bytes| {
                    tensorholo::slm::DisplayCalibration::from_bytes(
                        &bytes,
                        "calibration (.holocal)",
                    )
                })
                .transpose()?
                .map(Arc::new);
            Ok(self.inner.set_calibration(calibration)?)
        })
    }

    /// The models, precision, pre-filter and CNN plan this generator runs.
    pub fn info(&self) -> Result<GeneratorInfo> {
        guard(|| info(&self.inner))
    }

    /// Renders the built-in test scene `frames` times (after one warm-up) at this generator's resolution and
    /// returns the median stage timings, so an app can show what its device does.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for 0 frames.
    pub fn benchmark(&self, frames: u32) -> Result<BenchmarkReport> {
        guard(|| {
            if frames == 0 {
                return Err(invalid("benchmark needs at least 1 frame"));
            }
            let b = self.inner.benchmark(frames as usize)?;
            Ok(BenchmarkReport {
                frames,
                fps: b.fps,
                median: b.median.into(),
                info: info(&self.inner)?,
            })
        })
    }

    /// Starts a video stream: [`HologramStream::push`] frames, results reach `listener` in frame order on a
    /// background thread. The queue holds 2 frames and drops the oldest when full.
    ///
    /// Errors: [`TensorholoError::Internal`] if the worker thread cannot start.
    pub fn stream(&self, listener: Arc<dyn PatternsListener>) -> Result<Arc<HologramStream>> {
        guard(|| {
            let inner = self.inner.stream(
                Box::new(ListenerBridge(listener)),
                core::DEFAULT_STREAM_CAPACITY,
            )?;
            Ok(Arc::new(HologramStream { inner }))
        })
    }
}

fn info(g: &core::HologramGenerator) -> Result<GeneratorInfo> {
    let i = g.info()?;
    let json = serde_json::to_string(&i).map_err(|e| TensorholoError::Internal {
        message: format!("cannot serialise the generator info: {e}"),
    })?;
    Ok(GeneratorInfo {
        version: i.version,
        width: i.width as u32,
        height: i.height as u32,
        layers: i.layers as u32,
        precision: i.precision.to_string(),
        hologram_model: i.hologram_model,
        prefilter_model: i.prefilter_model,
        prefilter_reason: i.prefilter_reason,
        offset_mm: i.offset_m * 1e3,
        cnn_engine: i.plan.engine.to_string(),
        cnn_engine_reason: i.plan.engine_reason.clone(),
        cnn_kernel: i.plan.kernel.clone(),
        cnn_layout: i.plan.layout.to_string(),
        cnn_threads: i.plan.threads.unwrap_or(1) as u32,
        autotuned: i.plan.autotuned,
        cnn_plan_source: i.plan.source.name().to_string(),
        cnn_plan_detail: i.plan.source_detail.clone(),
        saved_plans: i.plan.saved().to_json(),
        backend: i.backend.active.to_string(),
        backend_reason: i.backend.reason,
        gpu_adapter: i.backend.adapter,
        calibration: i.calibration,
        display_mapping: i.display_mapping,
        json,
    })
}

/// Receives a [`HologramStream`]'s results, implemented by the app (Kotlin/Swift/Python). Called on the
/// stream's background thread, in frame order.
#[uniffi::export(with_foreign)]
pub trait PatternsListener: Send + Sync {
    /// The patterns of frame `index` (the number [`HologramStream::push`] returned for it).
    fn on_patterns(&self, index: u64, patterns: SlmPatterns);
    /// A frame failed (its message starts with `frame <index>:`); the stream goes on.
    fn on_error(&self, error: TensorholoError);
}

struct ListenerBridge(Arc<dyn PatternsListener>);

impl core::StreamListener for ListenerBridge {
    fn on_patterns(&mut self, index: u64, patterns: core::SlmPatterns) {
        self.0.on_patterns(index, patterns.into());
    }
    fn on_error(&mut self, index: u64, error: tensorholo::HoloError) {
        let mut e = TensorholoError::from(error);
        match &mut e {
            TensorholoError::InvalidInput { message }
            | TensorholoError::InvalidModel { message }
            | TensorholoError::Unsupported { message }
            | TensorholoError::Internal { message } => {
                *message = format!("frame {index}: {message}")
            }
        }
        self.0.on_error(e);
    }
}

/// A video stream ([`HologramGenerator::stream`]).
#[derive(Debug, uniffi::Object)]
pub struct HologramStream {
    inner: core::HologramStream,
}

#[uniffi::export]
impl HologramStream {
    /// Queues a frame without waiting for the hologram and returns its index (0, 1, 2… in push order); when
    /// the queue is full the oldest waiting frame is dropped.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] after [`HologramStream::close`].
    pub fn push(&self, frame: RgbdFrame) -> Result<u64> {
        guard(|| Ok(self.inner.push(frame.into_core())?))
    }

    /// Frames dropped so far because the queue was full.
    pub fn dropped_frames(&self) -> u64 {
        self.inner.dropped_frames()
    }

    /// Stops accepting frames, finishes the queued ones and waits: afterwards the listener is called no
    /// more. Calling it again does nothing.
    pub fn close(&self) {
        self.inner.close()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default a generated binding gives `GeneratorConfig`'s `field` (`name: Type = value` in Kotlin,
    /// `name: Type = Type(value)` in Swift), as a number. Other records (`DisplayProfile`) have fields of the
    /// same names: the search starts at `GeneratorConfig`'s definition.
    fn generated_default(source: &str, field: &str) -> f64 {
        let start = source
            .find("data class GeneratorConfig (")
            .or_else(|| source.find("public struct GeneratorConfig:"))
            .expect("no GeneratorConfig in the generated binding");
        let source = &source[start..];
        let at = source
            .find(&format!("{field}`: kotlin."))
            .or_else(|| source.find(&format!("*/{field}: ")))
            .unwrap_or_else(|| panic!("no field {field} in the generated binding"));
        let rest = &source[at..];
        let value = rest[rest.find('=').unwrap() + 1..]
            .trim_start()
            .trim_start_matches("UInt32(")
            .trim_start_matches("Double(");
        // The number alone (`8e-6`, `8u`, `0.005)) {` of the last argument in Swift).
        let end = value
            .find(|c: char| !(c.is_ascii_digit() || ".eE+-".contains(c)))
            .unwrap_or(value.len());
        let value = &value[..end];
        value
            .parse()
            .unwrap_or_else(|e| panic!("{field} = {value:?}: {e}"))
    }

    /// The numeric defaults uniffi writes into Kotlin and Swift (literals in `GeneratorConfig`'s
    /// `#[uniffi(default = …)]`) are the core's: a change on either side fails here. The generated files are
    /// the ones `check-generated.sh` keeps equal to this crate's source.
    #[test]
    fn uniffi_defaults_are_the_cores() {
        let core = core::GeneratorConfig::new(1, 1);
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("generated");
        for file in ["kotlin/tensorholo/tensorholo.kt", "swift/Tensorholo.swift"] {
            let source = std::fs::read_to_string(dir.join(file)).unwrap();
            let field = |kotlin: &str, swift: &str| {
                let name = if file.ends_with(".kt") { kotlin } else { swift };
                generated_default(&source, name)
            };
            assert_eq!(
                field("layers", "layers") as usize,
                core.models.layers,
                "{file}"
            );
            assert_eq!(
                field("offsetMm", "offsetMm") * 1e-3,
                core.offset_m,
                "{file}"
            );
            assert_eq!(
                field("pixelPitchM", "pixelPitchM"),
                core.optics.pixel_pitch_m,
                "{file}"
            );
            assert_eq!(
                field("volumeDepthM", "volumeDepthM"),
                core.optics.volume_depth_m,
                "{file}"
            );
            assert_eq!(
                ThreadCount::from_count(field("threads", "threads") as usize),
                core.threads,
                "{file}"
            );
        }
        assert_eq!(core.wavelength_ratio_tolerance, None);
        // And the fields the tests' config leaves `None` (or at the literal default) are the core's.
        let c = config(64, 48).to_core().unwrap();
        let want = core::GeneratorConfig::new(64, 48);
        assert_eq!(c.models, want.models);
        assert_eq!(c.optics, want.optics);
        assert_eq!(c.offset_m, want.offset_m);
        assert_eq!(
            (c.fit, c.backend, c.gpu_precision),
            (want.fit, want.backend, want.gpu_precision)
        );
        assert_eq!(
            c.wavelength_ratio_tolerance,
            want.wavelength_ratio_tolerance
        );
    }

    const PROFILE_4UM: &str = r#"{
        "name": "4 µm SLM",
        "pixel_pitch_m": 4e-6,
        "resolution": [24, 32],
        "wavelengths_m": [638e-9, 520e-9, 450e-9],
        "volume_depth_m": 1.5e-3,
        "offsets_m": [1.5e-3, 3e-3],
        "calibration": "slm.holocal"
    }"#;

    /// The JSON and the record give the core's profile and the core's `for_display` configuration, through
    /// the record of the configuration and back.
    #[test]
    fn a_display_profile_gives_the_cores_configuration() {
        let p = display_profile_from_json(PROFILE_4UM.into()).unwrap();
        let core_profile = core_display::DisplayProfile::from_json_str(PROFILE_4UM).unwrap();
        assert_eq!(p.to_core().unwrap(), core_profile);
        assert_eq!(p.resolution, vec![24, 32]);
        assert_eq!(p.calibration.as_deref(), Some("slm.holocal"));
        let record = generator_config_for_display(p).unwrap();
        assert_eq!((record.width, record.height), (32, 24));
        assert_eq!(record.wavelength_ratio_tolerance, None);
        let back = record.to_core().unwrap();
        let want = core::GeneratorConfig::for_display(&core_profile);
        assert_eq!(
            (
                back.width,
                back.height,
                back.models,
                back.optics,
                back.threads
            ),
            (
                want.width,
                want.height,
                want.models,
                want.optics,
                want.threads
            )
        );
        assert!((back.offset_m - want.offset_m).abs() < 1e-15);
        assert_eq!(
            (back.fit, back.backend, back.gpu_precision, back.engine),
            (want.fit, want.backend, want.gpu_precision, want.engine)
        );
        assert_eq!(
            back.wavelength_ratio_tolerance,
            want.wavelength_ratio_tolerance
        );
    }

    /// Bad profiles, from JSON or as records, are `InvalidInput` naming the key (the core's rules).
    #[test]
    fn bad_display_profiles_name_the_key() {
        let good = display_profile_from_json(PROFILE_4UM.into()).unwrap();
        let message = |r: Result<GeneratorConfig>| match r {
            Err(TensorholoError::InvalidInput { message }) => message,
            other => panic!("expected InvalidInput, got {other:?}"),
        };
        for (key, record) in [
            (
                "pixel_pitch_m",
                DisplayProfile {
                    pixel_pitch_m: -4e-6,
                    ..good.clone()
                },
            ),
            (
                "resolution",
                DisplayProfile {
                    resolution: vec![24],
                    ..good.clone()
                },
            ),
            (
                "resolution",
                DisplayProfile {
                    resolution: vec![24, 0],
                    ..good.clone()
                },
            ),
            (
                "wavelengths_m",
                DisplayProfile {
                    wavelengths_m: vec![638e-9, 520e-9],
                    ..good.clone()
                },
            ),
            (
                "offsets_m",
                DisplayProfile {
                    offsets_m: vec![],
                    ..good.clone()
                },
            ),
        ] {
            let m = message(generator_config_for_display(record));
            assert!(m.contains(&format!("`{key}`")), "{key}: {m}");
        }
        for (key, json) in [
            ("pixel_pitch_m", PROFILE_4UM.replace("4e-6", "-4e-6")),
            ("resolution", PROFILE_4UM.replace("[24, 32]", "[24, 32, 3]")),
            (
                "pixel_pich_m",
                PROFILE_4UM.replace("pixel_pitch_m", "pixel_pich_m"),
            ),
        ] {
            let m = message(display_profile_from_json(json).map(|_| unreachable!()));
            assert!(m.contains(key), "{key}: {m}");
        }
    }

    /// The display profiles the iOS and Android samples ship, the files in `displays/` and every JSON profile of
    /// `docs/DISPLAYS.md` are valid, and the shipped CNNs serve them at their first offset.
    #[cfg(feature = "embedded-models")]
    #[test]
    fn the_samples_and_documented_display_profiles_are_served() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let read = |file: &str| std::fs::read_to_string(root.join(file)).unwrap();
        let mut profiles: Vec<(String, String)> = [
            "ios/Example/Resources/display.json",
            "android/sample/src/main/assets/display.json",
        ]
        .map(|f| (f.to_string(), read(f)))
        .into();
        let mut files: Vec<_> = std::fs::read_dir(root.join("displays"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        for path in files {
            profiles.push((
                path.display().to_string(),
                std::fs::read_to_string(&path).unwrap(),
            ));
        }
        let docs = read("docs/DISPLAYS.md");
        for (i, block) in docs.split("```json\n").skip(1).enumerate() {
            let json = block.split("```").next().unwrap();
            profiles.push((
                format!("docs/DISPLAYS.md profile {}", i + 1),
                json.to_string(),
            ));
        }
        assert!(profiles.len() >= 9, "{} profiles", profiles.len());
        for (what, json) in profiles {
            let profile = display_profile_from_json(json).unwrap_or_else(|e| panic!("{what}: {e}"));
            let c = generator_config_for_display(profile)
                .and_then(|c| c.to_core())
                .unwrap_or_else(|e| panic!("{what}: {e}"));
            // The model check alone (no session): the display and offset are served.
            tensorholo::pipeline::HologramPipeline::embedded(&c.models, c.pipeline_config())
                .unwrap_or_else(|e| panic!("{what}: {e}"));
        }
    }

    /// A generator for the 4 µm profile renders and reports σ = 0.25.
    #[cfg(feature = "embedded-models")]
    #[test]
    fn a_generator_for_a_4um_display_reports_its_mapping() {
        let p = display_profile_from_json(PROFILE_4UM.into()).unwrap();
        let c = GeneratorConfig {
            threads: 1,
            engine: Some(CnnEngine::Native),
            ..generator_config_for_display(p).unwrap()
        };
        let g = HologramGenerator::new(c).unwrap();
        assert_eq!(g.render(frame()).unwrap().red.len(), 32 * 24);
        let info = g.info().unwrap();
        assert!(info.display_mapping.contains("σ = 0.25"), "{info:?}");
        assert!(info.json.contains("display_mapping"), "{}", info.json);
    }

    fn config(width: u32, height: u32) -> GeneratorConfig {
        GeneratorConfig {
            width,
            height,
            layers: 8,
            input: None,
            precision: None,
            offset_mm: 6.0,
            prefilter: None,
            threads: 1,
            fit: None,
            pixel_pitch_m: 8e-6,
            wavelengths_m: vec![],
            volume_depth_m: 6e-3,
            z_near_m: None,
            z_far_m: None,
            backend: None,
            gpu_precision: None,
            // The plan table's engine, named: the tests need no tract.
            engine: Some(CnnEngine::Native),
            wavelength_ratio_tolerance: None,
            tune: false,
            saved_plans: None,
        }
    }

    /// A tuned generator's plans, stored as text and given to a new generator, give the same codes without
    /// timing; the plan table's give the same codes in every generator; bad or conflicting plans are refused.
    #[cfg(feature = "embedded-models")]
    #[test]
    fn saved_plans_repeat_a_tuned_generator() {
        let tuned = HologramGenerator::new(GeneratorConfig {
            tune: true,
            threads: 0,
            ..config(48, 32)
        })
        .unwrap();
        let info = tuned.info().unwrap();
        assert_eq!(info.cnn_plan_source, "tuned");
        let again = HologramGenerator::new(GeneratorConfig {
            saved_plans: Some(info.saved_plans.clone()),
            threads: 0,
            ..config(48, 32)
        })
        .unwrap();
        let again_info = again.info().unwrap();
        assert_eq!(again_info.cnn_plan_source, "saved");
        assert_eq!(again_info.cnn_kernel, info.cnn_kernel);
        assert_eq!(again_info.cnn_threads, info.cnn_threads);
        let codes = |g: &HologramGenerator| {
            let p = g.render(frame()).unwrap();
            [p.red, p.green, p.blue]
        };
        assert_eq!(codes(&again), codes(&tuned));
        let table = || codes(&HologramGenerator::new(config(48, 32)).unwrap());
        assert_eq!(table(), table());
        for (plans, tune) in [
            (Some("{}".to_string()), false),
            (Some(info.saved_plans), true),
        ] {
            let e = HologramGenerator::new(GeneratorConfig {
                saved_plans: plans,
                tune,
                ..config(48, 32)
            })
            .unwrap_err();
            assert!(matches!(e, TensorholoError::InvalidInput { .. }), "{e:?}");
        }
    }

    /// A 48×32 RGB8 frame with metric depth (a ramp from 0.5 m to 1.5 m) and a few texture edges.
    fn frame() -> RgbdFrame {
        let (w, h) = (48u32, 32u32);
        let mut color = Vec::new();
        let mut depth = Vec::new();
        for y in 0..h {
            for x in 0..w {
                color.extend([(x * 5) as u8, (y * 7) as u8, ((x ^ y) * 9) as u8]);
                depth.extend((0.5 + (x as f32) / w as f32).to_le_bytes());
            }
        }
        RgbdFrame {
            color,
            color_format: ColorFormat::Rgb8,
            color_width: w,
            color_height: h,
            depth,
            depth_format: DepthFormat::MetresF32,
            depth_width: w,
            depth_height: h,
            color_row_stride: 0,
            depth_row_stride: 0,
            rotation: None,
            color_crop: None,
        }
    }

    /// The crop reaches the core: the right half of a frame whose left half is black converts to a
    /// bright frame; a crop outside the buffer is `InvalidInput` naming it.
    #[test]
    fn convert_frame_applies_the_colour_crop() {
        let mut f = frame();
        for (i, px) in f.color.chunks_mut(3).enumerate() {
            let v = if i % 48 < 24 { 0 } else { 255 };
            px.copy_from_slice(&[v; 3]);
        }
        let whole = convert_frame(f.clone(), 24, 32, Some(Fit::Stretch)).unwrap();
        assert_eq!(
            (whole.amplitude.len(), whole.depth.len()),
            (3 * 24 * 32, 24 * 32)
        );
        assert_eq!(whole.amplitude[0], 0.0);
        let crop = CropRect {
            x: 24,
            y: 0,
            width: 24,
            height: 32,
        };
        let right = convert_frame(
            RgbdFrame {
                color_crop: Some(crop),
                ..f.clone()
            },
            24,
            32,
            Some(Fit::Stretch),
        )
        .unwrap();
        assert!(right.amplitude.iter().all(|&a| a == 1.0));
        // The depth ramp (0.5 → 1.5 m across the width) is untouched by the colour crop.
        assert!(
            (right.z_near_m.unwrap() - 0.51).abs() < 0.02,
            "{:?}",
            right.z_near_m
        );
        let bad = RgbdFrame {
            color_crop: Some(CropRect { x: 25, ..crop }),
            ..f
        };
        match convert_frame(bad, 24, 32, None) {
            Err(TensorholoError::InvalidInput { message }) => {
                assert!(
                    message.contains("color_crop") && message.contains("48x32"),
                    "{message}"
                )
            }
            other => panic!("expected InvalidInput, got {other:?}"),
        }
    }

    fn model_file(name: &str) -> Vec<u8> {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/").to_string() + name;
        std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
    }

    /// The shipped files passed as bytes give the embedded generator's patterns exactly; a pre-filter of
    /// another offset and bytes that are no model are `InvalidModel`.
    #[cfg(feature = "embedded-models")]
    #[test]
    fn with_models_equals_the_embedded_models_and_checks_the_files() {
        let embedded = HologramGenerator::new(config(32, 24)).unwrap();
        let from_files = HologramGenerator::with_models(
            config(32, 24),
            model_file("holo8_rgbd.onnx"),
            Some(model_file("prefilter_6mm.onnx")),
        )
        .unwrap();
        let (a, b) = (
            embedded.render(frame()).unwrap(),
            from_files.render(frame()).unwrap(),
        );
        assert_eq!((a.red, a.green, a.blue), (b.red, b.green, b.blue));

        let wrong_offset = HologramGenerator::with_models(
            config(32, 24),
            model_file("holo8_rgbd.onnx"),
            Some(model_file("prefilter_12mm.onnx")),
        );
        assert!(
            matches!(&wrong_offset, Err(TensorholoError::InvalidModel { message }) if message.contains("offset")),
            "{wrong_offset:?}"
        );
        let garbage = HologramGenerator::with_models(config(32, 24), vec![7; 100], None);
        assert!(
            matches!(garbage, Err(TensorholoError::InvalidModel { .. })),
            "{garbage:?}"
        );
    }

    /// `engine` reaches the session: each engine runs when asked, the info names it (and the native kernel
    /// row), and both give nearly the same pattern (they agree to float rounding, not bit for bit).
    #[test]
    fn the_engine_choice_reaches_the_session() {
        let mut patterns = Vec::new();
        for (engine, name) in [(CnnEngine::Native, "native"), (CnnEngine::Tract, "tract")] {
            let g = HologramGenerator::new(GeneratorConfig {
                engine: Some(engine),
                ..config(32, 24)
            })
            .unwrap();
            let info = g.info().unwrap();
            assert_eq!(info.cnn_engine, name, "{info:?}");
            assert_eq!(
                info.cnn_kernel.is_some(),
                engine == CnnEngine::Native,
                "{info:?}"
            );
            assert!(info.json.contains("\"engine\""), "{}", info.json);
            patterns.push(g.render(frame()).unwrap().red);
        }
        let differ = patterns[0]
            .iter()
            .zip(&patterns[1])
            .filter(|(a, b)| a.abs_diff(**b) > 1)
            .count();
        assert!(
            differ * 100 <= patterns[0].len(),
            "{differ} codes differ by more than 1"
        );
    }

    /// Without a pre-filter file the generator encodes with AA-DPM, unlike the default embedded one.
    #[test]
    fn with_models_without_prefilter_runs_none() {
        let g = HologramGenerator::with_models(config(32, 24), model_file("holo8_rgbd.onnx"), None)
            .unwrap();
        let info = g.info().unwrap();
        assert_eq!(info.prefilter_model, None, "{info:?}");
        assert_eq!(info.layers, 8);
        let p = g.render(frame()).unwrap();
        assert_eq!(p.red.len(), 32 * 24);
        assert!(p.red.iter().any(|&c| c != p.red[0]), "constant pattern");
    }

    /// A library without the shipped CNNs says so instead of failing later.
    #[cfg(not(feature = "embedded-models"))]
    #[test]
    fn new_without_embedded_models_is_unsupported() {
        let e = HologramGenerator::new(config(32, 24)).unwrap_err();
        assert!(
            matches!(&e, TensorholoError::Unsupported { message } if message.contains("withModels")),
            "{e:?}"
        );
    }
}
