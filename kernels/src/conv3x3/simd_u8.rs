//! The u8×s8 SIMD kernel, written once for every vector ISA (AVX2 widening, AVX-VNNI, AVX-512 VNNI, NEON
//! widening, NEON SDOT, NEON USDOT).
//!
//! [`conv`] is generic over an accumulator type ([`SimdQ`]: `PX` pixels of i32 partial sums, possibly several
//! registers) and the register tile (`G` output channels, a multiple of 4, × `NV` accumulator units). Each
//! reduction step covers 4 input channels (one 32-bit lane of the `[H+2][C/4][Wp][4]` layout) of one tap:
//! it loads `NV` input units and, per output channel, one broadcast of that channel's 4 packed weights.
//!
//! The epilogue is the same f32 arithmetic on every path (bit-exact with the scalar row):
//! `v = (acc as f32)·mult[o] + bias[o]` (multiply, then add: never fused); ReLU `v > 0 ? v : 0`; residual
//! `v += (r − r_zp)·r_scale`; then either u8 `clamp(round_ties_even(v·inv_scale) + zp, 0, 255)`, four
//! output channels packed per 32-bit lane, or raw f32 to a planar `[C_out][H][W]` slice.

use super::job::{U8Job, U8Out};

/// `PX` pixels of i32 accumulators (`Self`) and the vector operations of the epilogue (`F`: `PX` f32
/// lanes). All methods are `unsafe`: the caller guarantees the ISA and valid pointers.
pub(crate) trait SimdQ: Copy {
    /// Pixels per accumulator unit.
    const PX: usize;
    /// Bytes of packed weights per output channel per step (4 × i8 = 4, or 4 × i16 = 8).
    const WB: usize;
    /// Input of `PX` pixels × 4 channels, as the dot product wants it.
    type X: Copy;
    /// One output channel's 4 weights, broadcast.
    type W: Copy;
    /// `PX` f32 lanes.
    type F: Copy;
    /// Every pixel's accumulator set to `v`.
    unsafe fn init(v: i32) -> Self;
    /// `PX · 4` bytes at `p`.
    unsafe fn load_x(p: *const u8) -> Self::X;
    /// `WB` bytes at `p`, broadcast.
    unsafe fn load_w(p: *const u8) -> Self::W;
    /// `self + Σ_c x[p][c]·w[c]` per pixel (exact i32).
    unsafe fn dot(self, x: Self::X, w: Self::W) -> Self;
    /// One reduction step of four output channels: `acc[l][v] ← acc[l][v].dot(x[v], w_l)` for `l` in 0..4,
    /// where `w_l` is channel `l`'s `WB`-byte weight group at `p + l·WB` (`4·WB` readable bytes). The
    /// default broadcasts each channel's group (`load_w`, then `dot`); a path with a dot product by element
    /// (NEON `SDOT`/`USDOT … .4b[l]`) loads the four groups in one register instead: 1 load per 4 channels
    /// rather than 4.
    #[inline(always)]
    unsafe fn step4<const NV: usize>(acc: &mut [[Self; NV]], x: &[Self::X; NV], p: *const u8) {
        for (l, accg) in acc.iter_mut().enumerate().take(4) {
            // SAFETY: the caller guarantees `4·WB` readable bytes at `p` and the ISA.
            let wv = unsafe { Self::load_w(p.add(l * Self::WB)) };
            for (a, &xv) in accg.iter_mut().zip(x.iter()) {
                // SAFETY: register arithmetic; ISA guaranteed by the caller.
                *a = unsafe { a.dot(xv, wv) };
            }
        }
    }
    /// Per-pixel sums converted to f32 (round to nearest even, as `i32 as f32`).
    unsafe fn to_f32(self) -> Self::F;
    unsafe fn splat(v: f32) -> Self::F;
    unsafe fn mul(a: Self::F, b: Self::F) -> Self::F;
    unsafe fn add(a: Self::F, b: Self::F) -> Self::F;
    unsafe fn sub(a: Self::F, b: Self::F) -> Self::F;
    /// `v > 0 ? v : 0`.
    unsafe fn relu(v: Self::F) -> Self::F;
    /// Byte `lane` (0..4) of each of the `PX` 32-bit words at `p`, as f32.
    unsafe fn load_byte(p: *const u8, lane: usize) -> Self::F;
    /// `clamp(round_ties_even(v·inv) + zp, 0, 255)` (still f32, an integer).
    unsafe fn quant(v: Self::F, inv: Self::F, zp: Self::F) -> Self::F;
    /// Packs 4 channels (`q[c]`, integers in 0..=255) per 32-bit word and stores `PX` words at `p`; words of
    /// pixels `valid..PX` get `border` in all four bytes.
    unsafe fn store_u8x4(p: *mut u8, q: [Self::F; 4], valid: usize, border: u8);
    /// Stores the first `valid` (1..=PX) lanes at `p`.
    unsafe fn store_f32(p: *mut f32, v: Self::F, valid: usize);
}

