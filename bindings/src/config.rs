//! [`GeneratorConfig`]: what a generator makes, as a record with the core's defaults, and its conversions to
//! and from the core's configuration; [`Prescription`], the viewer's spectacle prescription it may carry.

use std::sync::Arc;

use tensorholo::cnn::ThreadCount;
use tensorholo::display::AberrationProfile;
use tensorholo::generator as core;
use tensorholo::optics::OpticalSetup;
use tensorholo::scene::DepthRange;
use tensorholo::slm::model::DisplayModel;

use crate::enums::{Backend, CnnEngine, GpuPrecision, Precision, PrefilterMode, SceneInput};
use crate::error::{invalid, Result};
use crate::foveation::Foveation;
use crate::frames::{DepthUpsampling, Fit};

/// Everything a [`HologramGenerator`](crate::HologramGenerator) needs. Only `width` and `height` (the SLM's resolution in pixels) are
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
    /// How a camera frame's depth of a lower resolution than its colour is brought to the colour's;
    /// `None` = [`DepthUpsampling::Nearest`].
    #[uniffi(default = None)]
    pub depth_upsampling: Option<DepthUpsampling>,
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
    /// Where frames are computed; `None` = [`Backend::Auto`] ([`GeneratorInfo::backend`](crate::GeneratorInfo::backend) says which runs).
    #[uniffi(default = None)]
    pub backend: Option<Backend>,
    /// The GPU CNNs' arithmetic; `None` = [`GpuPrecision::Auto`].
    #[uniffi(default = None)]
    pub gpu_precision: Option<GpuPrecision>,
    /// The CPU CNN engine; `None` = [`CnnEngine::Auto`] ([`GeneratorInfo::cnn_engine`](crate::GeneratorInfo::cnn_engine) says which runs).
    #[uniffi(default = None)]
    pub engine: Option<CnnEngine>,
    /// Largest relative spread (a fraction: 0.01 = 1 %) of the lasers' depth scales accepted when the CNNs
    /// were trained for another, Fresnel-equivalent display (`docs/DISPLAYS.md`); `None` (default): the
    /// serving rule's, an estimated cost within 0.3 dB of the model's own score (about 1.8–2 %). A value
    /// wider than that shows as "widened" in [`GeneratorInfo::display_mapping`](crate::GeneratorInfo::display_mapping), with its cost.
    #[uniffi(default = None)]
    pub wavelength_ratio_tolerance: Option<f64>,
    /// Time the CNN candidates on this device at creation (engines, each layer's kernel row, threads; up to
    /// a few seconds) instead of taking the plan table's (default `false`: the same SLM codes on every run).
    /// [`GeneratorInfo::saved_plans`](crate::GeneratorInfo::saved_plans) then holds the result, to store and pass as `saved_plans` later.
    #[uniffi(default = false)]
    pub tune: bool,
    /// CNN plans stored from an earlier generator's [`GeneratorInfo::saved_plans`](crate::GeneratorInfo::saved_plans) (a
    /// `tensorholo.cnn-plans` JSON text): repeated without timing, so every run gives the same codes.
    /// `None` (default): the plan table (or `tune`). Refused with `tune`, or when made on a device whose
    /// kernels differ (another CPU class).
    #[uniffi(default = None)]
    pub saved_plans: Option<String>,
    /// The viewer's spectacle prescription, corrected in every frame (`docs/ABERRATION.md`); `None`
    /// (default): none. Give one (a zero one will do) to let [`HologramGenerator::set_prescription`](crate::HologramGenerator::set_prescription)
    /// change it between frames (a slider). Frames then run on the CPU with AA-DPM.
    #[uniffi(default = None)]
    pub prescription: Option<Prescription>,
    /// Measured aberrations, the JSON text of a `tensorholo.aberration` file (`holo calibrate aberration`),
    /// corrected as `prescription`; at most one of the two. `None` (default): none.
    #[uniffi(default = None)]
    pub aberration: Option<String>,
    /// Gaze-contingent frames ([`HologramGenerator::render_foveated`](crate::HologramGenerator::render_foveated),
    /// `docs/FOVEATION.md`); `None` (default): none, and that call is refused.
    #[uniffi(default = None)]
    pub foveation: Option<Foveation>,
    /// A display model fitted from camera captures: the JSON text of a `tensorholo.display-model` file
    /// (`holo calibrate model fit`, docs/CALIBRATION.md "The display model"), of the hologram's size. The photo
    /// mode ([`HologramGenerator::render_refined`](crate::HologramGenerator::render_refined)) then refines the
    /// patterns as that display shows them. `None` (default): the ideal display.
    #[uniffi(default = None)]
    pub display_model: Option<String>,
    /// A stream's frames with each colour's global phase aligned to the previous frame's (less phase churn
    /// for the SLM to settle; nothing the viewer sees), `docs/VIDEO.md`. Through the linear look-up table
    /// only: a stream through a calibrated one is refused. Default `false`.
    #[uniffi(default = false)]
    pub align_phase: bool,
}

