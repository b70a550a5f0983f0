//! The one error type of the SDK.

use std::path::PathBuf;

/// Every failure the SDK reports. Each variant names the offending input so that a caller (or the
/// `holo` CLI) can print a message a person can act on; nothing in the SDK panics on bad input.
#[derive(Debug, thiserror::Error)]
pub enum HoloError {
    /// A scalar parameter is out of its valid range (zero pitch, negative wavelength, zero levels…).
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Parameter name as the API spells it (e.g. `pixel_pitch_m`).
        name: &'static str,
        /// What is wrong and what is expected.
        reason: String,
    },
    /// Two arrays that must agree in shape do not.
    #[error("shape mismatch for {what}: expected {expected:?}, got {got:?}")]
    ShapeMismatch {
        /// Which array (e.g. `depth map vs RGB image`).
        what: String,
        /// Expected shape.
        expected: Vec<usize>,
        /// Shape that was passed.
        got: Vec<usize>,
    },
    /// Depth data is unusable (NaN, no valid pixel, wrong range for its encoding…).
    #[error("invalid depth: {0}")]
    InvalidDepth(String),
    /// Image or field data is unusable (NaN amplitude, empty image…).
    #[error("invalid data: {0}")]
    InvalidData(String),
    /// A file could not be read or written.
    #[error("cannot access `{path}`: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// An image file could not be decoded or encoded.
    #[error("cannot decode or encode image `{path}`: {source}")]
    Image {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: image::ImageError,
    },
    /// A `.npy` file could not be read or written, or holds the wrong dtype/shape.
    #[error("cannot read or write npy `{path}`: {reason}")]
    Npy {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// A CNN file (`docs/CONVENTIONS.md` §7) could not be decoded or compiled: truncated or corrupt protobuf,
    /// an operator tract cannot run, a graph that does not type-check.
    #[error("cannot load model `{source_name}`: {reason}")]
    ModelLoad {
        /// The file path, or `<bytes>` for an in-memory model.
        source_name: String,
        /// What went wrong (tract's message chain).
        reason: String,
    },
    /// A CNN file decodes but its inputs/outputs are not the contract's (`docs/CONVENTIONS.md` §7: input
    /// `rgbd` `[1,4L,H,W]` or `slm_field` `[1,6,H,W]`, outputs `amplitude` and `phase` or `real` and `imag`
    /// `[1,3,H,W]`, f32).
    #[error(
        "model `{source_name}` does not follow the I/O contract (docs/CONVENTIONS.md §7): {reason}"
    )]
    ModelContract {
        /// The file path, or `<bytes>`.
        source_name: String,
        /// Which input/output is wrong and what was expected.
        reason: String,
    },
    /// A CNN file's `tensorholo.*` metadata is missing, unparsable or disagrees with the SDK's configuration.
    #[error("model metadata `{key}` is `{found}`, expected {expected}")]
    ModelMetadata {
        /// Full key, e.g. `tensorholo.pixel_pitch_m`.
        key: String,
        /// The file's value (`<missing>` if absent).
        found: String,
        /// The expected value or format.
        expected: String,
    },
    /// A CNN does not serve the configured display (`docs/DISPLAYS.md`): which metadata key, why, and what
    /// would serve it (the nearest display it serves, a wider laser tolerance with its cost, retraining).
    #[error("{0}")]
    DisplayNotServed(Box<DisplayRefusal>),
    /// Running a CNN failed inside the inference engine (the model stays usable).
    #[error("model inference failed: {0}")]
    ModelRun(String),
    /// The GPU path failed: no adapter, a shader or buffer the device refuses (with the limit it exceeds), a
    /// validation error, or a lost device. `Backend::Auto` falls back to the CPU path on it.
    #[error("GPU: {0}")]
    Gpu(String),
    /// A failure inside the SDK that no input explains: a worker thread that stopped or panicked, a poisoned
    /// lock, a broken internal invariant. It is a bug (please report it); the message says what failed.
    /// The object that returned it may have to be recreated (the message says so where it applies).
    #[error("internal error (a bug, please report it): {0}")]
    Internal(String),
    /// A display calibration file (`.holocal`, [`crate::slm::DisplayCalibration`]) is not one, is truncated,
    /// corrupt (checksum), of another format version or inconsistent.
    #[error("cannot load display calibration `{source_name}`: {reason}")]
    Calibration {
        /// The file path, or `<bytes>` for an in-memory file.
        source_name: String,
        /// What is wrong.
        reason: String,
    },
    /// Long work (the focal-stack refinement, `crate::refine`) stopped because its caller asked it to (a
    /// progress callback's `ControlFlow::Break`); the message says what stopped and after how much of it.
    /// Nothing it would have produced was written or returned.
    #[error("cancelled: {0}")]
    Cancelled(String),
    /// Refusing to overwrite a file the user passed in as input.
    #[error("refusing to overwrite input file `{0}`")]
    WouldOverwriteInput(PathBuf),
}

