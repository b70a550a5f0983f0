//! The conversion rows of the quantised fills (`quant_fill.rs`): one interleaved u8 row of a channel group
//! (`4·W` bytes, pixel `x`'s four channels at `4x..4x + 4`) from or to the group's four f32 rows, and a u8
//! row requantised to another grid. Portable bodies on whole 4-byte pixels, compiled as they are (SSE2 on
//! x86-64, NEON on aarch64) and in `#[target_feature]` copies (AVX2, AVX-512F/BW: [`x86`]), dispatched through
//! [`PATHS`] under the process's level ([`level`]). Rust never contracts `a·b + c` into an
//! FMA and never reorders float arithmetic, so every copy computes bit-identical values (tested). At 1080p
//! the SSE2 copies were 4.6 % of an int8 frame's CPU time (the mixed-precision pre-filter's `s_1` and
//! `s_{N−1}`, the hologram CNN's input and concat).

use crate::dispatch::{self, Path};
use crate::error::KernelError;
use crate::isa::Isa;
use crate::quant::quantize;

/// One level's conversion rows: quantise four f32 rows into one interleaved u8 row (`dst, rows, zp,
/// offset, scale`), dequantise one back (`src, rows, zp, scale`), requantise a u8 row (`dst, src, zo,
/// other_scale, zp, scale`).
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

/// The conversion rows' paths, best first: the portable bodies' `#[target_feature]` copies, then the
/// bodies themselves (SSE2 / NEON).
pub(crate) static PATHS: &[Path<ConvertFns>] = &[
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx512,
        run: ConvertFns {
            quantize: x86::quantize_avx512,
            dequantize: x86::dequantize_avx512,
            requantize: x86::requantize_avx512,
        },
    },
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx2Fma,
        run: ConvertFns {
            quantize: x86::quantize_avx2,
            dequantize: x86::dequantize_avx2,
            requantize: x86::requantize_avx2,
        },
    },
    Path {
        isa: Isa::Scalar,
        run: ConvertFns {
            quantize: quantize_body,
            dequantize: dequantize_body,
            requantize: requantize_body,
        },
    },
];

/// One interleaved u8 row of a channel group quantised from its four f32 rows under `isa`
/// ([`ConvertFns::quantize`]; the pixels all slices hold). Errors: `isa` not available.
pub(crate) fn quantize_row(
    isa: Isa,
    dst: &mut [u8],
    rows: [&[f32]; 4],
    zp: u8,
    offset: f32,
    scale: f32,
) -> Result<(), KernelError> {
    let run = dispatch::pick(PATHS, isa)?.quantize;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the body is safe code on any lengths.
    unsafe { run(dst, rows, zp, offset, scale) };
    Ok(())
}

/// One interleaved u8 row dequantised into its group's four f32 rows under `isa`
/// ([`ConvertFns::dequantize`]). Errors: `isa` not available.
pub(crate) fn dequantize_row(
    isa: Isa,
    src: &[u8],
    rows: [&mut [f32]; 4],
    zp: f32,
    scale: f32,
) -> Result<(), KernelError> {
    let run = dispatch::pick(PATHS, isa)?.dequantize;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the body is safe code on any lengths.
    unsafe { run(src, rows, zp, scale) };
    Ok(())
}

/// A u8 row requantised under `isa` ([`ConvertFns::requantize`]). Errors: `isa` not available.
pub(crate) fn requantize_row(
    isa: Isa,
    dst: &mut [u8],
    src: &[u8],
    (zo, other_scale): (f32, f32),
    (zp, scale): (u8, f32),
) -> Result<(), KernelError> {
    let run = dispatch::pick(PATHS, isa)?.requantize;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the body is safe code on any lengths.
    unsafe { run(dst, src, zo, other_scale, zp, scale) };
    Ok(())
}

/// The level the conversions run under: this CPU's best ([`Isa::detect`]). The copies compute the same
/// values, so the level changes the speed only.
pub(crate) fn level() -> Isa {
    Isa::detect()
}

/// `dst[4x + k] = quantize((rows[k][x] + offset) / scale, zp)` (ONNX `QuantizeLinear` of `x + offset`), for
/// the pixels all five slices hold.
#[inline(always)]
pub(crate) fn quantize_body(dst: &mut [u8], rows: [&[f32]; 4], zp: u8, offset: f32, scale: f32) {
    let [r0, r1, r2, r3] = rows;
    let pixels = dst.chunks_exact_mut(4).zip(r0).zip(r1).zip(r2).zip(r3);
    let q = |v: f32| quantize((v + offset) / scale, zp);
    for ((((d, &a), &b), &c), &e) in pixels {
        d.copy_from_slice(&[q(a), q(b), q(c), q(e)]);
    }
}

