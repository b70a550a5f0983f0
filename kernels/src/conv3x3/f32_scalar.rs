//! `conv3x3.f32.8x8.scalar`: the portable fallback, safe code.
//!
//! Same tiling as the SIMD rows: a tile of `G = 8` output channels × `P = 8` pixels of accumulators is kept
//! for the whole `9·C_in` reduction; each step loads 8 input pixels and one packed weight per output channel.
//! With fixed-size arrays the compiler keeps the tile in vector registers where the target has them (the
//! copy of the tile for the epilogue keeps the accumulators at constant indices: measured 2× faster; a 4 × 8
//! tile measured the same as 8 × 8 on x86-64 SSE2).

use super::job::{F32Job, F32Out};
use super::simd_f32::ConvF32;
use super::{wino2x2, wino4x4};

/// Output-channel tile of the portable Winograd row.
pub(crate) const WINO_G: usize = 4;
/// Tiles (2 output columns each) per Winograd register tile of the portable row.
pub(crate) const WINO_NV: usize = 4;

/// Output-channel tile.
pub(crate) const G: usize = 8;
/// Pixel tile.
pub(crate) const P: usize = 8;

pub(crate) fn conv(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    conv_t::<G, P>(job, out)
}

pub(crate) fn conv_t<const G: usize, const P: usize>(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    let (w, h, wp, cout) = (job.w, job.h, job.wp, job.cout);
    let cin = job.ca + job.cb;
    let groups = cout.div_ceil(G);
    for y in job.y0..job.y1 {
        for grp in 0..groups {
            let mut x0 = 0;
            while x0 < w {
                let mut acc = [[0.0f32; P]; G];
                let mut wi = grp * cin * 9 * G;
                for (src, cs) in [(job.a, job.ca), (job.b, job.cb)] {
                    for ic in 0..cs {
                        for ky in 0..3 {
                            let row = ((y + ky) * cs + ic) * wp + x0;
                            for kx in 0..3 {
                                let xs: &[f32; P] =
                                    src[row + kx..row + kx + P].try_into().unwrap_or(&[0.0; P]);
                                let ws = &job.weights[wi..wi + G];
                                for g in 0..G {
                                    for p in 0..P {
                                        acc[g][p] += xs[p] * ws[g];
                                    }
                                }
                                wi += G;
                            }
                        }
                    }
                }
                let n = P.min(w - x0);
                // A copy for the epilogue keeps `acc` at constant indices (registers).
                let tile_acc = acc;
                for (g, acc) in tile_acc.iter().enumerate() {
                    let o = grp * G + g;
                    if o >= cout {
                        break;
                    }
                    let res_row = ((y + 1) * cout + o) * wp + 1 + x0;
                    let mut v = [0.0f32; P];
                    for p in 0..P {
                        let mut t = acc[p] + job.bias[o];
                        if job.relu {
                            t = if t > 0.0 { t } else { 0.0 };
                        }
                        if let Some(r) = job.residual {
                            t += r[res_row + p];
                        }
                        v[p] = if p < n { t } else { 0.0 };
                    }
                    match out {
                        F32Out::Rows { data, base } => {
                            data[res_row - *base..res_row - *base + P].copy_from_slice(&v)
                        }
                        F32Out::Planar(d) => {
                            let i = (o * h + y) * w + x0;
                            d[i..i + n].copy_from_slice(&v[..n]);
                        }
                    }
                }
                x0 += P;
            }
        }
    }
}

/// The portable peak loop: 16 independent multiply-add chains (no FMA); FLOPs = `iters · 16 · 2`.
pub(crate) fn peak(iters: u64) -> f32 {
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

/// One f32 as a one-lane register: the portable Winograd row is the generic body on it (multiply and add
/// unfused, as the direct scalar row computes them: no libm `fmaf` on targets without FMA).
impl ConvF32 for f32 {
    #[inline(always)]
    unsafe fn fma(acc: Self, a: Self, b: Self) -> Self {
        acc + a * b
    }
    #[inline(always)]
    unsafe fn keep_first(_v: Self, n: usize) -> Self {
        debug_assert!(n == 0);
        0.0
    }
    #[inline(always)]
    unsafe fn interleave(e: Self, o: Self) -> (Self, Self) {
        (e, o)
    }
    #[inline(always)]
    unsafe fn load_stride4(p: *const f32) -> [Self; 4] {
        // SAFETY: the caller guarantees 4 readable values at `p`.
        unsafe { [*p, *p.add(1), *p.add(2), *p.add(3)] }
    }
    #[inline(always)]
    unsafe fn interleave4(c: [Self; 4]) -> [Self; 4] {
        c
    }
}

/// `conv3x3.f32.wino2x2.4x4.scalar`: Winograd F(2×2, 3×3) on any CPU, 4 output channels × 4 tiles.
///
/// # Safety
/// `job` was checked by the safe API and its weights packed for Winograd with `G = 4`.
pub(crate) unsafe fn winograd(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    // SAFETY: the job was checked by the caller; 8-pixel tile ≤ MAX_TILE.
    unsafe { wino2x2::conv::<f32, WINO_G, WINO_NV>(job, out) }
}

/// `conv3x3.f32.wino4x4.4x4.scalar`: Winograd F(4×4, 3×3) on any CPU, 4 output channels × 4 tiles.
///
/// # Safety
/// `job` was checked by the safe API and its weights packed for F(4×4, 3×3) with `G = 4`.
pub(crate) unsafe fn winograd4(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    // SAFETY: the job was checked by the caller; 16-pixel tile ≤ MAX_TILE.
    unsafe { wino4x4::conv::<f32, WINO_G, WINO_NV>(job, out) }
}
