//! The conv3x3 kernel rows, as the benchmarks and callers see them (re-exported by the crate's
//! [`registry`](crate::registry), which adds the other families' paths): every row compiled for this target
//! ([`f32_kernels`], [`u8_kernels`]) and the one dispatch picks ([`selected_f32`], [`selected_f32_for`],
//! [`selected_u8`]), read from `table.rs` (the rows of every ISA level, which the plans and the tests read too). Plans take a row by name ([`Conv3x3F32::with_kernel`](crate::Conv3x3F32::with_kernel)).
//!
//! Names: `conv3x3.<dtype>.<G>x<V>.<isa>`, `G` output channels × `V` vector registers of pixels per tile
//! (for the scalar row, `V` counts pixels).

pub use super::row::{Algorithm, DType, KernelInfo, PackKind};
use super::table;
use crate::isa::Isa;

/// Every f32 row compiled for this target (available on this CPU or not), best first.
pub fn f32_kernels() -> impl Iterator<Item = &'static KernelInfo> {
    table::f32_rows().map(|r| &r.info)
}

/// The f32 row dispatch picks under `isa`: the first row (best first) whose ISA `isa` includes.
pub fn selected_f32(isa: Isa) -> &'static KernelInfo {
    &table::select_f32(isa).info
}

/// The f32 row a layer of `c_out` output channels runs under `isa` (see [`selected_f32`]; the row with the
/// least channel padding, the better one on a tie).
pub fn selected_f32_for(isa: Isa, c_out: usize) -> &'static KernelInfo {
    &table::select_f32_for(isa, c_out).info
}

/// The f32 row of `algorithm` a layer of `c_out` output channels runs under `isa` (as [`selected_f32_for`]
/// among that algorithm's rows; the portable one when `isa` has no vector row of it).
pub fn selected_f32_algorithm(isa: Isa, c_out: usize, algorithm: Algorithm) -> &'static KernelInfo {
    &table::select_f32_algorithm(isa, c_out, algorithm).info
}

/// Every f32 row of `algorithm` a plan under `isa` may run ([`Conv3x3F32::with_kernel`](crate::Conv3x3F32::with_kernel)):
/// [`selected_f32_algorithm`]'s row for `c_out` first, then the other vector rows `isa` includes, best first
/// (e.g. under AVX-512 the 8-channel AVX-512 row and the 6-channel AVX2 row; which is faster for a layer
/// depends on the CPU, so callers time them). Never a test-only row; the scalar row only under
/// [`Isa::Scalar`] or where no vector row has the algorithm.
pub fn f32_rows_of(
    isa: Isa,
    c_out: usize,
    algorithm: Algorithm,
) -> impl Iterator<Item = &'static KernelInfo> {
    table::f32_rows_of(isa, c_out, algorithm).map(|r| &r.info)
}

/// Every int8 row compiled for this target (available on this CPU or not), best first.
pub fn u8_kernels() -> impl Iterator<Item = &'static KernelInfo> {
    table::u8_rows().map(|r| &r.info)
}

/// The int8 row dispatch picks under `isa`.
pub fn selected_u8(isa: Isa) -> &'static KernelInfo {
    &table::select_u8(isa).info
}