/// Computes rows `[job.y0, job.y1)`.
///
/// # Safety
/// The CPU has the ISA of `Q`; `job` was checked by the safe API and its weights packed for `G` with
/// `Q::WB` bytes per weight group; `G % 4 == 0`; `Q::PX · NV ≤ MAX_TILE`.
#[inline(always)]
pub(crate) unsafe fn conv<Q: SimdQ, const G: usize, const NV: usize>(
    job: &U8Job<'_>,
    out: &mut U8Out<'_>,
) {
    let px = Q::PX;
    let tile = px * NV;
    // `step4` takes the group's channels four at a time: a `G` that is not a multiple of 4 would leave
    // channels unsummed, so it does not compile.
    const { assert!(G.is_multiple_of(4)) };
    debug_assert!(tile <= crate::buffer::planar::MAX_TILE);
    let (w, wp) = (job.w, job.wp);
    let cg = job.ga + job.gb;
    let groups = job.cout.div_ceil(G);
    debug_assert!(job.weights.len() == groups * cg * 9 * G * Q::WB);
    let srcs = [(job.a.as_ptr(), job.ga), (job.b.as_ptr(), job.gb)];
    for y in job.y0..job.y1 {
        for grp in 0..groups {
            let mut x0 = 0;
            while x0 < w {
                let mut acc = [[unsafe_init::<Q>(0); NV]; G];
                for (g, accg) in acc.iter_mut().enumerate() {
                    *accg = [unsafe_init::<Q>(job.init[grp * G + g]); NV];
                }
                // SAFETY: `grp < groups`: the group's `cg·9·G·WB` bytes are inside `job.weights`.
                let mut wptr = unsafe { job.weights.as_ptr().add(grp * cg * 9 * G * Q::WB) };
                for &(src, gs) in &srcs {
                    for j in 0..gs {
                        for ky in 0..3 {
                            // SAFETY: buffer row `y + ky ≤ h + 1`, group `j < gs`, column `x0 < w`: inside
                            // the source's `(h + 2)·gs·wp·4` bytes.
                            let row = unsafe { src.add((((y + ky) * gs + j) * wp + x0) * 4) };
                            for kx in 0..3 {
                                // SAFETY: columns up to `x0 + 2 + tile − 1 ≤ w + MAX_TILE < wp`.
                                let x0v = unsafe { Q::load_x(row.add(kx * 4)) };
                                let mut xv = [x0v; NV];
                                for (v, x) in xv.iter_mut().enumerate().skip(1) {
                                    // SAFETY: as above.
                                    *x = unsafe { Q::load_x(row.add((kx + v * px) * 4)) };
                                }
                                for (q4, acc4) in acc.chunks_exact_mut(4).enumerate() {
                                    // SAFETY: `wptr` walks the group's `cg·9` steps of `G·WB` bytes; channels
                                    // `4·q4 … 4·q4 + 3` of this step; ISA guaranteed by the caller.
                                    unsafe { Q::step4(acc4, &xv, wptr.add(4 * q4 * Q::WB)) };
                                }
                                // SAFETY: at most one past the group's last step.
                                wptr = unsafe { wptr.add(G * Q::WB) };
                            }
                        }
                    }
                }
                // A copy for the epilogue keeps `acc` at constant indices (registers).
                let tile_acc = acc;
                // SAFETY: the caller's guarantees.
                unsafe { epilogue::<Q, G, NV>(job, out, &tile_acc, y, x0, grp) };
                x0 += tile;
            }
        }
    }
}

#[inline(always)]
fn unsafe_init<Q: SimdQ>(v: i32) -> Q {
    // SAFETY: only called from `conv`, whose caller guarantees the ISA of `Q`.
    unsafe { Q::init(v) }
}