/// A viewer's spectacle prescription, corrected in every frame with the shipped CNNs (`docs/ABERRATION.md`,
/// "A viewer's prescription"): the display shows the hologram as this lens would let the viewer see it.
/// Ophthalmic conventions: a myope's sphere is negative; the axis is degrees counterclockwise from the
/// horizontal as the viewer sees the image.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct Prescription {
    /// Sphere in dioptres (negative for a myope), within ±20.
    pub sphere_d: f64,
    /// Cylinder in dioptres (either sign), within ±10; 0 (default) without astigmatism.
    #[uniffi(default = 0.0)]
    pub cylinder_d: f64,
    /// The cylinder's axis in degrees, 0–180; required with a cylinder (default `None`).
    #[uniffi(default = None)]
    pub axis_deg: Option<f64>,
    /// Focal length of the display's eyepiece in metres (default 0.021, the paper's).
    #[uniffi(default = 0.021)]
    pub eyepiece_focal_m: f64,
}

impl From<Prescription> for tensorholo::display::Prescription {
    fn from(p: Prescription) -> Self {
        Self {
            sphere_d: p.sphere_d,
            cylinder_d: p.cylinder_d,
            axis_deg: p.axis_deg,
            eyepiece_focal_m: p.eyepiece_focal_m,
        }
    }
}

impl From<tensorholo::display::Prescription> for Prescription {
    fn from(p: tensorholo::display::Prescription) -> Self {
        Self {
            sphere_d: p.sphere_d,
            cylinder_d: p.cylinder_d,
            axis_deg: p.axis_deg,
            eyepiece_focal_m: p.eyepiece_focal_m,
        }
    }
}

