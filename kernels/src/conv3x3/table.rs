//! The conv3x3 rows of every ISA level compiled for this target, best level first and the portable level
//! last (a level lists only the rows that need exactly its instructions: under a selected level `s` the
//! plans take rows from every level `s` includes), and the rules that pick a row ([`select_f32_for`]). The
//! plans ([`Conv3x3F32`](super::Conv3x3F32), [`Conv3x3U8`](super::Conv3x3U8)), the tests and, through
//! [`registry`](super::registry), the benchmarks read these lists; [`run_f32`] and [`run_u8`] are the one
//! place where a row is called through `unsafe`, each after checking that the CPU has the row's level.

use super::job::{F32Job, F32Out, U8Job, U8Out};
use super::row::{
    f32_info, u8_info, winograd4_info, winograd_info, Algorithm, F32Row, PackKind, U8Row,
};
#[cfg(target_arch = "x86_64")]
use super::{f32_avx2, f32_avx512, u8s8_avx2, u8s8_avx512vnni, u8s8_avxvnni};
#[cfg(target_arch = "aarch64")]
use super::{f32_neon, u8s8_neon, u8s8_neondot, u8s8_neoni8mm};
use super::{f32_scalar, u8s8_scalar};
use crate::error::KernelError;
use crate::isa::Isa;

/// The f32 rows of each level, best level first, the portable level last.
#[cfg(target_arch = "x86_64")]
static F32_LEVELS: &[&[F32Row]] = &[AVX512_F32, AVX2_F32, SCALAR_F32];
#[cfg(target_arch = "aarch64")]
static F32_LEVELS: &[&[F32Row]] = &[NEON_F32, SCALAR_F32];
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
static F32_LEVELS: &[&[F32Row]] = &[SCALAR_F32];

/// The int8 rows of each level, best level first, the portable level last.
#[cfg(target_arch = "x86_64")]
static U8_LEVELS: &[&[U8Row]] = &[AVX512VNNI_U8, AVXVNNI_U8, AVX2_U8, SCALAR_U8];
#[cfg(target_arch = "aarch64")]
static U8_LEVELS: &[&[U8Row]] = &[NEONI8MM_U8, NEONDOT_U8, NEON_U8, SCALAR_U8];
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
static U8_LEVELS: &[&[U8Row]] = &[SCALAR_U8];

#[cfg(target_arch = "x86_64")]
const AVX512_F32: &[F32Row] = &[
    F32Row {
        info: f32_info(
            "conv3x3.f32.8x3.avx512",
            Isa::Avx512,
            f32_avx512::G,
            16 * f32_avx512::NV,
        ),
        run: f32_avx512::conv,
    },
    F32Row {
        info: f32_info(
            "conv3x3.f32.6x4.avx512",
            Isa::Avx512,
            f32_avx512::G6,
            16 * f32_avx512::NV6,
        ),
        run: f32_avx512::conv6,
    },
    F32Row {
        info: winograd_info(
            "conv3x3.f32.wino2x2.8x2.avx512",
            Isa::Avx512,
            f32_avx512::G,
            16,
            f32_avx512::WINO_NV,
        ),
        run: f32_avx512::winograd,
    },
    F32Row {
        info: winograd4_info(
            "conv3x3.f32.wino4x4.24x1.avx512",
            Isa::Avx512,
            f32_avx512::WINO4_G,
            16,
            1,
        ),
        run: f32_avx512::winograd4_wide,
    },
    F32Row {
        info: winograd4_info(
            "conv3x3.f32.wino4x4.8x1.avx512",
            Isa::Avx512,
            f32_avx512::G,
            16,
            1,
        ),
        run: f32_avx512::winograd4,
    },
];

