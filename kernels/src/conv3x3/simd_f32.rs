//! The f32 SIMD kernel, written once for every vector ISA.
//!
//! [`conv`] is generic over a register type (the crate's [`SimdF32`]: load, broadcast, add, store…, with this
//! module's [`ConvF32`]: FMA, the Winograd transposes) and over the register tile (`G` output channels × `NV`
//! vectors of pixels). Each ISA file implements [`ConvF32`] for its register type (`crate::simd` holds its
//! [`SimdF32`] impl) and instantiates `conv` inside a `#[target_feature]` function; everything here is `#[inline(always)]`
//! so it is compiled with that function's features. AVX-512 (not available on the machine the tests run on)
//! thereby shares every line of loop and index logic with the tested AVX2 and NEON instances.

use super::job::{F32Job, F32Out};
#[cfg(test)]
use crate::simd::Pair;
use crate::simd::SimdF32;

/// The conv3x3 rows' operations on a [`SimdF32`] register: the fused multiply-add and its reduction step,
/// the epilogue's ReLU and partial-register mask, and the Winograd transforms' deinterleaving loads and
/// transposes. All methods are `unsafe`, as [`SimdF32`]'s.
pub(crate) trait ConvF32: SimdF32 {
    /// `acc + a·b` (fused).
    unsafe fn fma(acc: Self, a: Self, b: Self) -> Self;
    /// `v > 0 ? v : 0` per lane.
    ///
    /// Default: [`SimdF32::max`]`(v, 0)` (`maxps` returns the second operand for NaN and ±0).
    #[inline(always)]
    unsafe fn relu(v: Self) -> Self {
        // SAFETY: the caller guarantees the ISA.
        unsafe { Self::max(v, Self::zero()) }
    }
    /// Lanes `n..LANES` set to 0, lanes `0..n` kept (`n < LANES`).
    unsafe fn keep_first(v: Self, n: usize) -> Self;
    /// Loads the `LANES` pairs `(p[2i], p[2i + 1])` from `p` and returns them deinterleaved: the first
    /// elements in one register, the second in the other, lane `j` holding pair `π(j)` for a permutation `π`
    /// of the implementation's choosing (the identity, or what its shuffles give without crossing 128-bit
    /// lanes), the same for every `p` (the Winograd input transform's even and odd columns: lane `j` of the
    /// loads at `p` and at `p + 2` then belong to the same tile).
    ///
    /// Default: [`SimdF32::load_pairs`] (the identity).
    #[inline(always)]
    unsafe fn load_deinterleaved(p: *const f32) -> (Self, Self) {
        // SAFETY: the caller guarantees `2·LANES` readable values at `p` and the ISA.
        unsafe { Self::load_pairs(p) }
    }
    /// The inverse of [`load_deinterleaved`](Self::load_deinterleaved) on registers: the `LANES` pairs
    /// `(e[j], o[j])` back in memory order, as two registers (the Winograd output transform's columns back
    /// to pixels).
    unsafe fn interleave(e: Self, o: Self) -> (Self, Self);
    /// Loads the `LANES` quadruples `p[4i .. 4i + 4]` from `p` and returns them transposed: register `j`
    /// holds element `j` of every quadruple, lane `l` holding quadruple `π(l)` for a permutation `π` of the
    /// implementation's choosing, the same for every `p` (the F(4×4, 3×3) input transform's columns: lane `l`
    /// of the loads at `p` and at `p + 2` then belong to the same tile).
    unsafe fn load_stride4(p: *const f32) -> [Self; 4];
    /// Elements 0 and 1 of the quadruples at `p + 4` (the F(4×4, 3×3) input transform's tile columns 4 and
    /// 5), in the lanes of [`load_stride4`](Self::load_stride4)`(p)`, given `c0`, `c1` = its registers 0 and 1:
    /// the same values as registers 2 and 3 of `load_stride4(p + 2)`. Default: that load. An
    /// implementation may instead move each lane's value from the lane of the next quadruple in `c0`, `c1`
    /// and read only the last one (`p[4·LANES]`, `p[4·LANES + 1]`), bit for bit the same.
    ///
    /// # Safety
    /// The ISA of `Self`; `4·LANES + 2` readable values at `p`.
    #[inline(always)]
    unsafe fn next_columns(p: *const f32, c0: Self, c1: Self) -> [Self; 2] {
        let _ = (c0, c1);
        // SAFETY: the caller guarantees `4·LANES + 2` readable values at `p`, so `4·LANES` at `p + 2`.
        let [_, _, c4, c5] = unsafe { Self::load_stride4(p.add(2)) };
        [c4, c5]
    }
    /// The inverse of [`load_stride4`](Self::load_stride4) on registers: the `LANES` quadruples
    /// `(c[0][l], c[1][l], c[2][l], c[3][l])` back in memory order, as four registers of consecutive values
    /// (the F(4×4, 3×3) output transform's four columns back to pixels).
    unsafe fn interleave4(c: [Self; 4]) -> [Self; 4];
    /// One reduction step of a `G × NV` register tile: `acc[g][v] += x[v]·w[g]` for the `G` weights at `w`.
    /// Default: one broadcast per weight (`vbroadcastss` folds the load). NEON overrides it with FMAs by
    /// element (`fmla v.4s, x.4s, w.s[l]`: `G/4` weight loads instead of `G` broadcasts), the same fused
    /// operation, so the same bits.
    #[inline(always)]
    unsafe fn fma_step<const G: usize, const NV: usize>(
        acc: &mut [[Self; NV]; G],
        x: &[Self; NV],
        w: *const f32,
    ) {
        for (g, accg) in acc.iter_mut().enumerate() {
            // SAFETY: the caller guarantees `G` readable weights at `w` and the ISA.
            let wv = unsafe { Self::load_splat(w.add(g)) };
            for (a, &xv) in accg.iter_mut().zip(x.iter()) {
                // SAFETY: register arithmetic on the caller's ISA.
                *a = unsafe { Self::fma(*a, xv, wv) };
            }
        }
    }
    /// Hint: fetch the cache line of `p` into L1 (never faults). Default: nothing.
    #[inline(always)]
    unsafe fn prefetch(_p: *const f32) {}
}

