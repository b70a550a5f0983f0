//! The depthwise filter's paths (the method: [`crate::depthwise`]): one body, [`rows`], generic over its wide
//! tile ([`Tile`]): the portable [`Portable`] (an array of `L` f32 that the compiler vectorises for the
//! build's baseline) or, on x86-64, [`Regs`] (four registers of a [`SimdF32`] type), instantiated with
//! `__m256` and `__m512` inside the `#[target_feature]` functions of [`x86`]. The filter's
//! [`PATHS`](super::PATHS) list which serves each ISA level.

use std::ops::Range;

#[cfg(target_arch = "x86_64")]
use crate::simd::SimdF32;
#[cfg(target_arch = "x86_64")]
use std::marker::PhantomData;

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

/// A tile of `L` consecutive output pixels of one row whose sums stay in registers through every tap:
/// [`Portable`] (`L` f32 values that the compiler vectorises for the build's baseline) or, on x86-64,
/// [`Regs`] (four registers of a [`SimdF32`] type, written out).
pub(crate) trait Tile {
    /// Pixels per tile.
    const L: usize;
    /// `L` output pixels from input column `x0` on into `o[..L]` (added to it with `accumulate`), each sum
    /// `Σ_ky Σ_kx taps[ky·k + kx]·src[ky][x0 + i + kx]` in that order from 0.0, for the `k = src.len()` rows
    /// of a `k × k` kernel.
    ///
    /// # Safety
    /// The CPU has the ISA of the implementation. Slices are indexed with checks (`x0 + L + k − 1` values
    /// of every row of `src`, `L` of `o`), so lengths need no guarantee.
    unsafe fn run(src: &[&[f32]], taps: &[f32], x0: usize, o: &mut [f32], accumulate: bool);
}

/// The portable tile of `L` pixels ([`tile`]).
pub(crate) struct Portable<const L: usize>;

impl<const L: usize> Tile for Portable<L> {
    const L: usize = L;
    #[inline(always)]
    unsafe fn run(src: &[&[f32]], taps: &[f32], x0: usize, o: &mut [f32], accumulate: bool) {
        tile::<L>(src, taps, src.len(), x0, o, accumulate)
    }
}

/// The tile of four registers of `V` (`L = 4·LANES` pixels): per tap one broadcast weight and four loads
/// at the tap's offset, four independent multiply-then-add chains (never fused, as the portable tile).
#[cfg(target_arch = "x86_64")]
pub(crate) struct Regs<V>(PhantomData<V>);

#[cfg(target_arch = "x86_64")]
impl<V: SimdF32> Tile for Regs<V> {
    const L: usize = 4 * V::LANES;
    #[inline(always)]
    unsafe fn run(src: &[&[f32]], taps: &[f32], x0: usize, o: &mut [f32], accumulate: bool) {
        let (n, l, k) = (Self::L, V::LANES, src.len());
        let o = &mut o[..n];
        // SAFETY: the caller guarantees the ISA of `V`. Every load reads `LANES` values from offset
        // `kx + i·LANES ≤ k − 1 + 3·LANES` of a window of `L + k − 1` values, every store writes `LANES` from
        // offset `i·LANES` of `o`'s `L`.
        unsafe {
            let mut acc = [V::zero(); 4];
            for (row, t) in src.iter().zip(taps.chunks_exact(k)) {
                let win = row[x0..x0 + n + k - 1].as_ptr();
                for (kx, &tv) in t.iter().enumerate() {
                    let w = V::splat(tv);
                    for (i, a) in acc.iter_mut().enumerate() {
                        *a = V::add(*a, V::mul(w, V::load(win.add(kx + i * l))));
                    }
                }
            }
            for (i, a) in acc.into_iter().enumerate() {
                let p = o.as_mut_ptr().add(i * l);
                V::store(p, if accumulate { V::add(V::load(p), a) } else { a });
            }
        }
    }
}

/// The `#[target_feature]` entry points: the rows with the AVX2 and AVX-512F register tiles.
#[cfg(target_arch = "x86_64")]
pub(crate) mod x86 {
    use super::{Job, Regs};
    use std::arch::x86_64::*;
    use std::ops::Range;

    /// The rows with tiles of four ymm (32 pixels).
    ///
    /// # Safety
    /// The CPU has AVX2.
    #[target_feature(enable = "avx2")]
    pub(crate) unsafe fn rows_avx2(job: &Job<'_>, rows: Range<usize>, out: &mut [f32], acc: bool) {
        // SAFETY: AVX2 enabled here and present on the CPU (the caller's guarantee).
        unsafe { super::rows::<Regs<__m256>>(job, rows, out, acc) }
    }
    /// The rows with tiles of four zmm (64 pixels).
    ///
    /// # Safety
    /// The CPU has AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(crate) unsafe fn rows_avx512(
        job: &Job<'_>,
        rows: Range<usize>,
        out: &mut [f32],
        acc: bool,
    ) {
        // SAFETY: AVX-512F enabled here and present on the CPU (the caller's guarantee).
        unsafe { super::rows::<Regs<__m512>>(job, rows, out, acc) }
    }
}

/// Output rows `rows` into `out`, tiles of `T::L` pixels, then of 8, then one at a time (the module docs).
///
/// # Safety
/// The CPU has the ISA of `T` ([`Portable`]: none).
#[inline(always)]
pub(crate) unsafe fn rows<T: Tile>(
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
        while x + T::L <= inner.end {
            // SAFETY: the caller guarantees the ISA of `T`.
            unsafe { T::run(src, taps, x - r, &mut o[x..x + T::L], accumulate) };
            x += T::L;
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