#[cfg(target_arch = "x86_64")]
const AVX2_F32: &[F32Row] = &[
    F32Row {
        info: f32_info(
            "conv3x3.f32.6x2.avx2",
            Isa::Avx2Fma,
            f32_avx2::G,
            8 * f32_avx2::NV,
        ),
        run: f32_avx2::conv,
    },
    // Tests only: the AVX-512 row's tile geometry emulated on AVX2 (after the real rows: never
    // dispatched).
    F32Row {
        info: winograd_info(
            "conv3x3.f32.wino2x2.6x2.avx2",
            Isa::Avx2Fma,
            f32_avx2::G,
            8,
            f32_avx2::NV,
        ),
        run: f32_avx2::winograd,
    },
    F32Row {
        info: winograd4_info(
            "conv3x3.f32.wino4x4.6x2.avx2",
            Isa::Avx2Fma,
            f32_avx2::G,
            8,
            f32_avx2::NV,
        ),
        run: f32_avx2::winograd4,
    },
    #[cfg(test)]
    F32Row {
        info: f32_info("test.f32.8x3.avx512-geometry-on-avx2", Isa::Avx2Fma, 8, 48),
        run: f32_avx2::conv_avx512_geometry,
    },
    #[cfg(test)]
    F32Row {
        info: f32_info("test.f32.6x4.avx512-geometry-on-avx2", Isa::Avx2Fma, 6, 64),
        run: f32_avx2::conv6_avx512_geometry,
    },
    #[cfg(test)]
    F32Row {
        info: winograd_info(
            "test.f32.wino2x2.8x2.avx512-geometry-on-avx2",
            Isa::Avx2Fma,
            8,
            16,
            2,
        ),
        run: f32_avx2::winograd_avx512_geometry,
    },
    #[cfg(test)]
    F32Row {
        info: winograd4_info(
            "test.f32.wino4x4.8x1.avx512-geometry-on-avx2",
            Isa::Avx2Fma,
            8,
            16,
            1,
        ),
        run: f32_avx2::winograd4_avx512_geometry,
    },
    #[cfg(test)]
    F32Row {
        info: winograd4_info(
            "test.f32.wino4x4.24x1.avx512-geometry-on-avx2",
            Isa::Avx2Fma,
            24,
            16,
            1,
        ),
        run: f32_avx2::winograd4_wide_avx512_geometry,
    },
];

/// The portable rows: safe code, any CPU (the Winograd rows are the generic bodies on one-lane registers).
const SCALAR_F32: &[F32Row] = &[
    F32Row {
        info: f32_info(
            "conv3x3.f32.8x8.scalar",
            Isa::Scalar,
            f32_scalar::G,
            f32_scalar::P,
        ),
        run: f32_scalar::conv,
    },
    F32Row {
        info: winograd_info(
            "conv3x3.f32.wino2x2.4x4.scalar",
            Isa::Scalar,
            f32_scalar::WINO_G,
            1,
            f32_scalar::WINO_NV,
        ),
        run: f32_scalar::winograd,
    },
    F32Row {
        info: winograd4_info(
            "conv3x3.f32.wino4x4.4x4.scalar",
            Isa::Scalar,
            f32_scalar::WINO_G,
            1,
            f32_scalar::WINO_NV,
        ),
        run: f32_scalar::winograd4,
    },
];

#[cfg(target_arch = "x86_64")]
const AVX512VNNI_U8: &[U8Row] = &[U8Row {
    info: u8_info("conv3x3.u8s8.8x3.avx512vnni", Isa::Avx512Vnni, 8, 48),
    pack: PackKind::I8,
    run: u8s8_avx512vnni::conv_avx512vnni,
}];

#[cfg(target_arch = "x86_64")]
const AVXVNNI_U8: &[U8Row] = &[U8Row {
    info: u8_info("conv3x3.u8s8.4x2.avxvnni", Isa::AvxVnni, 4, 16),
    pack: PackKind::I8,
    run: u8s8_avxvnni::conv_avxvnni,
}];

