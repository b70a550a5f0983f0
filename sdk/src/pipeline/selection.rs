//! Which CNNs run: the shipped models by name ([`ModelSelection`], [`PrefilterMode`]) and the one rule that
//! pairs a hologram CNN with a shipped pre-filter by the offset mapped onto the training display (`s'/σ`,
//! [`crate::display::DisplayMapping`]; 1.5 mm at 4 µm ↔ the 6 mm pre-filter) ([`shipped_prefilter`], used by
//! [`super::HologramPipeline::with_shipped_prefilter`], and through it by the CLI and the bindings).

use std::sync::Arc;

use super::config::PipelineConfig;
use crate::error::{invalid, Result};
use crate::model::{HologramModel, Precision, SceneInput};

/// Whether the DDPM pre-filter CNN runs between offset propagation and double phase encoding (paper Eq. 6),
/// chosen by name (`HologramPipeline::with_shipped_prefilter` has the rule).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PrefilterMode {
    /// The shipped pre-filter where one exists for the offset and was trained with this CNN depth.
    #[default]
    Auto,
    /// Never: encode with the configured double phase method (AA-DPM by default).
    Off,
    /// Always the shipped pre-filter of the offset; an error where none is shipped.
    Required,
}

impl PrefilterMode {
    /// Short name: `auto`, `off`, `required`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Off => "off",
            Self::Required => "required",
        }
    }
}

/// The shipped CNNs by name ([`HologramPipeline::embedded`](crate::pipeline::HologramPipeline::embedded)). `Default`: RGB-D input, 8 layers, f32,
/// pre-filter [`PrefilterMode::Auto`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
pub struct ModelSelection {
    /// The scene the hologram CNN takes: an RGB-D image (default) or a layered depth image
    /// ([`crate::model::SceneInput`]; sessions then render with `HologramSession::render_ldi`).
    pub input: SceneInput,
    /// Hologram CNN depth: 8, 15 or 30 convolution layers (RGB-D), 8 (LDI).
    pub layers: usize,
    /// Weight format of both CNNs.
    pub precision: Precision,
    /// Whether the DDPM pre-filter CNN runs.
    pub prefilter: PrefilterMode,
}

impl Default for ModelSelection {
    fn default() -> Self {
        Self {
            input: SceneInput::Rgbd,
            layers: 8,
            precision: Precision::F32,
            prefilter: PrefilterMode::Auto,
        }
    }
}

/// Where a pipeline's pre-filter CNN comes from ([`super::HologramPipeline::with_prefilter`], the one rule
/// the CLI, the generator and the bindings share).
#[derive(Debug, Clone)]
pub enum PrefilterSource {
    /// The shipped pre-filter of the offset, as the mode says (`super::HologramPipeline::with_shipped_prefilter`).
    Shipped(PrefilterMode),
    /// The caller's own pre-filter CNN (e.g. `holo render --prefilter-model`): always used, and refused
    /// where it cannot be (a 0 m offset, metadata of another display or offset).
    Given(Arc<HologramModel>),
}

/// The rule of [`HologramPipeline::with_shipped_prefilter`](crate::pipeline::HologramPipeline::with_shipped_prefilter): the pre-filter to run (if any) and why.
pub(super) fn shipped_prefilter(
    hologram: &HologramModel,
    mode: PrefilterMode,
    precision: Precision,
    config: &PipelineConfig,
) -> Result<(Option<HologramModel>, String)> {
    // The shipped pre-filters are named by their offset on the training display (8 µm): a Fresnel-equivalent
    // display's offset s' maps to s'/σ there (docs/DISPLAYS.md); σ = 1 on the paper's display.
    let scale = crate::display::DisplayMapping::compute(
        &hologram.metadata().optics(),
        &config.optics,
        config.offset_m,
        config.wavelength_ratio_tolerance,
        hologram.metadata().card_score_db(),
    )?
    .scale;
    let mm = config.offset_m / scale * 1e3;
    // How the offset reads in messages: "6 mm", or "1.5 mm (6 mm on the training display)".
    let at = if scale == 1.0 {
        format!("{mm} mm")
    } else {
        format!(
            "{} mm ({mm} mm on the training display)",
            config.offset_m * 1e3
        )
    };
    if mode == PrefilterMode::Off {
        return Ok((None, "pre-filter off".into()));
    }
    if config.offset_m == 0.0 {
        return match mode {
            PrefilterMode::Required => Err(invalid(
                "prefilter",
                "a pre-filter CNN belongs to a non-zero SLM offset (DDPM, Eq. 6); none exists at 0 mm",
            )),
            _ => Ok((None, "no pre-filter at a 0 mm offset".into())),
        };
    }
    #[cfg(feature = "embedded-models")]
    {
        use crate::model::embedded::{
            files, paired_prefilter_file, paired_prefilter_model, prefilter_model,
            PREFILTER_OFFSETS_MM,
        };
        let shipped = PREFILTER_OFFSETS_MM
            .into_iter()
            .find(|&o| (o as f64 - mm).abs() < 1e-6 * (o as f64).max(1.0));
        let Some(offset_mm) = shipped else {
            return match mode {
                PrefilterMode::Required => Err(invalid(
                    "prefilter",
                    format!(
                        "no shipped pre-filter CNN for a {at} offset (shipped: {PREFILTER_OFFSETS_MM:?} \
                         mm); use one of those offsets, or the pre-filter off"
                    ),
                )),
                _ => Ok((
                    None,
                    format!("no shipped pre-filter for {at} (shipped: {PREFILTER_OFFSETS_MM:?} mm)"),
                )),
            };
        };
        let expected = config.model_config(hologram.metadata().input_layers);
        let layers = hologram.metadata().layers;
        let mapped = if scale == 1.0 {
            String::new()
        } else {
            format!(", serving {} mm on this display", config.offset_m * 1e3)
        };
        // The pre-filter trained on the holograms of a CNN of this depth, where this build embeds it (its
        // forms come together with their CNN's feature; the int8 QOperator form's engine is checked on load).
        let paired = paired_prefilter_file(offset_mm, layers, Precision::F32);
        if files().any(|(name, _)| name == paired) {
            let p = paired_prefilter_model(offset_mm, layers, precision, &expected)?;
            let why = format!(
                "shipped {offset_mm} mm pre-filter ({}, trained with the {layers}-layer hologram CNN{mapped})",
                if mode == PrefilterMode::Required {
                    "required"
                } else {
                    "auto"
                }
            );
            return Ok((Some(p), why));
        }
        if mode == PrefilterMode::Required {
            let p = prefilter_model(offset_mm, precision, &expected)?;
            let why = format!(
                "shipped {offset_mm} mm pre-filter (required{mapped}; trained with the 8-layer hologram CNN, none with \
                 the {layers}-layer one in this build)"
            );
            return Ok((Some(p), why));
        }
        Ok((
            None,
            format!(
                "no shipped {offset_mm} mm pre-filter trained with a {layers}-layer hologram CNN in this build \
                 (pre-filters of {:?} layers): encoding without one (require it to use the 8-layer CNN's)",
                crate::model::embedded::LAYERS
            ),
        ))
    }
    #[cfg(not(feature = "embedded-models"))]
    {
        let _ = (hologram, precision);
        match mode {
            PrefilterMode::Required => Err(invalid(
                "prefilter",
                "this build has no embedded models (feature `embedded-models`); pass a pre-filter file",
            )),
            _ => Ok((None, format!("no embedded pre-filter in this build ({at})"))),
        }
    }
}
