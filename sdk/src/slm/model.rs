//! A display model fitted from camera captures (`tensorholo.display-model`, docs/CALIBRATION.md "The display
//! model"): per colour the source field over the SLM, the SLM's crosstalk in the drive domain, its phase
//! response, the undiffracted (zero-order) light and the optics' aberration. Every part is optional; a model
//! without parts is the ideal display of `docs/REFINE.md` (a plane wave, each pixel showing `2π·code/256`).
//!
//! The field leaving the SLM for 8-bit codes (drive) `c` `[H, W]` is
//!
//! ```text
//! u = S · (exp(i·R(K ∗ c)) + z)
//! ```
//!
//! with `K` the crosstalk kernel (a small odd-size convolution of the drive, edges clamped: the fringing field
//! between neighbouring pixels), `R` the phase response (the existing look-up tables: one 256-entry curve,
//! `slm::PhaseCurve`, or per-pixel tiled curves, `slm::TiledCurves`; linear between codes; `2π·v/256`
//! without one), `z` the complex
//! zero-order fraction (`|z| < 1`) and `S = exp(P_a + i·P_φ)` the source, `P_a` and `P_φ` polynomials in the
//! SLM's normalised coordinates (a Gaussian beam is a quadratic `P_a`). A camera focused `distance_m` from the
//! SLM sees `g·|F⁻¹{M·E·H(distance_m)·F{u}}|²`, the refinement's display simulation (`refine::model`): `M` the
//! Fourier filter (Eq. 8–9), `H` the transfer function (Eq. 2, Eq. 10), `E = circ·exp(−i·ΣZ_j)` the optics'
//! aberration (the Zernike terms of Eq. 14–18) and `g` the capture set's gain.

use std::path::Path;

use ndarray::{Array3, ArrayView3, Axis};
use num_complex::Complex32;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{invalid, HoloError, Result};
use crate::optics::filter::aperture_fn;
use crate::optics::multiplier::{plane_multiplier, PlaneMultiplier};
use crate::optics::{OpticalSetup, PropagationOptions, Propagator, ZernikeCoefficients};
use crate::slm::lut::{interpolate_codes, AxisWeight};
use crate::slm::{LutRepresentation, PhaseCurve, TiledCurves};

/// Value of a display model file's `format` field.
pub const DISPLAY_MODEL_FORMAT: &str = "tensorholo.display-model";
/// Version of the display model format this build reads and writes.
pub const DISPLAY_MODEL_VERSION: u32 = 1;
/// The colours' keys in a model file and a capture manifest, in channel order (R, G, B).
pub const COLOUR_KEYS: [&str; 3] = ["red", "green", "blue"];
/// The largest crosstalk kernel side a model holds: 15 pixels.
pub const MAX_KERNEL_SIDE: usize = 15;

/// The source field over the SLM, `S = exp(P_a + i·P_φ)`, each polynomial's terms
/// `[x, y, x², y², x·y]` in the SLM's normalised coordinates (`x = (2j + 1)/W − 1`, `y = (2i + 1)/H − 1`,
/// `[-1, 1]` across the panel; `i` the row). Neither constant is stored: that of `P_a` is the colour's power,
/// which the refinement's least-squares scale per colour absorbs (the fit reports it,
/// `model_fit::FitReport::power`), and that of `P_φ` is invisible. A Gaussian beam of waist `w` (normalised)
/// centred at `(x₀, y₀)` has `log_amplitude = [2x₀/w², 2y₀/w², −1/w², −1/w², 0]`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SourceField {
    /// `P_a`'s coefficients (natural log of the amplitude).
    pub log_amplitude: [f64; 5],
    /// `P_φ`'s coefficients, radians.
    pub phase_rad: [f64; 5],
}

/// The SLM's crosstalk: a `[rows, cols]` kernel (both odd) applied to the drive (the codes as numbers) before
/// the phase response, centred, edges clamped. Not assumed isotropic. Weights summing to 1 keep a flat drive.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Crosstalk {
    /// `[rows, cols]`, both odd, at most [`MAX_KERNEL_SIDE`].
    pub size: [usize; 2],
    /// `rows·cols` weights, row-major.
    pub weights: Vec<f64>,
}

