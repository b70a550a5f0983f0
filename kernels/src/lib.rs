//! `tensorholo-kernels`: the convolution kernels of tensorholo's own CNN engine.
//!
//! Direct 3×3 convolutions (stride 1, zero padding 1) for exactly the TensorHolo network shapes (hidden
//! width 24 or 8, first layer 4·L or 6 channels, last layer reading a two-buffer concatenation), in f32 and
//! int8, for x86-64 (AVX2+FMA, AVX-512, AVX-VNNI, AVX-512 VNNI) and aarch64 (NEON, dot product, i8mm), with a
//! portable scalar fallback and run-time dispatch. No dependencies beyond `std`.
//!
//! * [`RowPlanar`]: activation buffers `[H+2][C][Wp]` with a zero (or zero-point) border, so padding costs
//!   nothing ([`buffer`] documents the layout).
//! * [`Conv3x3F32`]: a planned f32 convolution: weights packed for one kernel row, bias, ReLU, optional
//!   residual after the ReLU, optional second source, output to a buffer or to planar `[C][H][W]` f32, any
//!   row band.
//! * [`Conv3x3U8`]: the int8 plan (u8 activations with zero points, s8 weights with per-channel scales, i32
//!   accumulation, requantisation fused into the epilogue; every path bit-exact with the scalar one), any
//!   row band; u8 buffers are filled as ONNX `QuantizeLinear` does and take a new zero point when reused.
//! * [`Isa`]: detection (the crate reads no environment; a caller lowers the level per plan); [`registry`]: the kernels compiled for this target (conv3x3 rows, other families' levels).
//! * [`tanh_heads`], [`fake_quantize`]: the hologram CNN's heads and the int8 output grid, vectorised.
//! * [`depthwise()`], [`depthwise_rows`]: the pre-filter's fixed depthwise filter, register-tiled; [`peak`]:
//!   measured FMA / dot-product peaks.
//! * [`box_blur`]: box means of a per-pixel size from a summed-area table (a foveated periphery's synthetic
//!   defocus blur), vectorised.
//! * [`double_phase`]: the double phase encoding's rows (polynomial `atan2`/`acos`, wrap, linear look-up
//!   table codes) with documented error bounds, vectorised.
//!
//! ```
//! use tensorholo_kernels::{Conv3x3F32, Inputs, Isa, RowPlanar};
//! let (c_in, c_out, h, w) = (4, 24, 8, 10);
//! let weights = vec![0.01f32; c_out * c_in * 9];
//! let bias = vec![0.0f32; c_out];
//! let plan = Conv3x3F32::new(&weights, &bias, c_in, c_out, true, Isa::detect())?;
//! let rgbd = vec![0.5f32; c_in * h * w];
//! let offset = [-0.5f32; 4];
//! let input = RowPlanar::from_planar(&rgbd, c_in, h, w,
//!     Some(tensorholo_kernels::Affine { scale: &[1.0; 4], offset: &offset }))?;
//! let mut out = RowPlanar::new(c_out, h, w)?;
//! plan.run(Inputs::new(&input), &mut out, 0..h)?;
//! assert_eq!(out.get(0, 0, 0), Some(0.0));
//! # Ok::<(), tensorholo_kernels::KernelError>(())
//! ```
//!
//! `unsafe` appears only in the ISA files (`conv3x3/*_{avx2,avx512,neon,…}.rs`, the generic SIMD loops, the
//! `#[target_feature]` copies in `depthwise/body.rs`, `heads/body.rs`, `phasor/body.rs` and `buffer/rows.rs`,
//! the register traits of `simd/` (`SimdF32`, shared by the conv3x3 f32 rows and the double phase rows,
//! which write their bodies once and keep thin `#[target_feature]` entry points per ISA) and the double
//! phase rows' `double_phase/{simd,x86}.rs`) and where a family calls the path that
//! `dispatch.rs` picked from its table (each family lists its paths per ISA level next to its safe API, the
//! conv3x3 rows in `conv3x3/table.rs`; [`registry`] shows them); every public function is safe and checks
//! shapes and lengths. The crate's `README.md` maps the files.

pub mod box_blur;
pub mod buffer;
pub mod conv3x3;
pub mod depthwise;
mod dispatch;
pub mod double_phase;
mod error;
pub mod heads;
pub mod isa;
mod pack;
pub mod peak;
pub mod phasor;
mod quant;
pub mod registry;
mod simd;
pub mod spectral;
#[cfg(test)]
mod test_rng;

pub use buffer::{Affine, RowBand, RowPlanar};
pub use conv3x3::{Conv3x3F32, Conv3x3U8, Conv3x3U8Spec, Inputs, QuantU8};
pub use depthwise::{depthwise, depthwise_rows};
pub use error::KernelError;
pub use heads::{fake_quantize, tanh_heads};
pub use isa::Isa;
pub use registry::{Algorithm, DType, KernelInfo, PackKind};