#[cfg(target_arch = "x86_64")]
const AVX2_U8: &[U8Row] = &[
    U8Row {
        info: u8_info("conv3x3.u8s8.4x1.avx2", Isa::Avx2Fma, 4, 8),
        pack: PackKind::I16,
        run: u8s8_avx2::conv_avx2,
    },
    // Tests only: the VNNI rows' tile geometries emulated on AVX2 (after the real rows: never
    // dispatched).
    #[cfg(test)]
    U8Row {
        info: u8_info(
            "test.u8s8.4x2.avxvnni-geometry-on-avx2",
            Isa::Avx2Fma,
            4,
            16,
        ),
        pack: PackKind::I16,
        run: u8s8_avx2::conv_avxvnni_geometry,
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
        run: u8s8_avx2::conv_avx512vnni_geometry,
    },
];

#[cfg(target_arch = "aarch64")]
const NEONI8MM_U8: &[U8Row] = &[U8Row {
    info: u8_info("conv3x3.u8s8.8x3.neoni8mm", Isa::NeonI8mm, 8, 12),
    pack: PackKind::I8,
    run: u8s8_neoni8mm::conv_i8mm,
}];

#[cfg(target_arch = "aarch64")]
const NEONDOT_U8: &[U8Row] = &[U8Row {
    info: u8_info("conv3x3.u8s8.8x3.neondot", Isa::NeonDot, 8, 12),
    pack: PackKind::I8Xor128,
    run: u8s8_neondot::conv_dot,
}];

#[cfg(target_arch = "aarch64")]
const NEON_F32: &[F32Row] = &[
    F32Row {
        info: f32_info(
            "conv3x3.f32.8x3.neon",
            Isa::Neon,
            f32_neon::G,
            4 * f32_neon::NV,
        ),
        run: f32_neon::conv,
    },
    F32Row {
        info: winograd_info(
            "conv3x3.f32.wino2x2.8x3.neon",
            Isa::Neon,
            f32_neon::G,
            4,
            f32_neon::NV,
        ),
        run: f32_neon::winograd,
    },
    F32Row {
        info: winograd4_info(
            "conv3x3.f32.wino4x4.8x3.neon",
            Isa::Neon,
            f32_neon::G,
            4,
            f32_neon::NV,
        ),
        run: f32_neon::winograd4,
    },
];

#[cfg(target_arch = "aarch64")]
const NEON_U8: &[U8Row] = &[U8Row {
    info: u8_info("conv3x3.u8s8.4x1.neon", Isa::Neon, 4, 4),
    pack: PackKind::I16,
    run: u8s8_neon::conv_wide,
}];

const SCALAR_U8: &[U8Row] = &[U8Row {
    info: u8_info(
        "conv3x3.u8s8.8x8.scalar",
        Isa::Scalar,
        u8s8_scalar::G,
        u8s8_scalar::P,
    ),
    pack: PackKind::I8,
    run: u8s8_scalar::conv,
}];

/// The rows of the levels `isa` includes, best first.
fn under<R>(levels: &'static [&'static [R]], isa: Isa) -> impl Iterator<Item = &'static R>
where
    R: HasIsa,
{
    levels
        .iter()
        .flat_map(|l| l.iter())
        .filter(move |r| isa.includes(r.isa()))
}

/// A row's level (the two row types alike, for [`under`]).
trait HasIsa {
    fn isa(&self) -> Isa;
}
impl HasIsa for F32Row {
    fn isa(&self) -> Isa {
        self.info.isa
    }
}
impl HasIsa for U8Row {
    fn isa(&self) -> Isa {
        self.info.isa
    }
}

/// Every f32 row compiled for this target, best first.
pub(crate) fn f32_rows() -> impl Iterator<Item = &'static F32Row> {
    F32_LEVELS.iter().flat_map(|l| l.iter())
}

/// Every int8 row compiled for this target, best first.
pub(crate) fn u8_rows() -> impl Iterator<Item = &'static U8Row> {
    U8_LEVELS.iter().flat_map(|l| l.iter())
}

/// The f32 row dispatch picks under `isa`: the first direct row (best first) whose ISA `isa` includes.
/// Does not check that `isa` is available (plans do).
pub(crate) fn select_f32(isa: Isa) -> &'static F32Row {
    under(F32_LEVELS, isa)
        .find(|r| r.info.algorithm == Algorithm::Direct)
        .unwrap_or(&SCALAR_F32[0])
}

