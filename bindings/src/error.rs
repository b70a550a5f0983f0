//! [`TensorholoError`], the one error type every exported call returns, its mapping from the core's
//! [`tensorholo::HoloError`], and [`guard`], which runs an exported call's body so that a panic (a bug)
//! becomes [`TensorholoError::Internal`] instead of an untyped foreign error. Imports nothing of the crate:
//! every other module reads it.

use std::panic::{catch_unwind, AssertUnwindSafe};

/// Every failure reported to an app. Each variant carries a human-readable `message` naming the offending
/// input (the core's [`tensorholo::HoloError`] text); the variant says what the app can do about it.
///
/// Foreign names: Python `tensorholo.TensorholoError.InvalidInput` (etc., subclasses of `Exception`, text in
/// `e.message`), Kotlin `tensorholo.TensorholoException.InvalidInput` (text in `e.reason`: a Kotlin exception
/// cannot have a `message` field, see `uniffi.toml`), Swift `TensorholoError.InvalidInput(message:)`.
/// A new variant needs its Kotlin rename line in `uniffi.toml`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, uniffi::Error)]
pub enum TensorholoError {
    /// A parameter, buffer or file passed by the caller is unusable (wrong size or range, unreadable file…):
    /// fix the input and retry.
    #[error("invalid input: {message}")]
    InvalidInput {
        /// What is wrong, naming the input.
        message: String,
    },
    /// A CNN model cannot be loaded, breaks the I/O contract or carries wrong metadata: use another model.
    #[error("invalid model: {message}")]
    InvalidModel {
        /// What is wrong with the model.
        message: String,
    },
    /// The request is valid but this build or device does not support it.
    #[error("unsupported: {message}")]
    Unsupported {
        /// What is not supported.
        message: String,
    },
    /// The app cancelled the call (a progress callback returned `false`): nothing was produced.
    #[error("cancelled: {message}")]
    Cancelled {
        /// What stopped, and after how much of it.
        message: String,
    },
    /// A failure inside the library (inference engine error, or a panic: a bug, please report it).
    #[error("internal error: {message}")]
    Internal {
        /// What failed.
        message: String,
    },
}

impl From<tensorholo::HoloError> for TensorholoError {
    /// Maps every core error to the variant an app acts on; the message is the core's full text.
    /// The match is exhaustive on purpose: a new core variant must be classified here.
    fn from(error: tensorholo::HoloError) -> Self {
        use tensorholo::HoloError as E;
        let message = error.to_string();
        match error {
            E::InvalidParameter { .. }
            | E::ShapeMismatch { .. }
            | E::InvalidDepth(_)
            | E::InvalidData(_)
            | E::Io { .. }
            | E::Image { .. }
            | E::Npy { .. }
            | E::Calibration { .. }
            | E::WouldOverwriteInput(_) => Self::InvalidInput { message },
            E::Cancelled(_) => Self::Cancelled { message },
            E::ModelLoad { .. }
            | E::ModelContract { .. }
            | E::ModelMetadata { .. }
            | E::DisplayNotServed(_) => Self::InvalidModel { message },
            E::Gpu(_) => Self::Unsupported { message },
            E::ModelRun(_) | E::Internal(_) => Self::Internal { message },
        }
    }
}

/// What the exported calls return: a value or a [`TensorholoError`].
pub(crate) type Result<T, E = TensorholoError> = std::result::Result<T, E>;

/// A [`TensorholoError::InvalidInput`] with `message`.
pub(crate) fn invalid(message: impl Into<String>) -> TensorholoError {
    TensorholoError::InvalidInput {
        message: message.into(),
    }
}

/// Runs `f`, turning a panic inside it into [`TensorholoError::Internal`] (`"<what> panicked: <panic
/// message> (a bug, please report it)"`) instead of uniffi's untyped internal error. Wrap the body of
/// every exported fallible function in it.
///
/// Unwinding must stay enabled for this (the workspace's release profile must not set `panic = "abort"`;
/// `bindings/tests/run_all.sh` and a unit test check it). The closure is treated as unwind-safe: the
/// wrappers only touch state that is valid after a panic (an aborted call leaves no half-updated object
/// behind that a later call would trust) — keep it that way when wrapping stateful objects.
pub fn guard<T>(f: impl FnOnce() -> Result<T, TensorholoError>) -> Result<T, TensorholoError> {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|payload| {
        Err(TensorholoError::Internal {
            message: format!(
                "tensorholo panicked: {} (a bug, please report it)",
                panic_message(payload.as_ref())
            ),
        })
    })
}

