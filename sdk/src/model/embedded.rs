//! The shipped CNNs of `models/` (see `models/MODEL_CARD.md`), compiled into the library, each in f32 and two
//! int8 forms:
//! - cargo feature `embedded-models`: the RGB-D and the LDI hologram CNNs with 8 layers (midpoint
//!   hologram, any SLM offset) and the DDPM pre-filter CNNs for offsets of 6 and 12 mm;
//! - `models-15` and `models-30`: the 15-layer and 30-layer hologram CNNs, each with the pre-filter CNNs trained
//!   on its holograms (6 and 12 mm).
//!
//! The int8 QOperator forms run on tract only and are embedded only with the cargo feature `qop-models`,
//! which the `tract` feature turns on; without it, asking for one is an error naming the feature.
//!
//! The crate's default features embed all of them; the phone library (`tensorholo-ffi`) embeds only the
//! first set unless asked. Build with `--no-default-features` to leave them all out and load files with
//! [`HologramModel::from_path`](super::HologramModel::from_path) instead.

use super::{HologramModel, ModelConfig, ModelKind, Precision, SceneInput};
use crate::error::{invalid, Result};

// The bytes live in the crate `tensorholo-models` (the repository's models/ folder, so that `cargo package`
// carries them), whose features of the same names this crate's turn on: a file missing there is a compile error.
macro_rules! shipped {
    ($($name:literal),* $(,)?) => {
        &[$(($name, match tensorholo_models::get($name) {
            Some(bytes) => bytes,
            None => panic!(concat!("tensorholo-models lacks ", $name, " (its cargo features)")),
        })),*]
    };
}

/// Always embedded (feature `embedded-models`): the 8-layer RGB-D and LDI hologram CNNs and the pre-filters,
/// f32 and int8 QDQ.
const BASE: &[(&str, &[u8])] = shipped![
    "holo8_rgbd.onnx",
    "holo8_rgbd.int8-qdq.onnx",
    "holo8_ldi.onnx",
    "holo8_ldi.int8-qdq.onnx",
    "prefilter_6mm.onnx",
    "prefilter_6mm.int8-qdq.onnx",
    "prefilter_12mm.onnx",
    "prefilter_12mm.int8-qdq.onnx",
];

/// The int8 QOperator forms of [`BASE`]: tract runs them (feature `tract`, which turns on `qop-models`), no
/// other engine does.
#[cfg(feature = "qop-models")]
const BASE_QOP: &[(&str, &[u8])] = shipped![
    "holo8_rgbd.int8-qop.onnx",
    "holo8_ldi.int8-qop.onnx",
    "prefilter_6mm.int8-qop.onnx",
    "prefilter_12mm.int8-qop.onnx",
];
#[cfg(not(feature = "qop-models"))]
const BASE_QOP: &[(&str, &[u8])] = &[];

#[cfg(feature = "models-15")]
const HOLO15: &[(&str, &[u8])] = shipped![
    "holo15_rgbd.onnx",
    "holo15_rgbd.int8-qdq.onnx",
    "prefilter_6mm_holo15.onnx",
    "prefilter_6mm_holo15.int8-qdq.onnx",
    "prefilter_12mm_holo15.onnx",
    "prefilter_12mm_holo15.int8-qdq.onnx",
];
#[cfg(not(feature = "models-15"))]
const HOLO15: &[(&str, &[u8])] = &[];

#[cfg(all(feature = "models-15", feature = "qop-models"))]
const HOLO15_QOP: &[(&str, &[u8])] = shipped![
    "holo15_rgbd.int8-qop.onnx",
    "prefilter_6mm_holo15.int8-qop.onnx",
    "prefilter_12mm_holo15.int8-qop.onnx",
];
#[cfg(not(all(feature = "models-15", feature = "qop-models")))]
const HOLO15_QOP: &[(&str, &[u8])] = &[];

#[cfg(feature = "models-30")]
const HOLO30: &[(&str, &[u8])] = shipped![
    "holo30_rgbd.onnx",
    "holo30_rgbd.int8-qdq.onnx",
    "prefilter_6mm_holo30.onnx",
    "prefilter_6mm_holo30.int8-qdq.onnx",
    "prefilter_12mm_holo30.onnx",
    "prefilter_12mm_holo30.int8-qdq.onnx",
];
#[cfg(not(feature = "models-30"))]
const HOLO30: &[(&str, &[u8])] = &[];

