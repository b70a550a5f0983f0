//! Scene input: RGB-D frames and layered depth images, depth decoders for real sensor and file formats,
//! and a built-in procedural scene.
//!
//! * [`RgbdFrame`]: `[3, H, W]` linear amplitude (R, G, B) + `[H, W]` normalised depth `d ∈ [0,1]`,
//!   0 = near (`docs/CONVENTIONS.md` §4).
//! * [`LayeredDepthImage`] / [`LdiLayer`]: Shade et al. 1998, the LDI input of the paper's Fig. 1.
//! * Depth from files ([`load_rgbd`]): [`decode_depth_file`] with a [`DepthEncoding`] (one per row of the
//!   encoding table, `docs/CONVENTIONS.md` §6) → [`normalise_depth`] with a [`DepthRange`] and a
//!   [`DepthMapping`] (linear in diopters by default) → [`fill_invalid`] (holes take the farthest
//!   neighbouring depth, before any resizing, never read as near) → [`RgbdFrame::resize`].
//! * LDI folders ([`load_ldi_dir`], [`write_ldi_dir`]): `rgb_K` / `depth_K` image pairs, front layer first,
//!   what a renderer's depth-peeling pass writes (`docs/CONVENTIONS.md` §6.3).
//! * Phone camera buffers ([`CameraFrame::to_rgbd`]): an interleaved 8-bit colour buffer ([`ColorFormat`])
//!   and a depth buffer in the sensor's format ([`DepthFormat`]: AVDepthData, ARCore, `DEPTH16`), with row
//!   strides, a [`Rotation`], a colour [`CropRect`] registering colour with a depth map of a narrower field of
//!   view (ARCore), and a [`Fit`] to the hologram resolution.
//! * [`procedural`]: a deterministic test scene with near, mid and far textured objects and occlusions.
#![cfg_attr(
    feature = "research",
    doc = "* [`random`] (feature `research`): random textured scenes as LDIs ([`random_ldi`]), the input \
           side of the training dataset (paper section \"MIT-CGH-4K-V2\"), built by per-pixel depth \
           sorting ([`ldi_from_fragments`])."
)]
#![cfg_attr(
    not(feature = "research"),
    doc = "* `random` (feature `research`, off in this build): random textured scenes for the training \
           dataset."
)]
#![cfg_attr(
    feature = "research",
    doc = "* [`recording`] (feature `research`): phone recordings as Record3D and Stray Scanner export them \
           ([`open_recording`]), and folders of colour and depth frames paired by stem \
           ([`open_frame_folders`]), frame by frame with depth confidence ([`load_rgbd_with_confidence`])."
)]

mod camera;
mod depth;
#[cfg(feature = "research")]
mod exr;
mod frame;
#[cfg(feature = "research")]
mod frame_folders;
mod ldi_files;
mod load;
pub mod procedural;
#[cfg(feature = "research")]
pub mod random;
#[cfg(feature = "research")]
pub mod recording;
mod upsample;

pub use camera::{
    ldi_from_camera_frames, CameraFrame, CameraFrameBuf, CameraFrameReport, ColorFormat,
    ColorImage, ColorImageBuf, ConfidenceImage, ConfidenceImageBuf, CropRect, DepthFormat,
    DepthImage, DepthImageBuf, Fit, FrameOptions, Rotation,
};
pub use depth::{
    apply_confidence, decode_depth, decode_depth_bytes, decode_depth_file, fill_invalid,
    normalise_depth, DecodedDepth, DepthEncoding, DepthMapping, DepthRange, DEFAULT_MIN_CONFIDENCE,
    MAX_DEPTH_ASPECT_MISMATCH,
};
pub use frame::{LayeredDepthImage, LdiLayer, RgbdFrame};
#[cfg(feature = "research")]
pub use frame_folders::{open_frame_folders, FrameFolders};
pub use ldi_files::{
    ldi_files, load_ldi_dir, write_ldi_dir, LdiLayerFiles, LdiReport, MAX_LDI_FOLDER_LAYERS,
};
#[cfg(test)]
pub(crate) use load::shared_tum_frame;
pub use load::{
    decode_rgb_bytes, load_rgb, load_rgbd, load_rgbd_with_confidence, DepthReport, LoadOptions,
};
pub use procedural::{default_scene, default_scene_ldi};
#[cfg(feature = "research")]
pub use random::{
    ldi_from_fragments, random_ldi, Fragment, RandomSceneConfig, RandomSceneGenerator,
};
#[cfg(feature = "research")]
pub use recording::{open_recording, Recording, RecordingFrame, RecordingKind};
pub use upsample::{upsample_depth, DepthUpsampling};
