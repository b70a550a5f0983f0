//! The kernel table: one [`Ops`] per ISA level, listing what that level's instructions compile: its conv3x3
//! rows (f32 and int8, best first), its copies of the depthwise filter, the heads and the output grid, its
//! double phase rows, and its peak loops. A level's table holds only the kernels that need exactly that level; dispatch under a
//! selected level `s` reads every table whose level `s` includes, best level first, and takes the first entry
//! it finds (for conv3x3, the first row: see [`select_f32_for`] for the one refinement). So the f32 rows,
//! best first, are the tables' rows one after the other, and `avx512vnni` runs the `avx512` table's f32 row
//! and depthwise copy.
//!
//! The plans ([`crate::Conv3x3F32`], [`crate::Conv3x3U8`], [`crate::depthwise()`], [`crate::tanh_heads`],
//! [`crate::fake_quantize`], [`crate::double_phase`]), the tests and, through [`crate::registry`], the benchmarks read these tables,
//! and the `run_*` functions here are the single dispatch point: the one place outside the ISA files where a
//! kernel is called through `unsafe`, each after checking that the CPU has the entry's level.

use std::ops::Range;

use crate::buffer::rows;
use crate::conv3x3::job::{F32Job, F32Out, U8Job, U8Out};
use crate::conv3x3::row::{
    f32_info, u8_info, winograd4_info, winograd_info, Algorithm, F32Row, PackKind, U8Row,
};
#[cfg(target_arch = "x86_64")]
use crate::conv3x3::{f32_avx2, f32_avx512, u8s8_avx2, u8s8_avx512vnni, u8s8_avxvnni};
#[cfg(target_arch = "aarch64")]
use crate::conv3x3::{f32_neon, u8s8_neon, u8s8_neondot, u8s8_neoni8mm};
use crate::conv3x3::{f32_scalar, u8s8_scalar};
use crate::depthwise::body::{self as depthwise, Job as DepthwiseJob, PORTABLE_TILE};
#[cfg(target_arch = "x86_64")]
use crate::double_phase::avx2 as dpm_avx2;
#[cfg(target_arch = "x86_64")]
use crate::double_phase::avx512 as dpm_avx512;
use crate::double_phase::body::{self as dpm, EncodeParams};
use crate::error::KernelError;
use crate::heads::body as heads;
use crate::isa::Isa;
use crate::phasor::body as phasor;
use crate::quant::QuantU8;
use crate::spectral::body as spectral;

/// The depthwise filter on output rows `rows` of one checked plane (`accumulate`: add to `out`).
pub(crate) type DepthwiseFn = unsafe fn(&DepthwiseJob<'_>, Range<usize>, &mut [f32], bool);
/// The heads `(tanh(v) + 1)·scale` of `raw` into `out` (same length), on the output grid when given.
pub(crate) type HeadsFn = unsafe fn(&[f32], &mut [f32], f32, Option<QuantU8>);
/// The output grid (`QuantizeLinear` then `DequantizeLinear`) in place.
pub(crate) type GridFn = unsafe fn(&mut [f32], QuantU8);

/// The spectral helpers ([`crate::spectral`]): the column moves and the complex multiply.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SpectralFns {
    pub gather: unsafe fn(&[f32], [usize; 2], usize, &mut [f32], usize),
    pub scatter: unsafe fn(&[f32], usize, &mut [f32], [usize; 2], usize),
    pub multiply: unsafe fn(&mut [f32], &[f32], bool),
}

/// Pass 1 of the double phase encoding on a row: interleaved `(re, im)` in, `arg H` out; `(max |H|², Σ arg)`.
pub(crate) type DpmAnalyseFn = unsafe fn(&[f32], &mut [f32]) -> (f32, f64);
/// Pass 2 of the double phase encoding on a row: the wrapped double phase in place, codes if asked.
pub(crate) type DpmEncodeFn = unsafe fn(&[f32], &mut [f32], Option<&mut [u8]>, &EncodeParams);
/// Pass 1 on a row held as planes: `re`, `Im H` in place → `arg H`, `|H|` out; `(max |H|², Σ arg H)`.
pub(crate) type DpmAnalysePlanesFn = unsafe fn(&[f32], &mut [f32], &mut [f32]) -> (f32, f64);

