//! The real-time hologram pipeline (`docs/CONVENTIONS.md` §8, paper Fig. 3): RGB-D frame (or layered depth
//! image) → hologram CNN → midpoint hologram → offset propagation (Eq. 6; with the viewer's aberration
//! correction, Eq. 5) → pre-filter CNN (DDPM) →
//! double phase encoding (Eq. 7) → look-up table → three 8-bit SLM planes.
//!
//! - [`HologramPipeline`] holds the loaded CNNs and the display configuration, checked against each other
//!   once.
//! - [`HologramSession`] (one per resolution) owns everything a frame reuses: the CNN plans (the native
//!   engine's by default, or tract's), FFT plans, transfer functions, double-phase encoders and scratch
//!   buffers, and three colour worker threads. After the first frame, the optics stages (offset
//!   propagation, pre-filter input, double phase, LUT) perform no heap allocation: with the native CNN
//!   engine a frame allocates only the CNNs' output arrays (`sdk/tests/pipeline_alloc.rs` counts); tract
//!   allocates inside its plans.
//! - [`HologramSession::render_stream`] overlaps the hologram CNN of frame `n + 1` with the optics of frame
//!   `n` (two threads); its output equals [`HologramSession::render`]'s bit for bit.
//!
//! One concept per file, lower files first (a file imports only those above it in this list, and the
//! executors below the session import only the first three):
//!
//! - `config`: [`PipelineConfig`], [`Backend`], [`GpuPrecision`], [`MAX_HOLOGRAM_PIXELS`];
//! - `frame`: [`Heads`], [`SlmFrame`], [`FrameTimings`], [`check_not_black`] (what every executor produces);
//! - `report`: [`BackendReport`], [`SelfCheck`];
//! - `selection`: [`ModelSelection`], [`PrefilterMode`] and the one rule pairing a CNN with a pre-filter;
//! - `correction`: the viewer's aberration correction in the frame ([`AberrationReport`]: the kernel of
//!   paper Eq. 5 at the midpoint plane, joined to the offset propagation's pass);
//! - `models`: [`HologramPipeline`] (models + display configuration + calibration);
//! - `colour`, `workers`: one colour's optics and the three allocation-free worker threads;
//! - `cnn_stage`: input packing and the hologram CNN on a `CnnPlan` (tract, or the native engine);
//! - `executor`, `gpu_frame`: whole-frame accelerators behind one trait, and the GPU's;
//! - `fovea_tiles`: what a foveated session keeps (the CNNs' tiles and buffers, the periphery's tables);
//! - `session`: [`HologramSession`] and its CPU frame; `foveated`: its foveated frames (the CNN on a tile
//!   around the gaze, [`crate::foveation`]); `setup`: how a session is built (checks, the choice of
//!   an executor, the CNN plans, the colour states); `accelerated`: its frames on an accelerator (fallback,
//!   first-frame self-check, previews, stage timings); `stream`: its streams;
//! - `refiner`: the refinement of a pipeline's frames ([`crate::refine::FrameRefiner::for_pipeline`]).

mod accelerated;
mod cnn_stage;
mod colour;
pub(crate) mod config;
mod correction;
mod executor;
mod fovea_tiles;
mod foveated;
pub(crate) mod frame;
#[cfg(feature = "gpu")]
mod gpu_frame;
mod models;
mod pool;
mod refiner;
mod report;
mod selection;
mod session;
mod setup;
mod stream;
#[cfg(all(test, feature = "tract"))]
mod suite;
mod workers;

pub use config::{Backend, GpuPrecision, PipelineConfig, MAX_HOLOGRAM_PIXELS};
pub use correction::{AberrationReport, RESIDUAL_PLANES};
pub use frame::{check_not_black, FrameTimings, Heads, SlmFrame, BLACK_FRAME_AMPLITUDE};
pub use models::HologramPipeline;
pub use report::{BackendReport, SelfCheck, StageProfile, SELF_CHECK_MAX_FRACTION};
pub use selection::{ModelSelection, PrefilterMode, PrefilterSource};
pub use session::HologramSession;
