//! The hologram CNN's output heads and the int8 output grid, vectorised.
//!
//! The network's last convolution gives a raw value `v` per pixel and channel; the hologram CNN's heads map
//! it to amplitude or phase as `(tanh(v) + 1)·scale` (the model contract: amplitude in `[0, 2a]`, phase in
//! `[0, 2p]` radians). libm's `tanhf` is a function call per value that the compiler cannot vectorise, and
//! it was a fifth of an int8 frame of the 8-layer CNN (perf, 384², one thread). Here the heads are computed
//! as the equivalent logistic form
//!
//! ```text
//! (tanh(v) + 1)·scale = 2·scale / (1 + exp(−2v))
//! ```
//!
//! which keeps its relative accuracy where `tanh(v) + 1` is tiny (`v` very negative: the subtraction in
//! `tanh(v) + 1` would cancel), with a branch-free `exp` that the compiler vectorises: Cody–Waite range
//! reduction `t = n·ln 2 + r`, `|r| ≤ ln 2 / 2`, `n` rounded with the `1.5·2²³` trick, a degree-6
//! polynomial for `eʳ` (the Cephes `expf` coefficients, ≈ 1 ulp), and `2ⁿ` built from its exponent bits.
//! Measured against `f64` (`tests`): relative error ≤ 4·2⁻²⁴ over the whole range.
//!
//! The same code runs on every path, compiled once portable (SSE2 / NEON: 4 lanes) and, on x86-64, once
//! inside `#[target_feature(enable = "avx2")]` and `"avx512f"` functions (8 and 16 lanes). Rust never
//! contracts `a·b + c` into an FMA on its own, so every path gives the bit-identical result (tested).
//!
//! [`fake_quantize`] is ONNX `QuantizeLinear` then `DequantizeLinear` on a u8 grid: the int8 files round the
//! last convolution's output to a grid before the heads (or the pre-filter's sum).

pub(crate) mod body;

use crate::dispatch::{self, Path};
use crate::error::KernelError;
use crate::isa::Isa;
use crate::quant::{check_scale, QuantU8};

/// One level's heads and output grid.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeadsFns {
    /// The heads `(tanh(v) + 1)·scale` of `raw` into `out` (same length), on the output grid when given.
    pub heads: unsafe fn(&[f32], &mut [f32], f32, Option<QuantU8>),
    /// The output grid (`QuantizeLinear` then `DequantizeLinear`) in place.
    pub grid: unsafe fn(&mut [f32], QuantU8),
}

/// The heads' paths, best first: the portable body's `#[target_feature]` copies, then the body itself
/// (SSE2 / NEON).
pub(crate) static PATHS: &[Path<HeadsFns>] = &[
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx512,
        run: HeadsFns {
            heads: body::x86::heads_avx512,
            grid: body::x86::grid_avx512,
        },
    },
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx2Fma,
        run: HeadsFns {
            heads: body::x86::heads_avx2,
            grid: body::x86::grid_avx2,
        },
    },
    Path {
        isa: Isa::Scalar,
        run: HeadsFns {
            heads: body::heads_body,
            grid: body::grid_body,
        },
    },
];

fn check(raw: &[f32], out: &[f32]) -> Result<(), KernelError> {
    if raw.len() != out.len() {
        return Err(KernelError::Length {
            what: "heads output",
            expected: raw.len(),
            got: out.len(),
        });
    }
    Ok(())
}

fn check_grid(g: Option<QuantU8>) -> Result<(), KernelError> {
    match g {
        Some(g) => check_scale("output grid scale", g.scale),
        None => Ok(()),
    }
}