/// Computes rows `[job.y0, job.y1)` of the convolution.
///
/// Loop order: output row, output-channel group, pixel tile, then the `9·C_in` reduction with the
/// `G × NV` accumulators in registers. One group's packed weights (`9·C_in·G` values: 5 KiB for 24→24 with
/// G = 6) stay in L1 while the row's tiles stream the three input rows from L2 (measured 6–25 % faster than
/// the pixel tile outside the groups, where all 20 KiB of weights and the tile's inputs compete for L1).
///
/// # Safety
/// The CPU has the ISA of `V`; `job` was checked by the safe API (sources of `ca`/`cb` channels and `h × w`
/// pixels in the `RowPlanar` layout, weights packed for `G`, rows inside the frame, outputs of the right
/// length), and `V::LANES · NV ≤ MAX_TILE`, so every load stays inside the padded rows.
#[inline(always)]
pub(crate) unsafe fn conv<V: ConvF32, const G: usize, const NV: usize>(
    job: &F32Job<'_>,
    out: &mut F32Out<'_>,
) {
    let l = V::LANES;
    let tile = l * NV;
    debug_assert!(tile <= crate::buffer::planar::MAX_TILE && l <= 16);
    let (w, cout) = (job.w, job.cout);
    let cin = job.ca + job.cb;
    let groups = cout.div_ceil(G);
    debug_assert!(job.weights.len() == groups * cin * 9 * G && job.bias.len() == groups * G);
    let srcs = [(job.a.as_ptr(), job.ca), (job.b.as_ptr(), job.cb)];
    for y in job.y0..job.y1 {
        for grp in 0..groups {
            let mut x0 = 0;
            while x0 < w {
                // SAFETY: the caller's guarantees; `grp < groups`, `x0 < w`.
                unsafe { tile_at::<V, G, NV>(job, out, &srcs, y, grp, x0) };
                x0 += tile;
            }
        }
    }
}

