//! RGB-D frames from phone camera buffers: an interleaved 8-bit colour buffer with a row stride plus a
//! depth map in the sensor's own format and resolution → [`crate::scene::RgbdFrame`] at the hologram
//! resolution.
//!
//! [`CameraFrame::to_rgbd`] runs, in this order:
//! 1. validation of both buffers (sizes, row stride, buffer length, all with checked arithmetic), of the
//!    colour crop ([`CameraFrame::color_crop`], a [`CropRect`]) and of the target size, before anything is
//!    allocated; the crop, when given, replaces the colour buffer by its sub-rectangle (no copy), so that
//!    colour and depth cover the same field of view (registration: ARCore's depth covers the GPU texture's
//!    16:9 field of view, a band of its 4:3 CPU image);
//! 2. decoding: colour ([`ColorFormat`], sRGB 8-bit) → `[3, H, W]` amplitude with
//!    [`crate::color::srgb8_to_amplitude`], channels R, G, B whatever the byte order; depth
//!    ([`DepthFormat`], little-endian) → metres + validity mask ([`crate::scene::DecodedDepth`],
//!    metric);
//! 3. the clockwise [`Rotation`] that makes both buffers upright (fused with step 2: each output pixel reads
//!    its source pixel, no extra copy);
//! 4. depth (values and validity) brought to the colour resolution by nearest neighbour (the default: no depth
//!    mixed across an occlusion edge) or, with [`FrameOptions::depth_upsampling`], by the colour-guided joint
//!    bilateral upsampling ([`super::upsample_depth`]: depth mixed only among samples of similar colour, a
//!    hole's edge following the colour's).
//!    The (cropped) colour and the depth are assumed to cover the
//!    same field of view, as AVFoundation's `AVDepthData` (delivered alongside the photo / video frame) and
//!    ARKit's `sceneDepth` do, and ARCore's depth image does after the crop of step 1: the depth map is
//!    stretched onto the colour frame, so a depth map with another aspect ratio is stretched too (logged as
//!    a warning: the camera's side of the one other-aspect rule, `scene::depth::OtherAspect`, where files
//!    refuse);
//! 5. [`crate::scene::normalise_depth`] with [`FrameOptions::range`] / [`FrameOptions::mapping`]
//!    (automatic range = 1st / 99th percentiles of the valid depths), then [`crate::scene::fill_invalid`]:
//!    invalid pixels take the farthest neighbouring depth and are never read as near;
//! 6. the [`Fit`] to the hologram's `height × width` (crop, letterbox or stretch), resampling with
//!    [`crate::scene::RgbdFrame::resize`] (Catmull-Rom in intensity for amplitude, nearest for depth).
//!
//! Memory: the decoded colour `[3, H, W]` f32 and depth at colour resolution, the fitted output, and for
//! [`Fit::Crop`] one copy of the cropped region; nothing else at full resolution.
//!
//! The files, one concept each (each imports from the file that defines what it uses):
//! - `formats`: the pixel formats ([`ColorFormat`], [`DepthFormat`]) and the decoding of one pixel;
//! - `image`: the buffers as images ([`ColorImage`], [`DepthImage`], [`ConfidenceImage`]), one generic
//!   type each over borrowed (`&[u8]`) or owned (`Vec<u8>`: [`ColorImageBuf`], …) bytes, with their
//!   layout checks and rotated decoding;
//! - `fit`: [`Rotation`], the colour [`CropRect`] and the [`Fit`] to the hologram's size (steps 3 and 6);
//! - `frame`: [`CameraFrame`] → `RgbdFrame` (steps 1–5), [`FrameOptions`] (whose `Default` is the one
//!   statement of the camera's defaults) and [`CameraFrameReport`];
//! - `ldi`: [`ldi_from_camera_frames`], a layered depth image from one camera frame per layer.

mod fit;
mod formats;
mod frame;
mod image;
mod ldi;

pub use fit::{CropRect, Fit, Rotation};
pub use formats::{ColorFormat, DepthFormat};
pub use frame::{CameraFrame, CameraFrameBuf, CameraFrameReport, FrameOptions};
pub use image::{
    ColorImage, ColorImageBuf, ConfidenceImage, ConfidenceImageBuf, DepthImage, DepthImageBuf,
};
pub use ldi::ldi_from_camera_frames;