/// Result alias used throughout the SDK.
pub type Result<T> = std::result::Result<T, HoloError>;

/// Shorthand for [`HoloError::InvalidParameter`].
pub(crate) fn invalid(name: &'static str, reason: impl Into<String>) -> HoloError {
    HoloError::InvalidParameter {
        name,
        reason: reason.into(),
    }
}

/// A kernel-crate error (`tensorholo-kernels`: a size or ISA its kernels refuse) as [`HoloError::ModelRun`],
/// naming the native kernels: what the native CNN engine's `?` gives.
impl From<tensorholo_kernels::KernelError> for HoloError {
    fn from(e: tensorholo_kernels::KernelError) -> Self {
        HoloError::ModelRun(format!("native CNN engine: {e}"))
    }
}

/// Runs `f`, turning a panic inside it into an error `"{what} panicked: …"`: tract and the layer reader
/// walk untrusted graphs, and a corrupt file must never panic the caller.
pub(crate) fn guarded<T, E: From<String>>(
    what: &str,
    f: impl FnOnce() -> std::result::Result<T, E>,
) -> std::result::Result<T, E> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(p) => {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            Err(E::from(format!("{what} panicked: {msg}")))
        }
    }
}

/// What retraining for a display costs at the paper's scale (docs/DISPLAYS.md, "What it costs").
pub const RETRAIN_COST: &str = "40–95 GPU-hours at the paper's scale";

/// The nearest display a model serves ([`DisplayRefusal::nearest`]): the configured one with the lasers,
/// volume or offset changed. Metres.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct NearestDisplay {
    /// Laser wavelengths R, G, B.
    pub wavelengths_m: [f64; 3],
    /// SLM pixel pitch.
    pub pixel_pitch_m: f64,
    /// Volume depth.
    pub volume_depth_m: f64,
    /// Offset from the midpoint hologram to the SLM.
    pub offset_m: f64,
    /// The factor the display's other offsets take on it (the new depth scale over the old: 1 where the
    /// scale stays, e.g. for a volume).
    pub offsets_scale: f64,
}

/// Why a model cannot serve a display, and what would (the payload of [`HoloError::DisplayNotServed`]; built
/// by `crate::display::DisplayMapping::refusal`), in the order a user should try: the nearest display it
/// serves, a wider laser tolerance with its cost, retraining with its cost.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DisplayRefusal {
    /// The metadata key at fault: `tensorholo.wavelengths_m` (lasers), `tensorholo.pixel_pitch_m` (the
    /// non-paraxial residual), `tensorholo.volume_depth_m` or `tensorholo.offset_m`.
    pub key: String,
    /// The model's value of that key.
    pub found: String,
    /// What would have to hold, in words.
    pub expected: String,
    /// The nearest display this model serves, if any.
    pub nearest: Option<NearestDisplay>,
    /// For lasers: the tolerance (a fraction) that would serve this display as it is, and the estimated cost
    /// there (dB).
    pub tolerance: Option<(f64, f64)>,
}

impl std::fmt::Display for DisplayRefusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "model metadata `{}` is `{}`, expected {}",
            self.key, self.found, self.expected
        )?;
        let mut ways = Vec::new();
        if let Some(n) = &self.nearest {
            let w = n.wavelengths_m.map(|x| x * 1e9);
            ways.push(format!(
                "the nearest display it serves: {:.4} µm, lasers {:.2}/{:.2}/{:.2} nm, volume {:.6} mm, offset \
                 {:.6} mm",
                n.pixel_pitch_m * 1e6,
                w[0],
                w[1],
                w[2],
                n.volume_depth_m * 1e3,
                n.offset_m * 1e3
            ));
        }
        if let Some((t, cost)) = self.tolerance {
            ways.push(format!(
                "a laser tolerance of {:.2} % (`wavelength_ratio_tolerance` {t}; estimated cost {cost:.2} dB)",
                t * 100.0
            ));
        }
        ways.push(format!(
            "retraining for this display (docs/DISPLAYS.md, \"Retraining for another display\"; {RETRAIN_COST})"
        ));
        write!(f, "; what would serve: {}", ways.join("; or "))
    }
}
