//! The spectral helpers' paths (the method: [`crate::spectral`]): the portable bodies and the AVX-512F ones.
//! [`PATHS`](super::PATHS) lists which serves each ISA level.

/// Rows per tile of the portable moves: a tile's column segment is 8 complex values (64 bytes, one cache
/// line) written or read at once.
const TILE: usize = 8;

/// Calls `each(f, b)` with the `f32` index `f` of field value `[y][x0 + c]` (of a `[h][w]` complex field)
/// and `b` of block value `[c][y]` (of a `[bw][h]` block) for rows `rows` and block columns `cols`, in tiles
/// of [`TILE`] rows, column by column inside a tile.
#[inline(always)]
fn each_value(
    [h, w]: [usize; 2],
    x0: usize,
    rows: std::ops::Range<usize>,
    cols: std::ops::Range<usize>,
    mut each: impl FnMut(usize, usize),
) {
    let mut y0 = rows.start;
    while y0 < rows.end {
        let y1 = (y0 + TILE).min(rows.end);
        for c in cols.clone() {
            for y in y0..y1 {
                each(2 * (y * w + x0 + c), 2 * (c * h + y));
            }
        }
        y0 = y1;
    }
}

/// Portable [`crate::spectral::gather_columns`] (checked arguments).
pub(crate) fn gather_body(field: &[f32], hw: [usize; 2], x0: usize, block: &mut [f32], bw: usize) {
    each_value(hw, x0, 0..hw[0], 0..bw, |f, b| {
        block[b..b + 2].copy_from_slice(&field[f..f + 2])
    });
}

/// Portable [`crate::spectral::scatter_columns`] (checked arguments).
pub(crate) fn scatter_body(block: &[f32], bw: usize, field: &mut [f32], hw: [usize; 2], x0: usize) {
    each_value(hw, x0, 0..hw[0], 0..bw, |f, b| {
        field[f..f + 2].copy_from_slice(&block[b..b + 2])
    });
}

