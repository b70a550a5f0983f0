//! The depthwise filter's path (the method: [`crate::depthwise`]): the portable body, generic over the tile
//! width `L`, and its copies compiled inside `#[target_feature]` functions. The filter's
//! [`PATHS`](super::PATHS) list which serves each ISA level.

use std::ops::Range;

/// The largest kernel width taken (odd).
pub const MAX_TAPS: usize = 63;

/// Portable tile width: four 128-bit registers on SSE2 (16 registers), eight on NEON (32 registers).
#[cfg(target_arch = "aarch64")]
pub(crate) const PORTABLE_TILE: usize = 32;
#[cfg(not(target_arch = "aarch64"))]
pub(crate) const PORTABLE_TILE: usize = 16;

/// One checked plane and kernel.
pub(crate) struct Job<'a> {
    pub plane: &'a [f32],
    pub h: usize,
    pub w: usize,
    pub taps: &'a [f32],
    pub k: usize,
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod x86 {
    use super::{rows_body, Job};
    use std::ops::Range;

    /// # Safety
    /// The CPU has AVX2.
    #[target_feature(enable = "avx2")]
    pub(crate) unsafe fn rows_avx2(job: &Job<'_>, rows: Range<usize>, out: &mut [f32], acc: bool) {
        rows_body::<32>(job, rows, out, acc)
    }
    /// # Safety
    /// The CPU has AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(crate) unsafe fn rows_avx512(
        job: &Job<'_>,
        rows: Range<usize>,
        out: &mut [f32],
        acc: bool,
    ) {
        rows_body::<64>(job, rows, out, acc)
    }
}

/// Output rows `rows` into `out`, tiles of `L` pixels, then of 8, then one at a time (the module docs).
#[inline(always)]
pub(crate) fn rows_body<const L: usize>(
    job: &Job<'_>,
    rows: Range<usize>,
    out: &mut [f32],
    accumulate: bool,
) {
    let Job {
        plane,
        h,
        w,
        taps,
        k,
    } = *job;
    let r = k / 2;
    // Pixels whose reads all lie inside the row: r ≤ x < w − r.
    let inner = r..w.saturating_sub(r).max(r);
    for (y, o) in rows.zip(out.chunks_exact_mut(w)) {
        let mut src: [&[f32]; MAX_TAPS] = [&[]; MAX_TAPS];
        for (ky, s) in src[..k].iter_mut().enumerate() {
            let sy = (y + ky).saturating_sub(r).min(h - 1);
            *s = &plane[sy * w..(sy + 1) * w];
        }
        let src = &src[..k];
        let mut x = inner.start;
        while x + L <= inner.end {
            tile::<L>(src, taps, k, x - r, &mut o[x..x + L], accumulate);
            x += L;
        }
        while x + 8 <= inner.end {
            tile::<8>(src, taps, k, x - r, &mut o[x..x + 8], accumulate);
            x += 8;
        }
        // The edges and what no tile covered, with clamped reads.
        let single = (0..inner.start.min(w)).chain(x..w);
        for x in single {
            let mut a = 0.0f32;
            for (row, t) in src.iter().zip(taps.chunks_exact(k)) {
                for (kx, &tv) in t.iter().enumerate() {
                    a += tv * row[(x + kx).saturating_sub(r).min(w - 1)];
                }
            }
            store(&mut o[x], a, accumulate);
        }
    }
}

/// `L` output pixels from input column `x0` on (`x0 + L + k − 1 ≤ W`): their sums in registers through
/// every tap.
#[inline(always)]
fn tile<const L: usize>(
    src: &[&[f32]],
    taps: &[f32],
    k: usize,
    x0: usize,
    o: &mut [f32],
    accumulate: bool,
) {
    let mut acc = [0.0f32; L];
    for (row, t) in src.iter().zip(taps.chunks_exact(k)) {
        // `k` windows of `L` inputs, one per tap of this kernel row (no index to check per tap; `windows(L)`
        // yields exactly `L` values, so the conversion never fails).
        for (win, &tv) in row[x0..x0 + L + k - 1].windows(L).zip(t) {
            let Ok(win) = <&[f32; L]>::try_from(win) else {
                continue;
            };
            for (a, &v) in acc.iter_mut().zip(win) {
                *a += tv * v;
            }
        }
    }
    for (o, a) in o.iter_mut().zip(acc) {
        store(o, a, accumulate);
    }
}

#[inline(always)]
fn store(o: &mut f32, a: f32, accumulate: bool) {
    if accumulate {
        *o += a;
    } else {
        *o = a;
    }
}