/// The phase response in a model file, one of: `phases_rad`, the phase in radians each code displays over
/// the whole panel (the look-up tables' curve, `slm::PhaseCurve`: 256 non-decreasing values, code 0 first);
/// or `per_pixel`, the tiled per-pixel form of a calibration (`slm::TiledCurves`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ResponseFile {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    phases_rad: Option<Vec<f32>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    per_pixel: Option<TiledFile>,
}

/// A per-pixel response in a model file: the SLM's `[height, width]`, the tile's `[height, width]` and one
/// 256-value curve (radians) per tile, tiles row-major (`slm::TiledCurves`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TiledFile {
    slm_size: [usize; 2],
    tile: [usize; 2],
    tiles_rad: Vec<Vec<f32>>,
}

/// One colour's parts of a [`DisplayModel`]; each `None` is ideal.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColourDisplay {
    /// The source field over the SLM (`None`: a uniform plane wave).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<SourceField>,
    /// The phase response: the look-up tables' form, global ([`LutRepresentation::Global`]) or per pixel
    /// ([`LutRepresentation::Tiled`], of the model's SLM size) (`None`, or [`LutRepresentation::Linear`]:
    /// code `k` shows `2π·k/256`).
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        with = "response_serde"
    )]
    pub response: Option<LutRepresentation>,
    /// The crosstalk kernel (`None`: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crosstalk: Option<Crosstalk>,
    /// The zero-order fraction `z = [re, im]`, `|z| < 1` (`None`: 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zero_order: Option<[f64; 2]>,
    /// The optics' aberration in the Fourier plane, the Zernike terms of Eq. 14–18 (`None`: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aberration: Option<ZernikeCoefficients>,
}

mod response_serde {
    use super::{LutRepresentation, PhaseCurve, ResponseFile, TiledCurves, TiledFile};
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub(super) fn serialize<S: Serializer>(
        v: &Option<LutRepresentation>,
        s: S,
    ) -> std::result::Result<S::Ok, S::Error> {
        v.as_ref()
            .map(|r| match r {
                LutRepresentation::Linear => ResponseFile {
                    phases_rad: Some(PhaseCurve::linear().phases().to_vec()),
                    per_pixel: None,
                },
                LutRepresentation::Global(c) => ResponseFile {
                    phases_rad: Some(c.phases().to_vec()),
                    per_pixel: None,
                },
                LutRepresentation::Tiled(t) => {
                    let (h, w) = t.size();
                    let (th, tw) = t.tile();
                    ResponseFile {
                        phases_rad: None,
                        per_pixel: Some(TiledFile {
                            slm_size: [h, w],
                            tile: [th, tw],
                            tiles_rad: t.curves().iter().map(|c| c.phases().to_vec()).collect(),
                        }),
                    }
                }
            })
            .serialize(s)
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> std::result::Result<Option<LutRepresentation>, D::Error> {
        use serde::de::Error;
        let Some(file) = Option::<ResponseFile>::deserialize(d)? else {
            return Ok(None);
        };
        let r = match (file.phases_rad, file.per_pixel) {
            (Some(p), None) => {
                LutRepresentation::Global(PhaseCurve::new(&p).map_err(Error::custom)?)
            }
            (None, Some(t)) => {
                let curves = t
                    .tiles_rad
                    .iter()
                    .enumerate()
                    .map(|(i, c)| {
                        PhaseCurve::new(c).map_err(|e| Error::custom(format!("tile {i}: {e}")))
                    })
                    .collect::<std::result::Result<Vec<_>, _>>()?;
                let [h, w] = t.slm_size;
                let [th, tw] = t.tile;
                LutRepresentation::Tiled(
                    TiledCurves::new(h, w, th, tw, curves).map_err(Error::custom)?,
                )
            }
            _ => return Err(Error::custom(
                "a response gives either `phases_rad` (one curve) or `per_pixel` (tiled curves)",
            )),
        };
        Ok(Some(r))
    }
}

impl ColourDisplay {
    /// Whether every part is ideal.
    pub(crate) fn is_ideal(&self) -> bool {
        self == &Self::default()
    }

