//! The SDK as a phone app calls it (`docs/CONVENTIONS.md` §7; paper Fig. 3): camera-buffer frames in, SLM
//! patterns out, through one thread-safe [`HologramGenerator`].
//!
//! - [`GeneratorConfig`]: the hologram (SLM) resolution, the shipped CNNs by name ([`ModelSelection`]), the
//!   display and how camera frames fit it. Every field but `width` and `height` has a default.
//! - [`HologramGenerator`]: owns the pipeline and one [`HologramSession`] for the configured resolution
//!   behind a lock (`Send + Sync`: any thread may call it; calls run one at a time). Returns owned
//!   [`SlmPatterns`]; [`HologramGenerator::preview`] simulates what a viewer sees at a chosen depth.
//! - [`HologramStream`]: video. [`HologramStream::push`] never blocks: a bounded queue drops the oldest
//!   frame when full (camera semantics) and counts the drops; a worker thread runs the session's
//!   [`HologramSession::render_stream_each`] (the CNN of frame `n + 1` overlaps the optics of frame `n`) and
//!   hands results to a [`StreamListener`] in frame order. The metric depth range of the first frame is kept
//!   for the whole stream unless the configuration fixes one, so the volume does not breathe.
//!
//! The bindings (`bindings/`, crate `tensorholo-ffi`) are one-line wrappers over this module.

#[cfg(doc)]
use crate::pipeline::{HologramSession, ModelSelection};

mod config;
mod frames;
mod hologram;
mod stream;

pub use config::GeneratorConfig;
pub use frames::{
    pack_rgba, pack_rgba_planes, GeneratorBenchmark, PatternTimings, Preview, SlmPatterns,
};
pub use hologram::{GeneratorInfo, HologramGenerator};
pub use stream::{HologramStream, StreamListener, DEFAULT_STREAM_CAPACITY};

/// The largest hologram a generator makes: the session's limit, now [`crate::pipeline::MAX_HOLOGRAM_PIXELS`]
/// (this path is kept for one release).
pub use crate::pipeline::MAX_HOLOGRAM_PIXELS;
