//! [`GeneratorConfig`]: what a generator makes (size, CNNs, display, camera-frame fit) and its checks.

use std::sync::Arc;

#[cfg(doc)]
use crate::cnn::PlanReport;
#[cfg(test)]
use crate::cnn::ThreadCount;
#[cfg(doc)]
use crate::cnn::MAX_CNN_THREADS;
use crate::cnn::{CnnOptions, SavedPlans};
use crate::display::{AberrationProfile, AberrationSource, DisplayProfile, Prescription};
use crate::encoding::DoublePhaseMethod;
#[cfg(doc)]
use crate::error::HoloError;
use crate::error::{invalid, Result};
use crate::foveation::FoveationOptions;
use crate::optics::{OpticalSetup, PropagationOptions};
use crate::pipeline::{Backend, GpuPrecision, ModelSelection, PipelineConfig, MAX_HOLOGRAM_PIXELS};
use crate::scene::{DepthMapping, DepthRange, DepthUpsampling, Fit, FrameOptions};
use crate::slm::model::DisplayModel;

/// Everything a [`HologramGenerator`] needs. Build with [`GeneratorConfig::new`] and change the fields
/// you need; [`GeneratorConfig::validate`] says what is wrong.
///
/// [`HologramGenerator`]: super::HologramGenerator
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GeneratorConfig {
    /// Hologram (SLM) width in pixels.
    pub width: usize,
    /// Hologram (SLM) height in pixels.
    pub height: usize,
    /// The shipped CNNs: RGB-D or LDI input, layers 8/15/30, precision, pre-filter Auto/Off/Required
    /// (default RGB-D, 8, f32, Auto).
    pub models: ModelSelection,
    /// Distance `s` from the midpoint hologram to the SLM in metres (Eq. 6; default 6e-3; shipped
    /// pre-filters exist for 6e-3 and 12e-3).
    pub offset_m: f64,
    /// How the CPU CNNs run ([`CnnOptions`]; the default: the plan table's engine, layout and kernel rows on
    /// the cores the CPU reports, this CPU's best instruction set). With `cnn.tune` the candidates (engines,
    /// each layer's kernel row, threads) are timed when the generator is made, instead of taking the plan
    /// table's (the default: the same SLM codes on every run); save the result ([`GeneratorInfo::plan`],
    /// [`PlanReport::saved`]) and give it as `saved_plans` on later runs to repeat it without timing.
    ///
    /// [`GeneratorInfo::plan`]: super::GeneratorInfo::plan
    pub cnn: CnnOptions,
    /// CNN plans saved from an earlier (tuned) generator ([`PlanReport::saved`], read back with
    /// [`SavedPlans::from_json`]): repeated without timing, so every run gives the same SLM codes. `None`
    /// (the default): the plan table, or a timing with `cnn.tune`. Refused with `cnn.tune`, and at creation when
    /// made for another kernel ISA level than this CPU's.
    #[serde(serialize_with = "saved_source")]
    pub saved_plans: Option<Arc<SavedPlans>>,
    /// How camera frames fit the hologram ([`Fit::Crop`] by default).
    pub fit: Fit,
    /// How a camera frame's depth buffer of a lower resolution than its colour (ARKit's 256 × 192 LiDAR
    /// depth under a 1920 × 1440 image) is brought to the colour's resolution ([`FrameOptions::depth_upsampling`]):
    /// [`DepthUpsampling::Nearest`] by default (its cost), [`DepthUpsampling::JointBilateral`] for edges that
    /// follow the colour's (closer to full-resolution depth; docs/VIDEO.md gives both and the cost).
    pub depth_upsampling: DepthUpsampling,
    /// Wavelengths (R, G, B), pixel pitch and volume depth, all in metres (the paper's display: 638, 520,
    /// 450 nm, 8 µm, 6 mm).
    pub optics: OpticalSetup,
    /// Angular spectrum options (padding, band limit).
    pub options: PropagationOptions,
    /// Double phase method where no pre-filter CNN runs (AA-DPM by default).
    pub encoding: DoublePhaseMethod,
    /// Metric depth range mapped to the 3D volume (`None`: 1st/99th percentiles of each frame's valid
    /// depths; a stream keeps its first frame's).
    pub depth_range: Option<DepthRange>,
    /// Metric depth → normalised depth mapping (linear in diopters by default).
    pub depth_mapping: DepthMapping,
    /// Where frames are computed ([`Backend::Auto`] by default: the phone's GPU where it passes a
    /// first-frame self-check against the CPU, else the CPU; [`GeneratorInfo::backend`] says which).
    ///
    /// [`GeneratorInfo::backend`]: super::GeneratorInfo::backend
    pub backend: Backend,
    /// The GPU CNNs' arithmetic ([`GpuPrecision::Auto`] by default: f16 where the GPU has it, which halves
    /// their memory; docs/GPU.md).
    pub gpu_precision: GpuPrecision,
    /// Largest relative spread (a fraction: 0.01 = 1 %) of the per-colour depth scales accepted when the
    /// CNNs were trained for another, Fresnel-equivalent display (`docs/DISPLAYS.md`,
    /// [`crate::display::DisplayMapping`]); `None` (the default): the serving rule's, whose estimated cost
    /// stays within 0.3 dB of the model's own score. A value wider than the rule's is reported as "widened"
    /// in [`GeneratorInfo::display_mapping`].
    ///
    /// [`GeneratorInfo::display_mapping`]: super::GeneratorInfo::display_mapping
    pub wavelength_ratio_tolerance: Option<f64>,
    /// The viewer's spectacle prescription ([`Prescription`]: sphere and cylinder in dioptres, axis in
    /// degrees, the eyepiece in metres), corrected in every frame with the shipped CNNs
    /// ([`AberrationProfile::from_prescription`], `docs/ABERRATION.md`); `None` (the default): none. A
    /// generator made with one (a zero prescription included) can change it between frames
    /// ([`HologramGenerator::set_prescription`], a slider). Frames then run on the CPU and encode with
    /// `encoding` (AA-DPM), not a DDPM pre-filter CNN.
    ///
    /// [`HologramGenerator::set_prescription`]: super::HologramGenerator::set_prescription
    pub prescription: Option<Prescription>,
    /// Measured aberrations (a `tensorholo.aberration` file read with [`AberrationProfile::load`] or
    /// [`AberrationProfile::from_json_str`]), corrected as `prescription`; at most one of the two.
    pub aberration: Option<AberrationProfile>,
    /// Gaze-contingent frames (`docs/FOVEATION.md`): the fovea's radius, blend band and periphery blur that
    /// [`HologramGenerator::render_foveated`] uses; `None` (the default): none, and that call is refused.
    ///
    /// [`HologramGenerator::render_foveated`]: super::HologramGenerator::render_foveated
    pub foveation: Option<FoveationOptions>,
    /// A display model fitted from camera captures (`tensorholo.display-model`, [`DisplayModel::load`] or
    /// [`DisplayModel::from_json_str`]; docs/CALIBRATION.md "The display model"): the photo mode
    /// ([`HologramGenerator::render_refined`]) then refines the patterns as that display shows them (its
    /// source, crosstalk, phase response, zero order, aberration). `None` (the default): the ideal display.
    /// Its SLM size must be the hologram's.
    ///
    /// [`HologramGenerator::render_refined`]: super::HologramGenerator::render_refined
    #[serde(serialize_with = "model_itself")]
    pub display_model: Option<Arc<DisplayModel>>,
    /// A stream's frames ([`HologramGenerator::stream`]) with each colour's global phase aligned to the previous
    /// frame's ([`crate::encoding::PhaseContinuity`]: less phase churn for the SLM to settle, nothing the
    /// viewer sees); the linear look-up table only: a stream through a calibrated table is refused. Default
    /// `false`.
    ///
    /// [`HologramGenerator::stream`]: super::HologramGenerator::stream
    pub align_phase: bool,
}

