//! The CPU CNN engines of this build, the one place an engine is registered: [`engines`] lists them in order
//! of preference, and the engine choice (`cnn/select.rs`), the checks at pipeline creation
//! ([`crate::cnn::check_runnable`]) and the tests iterate it. A new engine is a folder under `cnn/`
//! implementing [`Engine`] plus one entry here.

use super::engine::Engine;
use super::native::NativeEngine;
#[cfg(feature = "tract")]
use super::tract::TractEngine;

/// The engines compiled into this build, best first (the native engine; tract with the cargo feature
/// `tract`).
pub(crate) fn engines() -> &'static [&'static dyn Engine] {
    &[
        &NativeEngine,
        #[cfg(feature = "tract")]
        &TractEngine,
    ]
}
