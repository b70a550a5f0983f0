//! The column pass of a cache-blocked 2-D FFT filter (the SDK's `optics::fft::Fft2::filter_rows`: the angular
//! spectrum method's spectral multiply, paper Eq. 2, and the offset propagation, Eq. 6): moving a block of
//! columns of a row-major complex field into a column-major block and back, and the element-wise complex
//! multiply by a transfer function's row, forwards or mirrored.
//!
//! Complex values are interleaved `(re, im)` `f32` pairs (`num_complex::Complex32`'s layout). The moves copy
//! values, and the multiply computes `(a + bi)(c + di) = (ac − bd) + (ad + bc)i` with a rounding after each
//! product, sum and difference (no fused multiply-add) on every path, so every path is bit-identical with
//! the portable one (tested) and with `Complex32`'s own `*`.
//!
//! AVX-512F path: the moves transpose 8 × 8 tiles of complex values in registers (each zmm holds 8 complex
//! values; three stages of 64-bit and 128-bit shuffles), instead of one 8-byte move per value through a tile
//! buffer; the multiply takes 8 complex values per zmm (the products of the duplicated real and imaginary
//! parts with the multiplier and its swapped pairs, the first sign flipped). Other levels run the portable
//! bodies.

pub(crate) mod body;

use crate::dispatch::{self, Path};
use crate::error::KernelError;
use crate::isa::Isa;
use crate::pack::check_len;

/// One level's column moves and complex multiply, on checked arguments.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SpectralFns {
    /// [`gather_columns`].
    pub gather: unsafe fn(&[f32], [usize; 2], usize, &mut [f32], usize),
    /// [`scatter_columns`].
    pub scatter: unsafe fn(&[f32], usize, &mut [f32], [usize; 2], usize),
    /// [`multiply`].
    pub multiply: unsafe fn(&mut [f32], &[f32], bool),
}

/// The paths, best first: AVX-512F's register transposes, then the portable loops.
pub(crate) static PATHS: &[Path<SpectralFns>] = &[
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx512,
        run: SpectralFns {
            gather: body::x86::gather_avx512,
            scatter: body::x86::scatter_avx512,
            multiply: body::x86::multiply_avx512,
        },
    },
    Path {
        isa: Isa::Scalar,
        run: SpectralFns {
            gather: body::gather_body,
            scatter: body::scatter_body,
            multiply: body::multiply_body,
        },
    },
];

/// Copies columns `x0 .. x0 + bw` of the row-major complex field `[h][w]` (`field`: `2·h·w` values) into the
/// column-major block `[bw][h]` (`block`: `2·bw·h` values): `block[b][y] = field[y][x0 + b]`. Errors: a
/// zero dimension, no columns or columns past `w` ([`KernelError::Shape`]), wrong slice lengths
/// ([`KernelError::Length`]), `isa` not available ([`KernelError::Isa`]).
pub fn gather_columns(
    field: &[f32],
    [h, w]: [usize; 2],
    x0: usize,
    block: &mut [f32],
    bw: usize,
    isa: Isa,
) -> Result<(), KernelError> {
    check_columns([h, w], x0, bw, field.len(), block.len())?;
    let run = dispatch::pick(PATHS, isa)?.gather;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the arguments are checked above.
    unsafe { run(field, [h, w], x0, block, bw) };
    Ok(())
}

/// The inverse of [`gather_columns`]: `field[y][x0 + b] = block[b][y]`; the field's other columns are left
/// as they are. Errors: as [`gather_columns`].
pub fn scatter_columns(
    block: &[f32],
    bw: usize,
    field: &mut [f32],
    [h, w]: [usize; 2],
    x0: usize,
    isa: Isa,
) -> Result<(), KernelError> {
    check_columns([h, w], x0, bw, field.len(), block.len())?;
    let run = dispatch::pick(PATHS, isa)?.scatter;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the arguments are checked above.
    unsafe { run(block, bw, field, [h, w], x0) };
    Ok(())
}

/// `values[i] ← values[i] · by[i]` (complex, interleaved; `values` and `by` of one even length), or with
/// `mirrored` `values[i] ← values[i] · by[n − 1 − i]` for `n` complex values (a spectrum's negative
/// frequencies read from its positive ones). Errors: lengths differ or are odd ([`KernelError::Length`]),
/// `isa` not available ([`KernelError::Isa`]).
pub fn multiply(
    values: &mut [f32],
    by: &[f32],
    mirrored: bool,
    isa: Isa,
) -> Result<(), KernelError> {
    check_len("multiplier (interleaved complex)", by.len(), values.len())?;
    if !values.len().is_multiple_of(2) {
        return Err(KernelError::Length {
            what: "complex values (interleaved, an even count)",
            expected: values.len() + 1,
            got: values.len(),
        });
    }
    let run = dispatch::pick(PATHS, isa)?.multiply;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the lengths are checked above.
    unsafe { run(values, by, mirrored) };
    Ok(())
}