    /// Checks the parts; `colour` names the entry.
    fn validate(&self, colour: &str) -> Result<()> {
        let bad = |part: &str, why: String| {
            Err(HoloError::InvalidData(format!(
                "display model `{colour}.{part}`: {why}"
            )))
        };
        if let Some(s) = &self.source {
            if s.log_amplitude
                .iter()
                .chain(&s.phase_rad)
                .any(|v| !v.is_finite() || v.abs() > 1e3)
            {
                return bad(
                    "source",
                    "coefficients must be finite and within ±1000".into(),
                );
            }
        }
        if let Some(k) = &self.crosstalk {
            let [r, c] = k.size;
            if r % 2 == 0 || c % 2 == 0 || r > MAX_KERNEL_SIDE || c > MAX_KERNEL_SIDE {
                return bad(
                    "crosstalk",
                    format!(
                        "kernel of {r}×{c}: both sides odd (centred on the pixel), 1 to {MAX_KERNEL_SIDE}"
                    ),
                );
            }
            if k.weights.len() != r * c {
                return bad(
                    "crosstalk",
                    format!("{} weights for a {r}×{c} kernel", k.weights.len()),
                );
            }
            if k.weights.iter().any(|v| !v.is_finite()) {
                return bad("crosstalk", "weights must be finite".into());
            }
        }
        if let Some([re, im]) = self.zero_order {
            let m = re.hypot(im);
            if m.is_nan() || m >= 1.0 {
                return bad(
                    "zero_order",
                    format!("|z| = {m}: the undiffracted fraction is finite and below 1"),
                );
            }
        }
        if let Some(a) = &self.aberration {
            if a.to_array().iter().any(|v| !v.is_finite()) {
                return bad("aberration", "coefficients must be finite".into());
            }
        }
        Ok(())
    }
}

/// A display model (module docs; docs/CALIBRATION.md "The display model"): the SLM size it was fitted for
/// and each colour's parts. Stored as JSON:
///
/// ```json
/// {"format": "tensorholo.display-model", "version": 1, "slm_size": [96, 96],
///  "green": {"source": {"log_amplitude": [0.1, 0, -0.8, -0.8, 0]},
///            "crosstalk": {"size": [3, 3], "weights": [0, 0.02, 0, 0.03, 0.9, 0.03, 0, 0.02, 0]},
///            "zero_order": [0.05, -0.02], "aberration": {"focus": 0.3}}}
/// ```
///
/// A colour without an entry is ideal; unknown keys are refused. Serialises to this form (`serde_json`);
/// [`DisplayModel::load`] reads it, validating every part.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ModelFile", into = "ModelFile")]
pub struct DisplayModel {
    /// The SLM's `[height, width]` in pixels.
    pub slm_size: [usize; 2],
    /// R, G, B.
    pub colours: [ColourDisplay; 3],
}

#[derive(Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    format: String,
    version: u32,
    slm_size: [usize; 2],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    red: Option<ColourDisplay>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    green: Option<ColourDisplay>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    blue: Option<ColourDisplay>,
}

impl DisplayModel {
    /// Whether every colour is ideal (the refinement then runs exactly as without a model).
    pub(crate) fn is_ideal(&self) -> bool {
        self.colours.iter().all(ColourDisplay::is_ideal)
    }

