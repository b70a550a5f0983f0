//! The kernel registry: one list of rows (name, ISA, register tile, function) per element type, in order
//! of preference. Dispatch ([`selected_f32`], [`selected_u8`]), the tests and the benchmarks all iterate
//! these lists, and `run_f32` / `run_u8` are the single place where a kernel function is called (the
//! `unsafe` call sites outside the ISA files).
//!
//! Names: `conv3x3.<dtype>.<G>x<V>.<isa>`, `G` output channels × `V` vector registers of pixels per tile
//! (for the scalar row, `V` counts pixels).

use super::job::{F32Job, F32Out, U8Job, U8Out};
use crate::error::KernelError;
use crate::isa::Isa;

/// Element type of a kernel family.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DType {
    /// f32 activations and weights, f32 accumulation.
    F32,
    /// u8 activations, s8 weights, i32 accumulation, requantisation in the epilogue.
    U8S8,
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
    /// Pixels per register tile.
    pub px_tile: usize,
}

impl KernelInfo {
    /// True when this CPU can run the row.
    pub fn is_available(&self) -> bool {
        self.isa.is_available()
    }
}

pub(crate) type F32Fn = unsafe fn(&F32Job<'_>, &mut F32Out<'_>);

/// A registered f32 kernel.
#[derive(Debug)]
pub(crate) struct F32Row {
    pub info: KernelInfo,
    pub run: F32Fn,
}

const fn f32_info(name: &'static str, isa: Isa, oc_tile: usize, px_tile: usize) -> KernelInfo {
    KernelInfo {
        name,
        isa,
        dtype: DType::F32,
        oc_tile,
        px_tile,
    }
}

const SCALAR_F32: F32Row = F32Row {
    info: f32_info(
        "conv3x3.f32.8x8.scalar",
        Isa::Scalar,
        super::f32_scalar::G,
        super::f32_scalar::P,
    ),
    run: super::f32_scalar::conv,
};

/// f32 rows, best first.
#[cfg(target_arch = "x86_64")]
pub(crate) static F32_ROWS: &[F32Row] = &[
    F32Row {
        info: f32_info(
            "conv3x3.f32.8x3.avx512",
            Isa::Avx512,
            super::f32_avx512::G,
            16 * super::f32_avx512::NV,
        ),
        run: super::f32_avx512::conv,
    },
    F32Row {
        info: f32_info(
            "conv3x3.f32.6x2.avx2",
            Isa::Avx2Fma,
            super::f32_avx2::G,
            8 * super::f32_avx2::NV,
        ),
        run: super::f32_avx2::conv,
    },
    // Tests only: the AVX-512 row's tile geometry emulated on AVX2 (after the real rows: never dispatched).
    #[cfg(test)]
    F32Row {
        info: f32_info("test.f32.8x3.avx512-geometry-on-avx2", Isa::Avx2Fma, 8, 48),
        run: super::f32_avx2::conv_avx512_geometry,
    },
    SCALAR_F32,
];

/// f32 rows, best first.
#[cfg(target_arch = "aarch64")]
pub(crate) static F32_ROWS: &[F32Row] = &[
    F32Row {
        info: f32_info(
            "conv3x3.f32.8x3.neon",
            Isa::Neon,
            super::f32_neon::G,
            4 * super::f32_neon::NV,
        ),
        run: super::f32_neon::conv,
    },
    SCALAR_F32,
];

/// f32 rows, best first.
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
pub(crate) static F32_ROWS: &[F32Row] = &[SCALAR_F32];

/// Every f32 row compiled for this target (available on this CPU or not), best first.
pub fn f32_kernels() -> impl Iterator<Item = &'static KernelInfo> {
    F32_ROWS.iter().map(|r| &r.info)
}

/// The f32 row dispatch picks under `isa`: the first row (best first) whose ISA `isa` includes. Does not
/// check that `isa` is available (plans do).
pub(crate) fn select_f32(isa: Isa) -> &'static F32Row {
    F32_ROWS
        .iter()
        .find(|r| isa.includes(r.info.isa))
        .unwrap_or(&F32_ROWS[F32_ROWS.len() - 1])
}