/// [`GeneratorConfig::display_model`] in reports: the model itself, or null.
fn model_itself<S: serde::Serializer>(
    model: &Option<Arc<DisplayModel>>,
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    match model {
        Some(m) => s.serialize_some(&**m),
        None => s.serialize_none(),
    }
}

/// [`GeneratorConfig::saved_plans`] in reports: the plans' origin, or null.
fn saved_source<S: serde::Serializer>(
    plans: &Option<Arc<SavedPlans>>,
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    match plans {
        Some(p) => s.serialize_some(&p.origin),
        None => s.serialize_none(),
    }
}

impl GeneratorConfig {
    /// The defaults for a `width × height` hologram: the shipped 8-layer f32 CNN, its pre-filter where it
    /// helps (Auto), SLM 6 mm from the midpoint hologram, autotuned CNN plan, centred crop, automatic depth
    /// range, the paper's display.
    pub fn new(width: usize, height: usize) -> Self {
        // The camera's defaults (fit, depth range and mapping, depth upsampling) are the conversion's own.
        let camera = FrameOptions::default();
        Self {
            width,
            height,
            models: ModelSelection::default(),
            offset_m: 6e-3,
            cnn: CnnOptions::default(),
            saved_plans: None,
            fit: camera.fit,
            depth_upsampling: camera.depth_upsampling,
            optics: OpticalSetup::default(),
            options: PropagationOptions::default(),
            encoding: DoublePhaseMethod::default(),
            depth_range: camera.range,
            depth_mapping: camera.mapping,
            backend: Backend::default(),
            gpu_precision: GpuPrecision::default(),
            wavelength_ratio_tolerance: None,
            prescription: None,
            aberration: None,
            foveation: None,
            display_model: None,
            align_phase: false,
        }
    }