/// The f32 row a layer of `c_out` output channels runs under `isa`: among the vector rows `isa` includes (the
/// scalar row only when there is none), the one that computes the fewest output channels in all (`c_out`
/// rounded up to its tile `G`), the earlier (better) row on a tie. For 24 and 8 channels that is the first
/// row; for the 6-channel last layers on AVX-512 it is the 6-channel AVX-512 tile `conv3x3.f32.6x4.avx512`
/// (the 8-channel tile computes 8 channels for 6; 1.3× faster than it on Zen 5), under AVX2 the 6 × 16
/// tile; callers time [`f32_rows_of`] where it matters.
pub(crate) fn select_f32_for(isa: Isa, c_out: usize) -> &'static F32Row {
    select_f32_algorithm(isa, c_out, Algorithm::Direct)
}

/// The f32 rows of `algorithm` a plan under `isa` may run: the vector rows `isa` includes (the scalar row
/// only when `isa` is [`Isa::Scalar`] or no vector row has the algorithm), never a test-only row;
/// [`select_f32_algorithm`]'s row for `c_out` first, then the others best first.
pub(crate) fn f32_rows_of(
    isa: Isa,
    c_out: usize,
    algorithm: Algorithm,
) -> impl Iterator<Item = &'static F32Row> {
    let first = select_f32_algorithm(isa, c_out, algorithm);
    let others = dispatchable_f32(isa, algorithm).filter(move |r| r.info.name != first.info.name);
    std::iter::once(first).chain(others)
}

/// The vector f32 rows of `algorithm` that `isa` includes, best first (the scalar row too under
/// [`Isa::Scalar`]), never a test-only row (emulated geometries).
fn dispatchable_f32(isa: Isa, algorithm: Algorithm) -> impl Iterator<Item = &'static F32Row> {
    under(F32_LEVELS, isa)
        .filter(move |r| r.info.algorithm == algorithm)
        .filter(|r| !r.info.name.starts_with("test."))
        .filter(move |r| r.info.isa != Isa::Scalar || isa == Isa::Scalar)
}

/// As [`select_f32_for`], among the rows of `algorithm` (the portable row of it when no vector row has one).
pub(crate) fn select_f32_algorithm(
    isa: Isa,
    c_out: usize,
    algorithm: Algorithm,
) -> &'static F32Row {
    let padded = |r: &F32Row| c_out.div_ceil(r.info.oc_tile) * r.info.oc_tile;
    dispatchable_f32(isa, algorithm)
        .min_by_key(|r| padded(r))
        .or_else(|| SCALAR_F32.iter().find(|r| r.info.algorithm == algorithm))
        .unwrap_or(&SCALAR_F32[0])
}

/// The int8 row dispatch picks under `isa` (first row, best first, whose ISA `isa` includes).
pub(crate) fn select_u8(isa: Isa) -> &'static U8Row {
    under(U8_LEVELS, isa).next().unwrap_or(&SCALAR_U8[0])
}

/// Runs an f32 row: the single dispatch point for f32. Errors: the row's ISA is not available on this CPU.
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every row of a level needs exactly the level's ISA, the levels run best first (no level includes a
    /// later one's without being it), and the portable level, last, has a row of each algorithm: dispatch
    /// always finds one.
    #[test]
    fn levels_hold_one_isa_best_first_and_end_portable() {
        fn check<R: HasIsa>(levels: &[&[R]]) {
            let isas: Vec<Isa> = levels.iter().map(|l| l[0].isa()).collect();
            for (l, isa) in levels.iter().zip(&isas) {
                assert!(l.iter().all(|r| r.isa() == *isa), "{isa}");
            }
            crate::dispatch::assert_best_first_ending_portable(&isas);
        }
        check(F32_LEVELS);
        check(U8_LEVELS);
        for a in [
            Algorithm::Direct,
            Algorithm::Winograd2x2,
            Algorithm::Winograd4x4,
        ] {
            assert!(SCALAR_F32.iter().any(|r| r.info.algorithm == a), "{a:?}");
        }
    }
}