/// # Safety
/// As [`conv`].
// `acc` is indexed `[g][v]` with `v` outer (one store per pixel unit and 4 output channels).
#[allow(clippy::needless_range_loop)]
#[inline(always)]
unsafe fn epilogue<Q: SimdQ, const G: usize, const NV: usize>(
    job: &U8Job<'_>,
    out: &mut U8Out<'_>,
    acc: &[[Q; NV]; G],
    y: usize,
    x0: usize,
    grp: usize,
) {
    let px = Q::PX;
    let (w, wp, cout) = (job.w, job.wp, job.cout);
    let c4 = cout.div_ceil(4);
    for v in 0..NV {
        let pxv = x0 + v * px;
        let valid = w.saturating_sub(pxv).min(px);
        for q4 in 0..G / 4 {
            let o4 = grp * G / 4 + q4;
            if o4 >= c4 {
                continue;
            }
            // Byte offset of this unit's first pixel in a `[H+2][C_out/4][Wp][4]` buffer.
            let at = (((y + 1) * c4 + o4) * wp + 1 + pxv) * 4;
            // SAFETY: register arithmetic; ISA guaranteed by the caller.
            let mut vals = [unsafe { Q::splat(job.out_zp) }; 4];
            for (c, val) in vals.iter_mut().enumerate() {
                let g = q4 * 4 + c;
                let o = grp * G + g;
                if o >= cout {
                    continue;
                }
                // SAFETY: register arithmetic; `o < cout ≤ mult.len(), bias.len()`.
                let mut r = unsafe {
                    let f = acc[g][v].to_f32();
                    Q::add(Q::mul(f, Q::splat(job.mult[o])), Q::splat(job.bias[o]))
                };
                if job.relu {
                    // SAFETY: register arithmetic.
                    r = unsafe { Q::relu(r) };
                }
                if let Some((res, rzp, rscale)) = job.residual {
                    debug_assert!(at + px * 4 <= res.len());
                    // SAFETY: the residual has the output's shape and layout; `px` words from `at` end before
                    // the row's `wp` columns (`wp ≥ w + 2 + MAX_TILE`).
                    r = unsafe {
                        let t = Q::sub(Q::load_byte(res.as_ptr().add(at), c), Q::splat(rzp));
                        Q::add(r, Q::mul(t, Q::splat(rscale)))
                    };
                }
                match out {
                    U8Out::Rows { .. } => {
                        // SAFETY: register arithmetic.
                        *val = unsafe { Q::quant(r, Q::splat(job.out_inv), Q::splat(job.out_zp)) };
                    }
                    U8Out::F32 {
                        data,
                        c_stride,
                        y_stride,
                        base,
                    } => {
                        if valid > 0 {
                            let i = U8Out::f32_index(*c_stride, *y_stride, *base, o, y, pxv);
                            debug_assert!(i + valid <= data.len());
                            // SAFETY: pixels `pxv..pxv + valid ≤ w` of row `y`, channel `o`: inside the
                            // slice, whose strides and base the safe API checked against its length.
                            unsafe { Q::store_f32(data.as_mut_ptr().add(i), r, valid) };
                        }
                    }
                }
            }
            if let U8Out::Rows { data, base } = out {
                debug_assert!(at >= *base && at - *base + px * 4 <= data.len());
                // SAFETY: as for the residual; words of pixels past `w` (right border) and the bytes of
                // padding channels get the zero point, which keeps the border invariant. Row `y` lies in the
                // band (`y0 ≤ y < y1`, checked by the safe API), which starts at element `base`.
                unsafe {
                    Q::store_u8x4(
                        data.as_mut_ptr().add(at - *base),
                        vals,
                        valid,
                        job.out_zp_u8,
                    )
                };
            }
        }
    }
}

/// The dot-product peak loop of the rows whose `dot` is one instruction (VNNI, `SDOT`, `USDOT`): `N`
/// independent chains `acc ← acc.dot(x, w)` from 1, `iters` steps each; the caller sums the chains it gets
/// back (a value derived from every chain, to keep the loop alive). Ops = `iters · N · PX · 4 · 2`.
///
/// # Safety
/// The CPU has the ISA of `Q`.
#[inline(always)]
pub(crate) unsafe fn peak_chains<Q: SimdQ, const N: usize>(iters: u64, x: Q::X, w: Q::W) -> [Q; N] {
    // SAFETY: the caller guarantees the ISA of `Q`; register-only operations.
    unsafe {
        let mut acc = [Q::init(1); N];
        for _ in 0..iters {
            for a in acc.iter_mut() {
                *a = a.dot(x, w);
            }
        }
        acc
    }
}