fn check_columns(
    [h, w]: [usize; 2],
    x0: usize,
    bw: usize,
    field: usize,
    block: usize,
) -> Result<(), KernelError> {
    if h == 0 || w == 0 || bw == 0 || x0 + bw > w {
        return Err(KernelError::Shape {
            what: format!(
                "columns {x0}..{} of a {h} × {w} complex field (none, or past its width)",
                x0 + bw
            ),
        });
    }
    check_len("complex field [H][W] (interleaved)", field, 2 * h * w)?;
    check_len(
        "complex block [columns][H] (interleaved)",
        block,
        2 * bw * h,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::Rng;

    fn paths() -> Vec<(String, Isa)> {
        dispatch::available_paths("spectral", PATHS)
    }

    #[test]
    fn moves_on_every_path_equal_the_element_loops() {
        let mut rng = Rng::new(3);
        for (h, w, x0, bw) in [
            (1, 1, 0, 1),
            (8, 16, 0, 16),
            (13, 40, 7, 16),
            (17, 33, 17, 16),
            (9, 20, 3, 5),
            (24, 64, 48, 16),
            (1080, 1920 / 8, 208, 16),
        ] {
            let field = rng.vec(2 * h * w);
            let mut want = vec![0.0f32; 2 * bw * h];
            for b in 0..bw {
                for y in 0..h {
                    let (s, d) = (2 * (y * w + x0 + b), 2 * (b * h + y));
                    want[d..d + 2].copy_from_slice(&field[s..s + 2]);
                }
            }
            for (name, isa) in paths() {
                let mut block = vec![f32::NAN; 2 * bw * h];
                gather_columns(&field, [h, w], x0, &mut block, bw, isa).unwrap();
                let same = block
                    .iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same, "{name} gather {h}×{w} x0 {x0} bw {bw}");
                // Scatter a changed block back: its columns change, the others stay.
                let changed: Vec<f32> = block.iter().map(|v| v * 2.0 + 1.0).collect();
                let mut back = field.clone();
                scatter_columns(&changed, bw, &mut back, [h, w], x0, isa).unwrap();
                for y in 0..h {
                    for x in 0..w {
                        for k in 0..2 {
                            let got = back[2 * (y * w + x) + k];
                            let expect = if (x0..x0 + bw).contains(&x) {
                                changed[2 * ((x - x0) * h + y) + k]
                            } else {
                                field[2 * (y * w + x) + k]
                            };
                            assert_eq!(
                                got.to_bits(),
                                expect.to_bits(),
                                "{name} scatter {h}×{w} at {y},{x}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn multiply_on_every_path_equals_complex_multiplication() {
        let mut rng = Rng::new(4);
        for n in [0usize, 1, 7, 8, 9, 16, 23, 541] {
            let values = rng.vec(2 * n);
            let mut by = rng.vec(2 * n);
            if n > 2 {
                // Awkward values: zeros, infinities, a NaN.
                by[0] = 0.0;
                by[1] = -0.0;
                by[2] = f32::INFINITY;
                by[5] = f32::NAN;
            }
            for mirrored in [false, true] {
                let want: Vec<f32> = (0..n)
                    .flat_map(|i| {
                        let j = if mirrored { n - 1 - i } else { i };
                        let (a, b) = (values[2 * i], values[2 * i + 1]);
                        let (c, d) = (by[2 * j], by[2 * j + 1]);
                        [a * c - b * d, a * d + b * c]
                    })
                    .collect();
                for (name, isa) in paths() {
                    let mut got = values.clone();
                    multiply(&mut got, &by, mirrored, isa).unwrap();
                    for (i, (g, e)) in got.iter().zip(&want).enumerate() {
                        let same = g.to_bits() == e.to_bits() || (g.is_nan() && e.is_nan());
                        assert!(same, "{name} n {n} mirrored {mirrored} at {i}: {g} vs {e}");
                    }
                }
            }
        }
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let isa = Isa::Scalar;
        let mut block = vec![0.0f32; 2 * 4 * 3];
        let field = vec![0.0f32; 2 * 3 * 10];
        assert!(matches!(
            gather_columns(&field, [3, 10], 7, &mut block, 4, isa),
            Err(KernelError::Shape { .. })
        ));
        assert!(matches!(
            gather_columns(&field[1..], [3, 10], 0, &mut block, 4, isa),
            Err(KernelError::Length { .. })
        ));
        let mut field = field;
        assert!(matches!(
            scatter_columns(&block[2..], 4, &mut field, [3, 10], 0, isa),
            Err(KernelError::Length { .. })
        ));
        let mut v = vec![0.0f32; 6];
        assert!(matches!(
            multiply(&mut v, &[0.0; 4], false, isa),
            Err(KernelError::Length { .. })
        ));
        let mut odd = vec![0.0f32; 5];
        assert!(matches!(
            multiply(&mut odd, &[0.0; 5], true, isa),
            Err(KernelError::Length { .. })
        ));
    }
}