#[cfg(all(feature = "models-30", feature = "qop-models"))]
const HOLO30_QOP: &[(&str, &[u8])] = shipped![
    "holo30_rgbd.int8-qop.onnx",
    "prefilter_6mm_holo30.int8-qop.onnx",
    "prefilter_12mm_holo30.int8-qop.onnx",
];
#[cfg(not(all(feature = "models-30", feature = "qop-models")))]
const HOLO30_QOP: &[(&str, &[u8])] = &[];

/// Every file embedded in this build: `(file name in models/, bytes)`.
pub fn files() -> impl Iterator<Item = (&'static str, &'static [u8])> {
    BASE.iter()
        .chain(BASE_QOP)
        .chain(HOLO15)
        .chain(HOLO15_QOP)
        .chain(HOLO30)
        .chain(HOLO30_QOP)
        .copied()
}

/// Layer counts of the RGB-D hologram CNNs the project ships (`models/`).
pub const SHIPPED_LAYERS: [usize; 3] = [8, 15, 30];

/// Layer counts of the LDI hologram CNNs the project ships (`models/holo8_ldi.onnx`; always embedded).
pub const SHIPPED_LDI_LAYERS: [usize; 1] = [8];

/// Layer counts of the shipped hologram CNNs taking `input`.
pub(crate) fn shipped_layers(input: SceneInput) -> &'static [usize] {
    match input {
        SceneInput::Rgbd => &SHIPPED_LAYERS,
        SceneInput::Ldi => &SHIPPED_LDI_LAYERS,
    }
}

/// Layer counts of the hologram CNNs embedded in this build (8, plus 15 and 30 with the features
/// `models-15` and `models-30`).
pub const LAYERS: &[usize] = match (cfg!(feature = "models-15"), cfg!(feature = "models-30")) {
    (true, true) => &[8, 15, 30],
    (true, false) => &[8, 15],
    (false, true) => &[8, 30],
    (false, false) => &[8],
};
/// SLM offsets (millimetres) of the shipped pre-filter CNNs.
pub const PREFILTER_OFFSETS_MM: [u32; 2] = [6, 12];

/// Errors: [`HoloError::InvalidParameter`](crate::HoloError) (`precision`) for the int8 QOperator form in a
/// build that does not embed it (no tract, the only engine that runs it).
fn check_engine(precision: Precision) -> Result<()> {
    if precision == Precision::Int8QOperator && !cfg!(feature = "qop-models") {
        return Err(invalid(
            "precision",
            format!(
                "the int8 QOperator form ({precision}) runs on tract only, and this build has no tract \
                 engine (cargo feature `tract`); the default int8 form ({}) runs on the native engine",
                super::DEFAULT_INT8
            ),
        ));
    }
    Ok(())
}

fn find(name: &str) -> Option<&'static [u8]> {
    files().find(|(n, _)| *n == name).map(|(_, b)| b)
}

/// File name in `models/` of the shipped RGB-D hologram CNN with `layers` layers in `precision`.
pub fn hologram_file(layers: usize, precision: Precision) -> String {
    scene_hologram_file(SceneInput::Rgbd, layers, precision)
}

/// File name in `models/` of the shipped hologram CNN taking `input` with `layers` layers in `precision`
/// (`holo{layers}_{rgbd|ldi}{suffix}.onnx`).
pub fn scene_hologram_file(input: SceneInput, layers: usize, precision: Precision) -> String {
    format!("holo{layers}_{input}{}.onnx", precision.file_suffix())
}

/// File name in `models/` of the shipped pre-filter CNN for an offset of `offset_mm` millimetres, trained with
/// the 8-layer hologram CNN ([`paired_prefilter_file`] with 8 layers).
pub fn prefilter_file(offset_mm: u32, precision: Precision) -> String {
    paired_prefilter_file(offset_mm, 8, precision)
}

/// File name in `models/` of the shipped pre-filter CNN for an offset of `offset_mm` millimetres trained on the
/// holograms of the `hologram_layers`-layer CNN: `prefilter_{offset}mm{suffix}.onnx` for 8 layers (the first
/// shipped), `prefilter_{offset}mm_holo{layers}{suffix}.onnx` for the others.
pub fn paired_prefilter_file(
    offset_mm: u32,
    hologram_layers: usize,
    precision: Precision,
) -> String {
    let depth = match hologram_layers {
        8 => String::new(),
        l => format!("_holo{l}"),
    };
    format!(
        "prefilter_{offset_mm}mm{depth}{}.onnx",
        precision.file_suffix()
    )
}