/// The f32 row dispatch picks under `isa`: the first row (best first) whose ISA `isa` includes.
pub fn selected_f32(isa: Isa) -> &'static KernelInfo {
    &select_f32(isa).info
}

/// The f32 row a layer of `c_out` output channels runs under `isa`: among the vector rows `isa` includes
/// (the scalar row only when there is none), the one that computes the fewest output channels in all
/// (`c_out` rounded up to its tile `G`), the earlier (better) row on a tie. For 24 and 8 channels that is the first row; for the 6-channel last layers on AVX-512 it is
/// the AVX2 6 × 16 tile (measured on Zen 4, one thread, 384²: 65 against 56 GFLOP/s for 24+4→6, 89 against
/// 73 for 8+6→6; the 8-channel tile computes 8 channels for 6).
pub(crate) fn select_f32_for(isa: Isa, c_out: usize) -> &'static F32Row {
    let padded = |r: &F32Row| c_out.div_ceil(r.info.oc_tile) * r.info.oc_tile;
    F32_ROWS
        .iter()
        .filter(|r| isa.includes(r.info.isa))
        // Test-only rows (emulated geometries) are never dispatched.
        .filter(|r| !r.info.name.starts_with("test."))
        .filter(|r| r.info.isa != Isa::Scalar || isa == Isa::Scalar)
        .min_by_key(|r| padded(r))
        .unwrap_or(&F32_ROWS[F32_ROWS.len() - 1])
}

/// The f32 row a layer of `c_out` output channels runs under `isa` (see [`selected_f32`]; the row with the
/// least channel padding, the better one on a tie).
pub fn selected_f32_for(isa: Isa, c_out: usize) -> &'static KernelInfo {
    &select_f32_for(isa, c_out).info
}

/// Runs an f32 row: the single dispatch point. Errors: the row's ISA is not available on this CPU.
pub(crate) fn run_f32(
    row: &F32Row,
    job: &F32Job<'_>,
    mut out: F32Out<'_>,
) -> Result<(), KernelError> {
    if !row.info.is_available() {
        return Err(KernelError::Kernel {
            name: row.info.name.into(),
        });
    }
    // SAFETY: the CPU has the row's ISA (checked just above); the plan packed the weights for this row's
    // tile and the safe API checked every shape, length and the row band (`Inputs::check`, `run*`).
    unsafe { (row.run)(job, &mut out) };
    Ok(())
}

/// Runs the f32 FMA peak loop of `isa` for `iters` iterations; returns the FLOPs done and a value to keep
/// the loop alive. Errors: `isa` not available.
pub(crate) fn run_peak_f32(isa: Isa, iters: u64) -> Result<(f64, f32), KernelError> {
    if !isa.is_available() {
        return Err(KernelError::Isa {
            name: isa.name().into(),
            why: "not available on this CPU",
        });
    }
    let it = iters as f64;
    #[cfg(target_arch = "x86_64")]
    {
        if Isa::Avx512.is_available() && isa.includes(Isa::Avx512) {
            // SAFETY: AVX-512F is available (checked just above).
            return Ok((it * 24.0 * 16.0 * 2.0, unsafe {
                super::f32_avx512::peak(iters)
            }));
        }
        if isa.includes(Isa::Avx2Fma) {
            // SAFETY: `isa` is available and includes AVX2 + FMA.
            return Ok((it * 12.0 * 8.0 * 2.0, unsafe {
                super::f32_avx2::peak(iters)
            }));
        }
    }
    #[cfg(target_arch = "aarch64")]
    {
        if isa.includes(Isa::Neon) {
            // SAFETY: `isa` is available and includes NEON.
            return Ok((it * 24.0 * 4.0 * 2.0, unsafe {
                super::f32_neon::peak(iters)
            }));
        }
    }
    Ok((it * 16.0 * 2.0, scalar_peak(iters)))
}

