//! [`DisplayProfile`]: a display as its profile file describes it, the [`GeneratorConfig`] for it, and
//! [`check_display`], which shipped CNNs serve it.

use tensorholo::display as core_display;
use tensorholo::generator as core;

use crate::config::{GeneratorConfig, Prescription};
#[cfg(doc)]
use crate::error::TensorholoError;
use crate::error::{guard, invalid, Result};
#[cfg(doc)]
use crate::generator::HologramGenerator;

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
    /// `aberration`: the viewer's or the optics' aberration file (`tensorholo.aberration`,
    /// `docs/ABERRATION.md`) as the profile gives it, or `None` (default). Not read by the library: the app
    /// passes the file's text as [`GeneratorConfig::aberration`].
    #[uniffi(default = None)]
    pub aberration: Option<String>,
    /// `prescription`: the viewer's spectacle prescription, or `None` (default); at most one of `aberration`
    /// and `prescription`. [`generator_config_for_display`] carries it into the configuration.
    #[uniffi(default = None)]
    pub prescription: Option<Prescription>,
}

impl DisplayProfile {
    /// The core's profile, checked by the core ([`core_display::DisplayProfile::new`]).
    ///
    /// Errors: [`TensorholoError::InvalidInput`] naming the key: as the core's profile rules (e.g.
    /// `resolution` not 2 values, a non-positive `pixel_pitch_m`, a wavelength outside 380–780 nm).
    pub(crate) fn to_core(&self) -> Result<core_display::DisplayProfile> {
        let resolution: Vec<usize> = self.resolution.iter().map(|&n| n as usize).collect();
        Ok(core_display::DisplayProfile::new(
            self.name.clone(),
            self.pixel_pitch_m,
            &resolution,
            &self.wavelengths_m,
            self.volume_depth_m,
            self.offsets_m.clone(),
            self.calibration.clone().map(Into::into),
        )?
        .with_aberration_file(self.aberration.clone().map(Into::into))?
        .with_prescription(self.prescription.map(Into::into))?)
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
            aberration: p.aberration.map(|c| c.to_string_lossy().into_owned()),
            prescription: p.prescription.map(Into::into),
        })
    }
}

/// Reads a display profile from its JSON text (a profile file's contents, `docs/DISPLAYS.md`): keys
/// `pixel_pitch_m`, `resolution`, `wavelengths_m`, `volume_depth_m`, `offsets_m` (SI units), optional `name`,
/// `calibration`, `aberration` and `prescription`; unknown keys are refused.
///
/// Errors: [`TensorholoError::InvalidInput`] whose message names the key at fault (a missing key, a wrong
/// type or array length, a non-positive pitch or volume, a wavelength outside 380–780 nm, an unknown key) or
/// says the text is not a JSON object.
#[uniffi::export]
pub fn display_profile_from_json(json: String) -> Result<DisplayProfile> {
    guard(|| DisplayProfile::from_core(core_display::DisplayProfile::from_json_str(&json)?))
}

/// The [`GeneratorConfig`] for a display: `width`/`height` from its `resolution`, its pitch, lasers and
/// volume, its first offset, its prescription; every other field at its default (change them before making
/// the generator; the profile's `aberration` file is the app's to read into [`GeneratorConfig::aberration`]).
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
    Err(crate::error::TensorholoError::Unsupported {
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::error::TensorholoError;

    pub(crate) const PROFILE_4UM: &str = r#"{
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
                back.cnn.threads
            ),
            (
                want.width,
                want.height,
                want.models,
                want.optics,
                want.cnn.threads
            )
        );
        assert!((back.offset_m - want.offset_m).abs() < 1e-15);
        assert_eq!(
            (back.fit, back.backend, back.gpu_precision, back.cnn.engine),
            (want.fit, want.backend, want.gpu_precision, want.cnn.engine)
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
}
