//! # tensorholo
//!
//! Core engine of Tensor Holography V2 (Shi, Li, Matusik, *Light: Science & Applications* 2022): it turns an
//! RGB-D frame (or a layered depth image) into the three 8-bit phase patterns a phase-only spatial light
//! modulator (SLM) displays, one per laser:
//! RGB-D frame → hologram CNN → midpoint hologram → offset propagation (Eq. 6) → pre-filter CNN → double phase
//! encoding (Eq. 7) → 8-bit SLM phase. Pure Rust, CPU (its own SIMD kernels, or tract) or GPU (wgpu); the
//! trained CNNs ship with it (crate `tensorholo-models`).
//!
//! ## Quick start
//!
//! The real-time pipeline with the shipped CNNs, on the built-in scene:
//!
//! ```
//! use tensorholo::pipeline::{HologramPipeline, ModelSelection, PipelineConfig};
//! use tensorholo::scene::default_scene;
//!
//! # fn main() -> tensorholo::Result<()> {
//! let frame = default_scene(64, 64)?; // RGB-D: amplitude [3, H, W] in [0, 1], depth [H, W] (0 = near)
//! let config = PipelineConfig { offset_m: 6e-3, ..PipelineConfig::default() }; // SLM 6 mm from the midpoint
//! // The embedded 8-layer f32 hologram CNN and its 6 mm pre-filter (`ModelSelection::default()`).
//! let pipeline = HologramPipeline::embedded(&ModelSelection::default(), config)?;
//! let mut session = pipeline.session(frame.height(), frame.width())?; // plans, buffers, workers
//! let slm = session.render(&frame)?; // slm.codes [3, H, W] u8: phase 2π·c/256, R, G, B; slm.timings
//! assert_eq!(slm.codes.dim(), (3, 64, 64));
//! # Ok(())
//! # }
//! ```
//!
//! Your own photo: [`scene::load_rgbd`] (colour and depth files, several depth encodings) or, from camera
//! buffers, the app-facing [`generator::HologramGenerator`] (what the Swift, Kotlin and Python bindings wrap).
//! Video: `session.render_stream`. Your own ONNX files: [`pipeline::HologramPipeline::new`].
//!
//! ## Modules
//!
//! Modules, one per concept (see `ARCHITECTURE.md`):
//! - [`optics`]: angular spectrum method (Eq. 2), offset propagation (Eq. 6), Fourier filter (Eq. 8–9),
//!   focal-stack reconstruction.
//! - [`encoding`]: double phase encoding (Eq. 7), AA-DPM, BL-DPM, phase wrapping and 8-bit codes.
//! - [`synthesis`]: silhouette-mask layer-based method (SM-LBM, Eq. 1–4) for reference holograms.
//! - [`scene`]: RGB-D frames, layered depth images, depth decoders, the built-in procedural scene.
//! - [`reference`](mod@reference): the non-learned pipeline (SM-LBM → offset → double phase → SLM codes →
//!   previews).
//! - [`refine`]: focal-stack refinement of an SLM pattern (Adam with the loss's analytic gradient),
//!   warm-started from the CNN's codes, aimed at SM-LBM's focal stack (`docs/REFINE.md`).
//! - [`foveation`]: gaze-contingent holograms: the 3D CNN in the fovea, a 2D hologram with synthetic blur
//!   elsewhere (the paper's Discussion; `docs/FOVEATION.md`).
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
//! ## Conventions
//!
//! `docs/CONVENTIONS.md` in the repository, §2–§4: SI units, channel order R, G, B, normalised depth
//! `d ∈ [0,1]` with 0 = near, a point at `d` lies at `z(d) = (0.5 − d)·volume_depth` from the midpoint plane,
//! `+z` along the light (toward the viewer). Every public item documents its array shapes, units, errors and
//! the paper equation it implements.
//!
//! ## Cargo features
//!
//! | feature | default | what |
//! |---|---|---|
//! | `embedded-models` | on | the shipped 8-layer RGB-D and LDI hologram CNNs and the 6/12 mm pre-filters compiled in (`model::embedded`, crate `tensorholo-models`); off, load ONNX files with [`model::HologramModel::from_path`] |
//! | `models-15`, `models-30` | on | also the 15- and 30-layer hologram CNNs with their pre-filters |
//! | `tract` | on | tract, the CNN engine for any ONNX graph that passes the contract and for int8 QOperator files (turns on `qop-models`: their embedded forms); off, the native engine and the GPU run the shipped models and any file of their architecture, at a fraction of the size |
//! | `research` | on | training-data tooling: `dataset` (`.npz` shards), random scenes, the aberration fit from spot captures |
//! | `gpu` | off | `gpu`: the whole frame as WGSL compute shaders on wgpu (Metal, Vulkan); `Backend::Gpu`/`Auto` in the pipeline |
//!
//! An application (the phone library does this) depends on it with `default-features = false, features =
//! ["embedded-models"]` (add `"gpu"`, `"tract"` as needed).
//!
//! ## Further reading
//!
//! In the repository (not part of this package): `README.md` (the first page), `docs/GUIDE.md` (the user
//! guide: every `holo` command, the library API, apps, phones, calibration, cargo features),
//! `ARCHITECTURE.md` (the crate map and a frame's data flow), `docs/CONVENTIONS.md` (units, signs, the model
//! I/O contract), `docs/GPU.md`, `docs/DISPLAYS.md` (display profiles, retraining), `docs/ABERRATION.md`,
//! `docs/CALIBRATION.md`, `docs/INPUTS.md` (input limits), `docs/BENCHMARKS.md`, `models/MODEL_CARD.md` (the
//! shipped CNNs and their measured quality; also the readme of `tensorholo-models`), `bindings/README.md` (the
//! app API).

/// The README's Rust example (README.md at the top of the repository), compiled and run as a doctest. Only
/// under `cfg(doctest)`: the packaged crate, whose README sits elsewhere, never compiles it.
#[cfg(doctest)]
#[doc = include_str!("../../README.md")]
pub struct ReadmeDoctests;

pub mod cnn;
pub mod color;
#[cfg(feature = "research")]
pub mod dataset;
pub mod display;
pub mod encoding;
pub mod error;
pub mod evaluation;
pub mod foveation;
pub mod generator;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod io;
pub mod metrics;
pub mod model;
pub mod optics;
pub mod pipeline;
pub mod reference;
pub mod refine;
pub mod scene;
pub mod slm;
mod splitmix;
pub mod synthesis;

pub use error::{HoloError, Result};
pub use num_complex::Complex32;