impl GeneratorConfig {
    /// The core configuration. Errors: [`TensorholoError::InvalidInput`](crate::TensorholoError::InvalidInput) for a non-finite or out-of-range
    /// number, a wavelength list that is neither empty nor 3 long, or only one of `z_near_m`/`z_far_m`.
    pub(crate) fn to_core(&self) -> Result<core::GeneratorConfig> {
        // Every field left `None` keeps the core's default (`core::GeneratorConfig::new`); the numeric
        // fields' uniffi defaults restate the core's, which `tests::uniffi_defaults_are_the_cores` pins.
        let mut c = core::GeneratorConfig::new(self.width as usize, self.height as usize);
        if let Some(input) = self.input {
            c.models.input = input.into();
        }
        c.models.layers = self.layers as usize;
        if let Some(precision) = self.precision {
            c.models.precision = precision.into();
        }
        if let Some(prefilter) = self.prefilter {
            c.models.prefilter = prefilter.into();
        }
        c.offset_m = self.offset_mm * 1e-3;
        c.cnn.threads = ThreadCount::from_count(self.threads as usize);
        if let Some(fit) = self.fit {
            c.fit = fit.into();
        }
        if let Some(upsampling) = self.depth_upsampling {
            c.depth_upsampling = upsampling.into();
        }
        if let Some(backend) = self.backend {
            c.backend = backend.into();
        }
        if let Some(engine) = self.engine {
            c.cnn.engine = engine.into();
        }
        if let Some(precision) = self.gpu_precision {
            c.gpu_precision = precision.into();
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
        c.cnn.tune = self.tune;
        c.saved_plans = match &self.saved_plans {
            Some(json) => Some(Arc::new(tensorholo::cnn::SavedPlans::from_json(json)?)),
            None => None,
        };
        c.prescription = self.prescription.map(Into::into);
        c.aberration = match &self.aberration {
            Some(json) => Some(AberrationProfile::from_json_str(json, "aberration")?),
            None => None,
        };
        c.foveation = self.foveation.map(Into::into);
        c.display_model = match &self.display_model {
            Some(json) => Some(Arc::new(DisplayModel::from_json_str(
                json,
                "display_model",
            )?)),
            None => None,
        };
        c.align_phase = self.align_phase;
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
            input: Some(c.models.input.into()),
            precision: Some(c.models.precision.into()),
            offset_mm: c.offset_m * 1e3,
            prefilter: Some(c.models.prefilter.into()),
            threads: match c.cnn.threads {
                ThreadCount::Auto => 0,
                ThreadCount::Fixed(n) => n as u32,
                // tract's one-thread default executor: one thread.
                ThreadCount::ProcessDefault => 1,
            },
            fit: Some(c.fit.into()),
            depth_upsampling: Some(c.depth_upsampling.into()),
            pixel_pitch_m: c.optics.pixel_pitch_m,
            wavelengths_m: c.optics.wavelengths_m.to_vec(),
            volume_depth_m: c.optics.volume_depth_m,
            z_near_m: c.depth_range.map(|r| r.z_near_m as f64),
            z_far_m: c.depth_range.map(|r| r.z_far_m as f64),
            backend: Some(c.backend.into()),
            gpu_precision: Some(c.gpu_precision.into()),
            engine: Some(c.cnn.engine.into()),
            wavelength_ratio_tolerance: c.wavelength_ratio_tolerance,
            tune: c.cnn.tune,
            saved_plans: c.saved_plans.map(|p| p.to_json()),
            prescription: c.prescription.map(Into::into),
            aberration: c.aberration.map(|a| a.to_json_string()),
            foveation: c.foveation.map(Into::into),
            // A model serialises to its file's JSON (serde of plain fields: it cannot fail).
            display_model: c
                .display_model
                .and_then(|m| serde_json::to_string(&*m).ok()),
            align_phase: c.align_phase,
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The default a generated binding gives the `record`'s `field` (`name: Type = value` in Kotlin,
    /// `name: Type = Type(value)` in Swift), as a number. Other records (`DisplayProfile`) have fields of the
    /// same names: the search starts at the record's definition.
    fn generated_default(source: &str, record: &str, field: &str) -> f64 {
        let start = source
            .find(&format!("data class {record} ("))
            .or_else(|| source.find(&format!("public struct {record}:")))
            .unwrap_or_else(|| panic!("no {record} in the generated binding"));
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
            let name = |kotlin: &'static str, swift: &'static str| {
                if file.ends_with(".kt") {
                    kotlin
                } else {
                    swift
                }
            };
            let field =
                |kotlin, swift| generated_default(&source, "GeneratorConfig", name(kotlin, swift));
            // The fovea's record: its defaults are the core's `FoveationOptions::default()`.
            let fovea = crate::foveation::Foveation::default();
            for (kotlin, swift, want) in [
                ("radiusDeg", "radiusDeg", fovea.radius_deg),
                ("eyepieceFocalM", "eyepieceFocalM", fovea.eyepiece_focal_m),
                ("bandPx", "bandPx", fovea.band_px),
                ("blurScale", "blurScale", fovea.blur_scale),
            ] {
                let got = generated_default(&source, "Foveation", name(kotlin, swift));
                assert_eq!(got, want, "{file}: Foveation.{kotlin}");
            }
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
                core.cnn.threads,
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
            (c.fit, c.depth_upsampling, c.backend, c.gpu_precision),
            (
                want.fit,
                want.depth_upsampling,
                want.backend,
                want.gpu_precision
            )
        );
        assert_eq!(
            c.wavelength_ratio_tolerance,
            want.wavelength_ratio_tolerance
        );
    }

    pub(crate) fn config(width: u32, height: u32) -> GeneratorConfig {
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
            depth_upsampling: None,
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
            prescription: None,
            aberration: None,
            foveation: None,
            display_model: None,
            align_phase: false,
        }
    }
}