/// The ONNX bytes of the shipped RGB-D hologram CNN with `layers` ∈ {8, 15, 30} layers.
///
/// Errors: [`HoloError::InvalidParameter`](crate::HoloError) for another layer count, or for 15 or 30
/// layers in a build without the feature `models-15` / `models-30` (the message names it); `precision`
/// for the int8 QOperator form in a build without `tract`.
pub fn hologram_cnn(layers: usize, precision: Precision) -> Result<&'static [u8]> {
    scene_hologram_cnn(SceneInput::Rgbd, layers, precision)
}

/// The ONNX bytes of the shipped hologram CNN taking `input` with `layers` layers (`shipped_layers`: 8, 15
/// or 30 for RGB-D, 8 for LDI).
///
/// Errors: as [`hologram_cnn`].
pub fn scene_hologram_cnn(
    input: SceneInput,
    layers: usize,
    precision: Precision,
) -> Result<&'static [u8]> {
    check_engine(precision)?;
    find(&scene_hologram_file(input, layers, precision)).ok_or_else(|| {
        let shipped = shipped_layers(input);
        let why = if shipped.contains(&layers) {
            format!(
                "the {layers}-layer hologram CNN is not embedded in this build (cargo feature \
                 `models-{layers}`; embedded: {LAYERS:?} layers)"
            )
        } else {
            format!("the shipped {input} hologram CNNs have {shipped:?} layers, not {layers}")
        };
        invalid("layers", why)
    })
}

/// The ONNX bytes of the shipped pre-filter CNN for an SLM offset of `offset_mm` ∈ {6, 12} millimetres, trained
/// with the 8-layer hologram CNN.
///
/// Errors: [`HoloError::InvalidParameter`](crate::HoloError) for another offset; `precision` for the int8
/// QOperator form in a build without `tract`.
pub fn prefilter_cnn(offset_mm: u32, precision: Precision) -> Result<&'static [u8]> {
    paired_prefilter_cnn(offset_mm, 8, precision)
}

/// The ONNX bytes of the shipped pre-filter CNN for an SLM offset of `offset_mm` ∈ {6, 12} millimetres trained
/// on the holograms of the `hologram_layers`-layer CNN (8, 15 or 30; the 15- and 30-layer ones come with
/// the features `models-15` / `models-30`, as their CNNs).
///
/// Errors: [`HoloError::InvalidParameter`](crate::HoloError) (`offset_mm`) for another offset, (`layers`) for a
/// depth without a pre-filter in this build; `precision` for the int8 QOperator form in a build without
/// `tract`.
pub fn paired_prefilter_cnn(
    offset_mm: u32,
    hologram_layers: usize,
    precision: Precision,
) -> Result<&'static [u8]> {
    check_engine(precision)?;
    if !PREFILTER_OFFSETS_MM.contains(&offset_mm) {
        return Err(invalid(
            "offset_mm",
            format!("the shipped pre-filter CNNs are for {PREFILTER_OFFSETS_MM:?} mm, not {offset_mm} mm"),
        ));
    }
    find(&paired_prefilter_file(offset_mm, hologram_layers, precision)).ok_or_else(|| {
        invalid(
            "layers",
            format!(
                "no shipped pre-filter CNN trained with the {hologram_layers}-layer hologram CNN in this \
                 build (embedded: those of {LAYERS:?} layers)"
            ),
        )
    })
}

/// Loads the shipped RGB-D hologram CNN with `layers` ∈ {8, 15, 30} layers in `precision`, checked against
/// `expected` like any file ([`HologramModel::from_bytes`]); errors name the embedded file.
///
/// Errors: as [`hologram_cnn`] and [`HologramModel::from_bytes`].
pub fn hologram_model(
    layers: usize,
    precision: Precision,
    expected: &ModelConfig,
) -> Result<HologramModel> {
    scene_hologram_model(SceneInput::Rgbd, layers, precision, expected)
}

