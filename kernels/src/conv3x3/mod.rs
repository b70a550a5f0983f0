//! Direct 3×3 convolutions (stride 1, zero padding 1, no groups) on [`RowPlanar`] buffers.
//!
//! A plan ([`Conv3x3F32`]) packs the weights once for the kernel row it selected (see [`registry`]) and
//! then runs any row band `[y0, y1)` of a frame: every output pixel is computed by the same instruction
//! sequence whatever the band, so any split of the rows (over threads, say) gives bit-identical frames.
//!
//! Epilogue per output value: `v = conv + bias`; `v = max(v, 0)` when the plan has ReLU; `v += residual`
//! when a residual buffer is given (after the ReLU). Inputs may come from two buffers (channel
//! concatenation: channels `[0, Ca)` from `a`, `[Ca, Ca + Cb)` from `b`) so no copy is needed.

pub mod registry;

mod f32_scalar;
#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
mod simd_f32;
#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
mod simd_u8;
mod u8s8;
#[cfg(target_arch = "x86_64")]
mod u8s8_avx2;
#[cfg(target_arch = "x86_64")]
mod u8s8_avx512vnni;
#[cfg(target_arch = "x86_64")]
mod u8s8_avxvnni;
#[cfg(target_arch = "aarch64")]
mod u8s8_neon;
#[cfg(target_arch = "aarch64")]
mod u8s8_neondot;
#[cfg(target_arch = "aarch64")]
mod u8s8_neoni8mm;
mod u8s8_scalar;

#[cfg(target_arch = "x86_64")]
mod f32_avx2;
#[cfg(target_arch = "x86_64")]
mod f32_avx512;
#[cfg(target_arch = "aarch64")]
mod f32_neon;

mod f32;
mod inputs;
mod job;
#[cfg(test)]
mod reference;
#[cfg(test)]
pub(crate) mod tests;

pub use f32::Conv3x3F32;
pub use inputs::Inputs;
pub use u8s8::{Conv3x3U8, Conv3x3U8Spec, QuantU8, MAX_C_IN_U8};