    /// The defaults of [`GeneratorConfig::new`] for the display a profile describes (`docs/DISPLAYS.md`):
    /// `width`/`height` from its `resolution` (`[height, width]` pixels), `optics` from
    /// [`DisplayProfile::optics`] (wavelengths, pitch and volume depth in metres) and `offset_m` from
    /// [`DisplayProfile::default_offset_m`] (the first of `offsets_m`). The profile's `calibration` file is
    /// not read here: load it and pass it to [`HologramGenerator::set_calibration`].
    ///
    /// Errors: none here (a profile from [`DisplayProfile::from_json_str`] or [`DisplayProfile::new`] is
    /// valid); whether the shipped CNNs serve the display (one depth scale `σ` for the three lasers, volume
    /// and offsets `σ`·6 mm) is checked when the generator is made, as [`HologramGenerator::new`].
    ///
    /// [`HologramGenerator::set_calibration`]: super::HologramGenerator::set_calibration
    /// [`HologramGenerator::new`]: super::HologramGenerator::new
    pub fn for_display(profile: &DisplayProfile) -> Self {
        let [height, width] = profile.resolution;
        Self {
            optics: profile.optics(),
            offset_m: profile.default_offset_m(),
            prescription: profile.prescription,
            ..Self::new(width, height)
        }
    }

    /// The aberration profile sessions correct: the prescription's on this configuration's display, or the
    /// measured one; `None` without either.
    ///
    /// The rule is [`AberrationSource::from_either`]'s.
    ///
    /// Errors: as [`AberrationSource::from_either`] and [`AberrationProfile::from_prescription`].
    pub(crate) fn aberration_profile(&self) -> Result<Option<Arc<AberrationProfile>>> {
        let source = AberrationSource::from_either(self.prescription, self.aberration.clone())?;
        source
            .map(|s| s.resolve(&self.optics).map(Arc::new))
            .transpose()
    }