/// One `G × NV` register tile: output row `y`, channel group `grp`, pixels `x0..x0 + tile`.
///
/// # Safety
/// As [`conv`]; `grp < groups`, `x0 < w`, `y0 ≤ y < y1`.
#[inline(always)]
unsafe fn tile_at<V: ConvF32, const G: usize, const NV: usize>(
    job: &F32Job<'_>,
    out: &mut F32Out<'_>,
    srcs: &[(*const f32, usize); 2],
    y: usize,
    grp: usize,
    x0: usize,
) {
    let l = V::LANES;
    let wp = job.wp;
    let cin = job.ca + job.cb;
    // SAFETY: the caller guarantees the ISA; the accumulators are plain registers.
    let mut acc = [[unsafe { V::zero() }; NV]; G];
    // SAFETY: `grp < groups`, so the group's `cin·9·G` weights are inside `job.weights`.
    let mut wptr = unsafe { job.weights.as_ptr().add(grp * cin * 9 * G) };
    for &(src, cs) in srcs {
        for ic in 0..cs {
            for ky in 0..3 {
                // SAFETY: buffer row `y + ky ≤ h + 1`, channel `ic < cs`, column `x0 < w`: inside
                // the source of `(h + 2)·cs·wp` values.
                let row = unsafe { src.add(((y + ky) * cs + ic) * wp + x0) };
                // Every cache line (16 f32) of the next tile but one: measured +2 % on 24→24 and +5 % on
                // 4→24 with AVX2 (one line per 16-pixel tile); with AVX-512 (48-pixel tiles, three lines)
                // prefetching only the first line left the loads of the other two missing L1 (perf: a third
                // of the 8→8 layer's time on the first loads of each input row).
                for line in (0..l * NV).step_by(16) {
                    // SAFETY: a prefetch never faults; the address is computed with wrapping arithmetic.
                    unsafe { V::prefetch(row.wrapping_add(2 * l * NV + line)) };
                }
                for kx in 0..3 {
                    // Any initial value: every element is loaded just below.
                    let mut xv = acc[0];
                    for (v, x) in xv.iter_mut().enumerate() {
                        // SAFETY: column `x0 + kx + v·l + lane ≤ w − 1 + 2 + tile − 1 < wp`
                        // (`wp ≥ w + 2 + MAX_TILE`): inside the padded row.
                        *x = unsafe { V::load(row.add(kx + v * l)) };
                    }
                    // SAFETY: `wptr` walks the group's `cin·9` steps of `G` weights; ISA guaranteed by the
                    // caller.
                    unsafe { V::fma_step(&mut acc, &xv, wptr) };
                    // SAFETY: at most one past the group's last step.
                    wptr = unsafe { wptr.add(G) };
                }
            }
        }
    }
    // A copy for the epilogue (which may index it with run-time values) keeps `acc` itself
    // accessed only at constant indices, so the compiler keeps it in registers.
    let tile_acc = acc;
    // SAFETY: the caller's guarantees (see `epilogue`).
    unsafe { epilogue::<V, G, NV>(job, out, &tile_acc, y, x0, grp) };
}

/// Bias, ReLU, residual and store of one `G × NV` tile at output row `y`, pixels `x0..x0 + tile`.
///
/// # Safety
/// As [`conv`].
#[inline(always)]
unsafe fn epilogue<V: ConvF32, const G: usize, const NV: usize>(
    job: &F32Job<'_>,
    out: &mut F32Out<'_>,
    acc: &[[V; NV]; G],
    y: usize,
    x0: usize,
    grp: usize,
) {
    let l = V::LANES;
    for (g, accg) in acc.iter().enumerate() {
        let o = grp * G + g;
        if o >= job.cout {
            continue;
        }
        // SAFETY: `o < groups·G = bias.len()`.
        let b = unsafe { V::load_splat(job.bias.as_ptr().add(o)) };
        for (v, &a) in accg.iter().enumerate() {
            // SAFETY: register arithmetic, ISA guaranteed by the caller; pixels `x0 + v·l ..` of row `y`.
            unsafe { store_pixels(job, out, V::add(a, b), o, y, x0 + v * l) };
        }
    }
}

/// The epilogue of one register of pixels `px..px + LANES` of output channel `o`, row `y`, with the bias
/// added: ReLU when the plan has it, the residual, and the store (lanes past `w` stored as 0 into a
/// [`RowPlanar`](crate::RowPlanar) buffer, which keeps its right border zero; not stored into a planar
/// slice). Shared by the direct and the Winograd kernels.
///
/// # Safety
/// As [`conv`]; `o < C_out`, row `y` inside the band, `px < w + MAX_TILE − LANES` (inside the padded row).
#[inline(always)]
pub(crate) unsafe fn store_pixels<V: ConvF32>(
    job: &F32Job<'_>,
    out: &mut F32Out<'_>,
    mut r: V,
    o: usize,
    y: usize,
    px: usize,
) {
    let l = V::LANES;
    let (w, h, wp, cout) = (job.w, job.h, job.wp, job.cout);
    if job.relu {
        // SAFETY: register arithmetic, ISA guaranteed by the caller.
        r = unsafe { V::relu(r) };
    }
    // Column `1 + px` of row `y + 1` in a `[H+2][C_out][Wp]` buffer.
    let at = ((y + 1) * cout + o) * wp + 1 + px;
    if let Some(res) = job.residual {
        // SAFETY: the residual is a `[H+2][C_out][Wp]` buffer; `at + l` stays before the end of its row
        // (`wp ≥ w + 2 + MAX_TILE`). Lanes past `w` read its zero border.
        r = unsafe { V::add(r, V::load(res.as_ptr().add(at))) };
    }
    let valid = w.saturating_sub(px).min(l);
    match out {
        F32Out::Rows { data, base } => {
            if valid < l {
                // SAFETY: register arithmetic; `valid < LANES`.
                r = unsafe { V::keep_first(r, valid) };
            }
            debug_assert!(at >= *base && at - *base + l <= data.len());
            // SAFETY: as for the residual: the vector ends before the row's `wp` columns end. Row `y` lies
            // in the band (`y0 ≤ y < y1`, checked by `run_band`), which starts at element `base`.
            unsafe { V::store(data.as_mut_ptr().add(at - *base), r) };
        }
        F32Out::Planar(d) => {
            if valid == 0 {
                return;
            }
            let i = (o * h + y) * w + px;
            if valid == l {
                debug_assert!(i + l <= d.len());
                // SAFETY: pixels `px..px + l ≤ w` of row `y` of channel `o` of a `[C_out][H][W]` slice.
                unsafe { V::store(d.as_mut_ptr().add(i), r) };
            } else {
                let mut tmp = [0.0f32; 16];
                // SAFETY: `tmp` holds 16 ≥ LANES values.
                unsafe { V::store(tmp.as_mut_ptr(), r) };
                d[i..i + valid].copy_from_slice(&tmp[..valid]);
            }
        }
    }
}