/// The heads as interleaved phasors ([`crate::phasor::phasors`]); whether every input was finite.
pub(crate) type PhasorsFn = unsafe fn(&[f32], &[f32], &mut [f32]) -> bool;
/// The same in place ([`crate::phasor::phasors_in_place`]).
pub(crate) type PhasorsInPlaceFn = unsafe fn(&mut [f32], &[f32]) -> bool;

/// The conversion rows of the quantised fills ([`crate::buffer`]'s `rows.rs`): quantise four f32 rows into
/// one interleaved u8 row (`zp`, `offset`, `scale`), dequantise one back (`zp`, `scale`), requantise a u8
/// row (`zo`, `other_scale`, `zp`, `scale`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ConvertFns {
    pub quantize: QuantizeRowFn,
    pub dequantize: DequantizeRowFn,
    pub requantize: RequantizeRowFn,
}

/// [`ConvertFns::quantize`]: `(dst, rows, zp, offset, scale)`.
pub(crate) type QuantizeRowFn = unsafe fn(&mut [u8], [&[f32]; 4], u8, f32, f32);
/// [`ConvertFns::dequantize`]: `(src, rows, zp, scale)`.
pub(crate) type DequantizeRowFn = unsafe fn(&[u8], [&mut [f32]; 4], f32, f32);
/// [`ConvertFns::requantize`]: `(dst, src, zo, other_scale, zp, scale)`.
pub(crate) type RequantizeRowFn = unsafe fn(&mut [u8], &[u8], f32, f32, u8, f32);

/// A peak loop: operations per iteration (a multiply-add counts 2) and the loop, which returns a value to
/// keep its chains alive.
#[derive(Debug)]
pub(crate) struct Peak<T> {
    pub ops_per_iter: f64,
    pub run: unsafe fn(u64) -> T,
}

/// The kernels of one ISA level. `None`: the level has no copy of its own (a lower level's serves).
#[derive(Debug)]
pub(crate) struct Ops {
    /// The level every entry needs.
    pub isa: Isa,
    /// conv3x3 f32 rows, best first.
    pub f32: &'static [F32Row],
    /// conv3x3 int8 rows, best first.
    pub u8: &'static [U8Row],
    /// The depthwise filter ([`crate::depthwise()`]).
    pub depthwise: Option<DepthwiseFn>,
    /// The heads ([`crate::tanh_heads`]).
    pub heads: Option<HeadsFn>,
    /// The output grid ([`crate::fake_quantize`]).
    pub grid: Option<GridFn>,
    /// Pass 1 of the double phase encoding on a row ([`crate::double_phase::analyse_row`]).
    pub dpm_analyse: Option<DpmAnalyseFn>,
    /// Pass 2 of the double phase encoding on a row ([`crate::double_phase::encode_row`]).
    pub dpm_encode: Option<DpmEncodeFn>,
    /// Pass 1 on a row held as planes ([`crate::double_phase::analyse_planes_row`]).
    pub dpm_analyse_planes: Option<DpmAnalysePlanesFn>,
    /// Pass 2 on a row's magnitudes ([`crate::double_phase::encode_abs_row`]).
    pub dpm_encode_abs: Option<DpmEncodeFn>,
    /// The heads as phasors ([`crate::phasor::phasors`]).
    pub phasors: Option<PhasorsFn>,
    /// The heads as phasors in place ([`crate::phasor::phasors_in_place`]).
    pub phasors_in_place: Option<PhasorsInPlaceFn>,
    /// The quantised fills' conversion rows ([`ConvertFns`]).
    pub convert: Option<ConvertFns>,
    /// The 2-D FFT filter's column moves and complex multiply ([`SpectralFns`]).
    pub spectral: Option<SpectralFns>,
    /// The f32 FMA peak ([`crate::peak::f32_fma_gflops`]).
    pub peak_f32: Option<Peak<f32>>,
    /// The int8 dot-product peak ([`crate::peak::int8_dot_gops`]).
    pub peak_u8: Option<Peak<i32>>,
}