    /// Checks every part (naming the entry, `green.crosstalk`) and the SLM size.
    ///
    /// Errors: [`HoloError::InvalidData`] naming the entry: a kernel of even size or of the wrong number of
    /// weights, non-finite values, `|zero_order| ≥ 1`, a zero SLM size.
    pub(crate) fn validate(&self) -> Result<()> {
        let [h, w] = self.slm_size;
        if h == 0 || w == 0 {
            return Err(HoloError::InvalidData(format!(
                "display model `slm_size`: {h}×{w}, both ≥ 1"
            )));
        }
        for (c, part) in self.colours.iter().enumerate() {
            part.validate(COLOUR_KEYS[c])?;
            if let Some(LutRepresentation::Tiled(t)) = &part.response {
                if t.size() != (h, w) {
                    let (th, tw) = t.size();
                    return Err(HoloError::InvalidData(format!(
                        "display model `{}.response`: per-pixel tables of a {th}×{tw} SLM in a model of \
                         {h}×{w}",
                        COLOUR_KEYS[c]
                    )));
                }
            }
        }
        Ok(())
    }

    /// Checks the model (as [`DisplayModel::validate`]) for a refinement that does (`viewer`) or does not see
    /// through a viewer's aberration: the two aberrations at once are refused.
    ///
    /// Errors: those of validation; [`HoloError::InvalidParameter`] (`display_model`) for a model with an
    /// aberration beside a viewer's.
    pub(crate) fn validate_for(&self, viewer: bool) -> Result<()> {
        self.validate()?;
        if viewer && self.colours.iter().any(|c| c.aberration.is_some()) {
            return Err(invalid(
                "display_model",
                "a display model with an aberration and a viewer's aberration at once: give one",
            ));
        }
        Ok(())
    }

    /// Refuses a model made for another SLM size than `[height, width]`.
    ///
    /// Errors: [`HoloError::ShapeMismatch`].
    pub(crate) fn check_size(&self, height: usize, width: usize) -> Result<()> {
        if self.slm_size != [height, width] {
            return Err(HoloError::ShapeMismatch {
                what: "display model's SLM size vs the frame's".into(),
                expected: self.slm_size.to_vec(),
                got: vec![height, width],
            });
        }
        Ok(())
    }

    /// Parses the JSON form; `source` names the input in errors.
    ///
    /// Errors: [`HoloError::InvalidData`] naming `source` and the entry: not this format or version, an
    /// unknown part or key, a value of the wrong type, and those of validation (kernel of even size,
    /// non-finite values, `|zero_order| ≥ 1`, a response curve that decreases).
    pub fn from_json_str(text: &str, source: &str) -> Result<Self> {
        crate::io::parse_json_object::<Self>(text, "a display model").map_err(|e| {
            HoloError::InvalidData(format!(
                "`{source}` is not a valid display model ({DISPLAY_MODEL_FORMAT} version \
                 {DISPLAY_MODEL_VERSION}, docs/CALIBRATION.md): {e}"
            ))
        })
    }

