//! A kernel row: its public description ([`KernelInfo`]: name, ISA level, register tile, element type), how
//! an int8 row wants its weights packed ([`PackKind`]), and the function that `table.rs` lists with it
//! (`F32Row`, `U8Row`).
//!
//! Names: `conv3x3.<dtype>.<G>x<V>.<isa>`, `G` output channels × `V` vector registers of pixels per tile
//! (for the scalar row, `V` counts pixels).

use super::job::{F32Job, F32Out, U8Job, U8Out};
use crate::isa::Isa;

/// Element type of a kernel family.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DType {
    /// f32 activations and weights, f32 accumulation.
    F32,
    /// u8 activations, s8 weights, i32 accumulation, requantisation in the epilogue.
    U8S8,
}

/// How a row computes the convolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Algorithm {
    /// Direct convolution: `9·C_in` multiply-adds per output value.
    Direct,
    /// Winograd's minimal filtering F(2×2, 3×3) (Lavin & Gray 2016, "Fast algorithms for convolutional
    /// neural networks"): each 2×2 output tile from a 4×4 input tile in `16·C_in` multiply-adds, 2.25× fewer
    /// than direct, plus the input and output transforms. Not bit-identical with direct (see the crate
    /// README for the error bound).
    Winograd2x2,
    /// Winograd's F(4×4, 3×3): each 4×4 output tile from a 6×6 input tile in `36·C_in` multiply-adds, 4×
    /// fewer than direct, with larger transforms and a larger rounding error than F(2×2, 3×3) (see the crate
    /// README). Its tiles span 4 frame rows ([`KernelInfo::row_group`]).
    Winograd4x4,
}

impl Algorithm {
    /// `direct` or `winograd2x2` (as in reports and `TENSORHOLO_CONV`).
    pub fn name(self) -> &'static str {
        match self {
            Algorithm::Direct => "direct",
            Algorithm::Winograd2x2 => "winograd2x2",
            Algorithm::Winograd4x4 => "winograd4x4",
        }
    }
}

/// Description of one kernel row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KernelInfo {
    /// Unique name, e.g. `conv3x3.f32.6x2.avx2`.
    pub name: &'static str,
    /// The ISA level the row needs.
    pub isa: Isa,
    /// Element type.
    pub dtype: DType,
    /// Output channels per register tile (`G`).
    pub oc_tile: usize,
    /// Pixels per register tile (Winograd rows: output pixels along one row, two tile columns per lane).
    pub px_tile: usize,
    /// How the row computes the convolution.
    pub algorithm: Algorithm,
}

impl KernelInfo {
    /// True when this CPU can run the row.
    pub fn is_available(&self) -> bool {
        self.isa.is_available()
    }

    /// The frame rows one tile spans: 4 for F(4×4, 3×3), else 1 (a direct row computes any row on its own;
    /// an F(2×2, 3×3) row computes any band from the rows around it, bit-identically). Tiles start at frame
    /// rows that are multiples of it; a caller that runs a layer on windows of a taller frame
    /// ([`Inputs::shifted`](crate::Inputs::shifted)) makes every band start at such a row, and end at one or at
    /// the frame's last row, so that a band never reads rows the window does not hold yet.
    pub fn row_group(&self) -> usize {
        match self.algorithm {
            Algorithm::Winograd4x4 => 4,
            Algorithm::Direct | Algorithm::Winograd2x2 => 1,
        }
    }

    /// The frame columns one tile's output spans, all of whose rounding depends on every input column of the
    /// tile: 1 (direct: each output its own sum), 2 (F(2×2, 3×3)), 4 (F(4×4, 3×3)). Tiles start at columns
    /// that are multiples of it. A caller that computes a frame in column slabs (zero padding at a slab's
    /// edges where the frame has values) gets the whole frame's bits at least the sum of this over the
    /// layers away from a slab's edge, when slabs start at multiples of 4.
    pub fn column_group(&self) -> usize {
        match self.algorithm {
            Algorithm::Direct => 1,
            Algorithm::Winograd2x2 => 2,
            Algorithm::Winograd4x4 => 4,
        }
    }
}

/// How an int8 row wants its weights packed (`[oc-group][ic/4][ky][kx][G][4]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PackKind {
    /// 4 × s8 per output channel and step (dot-product instructions, scalar).
    I8,
    /// As `I8`, for kernels that feed SDOT with `q ⊕ 0x80 = q − 128`: the packing adds `128·Σw` to the
    /// accumulator start.
    I8Xor128,
    /// 4 × i16 per output channel and step (widening paths: `vpmaddwd`, `smlal`).
    I16,
}

pub(crate) type F32Fn = unsafe fn(&F32Job<'_>, &mut F32Out<'_>);

/// A registered f32 kernel.
#[derive(Debug)]
pub(crate) struct F32Row {
    pub info: KernelInfo,
    pub run: F32Fn,
}

pub(crate) type U8Fn = unsafe fn(&U8Job<'_>, &mut U8Out<'_>);

/// A registered int8 kernel.
#[derive(Debug)]
pub(crate) struct U8Row {
    pub info: KernelInfo,
    pub pack: PackKind,
    pub run: U8Fn,
}

/// The description of an f32 row.
pub(crate) const fn f32_info(
    name: &'static str,
    isa: Isa,
    oc_tile: usize,
    px_tile: usize,
) -> KernelInfo {
    KernelInfo {
        name,
        isa,
        dtype: DType::F32,
        oc_tile,
        px_tile,
        algorithm: Algorithm::Direct,
    }
}

/// The description of an f32 Winograd F(2×2, 3×3) row with `lanes`-wide registers and `nv` of them per tile.
pub(crate) const fn winograd_info(
    name: &'static str,
    isa: Isa,
    oc_tile: usize,
    lanes: usize,
    nv: usize,
) -> KernelInfo {
    KernelInfo {
        px_tile: 2 * lanes * nv,
        algorithm: Algorithm::Winograd2x2,
        ..f32_info(name, isa, oc_tile, 0)
    }
}

/// The description of an f32 Winograd F(4×4, 3×3) row with `lanes`-wide registers and `nv` of them per tile.
pub(crate) const fn winograd4_info(
    name: &'static str,
    isa: Isa,
    oc_tile: usize,
    lanes: usize,
    nv: usize,
) -> KernelInfo {
    KernelInfo {
        px_tile: 4 * lanes * nv,
        algorithm: Algorithm::Winograd4x4,
        ..winograd_info(name, isa, oc_tile, lanes, nv)
    }
}

/// The description of an int8 row.
pub(crate) const fn u8_info(
    name: &'static str,
    isa: Isa,
    oc_tile: usize,
    px_tile: usize,
) -> KernelInfo {
    KernelInfo {
        name,
        isa,
        dtype: DType::U8S8,
        oc_tile,
        px_tile,
        algorithm: Algorithm::Direct,
    }
}