fn scalar_peak(iters: u64) -> f32 {
    let mut acc = [1.0f32; 16];
    let a = std::hint::black_box(0.999_999f32);
    let b = std::hint::black_box(1e-7f32);
    for _ in 0..iters {
        for x in acc.iter_mut() {
            *x = *x * a + b;
        }
    }
    acc.iter().sum()
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

pub(crate) type U8Fn = unsafe fn(&U8Job<'_>, &mut U8Out<'_>);

/// A registered int8 kernel.
#[derive(Debug)]
pub(crate) struct U8Row {
    pub info: KernelInfo,
    pub pack: PackKind,
    pub run: U8Fn,
}

const fn u8_info(name: &'static str, isa: Isa, oc_tile: usize, px_tile: usize) -> KernelInfo {
    KernelInfo {
        name,
        isa,
        dtype: DType::U8S8,
        oc_tile,
        px_tile,
    }
}

const SCALAR_U8: U8Row = U8Row {
    info: u8_info(
        "conv3x3.u8s8.8x8.scalar",
        Isa::Scalar,
        super::u8s8_scalar::G,
        super::u8s8_scalar::P,
    ),
    pack: PackKind::I8,
    run: super::u8s8_scalar::conv,
};

/// int8 rows, best first.
#[cfg(target_arch = "x86_64")]
pub(crate) static U8_ROWS: &[U8Row] = &[
    U8Row {
        info: u8_info("conv3x3.u8s8.8x3.avx512vnni", Isa::Avx512Vnni, 8, 48),
        pack: PackKind::I8,
        run: super::u8s8_avx512vnni::conv_avx512vnni,
    },
    U8Row {
        info: u8_info("conv3x3.u8s8.4x2.avxvnni", Isa::AvxVnni, 4, 16),
        pack: PackKind::I8,
        run: super::u8s8_avxvnni::conv_avxvnni,
    },
    U8Row {
        info: u8_info("conv3x3.u8s8.4x1.avx2", Isa::Avx2Fma, 4, 8),
        pack: PackKind::I16,
        run: super::u8s8_avx2::conv_avx2,
    },
    // Tests only: the VNNI rows' tile geometries emulated on AVX2 (after the real rows: never dispatched).
    #[cfg(test)]
    U8Row {
        info: u8_info(
            "test.u8s8.4x2.avxvnni-geometry-on-avx2",
            Isa::Avx2Fma,
            4,
            16,
        ),
        pack: PackKind::I16,
        run: super::u8s8_avx2::conv_avxvnni_geometry,
    },
    #[cfg(test)]
    U8Row {
        info: u8_info(
            "test.u8s8.8x3.avx512vnni-geometry-on-avx2",
            Isa::Avx2Fma,
            8,
            48,
        ),
        pack: PackKind::I16,
        run: super::u8s8_avx2::conv_avx512vnni_geometry,
    },
    SCALAR_U8,
];

/// int8 rows, best first.
#[cfg(target_arch = "aarch64")]
pub(crate) static U8_ROWS: &[U8Row] = &[
    U8Row {
        info: u8_info("conv3x3.u8s8.8x3.neoni8mm", Isa::NeonI8mm, 8, 12),
        pack: PackKind::I8,
        run: super::u8s8_neoni8mm::conv_i8mm,
    },
    U8Row {
        info: u8_info("conv3x3.u8s8.8x3.neondot", Isa::NeonDot, 8, 12),
        pack: PackKind::I8Xor128,
        run: super::u8s8_neondot::conv_dot,
    },
    U8Row {
        info: u8_info("conv3x3.u8s8.4x1.neon", Isa::Neon, 4, 4),
        pack: PackKind::I16,
        run: super::u8s8_neon::conv_wide,
    },
    SCALAR_U8,
];

/// int8 rows, best first.
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
pub(crate) static U8_ROWS: &[U8Row] = &[SCALAR_U8];

/// Every int8 row compiled for this target (available on this CPU or not), best first.
pub fn u8_kernels() -> impl Iterator<Item = &'static KernelInfo> {
    U8_ROWS.iter().map(|r| &r.info)
}