    /// Reads a model file (`tensorholo.display-model`, the struct's docs; written by `serde_json` from the
    /// model, which serialises to that form).
    ///
    /// Errors: [`HoloError::Io`] if unreadable; [`HoloError::InvalidData`] naming the file and the entry at
    /// fault (an unknown part, a kernel of even size, non-finite values, a zero-order fraction of 1 or more).
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::io::read_text(path)?;
        Self::from_json_str(&text, &path.display().to_string())
    }

    /// What the display this model describes shows of the SLM codes `codes` `[3, H, W]` (R, G, B: the 8-bit
    /// codes sent to the SLM), after the display's Fourier filter, expressed at the midpoint plane and
    /// multiplied by the frame's `amplitude_scale` `a`: per colour `a·F⁻¹{M·E·H(−s)·F{u}}` with
    /// `u = S·(exp(i·R(K ∗ codes)) + z)` and `s = offset_m` the SLM's distance from the midpoint plane in
    /// metres (the module docs: the same forward simulation as the refinement's loss and the simulated
    /// captures). It is the fitted display's counterpart of
    /// [`post_encoding_midpoint`](crate::optics::post_encoding_midpoint), which shows the ideal display of the
    /// codes' phases: `holo render --evaluate --display-model` scores it with the Table 2 protocol. A colour
    /// without parts shows the ideal display of its codes (`2π·code/256`). Returns `[3, H, W]` complex.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for codes that are not `[3, H, W]` of the model's SLM size;
    /// [`HoloError::InvalidParameter`] for a padded propagation (`pad`: the model runs on the refinement's
    /// unpadded grid), a non-finite offset or a scale that is not positive and finite; those of the
    /// propagation (an invalid `setup`).
    pub fn shown_midpoint(
        &self,
        codes: ArrayView3<u8>,
        amplitude_scale: f32,
        setup: &OpticalSetup,
        offset_m: f64,
        options: PropagationOptions,
    ) -> Result<Array3<Complex32>> {
        let (channels, h, w) = codes.dim();
        if channels != 3 {
            return Err(HoloError::ShapeMismatch {
                what: "SLM codes shown through a display model".into(),
                expected: vec![3, h, w],
                got: vec![channels, h, w],
            });
        }
        self.check_size(h, w)?;
        if options.pad {
            return Err(invalid(
                "pad",
                "a display model runs on the refinement's unpadded grid; padded propagation is not supported",
            ));
        }
        if !offset_m.is_finite() {
            return Err(invalid(
                "offset_m",
                format!("must be finite, got {offset_m}"),
            ));
        }
        if !(amplitude_scale > 0.0 && amplitude_scale.is_finite()) {
            return Err(invalid(
                "amplitude_scale",
                format!("must be > 0, got {amplitude_scale}"),
            ));
        }
        setup.validate()?;
        let mut out = Array3::<Complex32>::zeros((3, h, w));
        out.axis_iter_mut(Axis(0))
            .into_par_iter()
            .enumerate()
            .try_for_each(|(c, mut lane)| -> Result<()> {
                let part = &self.colours[c];
                let mut runtime = ColourRuntime::new(part, h, w);
                let drive: Vec<f32> = codes
                    .index_axis(Axis(0), c)
                    .iter()
                    .map(|&v| f32::from(v))
                    .collect();
                let mut unit = vec![Complex32::new(0.0, 0.0); h * w];
                runtime.forward(&drive, &mut unit);
                let (prop, m) = capture_multiplier(
                    setup,
                    options,
                    c,
                    (h, w),
                    -offset_m,
                    part.aberration.as_ref(),
                )?;
                let mut field = Vec::new();
                field_of(&prop, &m, &unit, &mut field);
                for (o, v) in lane.iter_mut().zip(&field) {
                    *o = v * amplitude_scale;
                }
                Ok(())
            })?;
        Ok(out)
    }

    /// The JSON form, pretty-printed, which [`DisplayModel::load`] reads back.
    #[cfg(test)]
    pub(crate) fn to_json_string(&self) -> String {
        serde_json::to_string_pretty(self).expect("a display model always serialises")
    }
}

impl TryFrom<ModelFile> for DisplayModel {
    type Error = String;

    fn try_from(file: ModelFile) -> std::result::Result<Self, String> {
        if file.format != DISPLAY_MODEL_FORMAT || file.version != DISPLAY_MODEL_VERSION {
            return Err(format!("format `{}` version {}", file.format, file.version));
        }
        let model = Self {
            slm_size: file.slm_size,
            colours: [
                file.red.unwrap_or_default(),
                file.green.unwrap_or_default(),
                file.blue.unwrap_or_default(),
            ],
        };
        model.validate().map_err(|e| e.to_string())?;
        Ok(model)
    }
}

impl From<DisplayModel> for ModelFile {
    fn from(model: DisplayModel) -> Self {
        let [red, green, blue] = model.colours.map(|p| Some(p).filter(|p| !p.is_ideal()));
        Self {
            format: DISPLAY_MODEL_FORMAT.into(),
            version: DISPLAY_MODEL_VERSION,
            slm_size: model.slm_size,
            red,
            green,
            blue,
        }
    }
}

/// The normalised coordinate of index `k` of `n`: `(2k + 1)/n − 1`.
pub(crate) fn normalised(k: usize, n: usize) -> f64 {
    (2 * k + 1) as f64 / n as f64 - 1.0
}

/// The polynomial terms `[x, y, x², y², x·y]` at `(x, y)`.
pub(crate) fn source_terms(x: f64, y: f64) -> [f64; 5] {
    [x, y, x * x, y * y, x * y]
}