/// The text of a panic payload (`panic!` with a literal or a formatted message), or a placeholder.
pub(crate) fn panic_message(payload: &(dyn std::any::Any + Send)) -> &str {
    if let Some(s) = payload.downcast_ref::<&'static str>() {
        s
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.as_str()
    } else {
        "<no message>"
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;
    use tensorholo::HoloError;

    #[test]
    fn guard_turns_a_panic_into_internal() {
        let r: Result<u32, _> = guard(|| panic!("index {} out of range", 7));
        match r {
            Err(TensorholoError::Internal { message }) => {
                assert!(
                    message.contains("panicked: index 7 out of range"),
                    "{message}"
                );
                assert!(message.contains("a bug, please report it"), "{message}");
            }
            other => panic!("expected Internal, got {other:?}"),
        }
        let r: Result<u32, _> = guard(|| panic!("literal"));
        assert!(
            matches!(&r, Err(TensorholoError::Internal { message }) if message.contains("panicked: literal")),
            "{r:?}"
        );
    }

    #[test]
    fn guard_passes_values_and_errors_through() {
        assert_eq!(guard(|| Ok(42)), Ok(42));
        let e = TensorholoError::Unsupported {
            message: "x".into(),
        };
        assert_eq!(guard(|| Err::<(), _>(e.clone())), Err(e));
    }

    /// One core error of every variant, with the foreign variant it must map to.
    fn core_errors() -> Vec<(HoloError, &'static str)> {
        let io = || std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        vec![
            (
                HoloError::InvalidParameter {
                    name: "pixel_pitch_m",
                    reason: "must be > 0".into(),
                },
                "InvalidInput",
            ),
            (
                HoloError::ShapeMismatch {
                    what: "depth vs rgb".into(),
                    expected: vec![2, 3],
                    got: vec![3, 2],
                },
                "InvalidInput",
            ),
            (HoloError::InvalidDepth("all NaN".into()), "InvalidInput"),
            (HoloError::InvalidData("empty".into()), "InvalidInput"),
            (
                HoloError::Io {
                    path: PathBuf::from("/nope.png"),
                    source: io(),
                },
                "InvalidInput",
            ),
            (
                HoloError::Image {
                    path: PathBuf::from("/bad.png"),
                    source: image::ImageError::IoError(io()),
                },
                "InvalidInput",
            ),
            (
                HoloError::Npy {
                    path: PathBuf::from("/a.npy"),
                    reason: "dtype".into(),
                },
                "InvalidInput",
            ),
            (
                HoloError::WouldOverwriteInput(PathBuf::from("/in.png")),
                "InvalidInput",
            ),
            (
                HoloError::ModelLoad {
                    source_name: "<bytes>".into(),
                    reason: "truncated".into(),
                },
                "InvalidModel",
            ),
            (
                HoloError::ModelContract {
                    source_name: "m.onnx".into(),
                    reason: "no rgbd input".into(),
                },
                "InvalidModel",
            ),
            (
                HoloError::ModelMetadata {
                    key: "tensorholo.pixel_pitch_m".into(),
                    found: "<missing>".into(),
                    expected: "a number".into(),
                },
                "InvalidModel",
            ),
            (HoloError::ModelRun("tract failed".into()), "Internal"),
            (HoloError::Internal("a worker stopped".into()), "Internal"),
            (HoloError::Gpu("no adapter".into()), "Unsupported"),
            (
                HoloError::Cancelled("refinement stopped after 2 of 10 iterations".into()),
                "Cancelled",
            ),
        ]
    }

    #[test]
    fn every_core_error_maps_to_its_variant_with_the_core_message() {
        for (core, expected) in core_errors() {
            let text = core.to_string();
            let (variant, message) = match TensorholoError::from(core) {
                TensorholoError::InvalidInput { message } => ("InvalidInput", message),
                TensorholoError::InvalidModel { message } => ("InvalidModel", message),
                TensorholoError::Unsupported { message } => ("Unsupported", message),
                TensorholoError::Cancelled { message } => ("Cancelled", message),
                TensorholoError::Internal { message } => ("Internal", message),
            };
            assert_eq!(variant, expected, "{text}");
            assert_eq!(message, text);
        }
    }

    /// Unwinding must stay on: with `panic = "abort"` [`guard`] cannot catch anything and a bug would kill
    /// the app's process. The workspace manifest is the one place a profile can set it; the crate's
    /// `compile_error!` only fires when such a profile is built, this test fires in every `cargo test`.
    #[test]
    fn no_profile_sets_panic_abort() {
        let manifest = concat!(env!("CARGO_MANIFEST_DIR"), "/../Cargo.toml");
        let text = std::fs::read_to_string(manifest).expect("workspace Cargo.toml");
        let offending: Vec<&str> = text
            .lines()
            .map(|l| l.split('#').next().unwrap_or("").trim())
            .filter(|l| {
                let compact: String = l.chars().filter(|c| !c.is_whitespace()).collect();
                compact.starts_with("panic=") && !compact.starts_with("panic=\"unwind\"")
            })
            .collect();
        assert!(
            offending.is_empty(),
            "{manifest} sets {offending:?}: bindings need panic = \"unwind\""
        );
    }
}
