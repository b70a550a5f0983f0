//! # tensorholo
//!
//! Core engine of Tensor Holography V2 (Shi, Li, Matusik, *Light: Science & Applications* 2022):
//! RGB-D frame → midpoint hologram → offset propagation → double phase encoding → 8-bit SLM phase.
//!
//! Modules, one per concept (see `ARCHITECTURE.md`):
//! - [`optics`]: angular spectrum method (Eq. 2), offset propagation (Eq. 6), Fourier filter (Eq. 8–9),
//!   focal-stack reconstruction.
//! - [`encoding`]: double phase encoding (Eq. 7), AA-DPM, BL-DPM, phase wrapping and 8-bit codes.
//! - [`synthesis`]: silhouette-mask layer-based method (SM-LBM, Eq. 1–4) for reference holograms.
//! - [`scene`]: RGB-D frames, layered depth images, depth decoders, the built-in procedural scene.
//! - [`reference`](mod@reference): the non-learned pipeline (SM-LBM → offset → double phase → SLM codes →
//!   previews).
//! - [`metrics`]: PSNR and SSIM.
//! - [`evaluation`]: the paper's Table 2 protocol (amplitude and focal-stack PSNR/SSIM against SM-LBM).
//! - [`model`]: the hologram and pre-filter CNNs as files (ONNX), engine-neutral: metadata, I/O contract,
//!   the TensorHolo residual graph, the embedded shipped models.
//! - [`cnn`]: the CPU CNN engines behind one interface: tensorholo's own kernels (`native`) and, with the
//!   cargo feature `tract`, tract; their plans, thread and layout tuning and the choice between them.
//! - [`pipeline`]: the real-time pipeline: [`pipeline::HologramSession`] turns RGB-D frames into SLM codes
//!   with the CNNs (hologram CNN → offset → pre-filter CNN → double phase → LUT), frame by frame or streamed.
//! - [`generator`]: the app-facing API the bindings wrap (camera buffers in, SLM patterns out).
//! - [`display`]: display profiles (JSON: SLM pitch and size, lasers, volume, offsets, calibration;
//!   `docs/DISPLAYS.md`).
//! - [`io`]: PNG and `.npy` input/output.
//! - [`slm`]: phase look-up tables (global, per-pixel), the display calibration file, calibration from
//!   captures (Eq. 12–13), the laser intensity map, the deep-black test (Fig. 11), a simulated SLM.
#![cfg_attr(
    feature = "research",
    doc = "- [`dataset`] (feature `research`): the training dataset (MIT-CGH-4K-V2 style): random LDIs + \
           SM-LBM midpoint holograms in `.npz` shards with a `manifest.json`."
)]
#![cfg_attr(
    feature = "gpu",
    doc = "- [`gpu`] (feature `gpu`): the whole frame as WGSL compute shaders on wgpu (Metal, Vulkan), below \
           the pipeline, which runs it as one of its frame executors."
)]
#![cfg_attr(
    not(feature = "gpu"),
    doc = "- `gpu` (feature `gpu`, off in this build): the whole frame on the GPU (wgpu)."
)]
#![cfg_attr(
    not(feature = "research"),
    doc = "- `dataset` (feature `research`, off in this build): the training dataset."
)]
//!
//! Conventions (`docs/CONVENTIONS.md` in the repository, §2–§4): SI units, channel order R, G, B, normalised
//! depth `d ∈ [0,1]` with 0 = near, a point at `d` lies at `z(d) = (0.5 − d)·volume_depth` from the midpoint
//! plane, `+z` along the light (toward the viewer).

pub mod cnn;
pub mod color;
#[cfg(feature = "research")]
pub mod dataset;
pub mod display;
pub mod encoding;
pub mod error;
pub mod evaluation;
pub mod generator;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod io;
pub mod metrics;
pub mod model;
pub mod optics;
pub mod pipeline;
pub mod reference;
pub mod scene;
pub mod slm;
mod splitmix;
pub mod synthesis;

pub use error::{HoloError, Result};
pub use num_complex::Complex32;
