//! Direct 3×3 convolutions (stride 1, zero padding 1, no groups) on [`RowPlanar`](crate::RowPlanar) buffers.
//!
//! A plan ([`Conv3x3F32`]) packs the weights once for the kernel row it selected (see [`registry`]; the rows
//! are listed per ISA level in `table.rs`) and then runs any row band `[y0, y1)` of a frame:
//! every output pixel is computed by the same instruction sequence whatever the band, so any split of the
//! rows (over threads, say) gives bit-identical frames.
//!
//! Epilogue per output value: `v = conv + bias`; `v = max(v, 0)` when the plan has ReLU; `v += residual`
//! when a residual buffer is given (after the ReLU). Inputs may come from two buffers (channel
//! concatenation: channels `[0, Ca)` from `a`, `[Ca, Ca + Cb)` from `b`) so no copy is needed.
//!
//! # Files
//!
//! * The plans (safe API): [`Conv3x3F32`] in `f32.rs`, [`Conv3x3U8`] in `u8s8.rs`, their operands
//!   ([`Inputs`]) in `inputs.rs`; [`registry`], the rows as callers see them.
//! * The contract between a plan and a kernel: `job.rs` (what a kernel reads and where it writes) and
//!   `row.rs` (a row's description and function type); `table.rs`, the rows of every ISA level and the
//!   rules that pick one (the one place a row is called through `unsafe`).
//! * The kernels, one file per element type and ISA family, `<dtype>_<isa>.rs` (`f32_avx2.rs`,
//!   `u8s8_avx512vnni.rs`, …; `*_scalar.rs` the portable rows), most of them instances of the generic loops
//!   `simd_f32.rs` (over `ConvF32`, an extension of the crate's register trait `crate::simd::SimdF32`) and
//!   `simd_u8.rs`. Test builds add `reference.rs`, the obviously-correct direct loop.

pub mod registry;

mod f32;
mod inputs;
pub(crate) mod job;
pub(crate) mod row;
mod table;
mod u8s8;

pub(crate) mod f32_scalar;
// The direct generic loop is instantiated only by the x86-64 and aarch64 rows; the Winograd body by every
// target (the portable row is the body on one-lane `f32` registers).
#[cfg_attr(
    not(any(target_arch = "x86_64", target_arch = "aarch64")),
    allow(dead_code)
)]
mod simd_f32;
#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
mod simd_u8;
pub(crate) mod u8s8_scalar;
mod wino2x2;
mod wino4x4;

#[cfg(target_arch = "x86_64")]
pub(crate) mod f32_avx2;
#[cfg(target_arch = "x86_64")]
pub(crate) mod f32_avx512;
#[cfg(target_arch = "x86_64")]
pub(crate) mod u8s8_avx2;
#[cfg(target_arch = "x86_64")]
pub(crate) mod u8s8_avx512vnni;
#[cfg(target_arch = "x86_64")]
pub(crate) mod u8s8_avxvnni;

#[cfg(target_arch = "aarch64")]
pub(crate) mod f32_neon;
#[cfg(target_arch = "aarch64")]
pub(crate) mod u8s8_neon;
#[cfg(target_arch = "aarch64")]
pub(crate) mod u8s8_neondot;
#[cfg(target_arch = "aarch64")]
pub(crate) mod u8s8_neoni8mm;

#[cfg(test)]
mod reference;
#[cfg(test)]
mod tests;

pub use crate::quant::QuantU8;
pub use f32::Conv3x3F32;
pub use inputs::Inputs;
pub use u8s8::{Conv3x3U8, Conv3x3U8Spec, MAX_C_IN_U8};