/// Loads the shipped hologram CNN taking `input` ([`scene_hologram_cnn`]), checked against `expected` with
/// its `input_layers` set to `input`'s.
///
/// Errors: as [`scene_hologram_cnn`] and [`HologramModel::from_bytes`].
pub fn scene_hologram_model(
    input: SceneInput,
    layers: usize,
    precision: Precision,
    expected: &ModelConfig,
) -> Result<HologramModel> {
    let expected = ModelConfig {
        input_layers: input.input_layers(),
        ..*expected
    };
    HologramModel::from_named_bytes(
        scene_hologram_cnn(input, layers, precision)?,
        &scene_hologram_file(input, layers, precision),
        ModelKind::Hologram,
        &expected,
    )
}

/// Loads the shipped pre-filter CNN for an SLM offset of `offset_mm` ∈ {6, 12} millimetres in `precision`
/// (trained with the 8-layer hologram CNN), checked against `expected` (its `offset_m` must be that offset);
/// errors name the embedded file.
///
/// Errors: as [`prefilter_cnn`] and [`HologramModel::from_bytes`].
pub(crate) fn prefilter_model(
    offset_mm: u32,
    precision: Precision,
    expected: &ModelConfig,
) -> Result<HologramModel> {
    paired_prefilter_model(offset_mm, 8, precision, expected)
}

/// Loads the shipped pre-filter CNN of `offset_mm` trained with the `hologram_layers`-layer hologram CNN
/// ([`paired_prefilter_cnn`]), checked against `expected` like any file.
///
/// Errors: as [`paired_prefilter_cnn`] and [`HologramModel::from_bytes`]; [`HoloError::ModelMetadata`](crate::HoloError)
/// if the file's `tensorholo.hologram_layers` is not `hologram_layers`.
pub(crate) fn paired_prefilter_model(
    offset_mm: u32,
    hologram_layers: usize,
    precision: Precision,
    expected: &ModelConfig,
) -> Result<HologramModel> {
    let model = HologramModel::from_named_bytes(
        paired_prefilter_cnn(offset_mm, hologram_layers, precision)?,
        &paired_prefilter_file(offset_mm, hologram_layers, precision),
        ModelKind::PreFilter,
        expected,
    )?;
    // The file's name pairs it; its metadata must agree (a renamed or mis-exported file is refused).
    match model.metadata().hologram_layers {
        Some(l) if l != hologram_layers => Err(crate::HoloError::ModelMetadata {
            key: "tensorholo.hologram_layers".into(),
            found: l.to_string(),
            expected: format!(
                "{hologram_layers} (embedded as {})",
                paired_prefilter_file(offset_mm, hologram_layers, precision)
            ),
        }),
        _ => Ok(model),
    }
}

/// One shipped CNN against a display ([`check_display`]): whether it serves the display at one offset, and
/// how (the mapping: `σ`, the laser spread's ceiling and estimated cost, the volume fit, the residual), or why
/// not and what would serve.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ShippedModelCheck {
    /// The embedded file (`holo8_rgbd.onnx`, `prefilter_6mm_holo15.int8-qdq.onnx`, …).
    pub file: String,
    /// `hologram-cnn` or `prefilter-cnn`.
    pub kind: &'static str,
    /// Convolution layers of the hologram CNN (a pre-filter: of the hologram CNN it pairs with).
    pub layers: usize,
    /// `rgbd` or `ldi` (a pre-filter: `rgbd`, the input of the CNN it pairs with).
    pub input: String,
    /// Weight format.
    pub precision: Precision,
    /// The display's offset checked, metres.
    pub offset_m: f64,
    /// How the model serves the display at that offset; `None` where it does not.
    pub mapping: Option<crate::display::DisplayMapping>,
    /// Why it does not, and what would serve; `None` where it does.
    pub refusal: Option<crate::display::DisplayRefusal>,
    /// Why no such model was checked (no pre-filter is shipped for the offset), where none was.
    pub note: Option<String>,
}

impl ShippedModelCheck {
    /// Whether the model serves the display at this offset.
    pub fn served(&self) -> bool {
        self.mapping.is_some()
    }
}