/// One colour's model on a `[H, W]` grid, ready to run: the source map, the kernel, the response table, the
/// zero order, and the buffers of the last forward pass (for the gradient).
#[derive(Debug, Clone)]
pub(crate) struct ColourRuntime {
    height: usize,
    width: usize,
    /// `S` per pixel, `None` for a plane wave.
    pub(crate) source: Option<Vec<Complex32>>,
    /// `(rows, cols, weights)`.
    kernel: Option<(usize, usize, Vec<f32>)>,
    /// The phase response, `None`: `2π·v/256`.
    response: Option<Response>,
    pub(crate) zero: Complex32,
    /// `K ∗ c` of the last forward pass.
    pub(crate) crossed: Vec<f32>,
    /// `S·exp(i·R(K ∗ c))` of the last forward pass.
    pub(crate) modulated: Vec<Complex32>,
    /// `∂L/∂c` of the last backward pass.
    pub(crate) grad: Vec<f32>,
    /// `∂L/∂(K ∗ c)` of the last backward pass.
    dphi: Vec<f32>,
}

/// A runtime's phase response.
#[derive(Debug, Clone)]
enum Response {
    /// Phase per code, the whole panel.
    Table(Box<[f32; 256]>),
    /// Per pixel, tiled, with each row's and column's bilinear weights.
    Tiled {
        curves: TiledCurves,
        rows: Vec<AxisWeight>,
        columns: Vec<AxisWeight>,
    },
}

/// A colour's parts as plain arrays ([`ColourRuntime::plain_parts`]), the response always in the tiled form
/// (one tile for a global table).
#[cfg_attr(not(feature = "gpu"), allow(dead_code))]
pub(crate) struct PlainParts<'a> {
    /// `S` per pixel `[H, W]`, `None`: a plane wave.
    pub(crate) source: Option<&'a [Complex32]>,
    /// The tiles' curves, `[tiles, 256]` flat, radians per code, tiles row-major.
    pub(crate) curves: Vec<f32>,
    /// Tiles per row of the tile grid.
    pub(crate) grid_cols: usize,
    /// Each row's bilinear weights `[H]` (all `(0, 0, 0)` for one tile).
    pub(crate) rows: Vec<AxisWeight>,
    /// Each column's bilinear weights `[W]`.
    pub(crate) columns: Vec<AxisWeight>,
    /// `(rows, cols, weights row-major)`.
    pub(crate) kernel: (usize, usize, Vec<f32>),
    /// The zero order `z`.
    pub(crate) zero: Complex32,
}

/// The linear response's slope, radians per code.
pub(crate) const LINEAR_SLOPE: f32 = std::f32::consts::TAU / 256.0;

impl ColourRuntime {
    /// Colour `part` on a `[height, width]` grid.
    pub(crate) fn new(part: &ColourDisplay, height: usize, width: usize) -> Self {
        let source = part.source.map(|s| {
            let mut out = Vec::with_capacity(height * width);
            for i in 0..height {
                let y = normalised(i, height);
                for j in 0..width {
                    let t = source_terms(normalised(j, width), y);
                    let dot = |c: &[f64; 5]| c.iter().zip(&t).map(|(a, b)| a * b).sum::<f64>();
                    out.push(Complex32::from_polar(
                        dot(&s.log_amplitude).exp() as f32,
                        dot(&s.phase_rad) as f32,
                    ));
                }
            }
            out
        });
        let n = height * width;
        Self {
            height,
            width,
            source,
            kernel: part.crosstalk.as_ref().map(|k| {
                (
                    k.size[0],
                    k.size[1],
                    k.weights.iter().map(|&v| v as f32).collect(),
                )
            }),
            response: part.response.as_ref().and_then(|r| match r {
                LutRepresentation::Linear => None,
                LutRepresentation::Global(c) => Some(Response::Table(Box::new(*c.phases()))),
                LutRepresentation::Tiled(t) => {
                    let (rows, columns) = t.row_and_column_weights();
                    Some(Response::Tiled {
                        curves: t.clone(),
                        rows,
                        columns,
                    })
                }
            }),
            zero: part
                .zero_order
                .map_or(Complex32::new(0.0, 0.0), |[re, im]| {
                    Complex32::new(re as f32, im as f32)
                }),
            crossed: vec![0.0; n],
            modulated: vec![Complex32::new(0.0, 0.0); n],
            grad: vec![0.0; n],
            dphi: Vec::with_capacity(n),
        }
    }