/// The hologram CNN's heads: `out[i] = (tanh(q(raw[i])) + 1)·scale`, where `q` is the int8 file's output
/// grid ([`fake_quantize`]'s rounding) when `grid` is given and the identity otherwise. `scale` is the
/// head's `a` (amplitude) or `p` (phase, radians) of the model contract; `raw` and `out` are any slices of
/// one length (e.g. one row `[W]` of one channel). Computed as `2·scale / (1 + exp(−2v))` on the widest
/// vector path `isa` allows (the module docs give the method); every path is bit-identical, and within
/// 4·2⁻²⁴ relative of the exact value. Errors: lengths differ ([`KernelError::Length`]), `isa` not
/// available ([`KernelError::Isa`]), a grid scale not finite and positive ([`KernelError::Parameter`]).
pub fn tanh_heads(
    raw: &[f32],
    out: &mut [f32],
    scale: f32,
    grid: Option<QuantU8>,
    isa: Isa,
) -> Result<(), KernelError> {
    check(raw, out)?;
    check_grid(grid)?;
    let run = dispatch::pick(PATHS, isa)?.heads;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the lengths are checked above.
    unsafe { run(raw, out, scale, grid) };
    Ok(())
}

/// ONNX `QuantizeLinear` then `DequantizeLinear` on the u8 grid `grid`, in place: `v ← (clamp(
/// round_ties_even(v / s) + zp, 0, 255) − zp)·s` (the int8 pre-filter's last convolution output before the
/// base filter is added, and the input the base filter reads). Bit-identical on every path. Errors:
/// `isa` not available ([`KernelError::Isa`]), a grid scale not finite and positive
/// ([`KernelError::Parameter`]).
pub fn fake_quantize(values: &mut [f32], grid: QuantU8, isa: Isa) -> Result<(), KernelError> {
    check_grid(Some(grid))?;
    let run = dispatch::pick(PATHS, isa)?.grid;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the body takes any length.
    unsafe { run(values, grid) };
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quant::quantize_f32;

    /// Values over the heads' whole range, with the awkward ones: 0, ±tiny, where tanh + 1 underflows, NaN's
    /// neighbours (±∞), and the grid's rounding ties.
    fn values() -> Vec<f32> {
        let mut v: Vec<f32> = (-4000..=4000).map(|i| i as f32 * 0.005).collect();
        v.extend([
            0.0,
            -0.0,
            1e-30,
            -1e-30,
            1e-7,
            -1e-7,
            30.0,
            -30.0,
            43.0,
            -43.0,
            44.5,
            -44.5,
            60.0,
            -60.0,
            1e10,
            -1e10,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ]);
        // Exact ties of a grid of step 0.25: k·0.25 + 0.125.
        v.extend((-50..50).map(|k| k as f32 * 0.25 + 0.125));
        let mut s = 0x2545_F491_4F6C_DD1Du64;
        v.extend((0..5000).map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 40.0
        }));
        v
    }

    fn available_paths() -> Vec<(String, Isa)> {
        crate::dispatch::available_paths("heads", PATHS)
    }

    #[test]
    fn heads_are_within_two_ulp_of_the_exact_value_on_every_path() {
        let v = values();
        for (name, isa) in available_paths() {
            for scale in [1.0f32, std::f32::consts::PI] {
                let mut out = vec![f32::NAN; v.len()];
                tanh_heads(&v, &mut out, scale, None, isa).unwrap();
                let mut worst = 0.0f64;
                for (&x, &o) in v.iter().zip(&out) {
                    // tanh(x) + 1 = 2 / (1 + exp(−2x)) exactly; in f64 the left side would cancel to 0
                    // for x < −19.
                    let exact = 2.0 * scale as f64 / (1.0 + (-2.0 * x as f64).exp());
                    if x.abs() < 19.0 {
                        let via_tanh = ((x as f64).tanh() + 1.0) * scale as f64;
                        assert!((via_tanh - exact).abs() <= 1e-15 * scale as f64, "{x}");
                    }
                    // Relative to the value, with a floor far below anything the SLM can show.
                    let err = (o as f64 - exact).abs() / exact.abs().max(1e-30);
                    worst = worst.max(err);
                    assert!(
                        err <= 4.0 * f32::EPSILON as f64 / 2.0 || (o as f64 - exact).abs() < 1e-37,
                        "{name}: heads({x}) = {o}, exact {exact}"
                    );
                }
                println!("{name} scale {scale}: worst relative error {worst:.2e}");
            }
        }
    }

    #[test]
    fn every_path_is_bit_identical_to_the_portable_one() {
        let v = values();
        let grid = QuantU8 {
            scale: 0.25,
            zero_point: 131,
        };
        let mut reference = [
            vec![0.0f32; v.len()],
            vec![0.0; v.len()],
            vec![0.0; v.len()],
        ];
        tanh_heads(&v, &mut reference[0], 1.5, None, Isa::Scalar).unwrap();
        tanh_heads(&v, &mut reference[1], 1.5, Some(grid), Isa::Scalar).unwrap();
        reference[2].copy_from_slice(&v);
        fake_quantize(&mut reference[2], grid, Isa::Scalar).unwrap();
        for (name, isa) in available_paths() {
            // Odd lengths: the vector loops' tails.
            for len in [v.len(), 1, 15, 17, 33] {
                let mut out = vec![0.0f32; len];
                tanh_heads(&v[..len], &mut out, 1.5, None, isa).unwrap();
                assert_eq!(bits(&out), bits(&reference[0][..len]), "{name}");
                tanh_heads(&v[..len], &mut out, 1.5, Some(grid), isa).unwrap();
                assert_eq!(bits(&out), bits(&reference[1][..len]), "{name} grid");
                out.copy_from_slice(&v[..len]);
                fake_quantize(&mut out, grid, isa).unwrap();
                assert_eq!(bits(&out), bits(&reference[2][..len]), "{name} fake");
            }
        }
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    #[test]
    fn the_grid_rounds_as_onnx_quantize_then_dequantize() {
        let v = values();
        for grid in [
            QuantU8 {
                scale: 0.25,
                zero_point: 131,
            },
            QuantU8 {
                scale: 0.0173,
                zero_point: 0,
            },
            QuantU8 {
                scale: 3.0,
                zero_point: 255,
            },
        ] {
            let mut out = v.clone();
            fake_quantize(&mut out, grid, Isa::detect()).unwrap();
            let zp = grid.zero_point as f32;
            for (&x, &o) in v.iter().zip(&out) {
                // The ONNX definition with libm's rounding.
                let q = ((x / grid.scale).round_ties_even() + zp).clamp(0.0, 255.0);
                assert_eq!(o, (q - zp) * grid.scale, "{x} on {grid:?}");
            }
            // A tie rounds to even: 0.125 on a 0.25 grid with zp 131 → step 0 (0.5 rounds to 0), 0.375 → 2.
            if grid.scale == 0.25 {
                let mut o = [0.125f32, 0.375];
                fake_quantize(&mut o, grid, Isa::Scalar).unwrap();
                assert_eq!(o, [0.0, 0.5]);
            }
        }
    }

    #[test]
    fn nan_stays_nan_and_bad_calls_are_errors() {
        let mut o = [0.0f32; 1];
        tanh_heads(&[f32::NAN], &mut o, 1.0, None, Isa::Scalar).unwrap();
        assert!(o[0].is_nan());
        assert!(matches!(
            tanh_heads(&[0.0; 3], &mut [0.0; 2], 1.0, None, Isa::Scalar),
            Err(KernelError::Length { .. })
        ));
        let bad = QuantU8 {
            scale: 0.0,
            zero_point: 0,
        };
        assert!(matches!(
            fake_quantize(&mut o, bad, Isa::Scalar),
            Err(KernelError::Parameter { .. })
        ));
        let missing = Isa::ALL.into_iter().find(|i| !i.is_available()).unwrap();
        assert!(matches!(
            tanh_heads(&[0.0], &mut o, 1.0, None, missing),
            Err(KernelError::Isa { .. })
        ));
    }

    #[test]
    fn quantize_matches_libm_rounding() {
        let zp = 77.0;
        for x in values() {
            let want = {
                let y = x.round_ties_even() + zp;
                let y = if y > 0.0 { y } else { 0.0 };
                if y < 255.0 {
                    y
                } else {
                    255.0
                }
            };
            assert_eq!(quantize_f32(x, zp), want, "{x}");
        }
    }
}