/// The FMA peak loop of the vector rows: `N` independent multiply-add chains `x ← x·0.999999 + 1e-7`, `iters`
/// steps each, summed into one register (a value derived from every chain, to keep the loop alive). FLOPs =
/// `iters · N · LANES · 2`.
///
/// # Safety
/// The CPU has the ISA of `V`.
#[inline(always)]
pub(crate) unsafe fn peak_chains<V: ConvF32, const N: usize>(iters: u64) -> V {
    // SAFETY: the caller guarantees the ISA of `V`; register-only operations.
    unsafe {
        let mut acc = [V::splat(1.0); N];
        let a = V::splat(0.999_999);
        let b = V::splat(1e-7);
        for _ in 0..iters {
            for x in acc.iter_mut() {
                *x = V::fma(b, *x, a);
            }
        }
        let mut s = V::zero();
        for x in acc {
            s = V::add(s, x);
        }
        s
    }
}

/// Tests only: two registers as one ([`Pair`]): each operation on both halves, the deinterleaving loads and
/// transposes half by half (the permutation of each half's lanes is `V`'s, the halves in order).
#[cfg(test)]
impl<V: ConvF32> ConvF32 for Pair<V> {
    #[inline(always)]
    unsafe fn fma(acc: Self, a: Self, b: Self) -> Self {
        // SAFETY: the caller guarantees the ISA.
        unsafe { Pair(V::fma(acc.0, a.0, b.0), V::fma(acc.1, a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn relu(v: Self) -> Self {
        // SAFETY: the caller guarantees the ISA.
        unsafe { Pair(V::relu(v.0), V::relu(v.1)) }
    }
    #[inline(always)]
    unsafe fn keep_first(v: Self, n: usize) -> Self {
        let l = V::LANES;
        // SAFETY: the caller guarantees the ISA; `n < 2·l`, so each half gets `n < l` or `n − l < l`.
        unsafe {
            match n.cmp(&l) {
                std::cmp::Ordering::Less => Pair(V::keep_first(v.0, n), V::zero()),
                std::cmp::Ordering::Equal => Pair(v.0, V::zero()),
                std::cmp::Ordering::Greater => Pair(v.0, V::keep_first(v.1, n - l)),
            }
        }
    }
    #[inline(always)]
    unsafe fn load_deinterleaved(p: *const f32) -> (Self, Self) {
        // SAFETY: the caller guarantees the ISA and `4·V::LANES` readable values at `p`.
        unsafe { Pair::halves(p, V::load_deinterleaved) }
    }
    #[inline(always)]
    unsafe fn interleave(e: Self, o: Self) -> (Self, Self) {
        // SAFETY: the caller guarantees the ISA.
        unsafe {
            let (p0, p1) = V::interleave(e.0, o.0);
            let (p2, p3) = V::interleave(e.1, o.1);
            (Pair(p0, p1), Pair(p2, p3))
        }
    }
    #[inline(always)]
    unsafe fn load_stride4(p: *const f32) -> [Self; 4] {
        // SAFETY: the caller guarantees the ISA and `8·V::LANES` readable values at `p`.
        unsafe {
            let lo = V::load_stride4(p);
            let hi = V::load_stride4(p.add(4 * V::LANES));
            [0, 1, 2, 3].map(|j| Pair(lo[j], hi[j]))
        }
    }
    #[inline(always)]
    unsafe fn interleave4(c: [Self; 4]) -> [Self; 4] {
        // SAFETY: the caller guarantees the ISA.
        unsafe {
            let lo = V::interleave4(c.map(|v| v.0));
            let hi = V::interleave4(c.map(|v| v.1));
            [
                Pair(lo[0], lo[1]),
                Pair(lo[2], lo[3]),
                Pair(hi[0], hi[1]),
                Pair(hi[2], hi[3]),
            ]
        }
    }
}