/// The portable level: safe code, any CPU; every kind of kernel has an entry here, so dispatch always finds
/// one. The depthwise, heads, grid and double phase entries are the portable bodies themselves (SSE2 / NEON).
const SCALAR: Ops = Ops {
    isa: Isa::Scalar,
    f32: &[
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
    ],
    u8: &[U8Row {
        info: u8_info(
            "conv3x3.u8s8.8x8.scalar",
            Isa::Scalar,
            u8s8_scalar::G,
            u8s8_scalar::P,
        ),
        pack: PackKind::I8,
        run: u8s8_scalar::conv,
    }],
    depthwise: Some(depthwise::rows_body::<PORTABLE_TILE>),
    heads: Some(heads::heads_body),
    grid: Some(heads::grid_body),
    dpm_analyse: Some(dpm::analyse_body),
    dpm_encode: Some(dpm::encode_body),
    dpm_analyse_planes: Some(dpm::analyse_planes_body),
    dpm_encode_abs: Some(dpm::encode_abs_body),
    phasors: Some(phasor::polar_body),
    phasors_in_place: Some(phasor::polar_in_place_body),
    convert: Some(ConvertFns {
        quantize: rows::quantize_body,
        dequantize: rows::dequantize_body,
        requantize: rows::requantize_body,
    }),
    spectral: Some(SpectralFns {
        gather: spectral::gather_body,
        scatter: spectral::scatter_body,
        multiply: spectral::multiply_body,
    }),
    peak_f32: Some(Peak {
        ops_per_iter: 16.0 * 2.0,
        run: f32_scalar::peak,
    }),
    peak_u8: Some(Peak {
        ops_per_iter: 16.0 * 2.0,
        run: u8s8_scalar::peak,
    }),
};