/// The inverse layout: `rows[k][x] = (src[4x + k] − zp)·scale` (ONNX `DequantizeLinear`), for the pixels all
/// five slices hold.
#[inline(always)]
pub(crate) fn dequantize_body(src: &[u8], rows: [&mut [f32]; 4], zp: f32, scale: f32) {
    let [r0, r1, r2, r3] = rows;
    let n = (src.len() / 4)
        .min(r0.len())
        .min(r1.len())
        .min(r2.len())
        .min(r3.len());
    let (src, r0, r1, r2, r3) = (
        &src[..4 * n],
        &mut r0[..n],
        &mut r1[..n],
        &mut r2[..n],
        &mut r3[..n],
    );
    for x in 0..n {
        // The pixel as one 32-bit word, its bytes shifted out.
        let p = u32::from_le_bytes([src[4 * x], src[4 * x + 1], src[4 * x + 2], src[4 * x + 3]]);
        let q = |k: u32| ((p >> (8 * k)) & 0xff) as i32 as f32;
        r0[x] = (q(0) - zp) * scale;
        r1[x] = (q(1) - zp) * scale;
        r2[x] = (q(2) - zp) * scale;
        r3[x] = (q(3) - zp) * scale;
    }
}

/// `dst[i] = quantize((src[i] − zo)·other_scale / scale, zp)`: a u8 row moved from the grid `(other_scale,
/// zo)` to `(scale, zp)`, for the bytes both slices hold.
#[inline(always)]
pub(crate) fn requantize_body(
    dst: &mut [u8],
    src: &[u8],
    zo: f32,
    other_scale: f32,
    zp: u8,
    scale: f32,
) {
    for (d, &q) in dst.iter_mut().zip(src) {
        let real = (q as f32 - zo) * other_scale;
        *d = quantize(real / scale, zp);
    }
}

/// The bodies compiled for AVX2 and for AVX-512F/BW (16 f32 or 64 u8 lanes a register).
#[cfg(target_arch = "x86_64")]
pub(crate) mod x86 {
    use super::{dequantize_body, quantize_body, requantize_body};

    /// The three bodies' `#[target_feature]` copies for one level: `copies!("features", "the level";
    /// quantize, dequantize, requantize)` (their names).
    macro_rules! copies {
        ($features:literal, $level:literal; $quantize:ident, $dequantize:ident, $requantize:ident) => {
            #[doc = concat!("[`quantize_body`] compiled for ", $level, ".")]
            #[doc = ""]
            #[doc = "# Safety"]
            #[doc = concat!("The CPU has ", $level, ".")]
            #[target_feature(enable = $features)]
            pub(crate) unsafe fn $quantize(d: &mut [u8], r: [&[f32]; 4], zp: u8, o: f32, s: f32) {
                quantize_body(d, r, zp, o, s)
            }
            #[doc = concat!("[`dequantize_body`] compiled for ", $level, ".")]
            #[doc = ""]
            #[doc = "# Safety"]
            #[doc = concat!("The CPU has ", $level, ".")]
            #[target_feature(enable = $features)]
            pub(crate) unsafe fn $dequantize(src: &[u8], r: [&mut [f32]; 4], zp: f32, s: f32) {
                dequantize_body(src, r, zp, s)
            }
            #[doc = concat!("[`requantize_body`] compiled for ", $level, ".")]
            #[doc = ""]
            #[doc = "# Safety"]
            #[doc = concat!("The CPU has ", $level, ".")]
            #[target_feature(enable = $features)]
            pub(crate) unsafe fn $requantize(
                d: &mut [u8],
                src: &[u8],
                zo: f32,
                so: f32,
                zp: u8,
                s: f32,
            ) {
                requantize_body(d, src, zo, so, zp, s)
            }
        };
    }

    copies!("avx2", "AVX2"; quantize_avx2, dequantize_avx2, requantize_avx2);
    copies!(
        "avx512f,avx512bw", "AVX-512F and AVX-512BW";
        quantize_avx512, dequantize_avx512, requantize_avx512
    );
}