    /// Checks everything that needs no model: non-zero sizes within [`MAX_HOLOGRAM_PIXELS`] whose RGBA
    /// outputs (`width · height · 4` bytes) fit in a `u32`, a finite non-negative offset, valid optics and
    /// depth range, a thread count within [`MAX_CNN_THREADS`], a finite wavelength ratio tolerance ≥ 0, a
    /// valid prescription or an aberration profile for this display (not both), valid foveation options
    /// ([`FoveationOptions::check`]), a valid display model of the hologram's size.
    ///
    /// Errors: [`HoloError::InvalidParameter`] naming the field.
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.height == 0 {
            return Err(invalid(
                "width/height",
                format!(
                    "the hologram needs a non-zero size, got {}×{}",
                    self.width, self.height
                ),
            ));
        }
        let pixels = self
            .width
            .checked_mul(self.height)
            .filter(|&p| p <= MAX_HOLOGRAM_PIXELS);
        let rgba_fits = pixels
            .and_then(|p| p.checked_mul(4))
            .is_some_and(|b| b <= u32::MAX as usize);
        if pixels.is_none() || !rgba_fits {
            return Err(invalid(
                "width/height",
                format!(
                    "{}×{} is larger than the {MAX_HOLOGRAM_PIXELS} pixels a generator makes",
                    self.width, self.height
                ),
            ));
        }
        if !(self.offset_m.is_finite() && self.offset_m >= 0.0) {
            return Err(invalid(
                "offset_m",
                format!("must be finite and ≥ 0 metres, got {}", self.offset_m),
            ));
        }
        self.optics.validate()?;
        if let Some(r) = &self.depth_range {
            r.validate()?;
        }
        self.cnn.validate()?;
        if self.cnn.tune && self.saved_plans.is_some() {
            return Err(invalid(
                "tune",
                "saved plans and a new tuning were both asked for: give one",
            ));
        }
        if let Some(p) = &self.saved_plans {
            p.validate()?;
        }
        // One of a prescription (valid) and a measured profile, for this display.
        if let Some(profile) = self.aberration_profile()? {
            profile.check_setup(&self.optics)?;
        }
        if let Some(t) = self.wavelength_ratio_tolerance {
            if !(t.is_finite() && t >= 0.0) {
                return Err(invalid(
                    "wavelength_ratio_tolerance",
                    format!("must be a finite fraction ≥ 0 (0.01 = 1 %), got {t}"),
                ));
            }
        }
        if let Some(f) = &self.foveation {
            f.check()?;
        }
        if let Some(m) = &self.display_model {
            m.validate()?;
            m.check_size(self.height, self.width)?;
        }
        Ok(())
    }

    /// The pipeline part of this configuration.
    pub fn pipeline_config(&self) -> PipelineConfig {
        PipelineConfig {
            optics: self.optics,
            options: self.options,
            offset_m: self.offset_m,
            encoding: self.encoding,
            cnn: self.cnn,
            backend: self.backend,
            gpu_precision: self.gpu_precision,
            wavelength_ratio_tolerance: self.wavelength_ratio_tolerance,
            foveation: self.foveation,
        }
    }

    /// The camera-frame conversion part of this configuration.
    pub fn frame_options(&self) -> FrameOptions {
        FrameOptions {
            fit: self.fit,
            range: self.depth_range,
            mapping: self.depth_mapping,
            depth_upsampling: self.depth_upsampling,
        }
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::error::HoloError;

    /// The camera's defaults are stated once, in `FrameOptions::default()`: a new configuration's are those.
    #[test]
    fn camera_defaults_are_the_conversions_own() {
        let c = GeneratorConfig::new(64, 48);
        assert_eq!(c.frame_options(), FrameOptions::default());
    }

    #[test]
    fn config_refuses_what_cannot_work() {
        assert!(GeneratorConfig::new(64, 48).validate().is_ok());
        let bad = |f: fn(&mut GeneratorConfig)| {
            let mut c = GeneratorConfig::new(64, 48);
            f(&mut c);
            c.validate().unwrap_err()
        };
        let name = |e: HoloError| match e {
            HoloError::InvalidParameter { name, .. } => name,
            e => panic!("unexpected {e}"),
        };
        assert_eq!(name(bad(|c| c.width = 0)), "width/height");
        assert_eq!(name(bad(|c| c.height = usize::MAX)), "width/height");
        assert_eq!(
            name(bad(|c| {
                c.width = 9000;
                c.height = 9000;
            })),
            "width/height"
        );
        assert_eq!(name(bad(|c| c.offset_m = f64::NAN)), "offset_m");
        assert_eq!(name(bad(|c| c.offset_m = -1e-3)), "offset_m");
        assert_eq!(
            name(bad(|c| c.cnn.threads = ThreadCount::Fixed(100_000))),
            "threads"
        );
        assert!(matches!(
            bad(|c| c.optics.pixel_pitch_m = f64::NAN),
            HoloError::InvalidParameter { .. }
        ));
        assert!(matches!(
            bad(|c| c.depth_range = Some(DepthRange {
                z_near_m: 2.0,
                z_far_m: 1.0
            })),
            HoloError::InvalidParameter { .. }
        ));
    }

    /// A 4 µm SLM at the paper's lasers: σ = (4/8)² = 0.25, so a 1.5 mm volume and 1.5 mm offsets.
    pub(in crate::generator) const PROFILE_4UM: &str = r#"{
        "name": "4 µm test SLM",
        "pixel_pitch_m": 4e-6,
        "resolution": [48, 64],
        "wavelengths_m": [638e-9, 520e-9, 450e-9],
        "volume_depth_m": 1.5e-3,
        "offsets_m": [1.5e-3, 3e-3]
    }"#;

    #[test]
    fn for_display_takes_size_optics_and_offset_from_the_profile() {
        let profile = DisplayProfile::from_json_str(PROFILE_4UM).unwrap();
        let c = GeneratorConfig::for_display(&profile);
        assert_eq!((c.width, c.height), (64, 48));
        assert_eq!(
            c.optics,
            OpticalSetup {
                wavelengths_m: [638e-9, 520e-9, 450e-9],
                pixel_pitch_m: 4e-6,
                volume_depth_m: 1.5e-3,
            }
        );
        assert_eq!(c.offset_m, 1.5e-3);
        assert_eq!(c.wavelength_ratio_tolerance, None);
        // Everything else is GeneratorConfig::new's.
        let want = GeneratorConfig {
            optics: c.optics,
            offset_m: c.offset_m,
            ..GeneratorConfig::new(64, 48)
        };
        assert_eq!(c, want);
        c.validate().unwrap();
        assert_eq!(c.pipeline_config().wavelength_ratio_tolerance, None);
    }

    #[test]
    fn a_bad_wavelength_ratio_tolerance_is_named() {
        for t in [f64::NAN, -0.01, f64::INFINITY] {
            let mut c = GeneratorConfig::new(64, 48);
            c.wavelength_ratio_tolerance = Some(t);
            assert!(
                matches!(
                    c.validate(),
                    Err(HoloError::InvalidParameter {
                        name: "wavelength_ratio_tolerance",
                        ..
                    })
                ),
                "{t}"
            );
        }
    }
}