/// The int8 row dispatch picks under `isa` (first row, best first, whose ISA `isa` includes).
pub(crate) fn select_u8(isa: Isa) -> &'static U8Row {
    U8_ROWS
        .iter()
        .find(|r| isa.includes(r.info.isa))
        .unwrap_or(&U8_ROWS[U8_ROWS.len() - 1])
}

/// The int8 row dispatch picks under `isa`.
pub fn selected_u8(isa: Isa) -> &'static KernelInfo {
    &select_u8(isa).info
}

/// Runs an int8 row: the single dispatch point for int8. Errors: the row's ISA is not available.
pub(crate) fn run_u8(row: &U8Row, job: &U8Job<'_>, mut out: U8Out<'_>) -> Result<(), KernelError> {
    if !row.info.is_available() {
        return Err(KernelError::Kernel {
            name: row.info.name.into(),
        });
    }
    // SAFETY: the CPU has the row's ISA (checked just above); the plan packed the weights as this row's
    // `pack` and tile require and the safe API checked every shape, length, zero point and the row band.
    unsafe { (row.run)(job, &mut out) };
    Ok(())
}

/// Runs the int8 dot-product peak loop of `isa` (its best int8 instruction) for `iters` iterations;
/// returns the integer operations done (a multiply-add counts 2) and a value to keep the loop alive.
pub(crate) fn run_peak_u8(isa: Isa, iters: u64) -> Result<(f64, i32), KernelError> {
    if !isa.is_available() {
        return Err(KernelError::Isa {
            name: isa.name().into(),
            why: "not available on this CPU",
        });
    }
    let it = iters as f64;
    #[cfg(target_arch = "x86_64")]
    {
        if isa.includes(Isa::Avx512Vnni) {
            // SAFETY: `isa` is available and includes AVX-512 VNNI.
            return Ok((it * 24.0 * 64.0 * 2.0, unsafe {
                super::u8s8_avx512vnni::peak_avx512vnni(iters)
            }));
        }
        if isa.includes(Isa::AvxVnni) {
            // SAFETY: `isa` is available and includes AVX-VNNI.
            return Ok((it * 12.0 * 32.0 * 2.0, unsafe {
                super::u8s8_avxvnni::peak_avxvnni(iters)
            }));
        }
        if isa.includes(Isa::Avx2Fma) {
            // SAFETY: `isa` is available and includes AVX2.
            return Ok((it * 12.0 * 16.0 * 2.0, unsafe {
                super::u8s8_avx2::peak_avx2(iters)
            }));
        }
    }
    #[cfg(target_arch = "aarch64")]
    {
        if isa.includes(Isa::NeonI8mm) {
            // SAFETY: `isa` is available and includes i8mm.
            return Ok((it * 24.0 * 16.0 * 2.0, unsafe {
                super::u8s8_neoni8mm::peak_i8mm(iters)
            }));
        }
        if isa.includes(Isa::NeonDot) {
            // SAFETY: `isa` is available and includes the dot product.
            return Ok((it * 24.0 * 16.0 * 2.0, unsafe {
                super::u8s8_neondot::peak_dot(iters)
            }));
        }
        if isa.includes(Isa::Neon) {
            // SAFETY: NEON.
            return Ok((it * 24.0 * 4.0 * 2.0, unsafe {
                super::u8s8_neon::peak_wide(iters)
            }));
        }
    }
    Ok((it * 16.0 * 2.0, scalar_peak_u8(iters)))
}

fn scalar_peak_u8(iters: u64) -> i32 {
    let mut acc = [1i32; 16];
    let a = std::hint::black_box(3i32);
    let b = std::hint::black_box(-5i32);
    for _ in 0..iters {
        for x in acc.iter_mut() {
            *x = x.wrapping_mul(a).wrapping_add(b);
        }
    }
    acc.iter().fold(0, |s, &x| s.wrapping_add(x))
}