/// x86-64 levels, best first.
#[cfg(target_arch = "x86_64")]
static OPS: [Ops; 5] = [
    Ops {
        isa: Isa::Avx512Vnni,
        f32: &[],
        u8: &[U8Row {
            info: u8_info("conv3x3.u8s8.8x3.avx512vnni", Isa::Avx512Vnni, 8, 48),
            pack: PackKind::I8,
            run: u8s8_avx512vnni::conv_avx512vnni,
        }],
        depthwise: None,
        heads: None,
        grid: None,
        dpm_analyse: None,
        dpm_encode: None,
        dpm_analyse_planes: None,
        dpm_encode_abs: None,
        phasors: None,
        phasors_in_place: None,
        convert: None,
        spectral: None,
        peak_f32: None,
        peak_u8: Some(Peak {
            ops_per_iter: 24.0 * 64.0 * 2.0,
            run: u8s8_avx512vnni::peak_avx512vnni,
        }),
    },
    Ops {
        isa: Isa::Avx512,
        f32: &[
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
        ],
        u8: &[],
        depthwise: Some(depthwise::x86::rows_avx512),
        heads: Some(heads::x86::heads_avx512),
        grid: Some(heads::x86::grid_avx512),
        dpm_analyse: Some(dpm_avx512::analyse_avx512),
        dpm_encode: Some(dpm_avx512::encode_avx512),
        dpm_analyse_planes: Some(dpm_avx512::analyse_planes_avx512),
        dpm_encode_abs: Some(dpm_avx512::encode_abs_avx512),
        phasors: Some(phasor::x86::polar_avx512),
        phasors_in_place: Some(phasor::x86::polar_in_place_avx512),
        convert: Some(ConvertFns {
            quantize: rows::x86::quantize_avx512,
            dequantize: rows::x86::dequantize_avx512,
            requantize: rows::x86::requantize_avx512,
        }),
        spectral: Some(SpectralFns {
            gather: spectral::x86::gather_avx512,
            scatter: spectral::x86::scatter_avx512,
            multiply: spectral::x86::multiply_avx512,
        }),
        peak_f32: Some(Peak {
            ops_per_iter: 24.0 * 16.0 * 2.0,
            run: f32_avx512::peak,
        }),
        peak_u8: None,
    },
    Ops {
        isa: Isa::AvxVnni,
        f32: &[],
        u8: &[U8Row {
            info: u8_info("conv3x3.u8s8.4x2.avxvnni", Isa::AvxVnni, 4, 16),
            pack: PackKind::I8,
            run: u8s8_avxvnni::conv_avxvnni,
        }],
        depthwise: None,
        heads: None,
        grid: None,
        dpm_analyse: None,
        dpm_encode: None,
        dpm_analyse_planes: None,
        dpm_encode_abs: None,
        phasors: None,
        phasors_in_place: None,
        convert: None,
        spectral: None,
        peak_f32: None,
        peak_u8: Some(Peak {
            ops_per_iter: 12.0 * 32.0 * 2.0,
            run: u8s8_avxvnni::peak_avxvnni,
        }),
    },
    Ops {
        isa: Isa::Avx2Fma,
        f32: &[
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
        ],
        u8: &[
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
        ],
        depthwise: Some(depthwise::x86::rows_avx2),
        heads: Some(heads::x86::heads_avx2),
        grid: Some(heads::x86::grid_avx2),
        dpm_analyse: Some(dpm_avx2::analyse_avx2),
        dpm_encode: Some(dpm_avx2::encode_avx2),
        dpm_analyse_planes: Some(dpm_avx2::analyse_planes_avx2),
        dpm_encode_abs: Some(dpm_avx2::encode_abs_avx2),
        phasors: Some(phasor::x86::polar_avx2),
        phasors_in_place: Some(phasor::x86::polar_in_place_avx2),
        convert: Some(ConvertFns {
            quantize: rows::x86::quantize_avx2,
            dequantize: rows::x86::dequantize_avx2,
            requantize: rows::x86::requantize_avx2,
        }),
        spectral: None,
        peak_f32: Some(Peak {
            ops_per_iter: 12.0 * 8.0 * 2.0,
            run: f32_avx2::peak,
        }),
        peak_u8: Some(Peak {
            ops_per_iter: 12.0 * 16.0 * 2.0,
            run: u8s8_avx2::peak_avx2,
        }),
    },
    SCALAR,
];