/// Portable [`crate::spectral::multiply`] (checked arguments): `(ac − bd, ad + bc)`, rounded after each
/// operation.
pub(crate) fn multiply_body(values: &mut [f32], by: &[f32], mirrored: bool) {
    let n = values.len() / 2;
    for i in 0..n {
        let j = if mirrored { n - 1 - i } else { i };
        let (a, b) = (values[2 * i], values[2 * i + 1]);
        let (c, d) = (by[2 * j], by[2 * j + 1]);
        values[2 * i] = a * c - b * d;
        values[2 * i + 1] = a * d + b * c;
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod x86 {
    use super::{each_value, multiply_body};
    use std::arch::x86_64::*;

    /// The 8 × 8 transpose of 64-bit elements (complex values) held in 8 zmm: element `j` of `r[i]` becomes
    /// element `i` of the result's `j`. Three stages: pairs of rows interleaved by 64-bit elements, then
    /// 128-bit lanes of row pairs, then 256-bit halves of row quadruples.
    ///
    /// # Safety
    /// The CPU has AVX-512F.
    #[inline(always)]
    unsafe fn transpose8(r: [__m512d; 8]) -> [__m512d; 8] {
        // SAFETY: register shuffles on the caller's ISA.
        unsafe {
            // s0 = [00 10 02 12 04 14 06 16], s1 = [01 11 03 13 05 15 07 17] (row, column), …
            let s = [
                _mm512_unpacklo_pd(r[0], r[1]),
                _mm512_unpackhi_pd(r[0], r[1]),
                _mm512_unpacklo_pd(r[2], r[3]),
                _mm512_unpackhi_pd(r[2], r[3]),
                _mm512_unpacklo_pd(r[4], r[5]),
                _mm512_unpackhi_pd(r[4], r[5]),
                _mm512_unpacklo_pd(r[6], r[7]),
                _mm512_unpackhi_pd(r[6], r[7]),
            ];
            // Lanes (128-bit) 0 and 2 of a and b interleaved, and lanes 1 and 3:
            // u0 = [00 10 20 30 04 14 24 34], u2 = [02 12 22 32 06 16 26 36], u1, u3 likewise from s1, s3.
            let even = _mm512_setr_epi64(0, 1, 8, 9, 4, 5, 12, 13);
            let odd = _mm512_setr_epi64(2, 3, 10, 11, 6, 7, 14, 15);
            let u = [
                _mm512_permutex2var_pd(s[0], even, s[2]),
                _mm512_permutex2var_pd(s[1], even, s[3]),
                _mm512_permutex2var_pd(s[0], odd, s[2]),
                _mm512_permutex2var_pd(s[1], odd, s[3]),
                _mm512_permutex2var_pd(s[4], even, s[6]),
                _mm512_permutex2var_pd(s[5], even, s[7]),
                _mm512_permutex2var_pd(s[4], odd, s[6]),
                _mm512_permutex2var_pd(s[5], odd, s[7]),
            ];
            // Column j < 4: the low halves of u[j] and u[j + 4]; column j + 4: their high halves.
            let low = _mm512_setr_epi64(0, 1, 2, 3, 8, 9, 10, 11);
            let high = _mm512_setr_epi64(4, 5, 6, 7, 12, 13, 14, 15);
            [
                _mm512_permutex2var_pd(u[0], low, u[4]),
                _mm512_permutex2var_pd(u[1], low, u[5]),
                _mm512_permutex2var_pd(u[2], low, u[6]),
                _mm512_permutex2var_pd(u[3], low, u[7]),
                _mm512_permutex2var_pd(u[0], high, u[4]),
                _mm512_permutex2var_pd(u[1], high, u[5]),
                _mm512_permutex2var_pd(u[2], high, u[6]),
                _mm512_permutex2var_pd(u[3], high, u[7]),
            ]
        }
    }

    /// [`super::gather_body`] on AVX-512F: whole 8 × 8 tiles transposed in registers, the rest (the rows and
    /// columns past the last whole tile) value by value as the portable body moves them ([`each_value`]).
    ///
    /// # Safety
    /// The CPU has AVX-512F; the arguments were checked (`crate::spectral`).
    #[target_feature(enable = "avx512f")]
    pub(crate) unsafe fn gather_avx512(
        field: &[f32],
        [h, w]: [usize; 2],
        x0: usize,
        block: &mut [f32],
        bw: usize,
    ) {
        let (h8, bw8) = (h / 8 * 8, bw / 8 * 8);
        let (src, dst) = (
            field.as_ptr().cast::<f64>(),
            block.as_mut_ptr().cast::<f64>(),
        );
        for y0 in (0..h8).step_by(8) {
            for b0 in (0..bw8).step_by(8) {
                // SAFETY: rows `y0 + i < h`, columns `x0 + b0 + 8 ≤ x0 + bw ≤ w` of the `[h][w]` field and
                // columns `b0 + j < bw`, rows `y0 .. y0 + 8 ≤ h` of the `[bw][h]` block (complex values, 8
                // bytes each; unaligned loads and stores); AVX-512F enabled here.
                unsafe {
                    let r = [0, 1, 2, 3, 4, 5, 6, 7]
                        .map(|i| _mm512_loadu_pd(src.add((y0 + i) * w + x0 + b0)));
                    for (j, c) in transpose8(r).into_iter().enumerate() {
                        _mm512_storeu_pd(dst.add((b0 + j) * h + y0), c);
                    }
                }
            }
        }
        // The columns past the last whole tile, all rows; the rows past the last whole tile, the tiled
        // columns.
        for (rows, cols) in [(0..h, bw8..bw), (h8..h, 0..bw8)] {
            each_value([h, w], x0, rows, cols, |f, b| {
                block[b..b + 2].copy_from_slice(&field[f..f + 2])
            });
        }
    }

    /// [`super::scatter_body`] on AVX-512F (the same tiles the other way: the transpose is its own inverse;
    /// the mirror of [`gather_avx512`], one `#[target_feature]` entry each: a shared closure would not be
    /// compiled for AVX-512).
    ///
    /// # Safety
    /// As [`gather_avx512`].
    #[target_feature(enable = "avx512f")]
    pub(crate) unsafe fn scatter_avx512(
        block: &[f32],
        bw: usize,
        field: &mut [f32],
        [h, w]: [usize; 2],
        x0: usize,
    ) {
        let (h8, bw8) = (h / 8 * 8, bw / 8 * 8);
        let (src, dst) = (
            block.as_ptr().cast::<f64>(),
            field.as_mut_ptr().cast::<f64>(),
        );
        for y0 in (0..h8).step_by(8) {
            for b0 in (0..bw8).step_by(8) {
                // SAFETY: as in `gather_avx512`, reads and writes exchanged.
                unsafe {
                    let c = [0, 1, 2, 3, 4, 5, 6, 7]
                        .map(|j| _mm512_loadu_pd(src.add((b0 + j) * h + y0)));
                    for (i, r) in transpose8(c).into_iter().enumerate() {
                        _mm512_storeu_pd(dst.add((y0 + i) * w + x0 + b0), r);
                    }
                }
            }
        }
        for (rows, cols) in [(0..h, bw8..bw), (h8..h, 0..bw8)] {
            each_value([h, w], x0, rows, cols, |f, b| {
                field[f..f + 2].copy_from_slice(&block[b..b + 2])
            });
        }
    }

    /// [`multiply_body`] on AVX-512F, 8 complex values a zmm: `(a, a)·(c, d) + (b, b)·(−d, c)` with the
    /// sign flipped by a bit mask (`x + (−y)` is `x − y` exactly), the mirrored multiplier's pairs reversed
    /// by a 64-bit permute; the last `n mod 8` values by the portable body.
    ///
    /// # Safety
    /// The CPU has AVX-512F; the arguments were checked (`crate::spectral`).
    #[target_feature(enable = "avx512f")]
    pub(crate) unsafe fn multiply_avx512(values: &mut [f32], by: &[f32], mirrored: bool) {
        let n = values.len() / 2;
        let n8 = n / 8 * 8;
        let (v, m) = (values.as_mut_ptr(), by.as_ptr());
        // SAFETY: AVX-512F enabled here; complex values `i .. i + 8 ≤ n8 ≤ n` of `values`, and of `by` either
        // `i ..` or, mirrored, `n − 8 − i .. n − i` (`n − 8 − i ≥ 0` for `i + 8 ≤ n`).
        unsafe {
            let sign = _mm512_set1_epi64(0x8000_0000);
            let reverse = _mm512_setr_epi64(7, 6, 5, 4, 3, 2, 1, 0);
            for i in (0..n8).step_by(8) {
                let x = _mm512_loadu_ps(v.add(2 * i));
                let mut c = if mirrored {
                    _mm512_loadu_ps(m.add(2 * (n - 8 - i)))
                } else {
                    _mm512_loadu_ps(m.add(2 * i))
                };
                if mirrored {
                    c = _mm512_castpd_ps(_mm512_permutexvar_pd(reverse, _mm512_castps_pd(c)));
                }
                let re = _mm512_moveldup_ps(x);
                let im = _mm512_movehdup_ps(x);
                let swapped = _mm512_permute_ps::<0b10_11_00_01>(c);
                let t1 = _mm512_mul_ps(re, c);
                let t2 = _mm512_mul_ps(im, swapped);
                let t2 = _mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(t2), sign));
                _mm512_storeu_ps(v.add(2 * i), _mm512_add_ps(t1, t2));
            }
        }
        // The tail: the portable body on the last values, with the matching multiplier values.
        let tail = &mut values[2 * n8..];
        if mirrored {
            multiply_body(tail, &by[..2 * (n - n8)], true);
        } else {
            multiply_body(tail, &by[2 * n8..], false);
        }
    }
}
