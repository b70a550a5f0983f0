//! # tensorholo-ffi
//!
//! The app-facing foreign-function interface of [`tensorholo`]: [uniffi](https://mozilla.github.io/uniffi-rs/)
//! (0.32, proc-macros only, no UDL) generates the Python (`tensorholo`), Kotlin (package `tensorholo`) and
//! Swift (module `Tensorholo`) bindings from the items exported here (`bindings/generate.sh`, configuration in
//! `bindings/uniffi.toml`, see `bindings/README.md`).
//!
//! How to expose a core API: one thin wrapper per item, exported with `#[uniffi::export]` (functions,
//! `impl` blocks of `#[derive(uniffi::Object)]` types), plain data as `#[derive(uniffi::Record)]`, every
//! fallible call returning `Result<_, TensorholoError>` and running its body under [`guard`], so that a core
//! [`tensorholo::HoloError`] becomes a typed foreign exception ([`From`] below) and a panic (a bug) becomes
//! [`TensorholoError::Internal`] instead of an untyped one. Bulk data (images, SLM codes) crosses as
//! `Vec<u8>` (Python `bytes`, Kotlin `ByteArray`, Swift `Data`), row-major, with its `width`/`height`
//! beside it. Do not export `async` functions: the Kotlin bindings would then need `kotlinx.coroutines`.
//!
//! The exported API, one module per concept ([`config`], [`display`], [`enums`], [`frames`],
//! [`generator`], [`stream`], each re-exported here): `HologramGenerator` (camera frames → `SlmPatterns`,
//! `preview`, `info`, `benchmark`, `stream`), `HologramStream`, the `PatternsListener` apps implement,
//! `pack_rgba`, `version`, `DisplayProfile` with `display_profile_from_json` and
//! `generator_config_for_display`, and `TensorholoError`: one thin wrapper per item of
//! [`tensorholo::generator`] (the core owns every rule; these modules convert types and errors, nothing
//! else). Names are the bindings' contract: Python `tensorholo.HologramGenerator`, Kotlin
//! `tensorholo.HologramGenerator`, Swift `HologramGenerator`.

// uniffi's `setup_scaffolding!` and `#[uniffi::export]` macros expand to `extern "C"` functions with
// `#[no_mangle]` and raw-pointer handling, which the workspace-wide `unsafe_code = "deny"` would reject.
// Everything this crate writes by hand is safe code.
#![allow(unsafe_code)]

pub mod config;
pub mod display;
pub mod enums;
pub mod error;
pub mod foveation;
pub mod frames;
pub mod generator;
pub mod refine;
pub mod stream;

// `guard` is useless without unwinding: refuse to build (any profile, or `-C panic=abort` in RUSTFLAGS)
// rather than ship a library whose bugs kill the app's process.
#[cfg(not(panic = "unwind"))]
compile_error!(
    "tensorholo-ffi needs panic = \"unwind\" (see `guard`); do not set panic = \"abort\""
);

pub use config::*;
pub use display::*;
pub use enums::*;
pub use foveation::*;
pub use frames::*;
pub use generator::*;
pub use refine::*;
pub use stream::*;

pub use error::{guard, TensorholoError};

uniffi::setup_scaffolding!("tensorholo");

/// The version of the `tensorholo` core this library was built from (semver, e.g. `"0.1.0"`).
///
/// Errors: none. Source: the workspace version (`Cargo.toml`), shared by the core and these bindings.
#[uniffi::export]
pub fn version() -> String {
    env!("CARGO_PKG_VERSION").to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn version_is_the_workspace_semver() {
        let v = version();
        let parts: Vec<&str> = v.split('.').collect();
        assert_eq!(parts.len(), 3, "{v}");
        assert!(parts.iter().all(|p| p.parse::<u32>().is_ok()), "{v}");
        assert_eq!(v, env!("CARGO_PKG_VERSION"));
    }
}