/// aarch64 levels, best first. NEON is the aarch64 baseline: the portable bodies of the depthwise filter,
/// the heads, the grid and the double phase rows are compiled with it already.
#[cfg(target_arch = "aarch64")]
static OPS: [Ops; 4] = [
    Ops {
        isa: Isa::NeonI8mm,
        f32: &[],
        u8: &[U8Row {
            info: u8_info("conv3x3.u8s8.8x3.neoni8mm", Isa::NeonI8mm, 8, 12),
            pack: PackKind::I8,
            run: u8s8_neoni8mm::conv_i8mm,
        }],
        depthwise: None,
        heads: None,
        grid: None,
        dpm_analyse: None,
        dpm_encode: None,
        dpm_analyse_planes: None,
        dpm_encode_abs: None,
        phasors: None,
        phasors_in_place: None,
        convert: None,
        spectral: None,
        peak_f32: None,
        peak_u8: Some(Peak {
            ops_per_iter: 24.0 * 16.0 * 2.0,
            run: u8s8_neoni8mm::peak_i8mm,
        }),
    },
    Ops {
        isa: Isa::NeonDot,
        f32: &[],
        u8: &[U8Row {
            info: u8_info("conv3x3.u8s8.8x3.neondot", Isa::NeonDot, 8, 12),
            pack: PackKind::I8Xor128,
            run: u8s8_neondot::conv_dot,
        }],
        depthwise: None,
        heads: None,
        grid: None,
        dpm_analyse: None,
        dpm_encode: None,
        dpm_analyse_planes: None,
        dpm_encode_abs: None,
        phasors: None,
        phasors_in_place: None,
        convert: None,
        spectral: None,
        peak_f32: None,
        peak_u8: Some(Peak {
            ops_per_iter: 24.0 * 16.0 * 2.0,
            run: u8s8_neondot::peak_dot,
        }),
    },
    Ops {
        isa: Isa::Neon,
        f32: &[
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
        ],
        u8: &[U8Row {
            info: u8_info("conv3x3.u8s8.4x1.neon", Isa::Neon, 4, 4),
            pack: PackKind::I16,
            run: u8s8_neon::conv_wide,
        }],
        depthwise: None,
        heads: None,
        grid: None,
        dpm_analyse: None,
        dpm_encode: None,
        dpm_analyse_planes: None,
        dpm_encode_abs: None,
        phasors: None,
        phasors_in_place: None,
        convert: None,
        spectral: None,
        peak_f32: Some(Peak {
            ops_per_iter: 24.0 * 4.0 * 2.0,
            run: f32_neon::peak,
        }),
        peak_u8: Some(Peak {
            ops_per_iter: 24.0 * 4.0 * 2.0,
            run: u8s8_neon::peak_wide,
        }),
    },
    SCALAR,
];

/// Other targets: the portable level only.
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
static OPS: [Ops; 1] = [SCALAR];

/// Every table compiled for this target (its CPU may lack some levels), best level first.
pub(crate) fn tables() -> &'static [Ops] {
    &OPS
}

/// The tables dispatch reads under `isa`: those whose level `isa` includes, best first.
fn under(isa: Isa) -> impl Iterator<Item = &'static Ops> {
    OPS.iter().filter(move |t| isa.includes(t.isa))
}

/// The portable table (the last).
fn portable() -> &'static Ops {
    &OPS[OPS.len() - 1]
}

/// Every f32 row compiled for this target, best first.
pub(crate) fn f32_rows() -> impl Iterator<Item = &'static F32Row> {
    OPS.iter().flat_map(|t| t.f32)
}

/// Every int8 row compiled for this target, best first.
pub(crate) fn u8_rows() -> impl Iterator<Item = &'static U8Row> {
    OPS.iter().flat_map(|t| t.u8)
}

/// The f32 row dispatch picks under `isa`: the first row (best first) whose ISA `isa` includes. Does not
/// check that `isa` is available (plans do).
pub(crate) fn select_f32(isa: Isa) -> &'static F32Row {
    under(isa)
        .flat_map(|t| t.f32)
        .find(|r| r.info.algorithm == Algorithm::Direct)
        .unwrap_or(&portable().f32[0])
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
    under(isa)
        .flat_map(|t| t.f32)
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
        .or_else(|| {
            portable()
                .f32
                .iter()
                .find(|r| r.info.algorithm == algorithm)
        })
        .unwrap_or(&portable().f32[0])
}

/// The int8 row dispatch picks under `isa` (first row, best first, whose ISA `isa` includes).
pub(crate) fn select_u8(isa: Isa) -> &'static U8Row {
    under(isa)
        .flat_map(|t| t.u8)
        .next()
        .unwrap_or(&portable().u8[0])
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