    /// Replaces the response by the table `phases` (radians per code; the fit's trial curves, unchecked).
    pub(crate) fn set_response(&mut self, phases: [f32; 256]) {
        self.response = Some(Response::Table(Box::new(phases)));
    }

    /// `out ← K ∗ input` (`transpose`: the adjoint, `Kᵀ ∗`, scattering to the clamped neighbours).
    fn convolve(&self, input: &[f32], out: &mut [f32], transpose: bool) {
        let Some((kr, kc, k)) = &self.kernel else {
            out.copy_from_slice(input);
            return;
        };
        let (h, w) = (self.height as isize, self.width as isize);
        let (hr, hc) = ((*kr / 2) as isize, (*kc / 2) as isize);
        out.fill(0.0);
        for i in 0..h {
            for j in 0..w {
                let p = (i * w + j) as usize;
                for (a, row) in k.chunks_exact(*kc).enumerate() {
                    let ii = (i + a as isize - hr).clamp(0, h - 1);
                    for (b, &kv) in row.iter().enumerate() {
                        let q = (ii * w + (j + b as isize - hc).clamp(0, w - 1)) as usize;
                        if transpose {
                            out[q] += kv * input[p];
                        } else {
                            out[p] += kv * input[q];
                        }
                    }
                }
            }
        }
    }

    /// This colour's parts as plain arrays, for the GPU refinement's kernels: `S` per pixel (`None`: a plane
    /// wave), the response as tiles (one tile for a global table; the linear table `2π·k/256` without one) with
    /// each row's and column's weights, the kernel's `(rows, cols, weights)` (`(1, 1, [1])` without one) and
    /// `z`.
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    pub(crate) fn plain_parts(&self) -> PlainParts<'_> {
        let one_tile = |table: &[f32]| {
            (
                table.to_vec(),
                1,
                vec![(0, 0, 0.0); self.height],
                vec![(0, 0, 0.0); self.width],
            )
        };
        let linear: [f32; 256] = std::array::from_fn(|k| k as f32 * LINEAR_SLOPE);
        let (curves, grid_cols, rows, columns) = match &self.response {
            None => one_tile(&linear),
            Some(Response::Table(t)) => one_tile(&t[..]),
            Some(Response::Tiled {
                curves,
                rows,
                columns,
            }) => (
                curves
                    .curves()
                    .iter()
                    .flat_map(|c| c.phases().iter().copied())
                    .collect(),
                curves.grid().1,
                rows.clone(),
                columns.clone(),
            ),
        };
        PlainParts {
            source: self.source.as_deref(),
            curves,
            grid_cols,
            rows,
            columns,
            kernel: self.kernel.clone().unwrap_or_else(|| (1, 1, vec![1.0])),
            zero: self.zero,
        }
    }

    /// The response at pixel `p` (row-major) to drive `v` (codes as numbers) and its slope.
    #[inline]
    pub(crate) fn respond(&self, p: usize, v: f32) -> (f32, f32) {
        match &self.response {
            None => (v * LINEAR_SLOPE, LINEAR_SLOPE),
            Some(Response::Table(t)) => interpolate_codes(v, |k| t[usize::from(k)]),
            Some(Response::Tiled {
                curves,
                rows,
                columns,
            }) => curves.phase_and_slope(rows[p / self.width], columns[p % self.width], v),
        }
    }

    /// `unit ← u = S·(exp(i·R(K ∗ drive)) + z)` for the drive `drive` `[H, W]` (codes as numbers), keeping
    /// what [`ColourRuntime::backward`] needs.
    pub(crate) fn forward(&mut self, drive: &[f32], unit: &mut [Complex32]) {
        let mut crossed = std::mem::take(&mut self.crossed);
        self.convolve(drive, &mut crossed, false);
        let mut modulated = std::mem::take(&mut self.modulated);
        for (p, (&v, (m, u))) in crossed
            .iter()
            .zip(modulated.iter_mut().zip(unit.iter_mut()))
            .enumerate()
        {
            let (phi, _) = self.respond(p, v);
            let (s, c) = phi.sin_cos();
            let src = self
                .source
                .as_ref()
                .map_or(Complex32::new(1.0, 0.0), |s| s[p]);
            *m = src * Complex32::new(c, s);
            *u = *m + src * self.zero;
        }
        self.modulated = modulated;
        self.crossed = crossed;
    }

    /// `grad ← ∂L/∂drive` from `g = ∂L/∂Re u + i·∂L/∂Im u` `[H, W]` of the last forward pass: through the
    /// source and the response (`∂L/∂φ = Im(g·conj(S·e^{iφ}))`, times the response's slope) and the kernel's
    /// adjoint.
    pub(crate) fn backward(&mut self, g: &[Complex32]) {
        let mut dphi = std::mem::take(&mut self.dphi);
        dphi.clear();
        dphi.extend(
            g.iter()
                .zip(&self.modulated)
                .zip(&self.crossed)
                .enumerate()
                .map(|(p, ((g, m), &v))| (g.im * m.re - g.re * m.im) * self.respond(p, v).1),
        );
        let mut grad = std::mem::take(&mut self.grad);
        self.convolve(&dphi, &mut grad, true);
        self.grad = grad;
        self.dphi = dphi;
    }
}