/// Which shipped CNNs of this build serve a display (`docs/DISPLAYS.md`): at each offset of `offsets_m`
/// (metres), every hologram CNN embedded (each depth, f32 and int8 QDQ; the LDI CNN), and the pre-filter each
/// depth pairs with at that offset (the one whose offset on the training display is `s'/σ`: 6 or 12 mm), with
/// the laser tolerance `tolerance` (`None`: the serving rule's, per model). What `holo display check` and
/// the bindings' `checkDisplay` print.
///
/// Errors: [`HoloError::InvalidParameter`](crate::HoloError) for invalid optics, offsets or tolerance; model
/// errors other than a display the model does not serve (a corrupt embedded file).
pub fn check_display(
    optics: &crate::optics::OpticalSetup,
    offsets_m: &[f64],
    tolerance: Option<f64>,
) -> Result<Vec<ShippedModelCheck>> {
    optics.validate()?;
    if offsets_m.is_empty() || offsets_m.iter().any(|s| !s.is_finite()) {
        return Err(invalid("offsets_m", "at least one finite offset in metres"));
    }
    let mut out = Vec::new();
    let precisions = [Precision::F32, super::DEFAULT_INT8];
    let hologram_cnns = LAYERS
        .iter()
        .map(|&l| (SceneInput::Rgbd, l))
        .chain(SHIPPED_LDI_LAYERS.iter().map(|&l| (SceneInput::Ldi, l)));
    for &offset_m in offsets_m {
        let expected = |input: SceneInput| ModelConfig {
            optics: *optics,
            offset_m,
            input_layers: input.input_layers(),
            wavelength_ratio_tolerance: tolerance,
        };
        for (input, layers) in hologram_cnns.clone() {
            for precision in precisions {
                let file = scene_hologram_file(input, layers, precision);
                let bytes = scene_hologram_cnn(input, layers, precision)?;
                let loaded = HologramModel::from_named_bytes(
                    bytes,
                    &file,
                    ModelKind::Hologram,
                    &expected(input),
                );
                let what = (ModelKind::Hologram, layers, input, precision);
                out.push(checked(file, what, &expected(input), loaded)?);
            }
        }
        // The pre-filters: the one each RGB-D depth pairs with at this offset, by its offset on the
        // training display (s'/σ; all shipped CNNs share the paper's display, so σ is one for all).
        if offset_m == 0.0 {
            continue;
        }
        let trained = crate::optics::OpticalSetup::default();
        let sigma =
            crate::display::DisplayMapping::compute(&trained, optics, offset_m, Some(1.0), 0.0)?
                .scale;
        let mm = offset_m / sigma * 1e3;
        let paired = PREFILTER_OFFSETS_MM
            .iter()
            .copied()
            .find(|&o| (mm - o as f64).abs() <= 1e-6 * o as f64);
        for &layers in LAYERS {
            for precision in precisions {
                let Some(o) = paired else {
                    out.push(ShippedModelCheck {
                        file: String::new(),
                        kind: ModelKind::PreFilter.metadata_name(),
                        layers,
                        input: SceneInput::Rgbd.to_string(),
                        precision,
                        offset_m,
                        mapping: None,
                        refusal: None,
                        note: Some(format!(
                            "no shipped pre-filter at {} mm ({} mm on the training display; shipped: 6 and 12 \
                             mm): encoded with AA-DPM",
                            offset_m * 1e3,
                            crate::display::sig(mm)
                        )),
                    });
                    continue;
                };
                let file = paired_prefilter_file(o, layers, precision);
                let bytes = paired_prefilter_cnn(o, layers, precision)?;
                let loaded = HologramModel::from_named_bytes(
                    bytes,
                    &file,
                    ModelKind::PreFilter,
                    &expected(SceneInput::Rgbd),
                );
                let what = (ModelKind::PreFilter, layers, SceneInput::Rgbd, precision);
                out.push(checked(file, what, &expected(SceneInput::Rgbd), loaded)?);
            }
        }
    }
    Ok(out)
}

/// The check of one model (`kind`, hologram layers, input, precision) loaded (or refused) against `expected`.
/// Errors: `loaded`'s error other than a display refusal.
fn checked(
    file: String,
    (kind, layers, input, precision): (ModelKind, usize, SceneInput, Precision),
    expected: &ModelConfig,
    loaded: Result<HologramModel>,
) -> Result<ShippedModelCheck> {
    let (mapping, refusal) = match loaded {
        Ok(m) => (Some(m.metadata().check(kind, expected)?), None),
        Err(crate::HoloError::DisplayNotServed(r)) => (None, Some(*r)),
        Err(e) => return Err(e),
    };
    Ok(ShippedModelCheck {
        file,
        kind: kind.metadata_name(),
        layers,
        input: input.to_string(),
        precision,
        offset_m: expected.offset_m,
        mapping,
        refusal,
        note: None,
    })
}