/// The entry `pick` chooses from the best table under `isa` that has one. Errors: `isa` not available on
/// this CPU ([`KernelError::Isa`]).
fn entry<F>(isa: Isa, pick: impl Fn(&'static Ops) -> Option<F>) -> Result<F, KernelError> {
    if !isa.is_available() {
        return Err(KernelError::Isa {
            name: isa.name().into(),
            why: "not available on this CPU",
        });
    }
    under(isa).find_map(pick).ok_or_else(|| KernelError::Isa {
        name: isa.name().into(),
        why: "no kernel of this kind compiled for it",
    })
}

/// The depthwise filter on `rows` of one checked plane under `isa`. Errors: `isa` not available.
pub(crate) fn run_depthwise(
    isa: Isa,
    job: &DepthwiseJob<'_>,
    rows: Range<usize>,
    out: &mut [f32],
    accumulate: bool,
) -> Result<(), KernelError> {
    let run = entry(isa, |t| t.depthwise)?;
    // SAFETY: `entry` returned the entry of a level that `isa` includes, and `isa` is available on this CPU;
    // the safe API checked the plane, the kernel and the rows.
    unsafe { run(job, rows, out, accumulate) };
    Ok(())
}

/// One interleaved u8 row of a channel group quantised from its four f32 rows under `isa`
/// ([`ConvertFns::quantize`]; the pixels all slices hold). Errors: `isa` not available.
pub(crate) fn run_quantize_row(
    isa: Isa,
    dst: &mut [u8],
    rows: [&[f32]; 4],
    zp: u8,
    offset: f32,
    scale: f32,
) -> Result<(), KernelError> {
    let run = entry(isa, |t| t.convert.map(|c| c.quantize))?;
    // SAFETY: `entry` returned the entry of a level that `isa` includes, and `isa` is available on this CPU;
    // the body is safe code on any lengths.
    unsafe { run(dst, rows, zp, offset, scale) };
    Ok(())
}

/// One interleaved u8 row dequantised into its group's four f32 rows under `isa` ([`ConvertFns::dequantize`]).
/// Errors: `isa` not available.
pub(crate) fn run_dequantize_row(
    isa: Isa,
    src: &[u8],
    rows: [&mut [f32]; 4],
    zp: f32,
    scale: f32,
) -> Result<(), KernelError> {
    let run = entry(isa, |t| t.convert.map(|c| c.dequantize))?;
    // SAFETY: as in `run_quantize_row`.
    unsafe { run(src, rows, zp, scale) };
    Ok(())
}

/// A u8 row requantised under `isa` ([`ConvertFns::requantize`]). Errors: `isa` not available.
pub(crate) fn run_requantize_row(
    isa: Isa,
    dst: &mut [u8],
    src: &[u8],
    (zo, other_scale): (f32, f32),
    (zp, scale): (u8, f32),
) -> Result<(), KernelError> {
    let run = entry(isa, |t| t.convert.map(|c| c.requantize))?;
    // SAFETY: as in `run_quantize_row`.
    unsafe { run(dst, src, zo, other_scale, zp, scale) };
    Ok(())
}

/// The heads under `isa` (lengths checked by the caller). Errors: `isa` not available.
pub(crate) fn run_heads(
    isa: Isa,
    raw: &[f32],
    out: &mut [f32],
    scale: f32,
    grid: Option<QuantU8>,
) -> Result<(), KernelError> {
    let run = entry(isa, |t| t.heads)?;
    // SAFETY: `entry` returned the entry of a level that `isa` includes, and `isa` is available on this CPU.
    unsafe { run(raw, out, scale, grid) };
    Ok(())
}

/// [`crate::spectral::gather_columns`] under `isa` (checked arguments). Errors: `isa` not available.
pub(crate) fn run_gather_columns(
    isa: Isa,
    field: &[f32],
    hw: [usize; 2],
    x0: usize,
    block: &mut [f32],
    bw: usize,
) -> Result<(), KernelError> {
    let run = entry(isa, |t| t.spectral)?.gather;
    // SAFETY: `entry` returned the entry of a level that `isa` includes, and `isa` is available on this CPU;
    // the caller checked the arguments.
    unsafe { run(field, hw, x0, block, bw) };
    Ok(())
}

/// [`crate::spectral::scatter_columns`] under `isa` (checked arguments). Errors: `isa` not available.
pub(crate) fn run_scatter_columns(
    isa: Isa,
    block: &[f32],
    bw: usize,
    field: &mut [f32],
    hw: [usize; 2],
    x0: usize,
) -> Result<(), KernelError> {
    let run = entry(isa, |t| t.spectral)?.scatter;
    // SAFETY: as `run_gather_columns`.
    unsafe { run(block, bw, field, hw, x0) };
    Ok(())
}

/// [`crate::spectral::multiply`] under `isa` (checked arguments). Errors: `isa` not available.
pub(crate) fn run_complex_multiply(
    isa: Isa,
    values: &mut [f32],
    by: &[f32],
    mirrored: bool,
) -> Result<(), KernelError> {
    let run = entry(isa, |t| t.spectral)?.multiply;
    // SAFETY: as `run_gather_columns`.
    unsafe { run(values, by, mirrored) };
    Ok(())
}

/// The output grid under `isa`. Errors: `isa` not available.
pub(crate) fn run_grid(isa: Isa, values: &mut [f32], grid: QuantU8) -> Result<(), KernelError> {
    let run = entry(isa, |t| t.grid)?;
    // SAFETY: `entry` returned the entry of a level that `isa` includes, and `isa` is available on this CPU.
    unsafe { run(values, grid) };
    Ok(())
}

/// Pass 1 of the double phase encoding on one checked row under `isa`. Errors: `isa` not available.
pub(crate) fn run_dpm_analyse(
    isa: Isa,
    field: &[f32],
    phase: &mut [f32],
) -> Result<(f32, f64), KernelError> {
    let run = entry(isa, |t| t.dpm_analyse)?;
    // SAFETY: `entry` returned the entry of a level that `isa` includes, and `isa` is available on this CPU;
    // the safe API checked the lengths.
    Ok(unsafe { run(field, phase) })
}

/// Pass 2 of the double phase encoding on one checked row under `isa`: `field` interleaved pairs, or with
/// `abs` the magnitudes. Errors: `isa` not available.
pub(crate) fn run_dpm_encode(
    isa: Isa,
    abs: bool,
    field: &[f32],
    phase: &mut [f32],
    codes: Option<&mut [u8]>,
    params: &EncodeParams,
) -> Result<(), KernelError> {
    let run = if abs {
        entry(isa, |t| t.dpm_encode_abs)?
    } else {
        entry(isa, |t| t.dpm_encode)?
    };
    // SAFETY: `entry` returned the entry of a level that `isa` includes, and `isa` is available on this CPU;
    // the safe API checked the lengths.
    unsafe { run(field, phase, codes, params) };
    Ok(())
}

/// Pass 1 of the double phase encoding on one checked row held as planes under `isa`. Errors: `isa` not
/// available.
pub(crate) fn run_dpm_analyse_planes(
    isa: Isa,
    re: &[f32],
    im_arg: &mut [f32],
    abs: &mut [f32],
) -> Result<(f32, f64), KernelError> {
    let run = entry(isa, |t| t.dpm_analyse_planes)?;
    // SAFETY: `entry` returned the entry of a level that `isa` includes, and `isa` is available on this CPU;
    // the safe API checked the lengths.
    Ok(unsafe { run(re, im_arg, abs) })
}

/// The heads as phasors under `isa` (lengths checked by the caller). Errors: `isa` not available.
pub(crate) fn run_phasors(
    isa: Isa,
    amplitude: &[f32],
    phase: &[f32],
    out: &mut [f32],
) -> Result<bool, KernelError> {
    let run = entry(isa, |t| t.phasors)?;
    // SAFETY: `entry` returned the entry of a level that `isa` includes, and `isa` is available on this CPU.
    Ok(unsafe { run(amplitude, phase, out) })
}

/// The heads as phasors in place under `isa` (lengths checked by the caller). Errors: `isa` not available.
pub(crate) fn run_phasors_in_place(
    isa: Isa,
    buf: &mut [f32],
    phase: &[f32],
) -> Result<bool, KernelError> {
    let run = entry(isa, |t| t.phasors_in_place)?;
    // SAFETY: `entry` returned the entry of a level that `isa` includes, and `isa` is available on this CPU.
    Ok(unsafe { run(buf, phase) })
}

/// Runs the f32 FMA peak loop of `isa` (its widest FMA) for `iters` iterations; returns the FLOPs done and a
/// value to keep the loop alive. Errors: `isa` not available.
pub(crate) fn run_peak_f32(isa: Isa, iters: u64) -> Result<(f64, f32), KernelError> {
    let peak = entry(isa, |t| t.peak_f32.as_ref())?;
    // SAFETY: `entry` returned the loop of a level that `isa` includes, and `isa` is available on this CPU.
    let sink = unsafe { (peak.run)(iters) };
    Ok((iters as f64 * peak.ops_per_iter, sink))
}

/// Runs the int8 dot-product peak loop of `isa` (its best int8 instruction) for `iters` iterations;
/// returns the integer operations done (a multiply-add counts 2) and a value to keep the loop alive.
/// Errors: `isa` not available.
pub(crate) fn run_peak_u8(isa: Isa, iters: u64) -> Result<(f64, i32), KernelError> {
    let peak = entry(isa, |t| t.peak_u8.as_ref())?;
    // SAFETY: `entry` returned the loop of a level that `isa` includes, and `isa` is available on this CPU.
    let sink = unsafe { (peak.run)(iters) };
    Ok((iters as f64 * peak.ops_per_iter, sink))
}

/// Tests: the levels whose table has an entry that `has` looks for, that this CPU has (a `SKIPPED` line for
/// each it lacks), as `(name, level)`, best first.
#[cfg(test)]
pub(crate) fn available_paths(module: &str, has: impl Fn(&Ops) -> bool) -> Vec<(String, Isa)> {
    OPS.iter()
        .filter(|t| has(t))
        .map(|t| t.isa)
        .filter(|i| {
            let ok = i.is_available();
            if !ok {
                println!("SKIPPED {module}.{i}: this CPU lacks {i}");
            }
            ok
        })
        .map(|i| (format!("{module}.{i}"), i))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every entry of a table needs exactly the table's level, the levels run best first within each
    /// architecture (no table includes a later one's level without being it), and the portable table,
    /// last, has an entry of every kind: dispatch always finds one.
    #[test]
    fn tables_hold_their_own_level_best_first_and_end_portable() {
        for t in tables() {
            assert!(t.f32.iter().all(|r| r.info.isa == t.isa), "{}", t.isa);
            assert!(t.u8.iter().all(|r| r.info.isa == t.isa), "{}", t.isa);
        }
        for (i, a) in tables().iter().enumerate() {
            for b in &tables()[..i] {
                assert!(!a.isa.includes(b.isa), "{} listed after {}", a.isa, b.isa);
            }
        }
        let p = portable();
        assert_eq!(p.isa, Isa::Scalar);
        assert!(!p.f32.is_empty() && !p.u8.is_empty());
        assert!(p.depthwise.is_some() && p.heads.is_some() && p.grid.is_some());
        assert!(p.dpm_analyse.is_some() && p.dpm_encode.is_some());
        assert!(p.dpm_analyse_planes.is_some() && p.dpm_encode_abs.is_some());
        assert!(p.peak_f32.is_some() && p.peak_u8.is_some());
    }

    #[test]
    fn every_available_level_has_peaks() {
        for isa in Isa::available() {
            assert!(run_peak_f32(isa, 4).is_ok(), "{isa}");
            assert!(run_peak_u8(isa, 4).is_ok(), "{isa}");
        }
    }
}