/// A camera's view of one capture: the multiplier `M·E·H(distance_m)` of colour `colour` on a `[H, W]` grid
/// with the model's aberration (`optics::multiplier::plane_multiplier`), the angular spectrum's `options`
/// unpadded (the captures and the fit: the defaults).
///
/// Errors: as `Propagator::new` and the transfer function's.
pub(crate) fn capture_multiplier(
    setup: &OpticalSetup,
    options: PropagationOptions,
    colour: usize,
    (height, width): (usize, usize),
    distance_m: f64,
    aberration: Option<&ZernikeCoefficients>,
) -> Result<(Propagator, PlaneMultiplier)> {
    let prop = setup.propagator(colour, (height, width), options)?;
    let aperture = aperture_fn(prop.plan());
    let m = plane_multiplier(&prop, &aperture, distance_m, aberration)?;
    Ok((prop, m))
}

/// The intensity `|F⁻¹{m·F{u}}|²` `[H, W]` of the SLM field `u` `[H, W]` through `m` on `prop`'s grid, with
/// the field `U` left in `field`.
pub(crate) fn intensity_of(
    prop: &Propagator,
    m: &PlaneMultiplier,
    u: &[Complex32],
    field: &mut Vec<Complex32>,
) -> Vec<f32> {
    field_of(prop, m, u, field);
    field.iter().map(|v| v.norm_sqr()).collect()
}

/// `field ← U = F⁻¹{m·F{u}}` `[H, W]` of the SLM field `u` `[H, W]` through `m` on `prop`'s (unpadded) grid.
fn field_of(prop: &Propagator, m: &PlaneMultiplier, u: &[Complex32], field: &mut Vec<Complex32>) {
    let plan = prop.plan();
    let fft = plan.fft();
    let n = u.len();
    let mut data = u.to_vec();
    let mut spectrum = vec![Complex32::new(0.0, 0.0); n];
    let mut scratch = vec![Complex32::new(0.0, 0.0); fft.scratch_len()];
    fft.forward(&mut data, &mut spectrum, &mut scratch);
    let cols = fft.height();
    for (r, row) in spectrum.chunks_exact_mut(cols).enumerate() {
        m.multiply_row(r, row, fft.isa());
    }
    field.resize(n, Complex32::new(0.0, 0.0));
    fft.inverse(&mut spectrum, field, &mut scratch);
}

#[cfg(test)]
mod tests;
